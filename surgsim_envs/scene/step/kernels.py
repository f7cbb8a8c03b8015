"""The per-substep kernels of the physics step (numba, ``cache=True``): read the tool geoms out of
MuJoCo's data, rate-limit the actuator targets, and write the reaction wrench into
``xfrc_applied``. Both step loops call them (the Python reference loop of
:class:`~surgsim_envs.scene.simulation.Simulation` and the compiled one,
:mod:`surgsim_envs.scene.step.loop`), so the two run the same code. Units: m, s, N, N m.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def gather_geoms(geom_ids, geom_body, body_root, bodies, geom_xpos, geom_xmat, cvel, subtree_com, xipos,
                 out_pos, out_mat, out_vel, out_com):
    """Copy the tool geoms' world poses and the velocity [w, v] of each geom origin (world frame)."""
    for k in range(geom_ids.shape[0]):
        g = geom_ids[k]
        b = geom_body[k]
        r = body_root[k]
        for j in range(3):
            out_pos[k, j] = geom_xpos[g, j]
        for j in range(9):
            out_mat[k, j] = geom_xmat[g, j]
        wx, wy, wz = cvel[b, 0], cvel[b, 1], cvel[b, 2]
        dx = geom_xpos[g, 0] - subtree_com[r, 0]
        dy = geom_xpos[g, 1] - subtree_com[r, 1]
        dz = geom_xpos[g, 2] - subtree_com[r, 2]
        out_vel[k, 0] = wx
        out_vel[k, 1] = wy
        out_vel[k, 2] = wz
        out_vel[k, 3] = cvel[b, 3] + wy * dz - wz * dy
        out_vel[k, 4] = cvel[b, 4] + wz * dx - wx * dz
        out_vel[k, 5] = cvel[b, 5] + wx * dy - wy * dx
    for t in range(bodies.shape[0]):
        for j in range(3):
            out_com[t, j] = xipos[bodies[t], j]


@njit(cache=True)
def rate_limit(ctrl, goal, rate, dt):
    """Move ``ctrl`` towards ``goal`` by at most ``rate * dt`` per entry; True while any entry still moves."""
    moving = False
    for i in range(ctrl.shape[0]):
        delta = goal[i] - ctrl[i]
        lim = rate[i] * dt
        if delta > lim:
            delta = lim
        elif delta < -lim:
            delta = -lim
        ctrl[i] += delta
        if abs(goal[i] - ctrl[i]) > 1e-12:
            moving = True
    return moving


@njit(cache=True)
def write_rows(xfrc, bodies, wrench):
    for k in range(bodies.shape[0]):
        for j in range(6):
            xfrc[bodies[k], j] = wrench[k, j]


@njit(cache=True)
def add_wrench(wrench, force, torque):
    """``wrench[:, :3] += force; wrench[:, 3:] += torque`` for (T,6), (T,3), (T,3)."""
    for k in range(wrench.shape[0]):
        for j in range(3):
            wrench[k, j] += force[k, j]
            wrench[k, 3 + j] += torque[k, j]


@njit(cache=True)
def advance_geoms(gpos, gpos0, gvel, s):
    """``gpos = gpos0 + s * (linear velocity of each geom origin)`` (s in seconds)."""
    for k in range(gpos.shape[0]):
        for j in range(3):
            gpos[k, j] = gpos0[k, j] + s * gvel[k, 3 + j]


@njit(cache=True)
def zero_rows(xfrc, bodies):
    for k in range(bodies.shape[0]):
        for j in range(6):
            xfrc[bodies[k], j] = 0.0

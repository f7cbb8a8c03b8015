"""Warp kernels of tool-tissue contact over W worlds (float64): the law of
:mod:`surgsim_envs.contact.model` (penalty normal force with one-sided damping, Coulomb stick/slip
friction with an anchor per (point, geom), :mod:`surgsim_envs.contact.friction`) for sphere,
capsule, box and cylinder tool geoms.

* :func:`gather_geoms`: one thread per (world, geom) copies MuJoCo Warp's float32 geom pose and
  the velocity of the geom origin (from the body's ``cvel`` about its root's ``subtree_com``, as
  ``scene/simulation.py`` does) into float64, and each tool body's torque reference ``xipos``.
* :func:`contact_points`: one thread per (world, candidate node): its force on the tissue
  (``f_ext``) and each geom's part of it (``point_force``, kept for the tool sums).
* :func:`tool_sums`: one thread per (world, tool body) sums the reactions of its geoms' points in
  the CPU kernel's order (points, then geoms), so no atomics are needed; then the per-tool
  report (normal and tangential force, contact and slipping points, penetration).
* :func:`geom_sums` (one thread per (world, geom)) and :func:`contact_node_mask` (per (world,
  node)): readouts computed when asked for, from the last tissue step's per-point parts (a
  grasper's per-jaw normal and tangential forces; the nodes in contact).
* :func:`write_reaction`: the sums into MuJoCo Warp's ``xfrc_applied`` (float32), and
  :func:`zero_reaction` clears those rows after ``step2``.
"""

from __future__ import annotations

import warp as wp

# forward kernels only: nothing differentiates them, and adjoints would double the compile time
wp.set_module_options({"enable_backward": False})

f64 = wp.float64
SPHERE, CAPSULE, BOX, CYLINDER = 0, 1, 2, 3


@wp.kernel
def gather_geoms(geom_ids: wp.array(dtype=wp.int32), geom_body: wp.array(dtype=wp.int32),
                 geom_root: wp.array(dtype=wp.int32), bodies: wp.array(dtype=wp.int32),
                 geom_xpos: wp.array2d(dtype=wp.vec3), geom_xmat: wp.array2d(dtype=wp.mat33),
                 cvel: wp.array2d(dtype=wp.spatial_vector), subtree_com: wp.array2d(dtype=wp.vec3),
                 xipos: wp.array2d(dtype=wp.vec3),
                 gpos: wp.array2d(dtype=wp.vec3d), gmat: wp.array2d(dtype=wp.mat33d),
                 gang: wp.array2d(dtype=wp.vec3d), glin: wp.array2d(dtype=wp.vec3d), tcom: wp.array2d(dtype=wp.vec3d)):
    w, k = wp.tid()
    g = geom_ids[k]
    b = geom_body[k]
    p = wp.vec3d(geom_xpos[w, g])
    gpos[w, k] = p
    gmat[w, k] = wp.mat33d(geom_xmat[w, g])
    cv = cvel[w, b]
    om = wp.vec3d(f64(cv[0]), f64(cv[1]), f64(cv[2]))
    r = p - wp.vec3d(subtree_com[w, geom_root[k]])
    gang[w, k] = om
    glin[w, k] = wp.vec3d(f64(cv[3]) + om[1] * r[2] - om[2] * r[1], f64(cv[4]) + om[2] * r[0] - om[0] * r[2],
                          f64(cv[5]) + om[0] * r[1] - om[1] * r[0])
    if k < bodies.shape[0]:
        tcom[w, k] = wp.vec3d(xipos[w, bodies[k]])


@wp.func
def bounding_radius(kind: int, s0: f64, s1: f64, s2: f64) -> f64:
    """Radius (m) of a sphere about the geom centre containing the shape (contact/shapes.py)."""
    if kind == 0:
        return s0
    if kind == 1:
        return s0 + s1
    if kind == 2:
        return wp.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    return wp.sqrt(s0 * s0 + s1 * s1)


@wp.func
def local_outside(kind: int, s0: f64, s1: f64, s2: f64, q: wp.vec3d) -> bool:
    """Local point q outside (or on) the shape, without square roots (contact/shapes.py)."""
    if kind == 0:
        return q[0] * q[0] + q[1] * q[1] + q[2] * q[2] >= s0 * s0
    if kind == 1:
        sz = wp.min(wp.max(q[2], -s1), s1)
        return q[0] * q[0] + q[1] * q[1] + (q[2] - sz) * (q[2] - sz) >= s0 * s0
    if kind == 2:
        return wp.abs(q[0]) >= s0 or wp.abs(q[1]) >= s1 or wp.abs(q[2]) >= s2
    return wp.abs(q[2]) >= s1 or q[0] * q[0] + q[1] * q[1] >= s0 * s0


@wp.func
def local_sdf(kind: int, s0: f64, s1: f64, s2: f64, q: wp.vec3d) -> wp.vec4d:
    """(local outward normal (3), signed distance m) of local point q to the shape at the origin:
    the arithmetic of ``contact.shapes.local_sdf`` for SPHERE 0, CAPSULE 1, BOX 2, CYLINDER 3."""
    zero = f64(0.0)
    one = f64(1.0)
    if kind == 0 or kind == 1:
        sz = zero
        if kind == 1:
            sz = wp.min(wp.max(q[2], -s1), s1)
        vx = q[0]
        vy = q[1]
        vz = q[2] - sz
        nv = wp.sqrt(vx * vx + vy * vy + vz * vz)
        if nv > f64(1e-300):
            return wp.vec4d(vx / nv, vy / nv, vz / nv, nv - s0)
        if kind == 0:
            return wp.vec4d(zero, zero, one, nv - s0)
        return wp.vec4d(one, zero, zero, nv - s0)
    if kind == 2:
        ax = wp.abs(q[0]) - s0
        ay = wp.abs(q[1]) - s1
        az = wp.abs(q[2]) - s2
        if ax > zero or ay > zero or az > zero:
            dx = q[0] - wp.min(wp.max(q[0], -s0), s0)
            dy = q[1] - wp.min(wp.max(q[1], -s1), s1)
            dz = q[2] - wp.min(wp.max(q[2], -s2), s2)
            dist = wp.sqrt(dx * dx + dy * dy + dz * dz)
            return wp.vec4d(dx / dist, dy / dist, dz / dist, dist)
        if ax >= ay and ax >= az:
            sx = one
            if q[0] < zero:
                sx = -one
            return wp.vec4d(sx, zero, zero, ax)
        if ay >= az:
            sy = one
            if q[1] < zero:
                sy = -one
            return wp.vec4d(zero, sy, zero, ay)
        sz2 = one
        if q[2] < zero:
            sz2 = -one
        return wp.vec4d(zero, zero, sz2, az)
    rho = wp.sqrt(q[0] * q[0] + q[1] * q[1])
    ex = one
    ey = zero
    if rho > f64(1e-300):
        ex = q[0] / rho
        ey = q[1] / rho
    dr = rho - s0
    dzc = wp.abs(q[2]) - s1
    sgn = one
    if q[2] < zero:
        sgn = -one
    if dr > zero or dzc > zero:
        crho = wp.min(rho, s0)
        dx = q[0] - ex * crho
        dy = q[1] - ey * crho
        dz = q[2] - wp.min(wp.max(q[2], -s1), s1)
        dist = wp.sqrt(dx * dx + dy * dy + dz * dz)
        return wp.vec4d(dx / dist, dy / dist, dz / dist, dist)
    if dr >= dzc:
        return wp.vec4d(ex, ey, zero, dr)
    return wp.vec4d(zero, zero, sgn, dzc)


@wp.kernel
def contact_points(x: wp.array2d(dtype=wp.vec3d), v: wp.array2d(dtype=wp.vec3d), cand: wp.array(dtype=wp.int32),
                   kind: wp.array(dtype=wp.int32), tool: wp.array(dtype=wp.int32), size: wp.array2d(dtype=f64),
                   gpos: wp.array2d(dtype=wp.vec3d), gmat: wp.array2d(dtype=wp.mat33d),
                   gang: wp.array2d(dtype=wp.vec3d), glin: wp.array2d(dtype=wp.vec3d),
                   mu: wp.array2d(dtype=f64), mu_s: wp.array2d(dtype=f64), k_n: f64, c_n: f64, k_t: f64,
                   anchor: wp.array3d(dtype=wp.vec3d), state: wp.array3d(dtype=wp.int32),
                   f_ext: wp.array2d(dtype=wp.vec3d), point_force: wp.array3d(dtype=wp.vec3d),
                   point_fn: wp.array3d(dtype=f64), point_ft: wp.array3d(dtype=wp.vec3d),
                   point_depth: wp.array3d(dtype=f64)):
    w, c = wp.tid()
    i = cand[c]
    xi = x[w, i]
    zero = wp.vec3d(f64(0.0), f64(0.0), f64(0.0))
    ftot = zero
    for g in range(kind.shape[0]):
        point_force[w, c, g] = zero
        point_fn[w, c, g] = f64(0.0)
        point_ft[w, c, g] = zero
        point_depth[w, c, g] = f64(0.0)
        s0 = size[g, 0]
        s1 = size[g, 1]
        s2 = size[g, 2]
        d = xi - gpos[w, g]
        rg = bounding_radius(kind[g], s0, s1, s2)
        if d[0] * d[0] + d[1] * d[1] + d[2] * d[2] >= rg * rg:
            state[w, c, g] = 0
            continue
        R = gmat[w, g]
        q = wp.transpose(R) * d          # local = R^T (x - pos)
        if local_outside(kind[g], s0, s1, s2, q):
            state[w, c, g] = 0
            continue
        sd = local_sdf(kind[g], s0, s1, s2, q)
        phi = sd[3]
        if phi >= f64(0.0):
            state[w, c, g] = 0
            continue
        nl = wp.vec3d(sd[0], sd[1], sd[2])
        n = R * nl
        depth = -phi
        om = gang[w, g]
        u = glin[w, g]
        vs = wp.vec3d(u[0] + om[1] * d[2] - om[2] * d[1], u[1] + om[2] * d[0] - om[0] * d[2],
                      u[2] + om[0] * d[1] - om[1] * d[0])
        vi = v[w, i]
        vn = (vi[0] - vs[0]) * n[0] + (vi[1] - vs[1]) * n[1] + (vi[2] - vs[2]) * n[2]
        f_n = k_n * depth
        if vn < f64(0.0):
            f_n = f_n - c_n * vn
        # Coulomb stick/slip with the anchor kept in the geom's local frame
        t = tool[g]
        ft = zero
        slip = int(0)
        st = state[w, c, g]
        if st == 0:
            anchor[w, c, g] = q
        else:
            a = gpos[w, g] + R * anchor[w, c, g]
            e = xi - a
            en = e[0] * n[0] + e[1] * n[1] + e[2] * n[2]
            tv = wp.vec3d(e[0] - en * n[0], e[1] - en * n[1], e[2] - en * n[2])
            stretch = wp.sqrt(tv[0] * tv[0] + tv[1] * tv[1] + tv[2] * tv[2])
            cap = mu[w, t] * f_n
            if st != 2:
                if mu_s[w, t] > mu[w, t]:
                    cap = mu_s[w, t] * f_n
            else:
                cap = cap * f64(1.000000001)
            if k_t * stretch <= cap:
                ft = -k_t * tv
            else:
                slip = 1
                cap = mu[w, t] * f_n
                sc = cap / stretch
                ft = -sc * tv
                keep = cap / (k_t * stretch)
                na = wp.vec3d(xi[0] - keep * tv[0], xi[1] - keep * tv[1], xi[2] - keep * tv[2])
                anchor[w, c, g] = wp.transpose(R) * (na - gpos[w, g])
        state[w, c, g] = 1 + slip
        gf = wp.vec3d(f_n * n[0] + ft[0], f_n * n[1] + ft[1], f_n * n[2] + ft[2])
        ftot = ftot + gf
        point_force[w, c, g] = gf
        point_fn[w, c, g] = f_n
        point_ft[w, c, g] = ft
        point_depth[w, c, g] = depth
    f_ext[w, i] = ftot


@wp.kernel
def tool_sums(x: wp.array2d(dtype=wp.vec3d), cand: wp.array(dtype=wp.int32), tool: wp.array(dtype=wp.int32),
              point_force: wp.array3d(dtype=wp.vec3d), point_fn: wp.array3d(dtype=f64),
              point_ft: wp.array3d(dtype=wp.vec3d), point_depth: wp.array3d(dtype=f64),
              state: wp.array3d(dtype=wp.int32), tcom: wp.array2d(dtype=wp.vec3d),
              tool_force: wp.array2d(dtype=wp.vec3d), tool_torque: wp.array2d(dtype=wp.vec3d),
              tool_fn: wp.array2d(dtype=f64), tool_ft: wp.array2d(dtype=f64), tool_contacts: wp.array2d(dtype=wp.int32),
              tool_slipping: wp.array2d(dtype=wp.int32), tool_depth: wp.array2d(dtype=f64)):
    """Reaction force (N) and torque about the body's centre of mass (N m) on tool body t: minus the
    sum over its geoms' contact points of their forces, applied at the points (positions before
    the tissue step, as the CPU loop takes them); and its contact report, as the CPU kernel's: the
    sum of normal magnitudes, the magnitude of the summed friction force, the points touching the
    body and those sliding on one of its geoms (each point counted once per body), the deepest
    penetration."""
    w, t = wp.tid()
    F = wp.vec3d(f64(0.0), f64(0.0), f64(0.0))
    M = wp.vec3d(f64(0.0), f64(0.0), f64(0.0))
    fn = f64(0.0)
    ftv = wp.vec3d(f64(0.0), f64(0.0), f64(0.0))
    depth = f64(0.0)
    count = int(0)
    slipping = int(0)
    com = tcom[w, t]
    for c in range(cand.shape[0]):
        touched = int(0)
        slid = int(0)
        for g in range(tool.shape[0]):
            if tool[g] != t:
                continue
            d = point_depth[w, c, g]
            if d <= f64(0.0):
                continue
            gf = point_force[w, c, g]
            F = F - gf
            r = x[w, cand[c]] - com
            M = M - wp.cross(r, gf)
            fn = fn + point_fn[w, c, g]
            ftv = ftv + point_ft[w, c, g]
            touched = 1
            if state[w, c, g] == 2:
                slid = 1
            if d > depth:
                depth = d
        count = count + touched
        slipping = slipping + slid
    tool_force[w, t] = F
    tool_torque[w, t] = M
    tool_fn[w, t] = fn
    tool_ft[w, t] = wp.sqrt(ftv[0] * ftv[0] + ftv[1] * ftv[1] + ftv[2] * ftv[2])
    tool_contacts[w, t] = count
    tool_slipping[w, t] = slipping
    tool_depth[w, t] = depth


@wp.kernel
def geom_sums(point_fn: wp.array3d(dtype=f64), point_ft: wp.array3d(dtype=wp.vec3d),
              point_depth: wp.array3d(dtype=f64), geom_fn: wp.array2d(dtype=f64), geom_ft: wp.array2d(dtype=f64)):
    """Per geom (one thread per (world, geom), points summed in order, as the CPU kernel's
    ``geom_normal_force`` / ``geom_tangential_force``): the sum of the normal force magnitudes (N)
    and the magnitude of the summed friction force (N) of its contact points; e.g. a grasper's
    per-jaw forces."""
    w, g = wp.tid()
    fn = f64(0.0)
    ftv = wp.vec3d(f64(0.0), f64(0.0), f64(0.0))
    for c in range(point_fn.shape[1]):
        if point_depth[w, c, g] <= f64(0.0):
            continue
        fn = fn + point_fn[w, c, g]
        ftv = ftv + point_ft[w, c, g]
    geom_fn[w, g] = fn
    geom_ft[w, g] = wp.sqrt(ftv[0] * ftv[0] + ftv[1] * ftv[1] + ftv[2] * ftv[2])


@wp.kernel
def contact_node_mask(f_ext: wp.array2d(dtype=wp.vec3d), mask: wp.array2d(dtype=wp.int32)):
    """1 for the nodes that felt a contact force in the last tissue step (|f|^2 > 0, as
    ``grasp.terms.contact_nodes`` on the CPU), else 0."""
    w, i = wp.tid()
    f = f_ext[w, i]
    hit = int(0)
    if f[0] * f[0] + f[1] * f[1] + f[2] * f[2] > f64(0.0):
        hit = 1
    mask[w, i] = hit


@wp.kernel
def advance_geoms(gpos0: wp.array2d(dtype=wp.vec3d), glin: wp.array2d(dtype=wp.vec3d), s: f64,
                  gpos: wp.array2d(dtype=wp.vec3d)):
    """Tissue sub-cycling: geom origins moved along their velocity for ``s`` seconds (orientation held)."""
    w, k = wp.tid()
    gpos[w, k] = gpos0[w, k] + s * glin[w, k]


@wp.kernel
def add_wrench(tool_force: wp.array2d(dtype=wp.vec3d), tool_torque: wp.array2d(dtype=wp.vec3d),
               sum_force: wp.array2d(dtype=wp.vec3d), sum_torque: wp.array2d(dtype=wp.vec3d)):
    w, t = wp.tid()
    sum_force[w, t] = sum_force[w, t] + tool_force[w, t]
    sum_torque[w, t] = sum_torque[w, t] + tool_torque[w, t]


@wp.kernel
def write_reaction(bodies: wp.array(dtype=wp.int32), sum_force: wp.array2d(dtype=wp.vec3d),
                   sum_torque: wp.array2d(dtype=wp.vec3d), n: f64, xfrc: wp.array2d(dtype=wp.spatial_vector)):
    """The reaction (mean over ``n`` tissue sub-steps) into ``xfrc_applied``; the sums are cleared."""
    w, t = wp.tid()
    F = sum_force[w, t] / n
    M = sum_torque[w, t] / n
    sum_force[w, t] = wp.vec3d(f64(0.0), f64(0.0), f64(0.0))
    sum_torque[w, t] = wp.vec3d(f64(0.0), f64(0.0), f64(0.0))
    xfrc[w, bodies[t]] = wp.spatial_vector(wp.float32(F[0]), wp.float32(F[1]), wp.float32(F[2]),
                                           wp.float32(M[0]), wp.float32(M[1]), wp.float32(M[2]))


@wp.kernel
def zero_reaction(bodies: wp.array(dtype=wp.int32), xfrc: wp.array2d(dtype=wp.spatial_vector)):
    w, t = wp.tid()
    xfrc[w, bodies[t]] = wp.spatial_vector()

"""Warp kernels of the mass-spring tissue step over W worlds (float64), the physics of
:func:`surgsim_envs.tissue.msd_kernels.symplectic_step_work` (docs/models/mass_spring.md):

    f_e = K1 dl + K2 dl^3 + s_e,   s_e = decay s_e + kMg (dl - dl_e)   (Maxwell branch, committed)
    volume term per tet: -kv (V - V0) / V0 dV/dx
    v += dt ((f_springs + f_volume + f_ext - b0 v) / m + g);   x += dt v   (fixed nodes untouched)

Three launches per step, no atomics: one thread per (world, spring) writes the spring's force
vector, one per (world, tet) its four corner forces, and one per (world, node) gathers them
through CSR incidence lists (``node_springs``: spring id and sign; ``node_corners``: slot
``4 t + corner``) and integrates. A node's sum runs in a fixed order (springs, then tets), so a
step is deterministic; the order differs from the CPU kernel's scatter, so the two agree to
rounding (about 1e-16 relative per step), not bit for bit.

``fresh[w] = 1`` marks a world whose Maxwell branches were just reset: its first step uses the
branch coefficients of a zero interval (kM, decay 1), as the CPU model does after ``reset()``.
"""

from __future__ import annotations

import warp as wp

# forward kernels only: nothing differentiates them, and adjoints would double the compile time
wp.set_module_options({"enable_backward": False})

f64 = wp.float64


@wp.kernel
def spring_forces(x: wp.array2d(dtype=wp.vec3d), si: wp.array(dtype=wp.int32), sj: wp.array(dtype=wp.int32),
                  L0: wp.array(dtype=f64), K1: wp.array2d(dtype=f64), K2: wp.array2d(dtype=f64),
                  kM: wp.array2d(dtype=f64), kMg: wp.array2d(dtype=f64), decay: wp.array(dtype=f64),
                  fresh: wp.array(dtype=wp.int32), s_state: wp.array2d(dtype=f64), dl_state: wp.array2d(dtype=f64),
                  f_spring: wp.array2d(dtype=wp.vec3d)):
    """Force on node si[e] (N) of spring e in world w (node sj[e] gets its negative); commits the branch."""
    w, e = wp.tid()
    d = x[w, sj[e]] - x[w, si[e]]
    length = wp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    dl = length - L0[e]
    kg = kMg[w, e]
    dec = decay[e]
    if fresh[w] != 0:
        kg = kM[w, e]
        dec = f64(1.0)
    sb = dec * s_state[w, e] + kg * (dl - dl_state[w, e])
    s_state[w, e] = sb
    dl_state[w, e] = dl
    f = K1[w, e] * dl + K2[w, e] * dl * dl * dl + sb
    c = f64(0.0)
    if length > f64(1e-300):
        c = f / length
    f_spring[w, e] = wp.vec3d(c * d[0], c * d[1], c * d[2])


@wp.kernel
def volume_forces(x: wp.array2d(dtype=wp.vec3d), tets: wp.array2d(dtype=wp.int32), V0: wp.array(dtype=f64),
                  kv: wp.array2d(dtype=f64), f_corner: wp.array2d(dtype=wp.vec3d)):
    """Forces (N) of tet t's volume term on its four corners, into slots 4 t .. 4 t + 3."""
    w, t = wp.tid()
    xa = x[w, tets[t, 0]]
    e1 = x[w, tets[t, 1]] - xa
    e2 = x[w, tets[t, 2]] - xa
    e3 = x[w, tets[t, 3]] - xa
    g1 = wp.vec3d(e2[1] * e3[2] - e2[2] * e3[1], e2[2] * e3[0] - e2[0] * e3[2], e2[0] * e3[1] - e2[1] * e3[0])
    g2 = wp.vec3d(e3[1] * e1[2] - e3[2] * e1[1], e3[2] * e1[0] - e3[0] * e1[2], e3[0] * e1[1] - e3[1] * e1[0])
    g3 = wp.vec3d(e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0])
    vol = (e1[0] * g1[0] + e1[1] * g1[1] + e1[2] * g1[2]) / f64(6.0)
    k = -kv[w, t] * (vol - V0[t]) / (f64(6.0) * V0[t])
    f_corner[w, 4 * t + 1] = k * g1
    f_corner[w, 4 * t + 2] = k * g2
    f_corner[w, 4 * t + 3] = k * g3
    f_corner[w, 4 * t] = -(k * g1 + k * g2 + k * g3)


@wp.kernel
def integrate_nodes(x: wp.array2d(dtype=wp.vec3d), v: wp.array2d(dtype=wp.vec3d),
                    spring_start: wp.array(dtype=wp.int32), node_springs: wp.array(dtype=wp.int32),
                    spring_sign: wp.array(dtype=f64), corner_start: wp.array(dtype=wp.int32),
                    node_corners: wp.array(dtype=wp.int32), f_spring: wp.array2d(dtype=wp.vec3d),
                    f_corner: wp.array2d(dtype=wp.vec3d), f_ext: wp.array2d(dtype=wp.vec3d),
                    inv_mass: wp.array(dtype=f64), b0: wp.array(dtype=f64), gravity: wp.vec3d,
                    fixed: wp.array(dtype=wp.int32), dt: f64, fresh: wp.array(dtype=wp.int32),
                    diverged: wp.array(dtype=wp.int32)):
    """Gather node i's forces and take its symplectic Euler step (fixed nodes stay); a non-finite
    position sets ``diverged[w]`` (every writer writes 1: no atomics needed)."""
    w, i = wp.tid()
    if i == 0:
        fresh[w] = 0          # read by spring_forces earlier in this step; the next step is not fresh
    if fixed[i] != 0:
        return
    f = wp.vec3d(f64(0.0), f64(0.0), f64(0.0))
    for q in range(spring_start[i], spring_start[i + 1]):
        f = f + spring_sign[q] * f_spring[w, node_springs[q]]
    for q in range(corner_start[i], corner_start[i + 1]):
        f = f + f_corner[w, node_corners[q]]
    im = inv_mass[i]
    b = b0[i]
    vi = v[w, i]
    fe = f_ext[w, i]
    vn = wp.vec3d(vi[0] + dt * ((f[0] + fe[0] - b * vi[0]) * im + gravity[0]),
                  vi[1] + dt * ((f[1] + fe[1] - b * vi[1]) * im + gravity[1]),
                  vi[2] + dt * ((f[2] + fe[2] - b * vi[2]) * im + gravity[2]))
    v[w, i] = vn
    xi = x[w, i]
    xn = wp.vec3d(xi[0] + dt * vn[0], xi[1] + dt * vn[1], xi[2] + dt * vn[2])
    x[w, i] = xn
    if not (wp.isfinite(xn[0]) and wp.isfinite(xn[1]) and wp.isfinite(xn[2])):
        diverged[w] = 1


@wp.kernel
def scale_spring_constants(worlds: wp.array(dtype=wp.int32), factors: wp.array2d(dtype=f64),
                           indptr: wp.array(dtype=wp.int32), cols: wp.array(dtype=wp.int32),
                           weights: wp.array(dtype=f64), base: wp.array2d(dtype=f64), K1: wp.array2d(dtype=f64),
                           K2: wp.array2d(dtype=f64), kM: wp.array2d(dtype=f64), kMg: wp.array2d(dtype=f64)):
    """World ``worlds[k]``'s spring constants from per-tet Young's factors ``factors[k]``: each is the
    template's (``base`` rows K1, K2, kM, kMg) times the E V-weighted mean factor of the spring's
    tets (CSR row e of ``BatchSimulation``'s spring weights, summed in its order as scipy's product)."""
    k, e = wp.tid()
    acc = f64(0.0)
    for jj in range(indptr[e], indptr[e + 1]):
        acc += weights[jj] * factors[k, cols[jj]]
    w = worlds[k]
    K1[w, e] = base[0, e] * acc
    K2[w, e] = base[1, e] * acc
    kM[w, e] = base[2, e] * acc
    kMg[w, e] = base[3, e] * acc


@wp.kernel
def scale_volume_constants(worlds: wp.array(dtype=wp.int32), factors: wp.array2d(dtype=f64),
                           base: wp.array(dtype=f64), kv: wp.array2d(dtype=f64)):
    """World ``worlds[k]``'s volume stiffness of tet t: the template's times its factor."""
    k, t = wp.tid()
    kv[worlds[k], t] = base[t] * factors[k, t]

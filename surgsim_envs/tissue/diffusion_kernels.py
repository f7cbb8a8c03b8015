"""numba kernels of the chemical-diffusion surface model (Zhong et al. 2016): one explicit step.

Flat arrays only (no Python objects), so the same kernel can later run batched. The operators
come from :mod:`surgsim_envs.tissue.diffusion_operator`; the model is
:mod:`surgsim_envs.tissue.diffusion`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: |C| (Pa) above which the concentration is taken as diverging
MAX_CONCENTRATION = 1e12
#: |C| may exceed the largest load or initial value by this factor before it counts as diverging
#: (the explicit update obeys the maximum principle when stable; obtuse triangles overshoot a little)
GROWTH = 4.0


@njit(cache=True, nogil=True)
def diffuse(conc, tmp, source, nodes, rate_ptr, rate_idx, rate_val, inv_tau, dt, substeps):
    """``substeps`` explicit Euler steps of dC/dt = sum_j a_ij (C_j - C_i) + (p_i - C_i) / tau
    (eqs. 9.9 / 9.16 with the load and the exchange with the bulk) over ``nodes``; ``source`` is
    p (Pa). Returns False if the concentration diverged (non-finite or > MAX_CONCENTRATION)."""
    h = dt / substeps
    for _ in range(substeps):
        for q in range(nodes.shape[0]):
            i = nodes[q]
            ci = conc[i]
            acc = (source[i] - ci) * inv_tau
            for k in range(rate_ptr[i], rate_ptr[i + 1]):
                acc += rate_val[k] * (conc[rate_idx[k]] - ci)
            tmp[i] = ci + h * acc
        ok = True
        for q in range(nodes.shape[0]):
            i = nodes[q]
            c = tmp[i]
            if not (abs(c) < MAX_CONCENTRATION):
                ok = False
            conc[i] = c
        if not ok:
            return False
    return True


@njit(cache=True, nogil=True)
def load_source(forces, normals, areas, nodes, source):
    """Contact pressure p_i = max(0, -G_i . n_i) / S_i (Pa) at every node in ``nodes``; returns max p."""
    pmax = 0.0
    for q in range(nodes.shape[0]):
        i = nodes[q]
        gn = forces[i, 0] * normals[i, 0] + forces[i, 1] * normals[i, 1] + forces[i, 2] * normals[i, 2]
        p = -gn / areas[i] if gn < 0.0 else 0.0
        source[i] = p
        if p > pmax:
            pmax = p
    return pmax


@njit(cache=True, nogil=True)
def max_abs(values, nodes):
    """max |values[i]| over ``nodes`` (inf if any is non-finite)."""
    out = 0.0
    for q in range(nodes.shape[0]):
        v = abs(values[nodes[q]])
        if not (v < np.inf):
            return np.inf
        if v > out:
            out = v
    return out


#: columns of the per-node coefficient table ``coef`` (N, COEF_COLUMNS)
NX, NY, NZ, AREA, INV_MASS, DAMPING, K_AREA, BETA = range(8)
COEF_COLUMNS = 8


@njit(cache=True, nogil=True)
def move_nodes(pos, vel, rest, conc, forces, coef, gf_ptr, gf_idx, gf_val, free, gravity, dt):
    """Eq. 9.22, symplectic Euler, at the ``free`` nodes:
    m a = -S C n (the diffused load) + G~ (external force minus its compressive normal part)
          - sum_k gf_val[k] C[gf_idx[k]] (gradient force, eqs. 9.19-9.21)
          - S kappa (1 + beta |u|^2) u (the bulk under the surface) - damping m v + m g.
    ``coef`` rows: normal (3), S, 1/m, damping (1/s), S kappa (N/m), beta (1/m^2)."""
    for q in range(free.shape[0]):
        i = free[q]
        gx = 0.0
        gy = 0.0
        gz = 0.0
        for k in range(gf_ptr[i], gf_ptr[i + 1]):
            c = conc[gf_idx[k]]
            gx += gf_val[k, 0] * c
            gy += gf_val[k, 1] * c
            gz += gf_val[k, 2] * c
        nx = coef[i, NX]
        ny = coef[i, NY]
        nz = coef[i, NZ]
        fx = forces[i, 0]
        fy = forces[i, 1]
        fz = forces[i, 2]
        gn = fx * nx + fy * ny + fz * nz
        if gn < 0.0:                      # the compressive part enters through the concentration
            fx -= gn * nx
            fy -= gn * ny
            fz -= gn * nz
        load = coef[i, AREA] * conc[i]
        ux = pos[i, 0] - rest[i, 0]
        uy = pos[i, 1] - rest[i, 1]
        uz = pos[i, 2] - rest[i, 2]
        k_el = coef[i, K_AREA] * (1.0 + coef[i, BETA] * (ux * ux + uy * uy + uz * uz))
        c_d = coef[i, DAMPING]
        h_m = dt * coef[i, INV_MASS]
        vx = vel[i, 0] + h_m * (fx - load * nx - gx - k_el * ux) + dt * (gravity[0] - c_d * vel[i, 0])
        vy = vel[i, 1] + h_m * (fy - load * ny - gy - k_el * uy) + dt * (gravity[1] - c_d * vel[i, 1])
        vz = vel[i, 2] + h_m * (fz - load * nz - gz - k_el * uz) + dt * (gravity[2] - c_d * vel[i, 2])
        vel[i, 0] = vx
        vel[i, 1] = vy
        vel[i, 2] = vz
        pos[i, 0] += dt * vx
        pos[i, 1] += dt * vy
        pos[i, 2] += dt * vz


@njit(cache=True, nogil=True)
def diffusion_step(pos, vel, rest, conc, tmp, source, forces, coef, normals, areas,
                   rate_ptr, rate_idx, rate_val, gf_ptr, gf_idx, gf_val, active, free, gravity, inv_tau, dt, substeps,
                   bound):
    """One model step: load -> diffusion -> forces and motion.

    ``bound`` (Pa) is the largest |C| seen or injected so far: a stable update obeys the maximum
    principle (|C| never exceeds it), so |C| above ``GROWTH x bound`` means divergence. Returns
    the new bound, or -1 if the concentration diverged (the nodes are then not moved)."""
    pmax = load_source(forces, normals, areas, active, source)
    if pmax > bound:
        bound = pmax
    if not diffuse(conc, tmp, source, active, rate_ptr, rate_idx, rate_val, inv_tau, dt, substeps):
        return -1.0
    if max_abs(conc, active) > GROWTH * bound + 1e-9:
        return -1.0
    move_nodes(pos, vel, rest, conc, forces, coef, gf_ptr, gf_idx, gf_val, free, gravity, dt)
    return bound

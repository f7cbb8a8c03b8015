"""The compiled step of :class:`MassSpringModel` (the tasks' default model), integrators
"symplectic" and "auto" (the ABI: :mod:`surgsim_envs.tissue.compiled`; the scene's compiled substep
loop calls it through a function pointer): its table section, step and energy.

The step is ``MassSpringModel._advance``: symplectic (``symplectic_step_work`` with the spring
pass's work buffer ``MassSpringModel.spring_work``) or, when "auto" picks it, the linearly implicit
step (``implicit_step`` on the model's CG buffers, then the contact stiffness's implicit part taken
out of ``integrated_external_forces``, whose reaction the loop gives the tools). The Maxwell
coefficients are those of ``MassSpringModel.symplectic_kernel_state``: the first step's span the
interval since the last commit, the others' span dt. The energy is the model's
``elastic_energy()``: springs and Maxwell branches plus the per-tet volume term.
"""

from __future__ import annotations

import numpy as np
from numba import cfunc, njit

from surgsim_envs.tissue.compiled import (MODEL_ROW, CompiledStep, b1_1, energy_signature, f8_1, f8_2, f8_3, i8_1,
                                          i8_2, step_arrays, step_signature, table_at)
from surgsim_envs.tissue.mass_spring import CG_MAX_ITER
from surgsim_envs.tissue.msd_kernels import elastic_energy, implicit_step, symplectic_step_work, volume_energy

#: the model's table section (from ``MODEL_ROW``), in :func:`unpack` order
KINDS = ["f8_1", "f8_1", "f8_1", "b1_1", "i8_1", "i8_1", "f8_1", "f8_1", "f8_1",   # inv_mass .. K2
         "f8_1", "f8_1", "f8_1", "f8_1", "f8_1", "f8_1", "f8_2",                   # kMg0 .. f_buf
         "i8_2", "f8_1", "f8_1", "f8_2", "f8_1", "f8_1",                           # tets, V0, kv, work, kM, masses
         "f8_1", "f8_1", "f8_2", "f8_1", "f8_2", "f8_2", "f8_2", "f8_2", "f8_2",   # CG: coef_a .. ap
         "f8_3", "f8_1", "f8_1"]                                                   # vgrad, vcoef, [tol, max_iter]


def arrays(tissue, dt: float) -> list:
    """The table section of ``tissue`` for steps of ``dt`` s (the model's own arrays; its implicit
    buffers are allocated here if they are not yet: work space, every step overwrites them)."""
    (_, _, inv_mass, b0, gravity, fixed, si, sj, L0, K1, K2, kMg0, decay0, kMg, decay, s, dl, f_buf, tets, V0,
     kv) = tissue.symplectic_kernel_state(dt)
    if tissue._cg is None:
        tissue._allocate_implicit_buffers()
    r, z, p, ap, pre = tissue._cg
    params = getattr(tissue, "_compiled_cg_params", None)
    if params is None or params[0] != tissue.cg_tol:
        params = tissue._compiled_cg_params = np.array([tissue.cg_tol, CG_MAX_ITER], dtype=np.float64)
    return [inv_mass, b0, gravity, fixed, si, sj, L0, K1, K2, kMg0, decay0, kMg, decay, s, dl, f_buf, tets, V0, kv,
            tissue.spring_work(), tissue.kM, tissue.masses, tissue._coef_a, tissue._coef_g, tissue._unit,
            tissue._diag, pre, r, z, p, ap, tissue._vgrad, tissue._vcoef, params]


@njit(cache=True)
def unpack(tab, at):
    return (f8_1(tab, at), f8_1(tab, at + 1), f8_1(tab, at + 2), b1_1(tab, at + 3), i8_1(tab, at + 4),
            i8_1(tab, at + 5), f8_1(tab, at + 6), f8_1(tab, at + 7), f8_1(tab, at + 8), f8_1(tab, at + 9),
            f8_1(tab, at + 10), f8_1(tab, at + 11), f8_1(tab, at + 12), f8_1(tab, at + 13), f8_1(tab, at + 14),
            f8_2(tab, at + 15), i8_2(tab, at + 16), f8_1(tab, at + 17), f8_1(tab, at + 18), f8_2(tab, at + 19),
            f8_1(tab, at + 20), f8_1(tab, at + 21),
            f8_1(tab, at + 22), f8_1(tab, at + 23), f8_2(tab, at + 24), f8_1(tab, at + 25), f8_2(tab, at + 26),
            f8_2(tab, at + 27), f8_2(tab, at + 28), f8_2(tab, at + 29), f8_2(tab, at + 30), f8_3(tab, at + 31),
            f8_1(tab, at + 32), f8_1(tab, at + 33))


@njit(cache=True, nogil=True)
def step(pos, vel, fext, kc, integrated, dt, first, implicit, auto, t):
    """One step of the model under external forces ``fext`` (N,3) N with contact stiffness ``kc``
    (N,) N/m; True if it changed ``integrated`` (the implicit step), see the module docstring."""
    (inv_mass, b0, gravity, fixed, si, sj, L0, K1, K2, kMg0, decay0, kMg, decay, s, dl, f_buf, tets, V0, kv, work,
     _, masses, coef_a, coef_g, unit, diag, pre, r, z, p, ap, vgrad, vcoef, params) = t
    kMg_c = kMg0 if first else kMg
    decay_c = decay0 if first else decay
    if not implicit:
        symplectic_step_work(pos, vel, inv_mass, b0, fext, gravity, fixed, dt, si, sj, L0, K1, K2, kMg_c, decay_c, s,
                             dl, f_buf, tets, V0, kv, work)
        return False
    auto[4] = implicit_step(pos, vel, masses, b0, fext, gravity, fixed, kc, dt, si, sj, L0, K1, K2, kMg_c, decay_c,
                            kMg, s, dl, f_buf, coef_a, coef_g, unit, diag, pre, r, z, p, ap, params[0],
                            int(params[1]), tets, V0, kv, vgrad, vcoef)
    for i in range(pos.shape[0]):      # backward Euler integrated f_ext - kc (x_{n+1} - x_n) = f_ext - dt kc v_{n+1}
        if not fixed[i]:
            c = dt * kc[i]
            for q in range(3):
                integrated[i, q] -= c * vel[i, q]
    return True


@njit(cache=True)
def energy(pos, t):
    """``MassSpringModel.elastic_energy()`` (J) after a step of dt."""
    (_, _, _, _, si, sj, L0, K1, K2, _, _, kMg, decay, s, dl, _, tets, V0, kv, _, kM) = t[:21]
    return elastic_energy(pos, si, sj, L0, K1, K2, kM, kMg, decay, s, dl) + volume_energy(pos, tets, V0, kv)


def committed(tissue, dt: float) -> None:
    tissue.committed_symplectic_steps(dt)


@cfunc(step_signature(), cache=True)
def step_c(address, rows, dt, first, implicit):
    """:func:`step` on the arrays of the address table at ``address`` (the loop's step pointer)."""
    tab = table_at(address, rows)
    pos, vel, fext, kc, integrated, auto = step_arrays(tab)
    changed = step(pos, vel, fext, kc, integrated, dt, first != 0, implicit != 0, auto, unpack(tab, MODEL_ROW))
    return 1 if changed else 0


@cfunc(energy_signature(), cache=True)
def energy_c(address, rows):
    """:func:`energy` on the arrays of the address table at ``address`` (the loop's energy pointer)."""
    tab = table_at(address, rows)
    return energy(step_arrays(tab)[0], unpack(tab, MODEL_ROW))


def key(tissue, dt: float) -> tuple:
    """What :func:`arrays` depends on besides the tissue's ``state_version``: the intervals of the
    Maxwell coefficients (first step, others) and the CG tolerance."""
    return (tissue._pending_dt, dt, tissue.cg_tol)


COMPILED_STEP = CompiledStep(step_c, energy_c, KINDS, ("symplectic", "auto"), arrays, key, committed)

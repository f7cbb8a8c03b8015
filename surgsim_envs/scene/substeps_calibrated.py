"""Compiled substeps for :class:`CalibratedMassSpringModel` (``mass_spring_calibrated``) against
:class:`ContactModel`, integrator "symplectic" (its "auto" can choose "subcycled", which stays on the
generic loop): the mass-spring loop
(:mod:`surgsim_envs.scene.substeps_loop`) with the model's own step
and energy, which carry its averaged-nodal-volume term instead of the per-tet one.

Step, as ``CalibratedMassSpringModel._advance``: symplectic = the external forces plus the nodal
volume forces (``nodal_volume_kernels.add_forces``) into the model's ``_fvol``, then the
mass-spring symplectic step under them; implicit ("auto" picks it) = ``nodal_volume_kernels.
implicit_step``, which integrates exactly the external forces given (no stiffness term taken out,
as in the generic step). Energy = springs and Maxwell branches + the nodal volume term.
"""

from __future__ import annotations

import numpy as np
from numba import cfunc, njit

from surgsim_envs.contact.model import ContactModel
from surgsim_envs.scene import substeps_mass_spring as ms
from surgsim_envs.scene.array_table import f8_1, f8_2, f8_3, i8_2
from surgsim_envs.scene.compiled_substeps import register_compiled_substeps
from surgsim_envs.scene.substeps_loop import (COMMON_SLOTS, SubstepsRunner, TissueOps, energy_signature,
                                              step_arrays, step_signature, table_at)
from surgsim_envs.tissue import nodal_volume_kernels as nvk
from surgsim_envs.tissue.calibrated_mass_spring import CalibratedMassSpringModel
from surgsim_envs.tissue.mass_spring import CG_MAX_ITER, CG_TOLERANCE
from surgsim_envs.tissue.msd_kernels import elastic_energy, symplectic_step_work

#: the mass-spring section, then: _fvol, nodal-volume tets, rest volumes, bulk moduli, volume buffer,
#: gradient buffer, energy scratch, implicit buffers (gradients, coefficients, sums)
KINDS = ms.KINDS + ["f8_2", "i8_2", "f8_1", "f8_1", "f8_1", "f8_3", "f8_1", "f8_3", "f8_1", "f8_1"]


def arrays(tissue, dt: float) -> list:
    base = ms.arrays(tissue, dt)
    base[-1] = _PARAMS                      # this model's implicit step uses the module's CG tolerance
    scratch = getattr(tissue, "_compiled_energy_scratch", None)
    if scratch is None or scratch.shape != (tissue.n_nodes,):
        scratch = tissue._compiled_energy_scratch = np.zeros(tissue.n_nodes)
    return base + [tissue._fvol, tissue._ntets, tissue.node_rest_volume, tissue.node_bulk, tissue._vbuf,
                   _NO_GRAD, scratch, tissue._ngrad, tissue._nc, tissue._nsbuf]


_NO_GRAD = np.zeros((0, 4, 3))             # unused slot (the fused volume pass recomputes its gradients)
_PARAMS = np.array([CG_TOLERANCE, CG_MAX_ITER], dtype=np.float64)
_BASE_SLOTS = len(ms.KINDS)


@njit(cache=True)
def unpack(tab, at):
    b = at + _BASE_SLOTS
    return (ms.unpack(tab, at), (f8_2(tab, b), i8_2(tab, b + 1), f8_1(tab, b + 2), f8_1(tab, b + 3),
                                 f8_1(tab, b + 4), f8_3(tab, b + 5), f8_1(tab, b + 6), f8_3(tab, b + 7),
                                 f8_1(tab, b + 8), f8_1(tab, b + 9)))


@njit(cache=True, nogil=True)
def step(pos, vel, fext, kc, integrated, dt, first, implicit, auto, t):
    """One step of the model (module docstring); never changes ``integrated`` (returns False)."""
    base, extra = t
    (inv_mass, b0, gravity, fixed, si, sj, L0, K1, K2, kMg0, decay0, kMg, decay, s, dl, f_buf, tets, V0, kv, work,
     _, masses, coef_a, coef_g, unit, diag, pre, r, z, p, ap, _, _, params) = base
    fvol, ntets, V0n, bulk, vbuf, vgbuf, _, ngrad, nc, nsbuf = extra
    kMg_c = kMg0 if first else kMg
    decay_c = decay0 if first else decay
    if not implicit:
        for i in range(fext.shape[0]):
            for q in range(3):
                fvol[i, q] = fext[i, q]
        nvk.add_forces(pos, ntets, V0n, bulk, vbuf, fvol)
        symplectic_step_work(pos, vel, inv_mass, b0, fvol, gravity, fixed, dt, si, sj, L0, K1, K2, kMg_c, decay_c, s,
                             dl, f_buf, tets, V0, kv, work)
        return False
    auto[4] = nvk.implicit_step(pos, vel, masses, b0, fext, gravity, fixed, kc, dt, si, sj, L0, K1, K2, kMg_c,
                                decay_c, kMg, s, dl, f_buf, coef_a, coef_g, unit, diag, pre, r, z, p, ap, params[0],
                                int(params[1]), ntets, V0n, bulk, ngrad, nc, vbuf, nsbuf)
    return False


@njit(cache=True)
def energy(pos, t):
    """``CalibratedMassSpringModel.elastic_energy()`` (J) after a step of dt."""
    base, extra = t
    (_, _, _, _, si, sj, L0, K1, K2, _, _, kMg, decay, s, dl, _, _, _, _, _, kM) = base[:21]
    _, ntets, V0n, bulk, _, _, scratch, _, _, _ = extra
    return elastic_energy(pos, si, sj, L0, K1, K2, kM, kMg, decay, s, dl) + nvk.energy(pos, ntets, V0n, bulk, scratch)


@cfunc(step_signature(), cache=True)
def step_c(address, rows, dt, first, implicit):
    """:func:`step` on the arrays of the address table at ``address`` (the loop's step pointer)."""
    tab = table_at(address, rows)
    pos, vel, fext, kc, integrated, auto = step_arrays(tab)
    changed = step(pos, vel, fext, kc, integrated, dt, first != 0, implicit != 0, auto, unpack(tab, COMMON_SLOTS))
    return 1 if changed else 0


@cfunc(energy_signature(), cache=True)
def energy_c(address, rows):
    """:func:`energy` on the arrays of the address table at ``address`` (the loop's energy pointer)."""
    tab = table_at(address, rows)
    return energy(step_arrays(tab)[0], unpack(tab, COMMON_SLOTS))


OPS = TissueOps(step_c, energy_c, KINDS, arrays, ms.committed)


def runner(sim, tissue, contact, fns) -> SubstepsRunner:
    return SubstepsRunner(sim, tissue, contact, fns, OPS)


# "symplectic" only: this model's "auto" may also pick its "subcycled" integrator (n explicit
# steps per dt), which this loop does not do, so "auto" and "subcycled" keep the generic loop
register_compiled_substeps(ContactModel, CalibratedMassSpringModel, "symplectic", runner)

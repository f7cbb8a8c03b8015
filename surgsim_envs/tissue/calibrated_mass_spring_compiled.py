"""The compiled step of :class:`CalibratedMassSpringModel` (``mass_spring_calibrated``), integrators
"symplectic", "auto" and "subcycled" (the ABI: :mod:`surgsim_envs.tissue.compiled`): the mass-spring
section (:mod:`surgsim_envs.tissue.mass_spring_compiled`) with the model's own step and energy, which
carry its averaged-nodal-volume term instead of the per-tet one, and its sub-cycling.

Step, as ``CalibratedMassSpringModel._advance`` with the choice of ``_pick``:

* symplectic: ``nodal_volume_kernels.symplectic_substeps`` with one step (external forces plus the
  nodal volume forces, then the mass-spring symplectic step under them);
* "auto", when the loop's per-step test finds dt above the explicit limit (with the contact
  stiffness): n = ceil(dt / (DT_SAFETY critical_dt)) as ``_pick`` computes it; while n <=
  ``MAX_SUBCYCLES`` and the contact stiffness alone is stable at dt, the same kernel with n steps of
  dt / n ("subcycled"), else ``nodal_volume_kernels.implicit_step`` and the contact stiffness's
  implicit part taken out of ``integrated_external_forces`` (whose reaction the loop gives the tools);
* integrator "subcycled": n steps of dt / n with n = ``subcycle_count(dt)``, given per chunk by
  :class:`CalibratedCompiledStep` (third entry of the step state).

The Maxwell-branch coefficients: the first step of a loop call spans the interval since the last
commit (``symplectic_kernel_state``), every later one the previous step's dt / n; the table carries
them for dt / 1 .. dt / max(MAX_SUBCYCLES, n) (rows of ``_branch_coeffs``, so the same numbers the Python
step uses), and a state [n of the last step, its kind, n of "subcycled" or 0] whose first two entries
:func:`committed` turns into the model's ``_pending_dt`` and :meth:`CalibratedCompiledStep.active_after`
into ``active_integrator``.
Energy = springs and Maxwell branches (at the last step's interval) + the nodal volume term.
"""

from __future__ import annotations

import math

import numpy as np
from numba import cfunc, njit

from surgsim_envs.tissue import mass_spring_compiled as ms
from surgsim_envs.tissue import nodal_volume_kernels as nvk
from surgsim_envs.tissue.base import AUTO_RECHECK_STEPS, DT_SAFETY, max_ratio
from surgsim_envs.tissue.calibrated_mass_spring import MAX_SUBCYCLES
from surgsim_envs.tissue.compiled import (MODEL_ROW, CompiledStep, energy_signature, f8_1, f8_2, f8_3, i8_2,
                                          step_arrays, step_signature, table_at)
from surgsim_envs.tissue.mass_spring import CG_MAX_ITER, CG_TOLERANCE
from surgsim_envs.tissue.msd_kernels import elastic_energy

#: the mass-spring section, then: _fvol, nodal-volume tets, rest volumes, bulk moduli, volume buffer,
#: Maxwell coefficients (kMg, decay) for dt / 1 .. dt / MAX_SUBCYCLES, step state [n, kind], energy
#: scratch, implicit buffers (gradients, coefficients, sums)
KINDS = ms.KINDS + ["f8_2", "i8_2", "f8_1", "f8_1", "f8_1", "f8_2", "f8_2", "f8_1", "f8_1", "f8_3", "f8_1", "f8_1"]
#: kinds of step in the state's second entry (the runner maps them to ``active_integrator``)
SYMPLECTIC, IMPLICIT, SUBCYCLED = 0.0, 1.0, 2.0
_KIND_NAMES = {SYMPLECTIC: "symplectic", IMPLICIT: "implicit", SUBCYCLED: "subcycled"}


def _branch_rows(tissue, dt: float, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """(kMg, decay) of the Maxwell branches over dt / (r + 1), r = 0 .. rows - 1, as (rows, E) arrays (the
    model's ``_branch_coeffs`` rows; rebuilt when dt, the row count or the model's coefficients change)."""
    head = tissue._branch_coeffs(float(dt))[0]
    cached = getattr(tissue, "_compiled_branch_rows", None)
    if cached is not None and cached[0] == (dt, rows) and cached[1] is head:
        return cached[2], cached[3]
    coeffs = [tissue._branch_coeffs(float(dt) / n) for n in range(1, rows + 1)]
    kmg = np.ascontiguousarray(np.stack([c[0] for c in coeffs]))
    decay = np.ascontiguousarray(np.stack([c[1] for c in coeffs]))
    tissue._compiled_branch_rows = ((dt, rows), head, kmg, decay)   # keeps ``head`` alive: its identity is the key
    return kmg, decay


def _state(tissue) -> np.ndarray:
    state = getattr(tissue, "_compiled_step_state", None)
    if state is None:
        state = tissue._compiled_step_state = np.array([1.0, SYMPLECTIC, 0.0])
    return state


def arrays(tissue, dt: float) -> list:
    base = ms.arrays(tissue, dt)
    base[-1] = _PARAMS                      # this model's implicit step uses the module's CG tolerance
    scratch = getattr(tissue, "_compiled_energy_scratch", None)
    if scratch is None or scratch.shape != (tissue.n_nodes,):
        scratch = tissue._compiled_energy_scratch = np.zeros(tissue.n_nodes)
    kmg_rows, decay_rows = _branch_rows(tissue, dt, max(MAX_SUBCYCLES, int(_state(tissue)[2])))
    return base + [tissue._fvol, tissue._ntets, tissue.node_rest_volume, tissue.node_bulk, tissue._vbuf,
                   kmg_rows, decay_rows, _state(tissue), scratch, tissue._ngrad, tissue._nc, tissue._nsbuf]


_PARAMS = np.array([CG_TOLERANCE, CG_MAX_ITER], dtype=np.float64)
_BASE_SLOTS = len(ms.KINDS)


@njit(cache=True)
def unpack(tab, at):
    b = at + _BASE_SLOTS
    return (ms.unpack(tab, at), (f8_2(tab, b), i8_2(tab, b + 1), f8_1(tab, b + 2), f8_1(tab, b + 3),
                                 f8_1(tab, b + 4), f8_2(tab, b + 5), f8_2(tab, b + 6), f8_1(tab, b + 7),
                                 f8_1(tab, b + 8), f8_3(tab, b + 9), f8_1(tab, b + 10), f8_1(tab, b + 11)))


@njit(cache=True)
def subcycles_for(dt, crit, kc, masses):
    """``CalibratedMassSpringModel._pick`` after the base choice went implicit: the number of symplectic
    steps of dt / n ("subcycled") or 0 (take the implicit step). ``crit`` is the model's critical dt
    without contact; the contact stiffness ``kc`` (N/m per node) must be stable at dt on its own."""
    if not (crit > 0) or not math.isfinite(crit):
        return 0
    n = math.ceil(dt / (DT_SAFETY * crit) - 1e-12)
    rate = max_ratio(kc, masses)
    if not (math.isfinite(rate) and rate > 0):
        rate = 0.0
    contact_ok = rate <= 0 or dt <= DT_SAFETY * 2.0 / math.sqrt(rate)
    if n <= MAX_SUBCYCLES and contact_ok:
        return n
    return 0


@njit(cache=True, nogil=True)
def step(pos, vel, fext, kc, integrated, dt, first, implicit, auto, t):
    """One step of the model (module docstring); True if it changed ``integrated`` (the implicit step)."""
    base, extra = t
    (inv_mass, b0, gravity, fixed, si, sj, L0, K1, K2, kMg0, decay0, kMg, decay, s, dl, f_buf, tets, V0, kv, work,
     _, masses, coef_a, coef_g, unit, diag, pre, r, z, p, ap, _, _, params) = base
    fvol, ntets, V0n, bulk, vbuf, kmg_rows, decay_rows, state, _, ngrad, nc, nsbuf = extra
    last = int(state[0]) - 1               # the branches were committed over dt / state[0]
    kMg_c = kMg0 if first else kmg_rows[last]
    decay_c = decay0 if first else decay_rows[last]
    n = int(state[2]) if state[2] > 0 else 1    # integrator "subcycled": n set by the runner per chunk
    if implicit:
        n = subcycles_for(dt, auto[0], kc, masses)
        if n == 0:
            auto[4] = nvk.implicit_step(pos, vel, masses, b0, fext, gravity, fixed, kc, dt, si, sj, L0, K1, K2, kMg_c,
                                        decay_c, kMg, s, dl, f_buf, coef_a, coef_g, unit, diag, pre, r, z, p, ap,
                                        params[0], int(params[1]), ntets, V0n, bulk, ngrad, nc, vbuf, nsbuf)
            for i in range(pos.shape[0]):   # backward Euler integrated f_ext - dt kc v_{n+1}
                if not fixed[i]:
                    c = dt * kc[i]
                    for q in range(3):
                        integrated[i, q] -= c * vel[i, q]
            state[0] = 1.0
            state[1] = IMPLICIT
            return True
    h = dt / n
    nvk.symplectic_substeps(n, h, pos, vel, inv_mass, b0, fext, gravity, fixed, si, sj, L0, K1, K2, kMg_c, decay_c,
                            kmg_rows[n - 1], decay_rows[n - 1], s, dl, f_buf, fvol, work, tets, V0, kv, ntets, V0n,
                            bulk, vbuf)
    state[0] = float(n)
    state[1] = SUBCYCLED if (implicit or state[2] > 0) else SYMPLECTIC
    return False


@njit(cache=True)
def energy(pos, t):
    """``CalibratedMassSpringModel.elastic_energy()`` (J) after a step (branches at its interval)."""
    base, extra = t
    (_, _, _, _, si, sj, L0, K1, K2, _, _, _, _, s, dl, _, _, _, _, _, kM) = base[:21]
    _, ntets, V0n, bulk, _, kmg_rows, decay_rows, state, scratch, _, _, _ = extra
    last = int(state[0]) - 1
    return (elastic_energy(pos, si, sj, L0, K1, K2, kM, kmg_rows[last], decay_rows[last], s, dl)
            + nvk.energy(pos, ntets, V0n, bulk, scratch))


def committed(tissue, dt: float) -> None:
    """After the loop stepped the model: the branches are committed over the last step's dt / n."""
    n = int(_state(tissue)[0])
    tissue._pending_dt = float(dt) / n
    if _state(tissue)[1] == SUBCYCLED:
        tissue._subcycles = n


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
    """What :func:`arrays` depends on besides the tissue's ``state_version`` (every buffer the model
    replaces calls ``notify_changed()``): the mass-spring section's intervals and CG tolerance
    (``mass_spring_compiled.key``) and the number of Maxwell rows (``_state``'s third entry: n of
    integrator "subcycled")."""
    return (tissue._pending_dt, dt, tissue.cg_tol, int(_state(tissue)[2]))


class CalibratedCompiledStep(CompiledStep):
    """Reports the step "auto" took last (symplectic, subcycled or implicit), and runs integrator
    "subcycled" in chunks: n = ``subcycle_count(dt)`` is evaluated in Python where the Python step
    evaluates it (before the first step and every AUTO_RECHECK_STEPS steps, :meth:`plan`), and each
    chunk up to the next re-evaluation runs compiled with that n. With several tissue steps per
    MuJoCo step a re-evaluation can fall inside a MuJoCo step, where a loop call cannot stop: such
    scenes keep the Python loop (:meth:`applies`)."""

    def applies(self, tissue, rigid_subcycles: int) -> bool:
        return not (tissue.integrator == "subcycled" and rigid_subcycles > 1)

    def plan(self, tissue, dt: float) -> int | None:
        if tissue.integrator != "subcycled":
            return None
        _state(tissue)[2] = float(tissue.subcycle_count(dt))        # re-evaluates n as _advance would
        return max(AUTO_RECHECK_STEPS - (tissue.steps - tissue._sub_step), 1)

    def finish(self, tissue) -> None:
        _state(tissue)[2] = 0.0

    def active_after(self, tissue, implicit: bool) -> str:
        return _KIND_NAMES[float(_state(tissue)[1])]


COMPILED_STEP = CalibratedCompiledStep(step_c, energy_c, KINDS, ("symplectic", "auto", "subcycled"), arrays, key,
                                       committed)

"""Compiled substeps for the tasks' default pairing: :class:`ContactModel` against
:class:`MassSpringModel` with its symplectic integrator (registered in
:mod:`surgsim_envs.scene.compiled_substeps`).

One numba call runs the substeps of a control step; per substep, in the generic loop's order and
with the same kernels (so the result is bit-for-bit the generic loop's):

1. scheduled controls (``ctrl_ids``/``ctrl_values``, e.g. Slippage's jaw and pull), then the rate
   limiter while a tool target moves;
2. ``mj_step1``; the tool geoms' poses and velocities (``_gather_geoms``);
3. contact (``contact_kernel_prepared``: ``ContactModel.compute_prepared``'s kernel);
4. tissue: refuse non-finite contact input (hand back, Python raises ``NonFiniteInputError``), the
   symplectic kernel, fixed nodes, time and step count, the guard's cheap checks (non-finite
   state, runaway speed: hand back, Python raises ``TissueUnstableError``) and, every
   ``check_every`` steps, hand back for the costly ones;
5. the reaction wrench into ``xfrc_applied``; ``mj_step2``; the rows zeroed again.

The loop releases the GIL (``nogil``), as the bindings' ``mj_step`` does, so a haptic servo thread
keeps running during a control step.

The symplectic integrator integrates exactly the contact forces given, so the increment that
``ContactModel.attribute_increment`` would add is zero and is not computed.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surgsim_envs.contact.model import ContactModel, contact_kernel_prepared
from surgsim_envs.scene.compiled_substeps import (COSTLY_CHECK, CONTACT_ERROR, DONE, GUARD_FAILED, NO_IDS,
                                                  NO_VALUES, NON_FINITE_INPUT, register_compiled_substeps)
from surgsim_envs.scene.mujoco_native import call_model_data, model_data_addresses
from surgsim_envs.scene.simulation import (_add_wrench, _advance_geoms, _gather_geoms, _rate_limit, _write_rows,
                                           _zero_rows)
from surgsim_envs.tissue.guard import first_non_finite, max_speed_squared
from surgsim_envs.tissue.mass_spring import MassSpringModel
from surgsim_envs.tissue.msd_kernels import elastic_energy, symplectic_step_work, volume_energy


@njit(cache=True)
def _costly_check(pos, vel, masses, tissue, kM, energy, good_pos, good_vel, clock, snap):
    """The guard's every-``check_every`` checks for this model (it has no elements that can invert):
    False if the kinetic energy exceeds ``energy_factor * (energy_ref + energy_floor)`` (then
    nothing is updated: Python repeats the check and raises); else raise ``energy_ref`` to the
    total energy and snapshot the state as the last good one. energy: [ref, factor, floor]."""
    ke = 0.0
    for i in range(vel.shape[0]):
        ke += masses[i] * (vel[i, 0] * vel[i, 0] + vel[i, 1] * vel[i, 1] + vel[i, 2] * vel[i, 2])
    ke *= 0.5
    if ke > energy[1] * (energy[0] + energy[2]):
        return False
    (_, _, _, _, _, _, si, sj, L0, K1, K2, _, _, kMg, decay, s_state, dl_state, _, tets, V0, kv) = tissue
    total = ke + (elastic_energy(pos, si, sj, L0, K1, K2, kM, kMg, decay, s_state, dl_state)
                  + volume_energy(pos, tets, V0, kv))
    if total > energy[0]:
        energy[0] = total
    for i in range(pos.shape[0]):
        for j in range(3):
            good_pos[i, j] = pos[i, j]
            good_vel[i, j] = vel[i, j]
    clock[1] = clock[0]
    snap[0] = True
    return True


@njit(cache=True, nogil=True)
def run_substeps(k, j, count, resume, native, controls, ctrl_ids, ctrl_values, gather, reaction, contact, tissue,
                 fixed_idx, fixed_targets, integrated, max_speed2, check_every, clock, counts, guard, sub):
    """``count`` physics steps as MuJoCo steps ``k .. count/n - 1`` of ``n`` tissue steps each (see the
    module docstring; n = 1 is the documented one-to-one loop), starting at tissue step ``j`` of
    MuJoCo step ``k``. ``resume``: that tissue step is done (after a check in Python): continue
    with its reaction. counts: [tissue steps, simulation steps, tissue steps taken in this batch];
    clock: [tissue time, time of the last good state]. guard: (in_kernel, masses, kM, energy,
    good_pos, good_vel, snap): with ``in_kernel`` the costly checks run here (:func:`_costly_check`),
    else they are handed back. sub: (n, n * dt, gpos0 buffer, spring work buffer (4, E)): sub-cycling
    (``tissue_subcycles``) and the spring pass's buffer (``MassSpringModel.spring_work``).
    Returns (status, MuJoCo step index, tissue step index within it)."""
    step1, step2, m_ptr, d_ptr = native
    ctrl, goal, rate, moving, dt = controls
    xfrc, bodies, wrench = reaction
    n, big_dt, gpos0, work = sub
    gpos, gmat, gvel, tcom = gather[9], gather[10], gather[11], gather[12]
    (pos, vel, inv_mass, b0, gravity, fixed, si, sj, L0, K1, K2, kMg0, decay0, kMg, decay, s_state, dl_state, f_buf,
     tets, V0, kv) = tissue
    forces, stiffness, tool_force, tool_torque = contact[13], contact[14], contact[16], contact[17]
    costly_here, masses, kM, energy, good_pos, good_vel, snap = guard
    rigid = count // n
    while k < rigid:
        if j == 0 and not resume:
            for q in range(ctrl_ids.shape[0]):
                ctrl[ctrl_ids[q]] = ctrl_values[k, q]
            if moving[0]:
                moving[0] = _rate_limit(ctrl, goal, rate, big_dt)
            call_model_data(step1, m_ptr, d_ptr)
            _gather_geoms(*gather)
            for g in range(gpos.shape[0]):
                for q in range(3):
                    gpos0[g, q] = gpos[g, q]
            for t in range(wrench.shape[0]):
                for q in range(6):
                    wrench[t, q] = 0.0
        while j < n:
            if not resume:
                if j > 0:
                    _advance_geoms(gpos, gpos0, gvel, j * dt)
                if contact_kernel_prepared(pos, vel, gpos, gmat, gvel, tcom, contact) != 0:
                    return CONTACT_ERROR, k, j
                if first_non_finite(forces) >= 0 or first_non_finite(stiffness) >= 0:
                    return NON_FINITE_INPUT, k, j
                for i in range(forces.shape[0]):
                    for q in range(3):
                        integrated[i, q] = forces[i, q]
                if counts[2] == 0:
                    symplectic_step_work(pos, vel, inv_mass, b0, forces, gravity, fixed, dt, si, sj, L0, K1, K2,
                                         kMg0, decay0, s_state, dl_state, f_buf, tets, V0, kv, work)
                else:
                    symplectic_step_work(pos, vel, inv_mass, b0, forces, gravity, fixed, dt, si, sj, L0, K1, K2,
                                         kMg, decay, s_state, dl_state, f_buf, tets, V0, kv, work)
                counts[2] += 1
                for q in range(fixed_idx.shape[0]):
                    i = fixed_idx[q]
                    for c in range(3):
                        pos[i, c] = fixed_targets[i, c]
                        vel[i, c] = 0.0
                clock[0] += dt
                counts[0] += 1
                v2 = max_speed_squared(pos, vel)
                if not np.isfinite(v2) or v2 > max_speed2:
                    return GUARD_FAILED, k, j
                if counts[0] % check_every == 0:
                    if not costly_here:
                        return COSTLY_CHECK, k, j
                    if not _costly_check(pos, vel, masses, tissue, kM, energy, good_pos, good_vel, clock, snap):
                        return GUARD_FAILED, k, j
            resume = False
            _add_wrench(wrench, tool_force, tool_torque)
            j += 1
        if n > 1:
            for t in range(wrench.shape[0]):
                for q in range(6):
                    wrench[t, q] /= n
        _write_rows(xfrc, bodies, wrench)
        call_model_data(step2, m_ptr, d_ptr)
        _zero_rows(xfrc, bodies)
        counts[1] += n
        k += 1
        j = 0
    return DONE, k, 0


class MassSpringSymplecticRunner:
    """Runs :func:`run_substeps` for one :class:`Simulation` and does the Python side: binds the
    current arrays (tissue arrays are replaced by reset()), mirrors the counters and the guard's
    state back into the model, the guard and the simulation, and turns the hand-backs into the
    generic loop's checks and errors (the Python check is repeated on the same state, so the error
    and its message are the ones ``TissueModel.step`` raises)."""

    def __init__(self, sim, tissue, contact, fns):
        self.sim, self.tissue, self.contact = sim, tissue, contact
        self._fns = fns
        self._clock = np.zeros(2)
        self._counts = np.zeros(3, dtype=np.int64)
        self._moving = np.zeros(1, dtype=np.bool_)
        self._energy = np.zeros(3)
        self._snap = np.zeros(1, dtype=np.bool_)
        self._scratch = None
        self._contact_state = (None, None)
        self._gpos0 = None

    def _guard_arrays(self):
        guard, tissue = self.tissue.guard, self.tissue
        e = self._energy
        e[0], e[1], e[2] = guard._energy_ref, guard.energy_factor, guard.energy_floor
        self._snap[0] = False
        good = guard._good_pos
        if good is not None and good.shape == tissue.positions.shape:
            return (True, tissue.masses, tissue.kM, e, good, guard._good_vel, self._snap)
        if self._scratch is None or self._scratch[0].shape != tissue.positions.shape:
            self._scratch = (np.zeros_like(tissue.positions), np.zeros_like(tissue.positions))
        return (True, tissue.masses, tissue.kM, e, self._scratch[0], self._scratch[1], self._snap)

    def run(self, count: int, ctrl_ids=NO_IDS, ctrl_values=NO_VALUES) -> None:
        sim, tissue, contact = self.sim, self.tissue, self.contact
        guard = tissue.guard
        dt = sim.dt
        m_ptr, d_ptr = model_data_addresses(sim.model, sim.data)
        native = (self._fns[0], self._fns[1], m_ptr, d_ptr)
        moving = self._moving
        moving[0] = sim._moving
        controls = (sim._views["ctrl"], sim._goal, sim._rate, moving, dt)
        reaction = (sim._views["xfrc_applied"], sim._bodies, sim._wrench)
        state = tissue.symplectic_kernel_state(dt)
        if self._contact_state[0] is not contact._prepared:      # rebuilt only after a new prepare()
            self._contact_state = (contact._prepared, contact.kernel_state())
        cstate = self._contact_state[1]
        clock, counts = self._clock, self._counts
        clock[0] = tissue.time
        counts[0], counts[1], counts[2] = tissue.steps, sim.steps, 0
        max_speed2 = float(guard.max_speed) ** 2
        k, j, resume = 0, 0, False
        done = False
        n = sim.tissue_subcycles
        if self._gpos0 is None or self._gpos0.shape != sim._gpos.shape:
            self._gpos0 = np.empty_like(sim._gpos)
        sub = (n, dt * n, self._gpos0, tissue.spring_work())
        try:
            while True:
                gstate = self._guard_arrays()
                status, k, j = run_substeps(k, j, count, resume, native, controls, ctrl_ids, ctrl_values,
                                            sim._gather_args, reaction, cstate, state, tissue._fixed_idx,
                                            tissue.fixed_targets, tissue.integrated_external_forces, max_speed2,
                                            guard.check_every, clock, counts, gstate, sub)
                self._sync(dt)
                if status == DONE:
                    done = True
                    return
                if status in (COSTLY_CHECK, GUARD_FAILED):
                    guard.check(tissue, dt)    # raises the generic loop's error; else (a rounding tie) go on
                    resume = True
                    continue
                if status == CONTACT_ERROR:
                    contact._raise_kernel_error(*cstate[4:7])
                if status == NON_FINITE_INPUT:
                    guard.check_inputs(tissue, contact.result.forces, contact.result.stiffness)
                raise RuntimeError(f"compiled substeps stopped with status {status} at step {k}.{j} "
                                   "without an error from the Python check (please report)")
        finally:
            if not done:        # an error (or an interrupt) left the loop: counters as far as they got
                self._sync(dt)

    def _sync(self, dt: float) -> None:
        tissue, sim = self.tissue, self.sim
        guard = tissue.guard
        tissue.time = float(self._clock[0])
        tissue.steps = int(self._counts[0])
        sim.steps = int(self._counts[1])
        sim._moving = bool(self._moving[0])
        guard._energy_ref = float(self._energy[0])
        if self._snap[0]:
            self._snap[0] = False
            guard._good_time = float(self._clock[1])
            if guard._good_pos is None or guard._good_pos.shape != tissue.positions.shape:
                guard._good_pos, guard._good_vel = self._scratch
                self._scratch = None
        if self._counts[2]:
            tissue._last_dt = dt
            tissue.committed_symplectic_steps(dt)


register_compiled_substeps(ContactModel, MassSpringModel, "symplectic", MassSpringSymplecticRunner)

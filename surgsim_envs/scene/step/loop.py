"""The compiled substep loop shared by every tissue model with a compiled step, and its Python runner.

One numba call runs the substeps of a control step. It mirrors the reference loop
(``Simulation._reference_steps``) operation for operation, with the same kernels, so the result is
bit for bit the same (tests/test_compiled_substeps.py, tests/test_compiled_calibrated.py run both on
every task). Per substep:

1. scheduled controls (``ctrl_ids``/``ctrl_values``, e.g. Slippage's jaw and pull), then the rate
   limiter while a tool target moves;
2. ``mj_step1``; the tool geoms' poses and velocities (``gather_geoms``);
3. contact (``contact_kernel_prepared``: ``ContactModel.compute_prepared``'s kernel);
4. tissue: refuse non-finite contact input (hand back, Python raises ``NonFiniteInputError``), the
   model's compiled step (a C function pointer, :mod:`surgsim_envs.tissue.compiled`), fixed nodes,
   time and step count, the guard's cheap checks (non-finite state, runaway speed: hand back, Python
   raises ``TissueUnstableError``) and, every ``check_every`` steps, its costly ones (kinetic energy
   against the reference; the reference raised to kinetic + the model's elastic energy; the state
   kept as the last good one);
5. the reaction wrench into ``xfrc_applied``; ``mj_step2``; the rows zeroed again.

With ``tissue_subcycles`` n > 1 each MuJoCo step carries n tissue steps (steps 3-4 and the wrench
sum), the tool geoms advanced along their velocity, and the mean of the n reactions is written.

**Arguments.** All arrays travel in one address table (:class:`~surgsim_envs.tissue.compiled.ArrayTable`):
the tissue's step rows and its model section (the ABI of :mod:`surgsim_envs.tissue.compiled`), then
this loop's section from row ``base``: the ``GATHER``, ``CONTACT`` and ``REST`` rows below. The loop
releases the GIL (``nogil``), as the bindings' ``mj_step`` does, so a haptic servo thread keeps
running during a control step.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from surgsim_envs.contact.integrated_readings import integrated_readings_kernel
from surgsim_envs.contact.model import attribute_increment_kernel, contact_kernel_prepared, contact_rows_start
from surgsim_envs.scene.step.kernels import add_wrench, advance_geoms, gather_geoms, rate_limit, write_rows, zero_rows
from surgsim_envs.scene.step.mujoco_native import call_model_data, model_data_addresses
from surgsim_envs.tissue.base import AUTO_RECHECK_STEPS, DT_SAFETY, max_ratio
from surgsim_envs.tissue.compiled import (MODEL_ROW, STEP_KINDS, ArrayTable, CompiledStep, b1_1, call_energy,
                                          call_step, f8_1, f8_2, f8_3, i8_1, i8_2, step_arrays, u1_2)
from surgsim_envs.tissue.guard import all_finite, speed_within

#: statuses the loop returns with the substep index it stopped at
DONE, CONTACT_ERROR, NON_FINITE_INPUT, GUARD_FAILED, AUTO_RECHECK = 0, 1, 2, 3, 4
NO_IDS = np.zeros(0, dtype=np.int64)
NO_VALUES = np.zeros((0, 0))

# ---------------------------------------------------------------------------------------------
# the loop's section of the address table, rows relative to its start ``base``
SLOT_GATHER = 0            # 13: the arguments of gather_geoms
GATHER_KINDS = ["i8_1"] * 4 + ["f8_2"] * 9
SLOT_CONTACT = 13          # 35: ContactModel.kernel_state() arrays (scalars in the last one)
CONTACT_KINDS = ["i8_1", "i8_2", "f8_2", "i8_1", "i8_1", "i8_1", "f8_2", "f8_1", "f8_3", "u1_2", "f8_2", "f8_1",
                 "f8_2", "f8_2", "f8_2", "f8_1", "f8_1", "f8_2", "f8_1", "f8_1", "f8_2", "i8_1", "i8_1", "f8_1",
                 "i8_1", "i8_1", "i8_1", "f8_2", "f8_2", "f8_1", "f8_1", "f8_2", "i8_1", "f8_3", "f8_1"]
#: kernel_state() entries that are arrays, in table order (8, 9, 10, 33 are the scalars k_n, c_n, k_t, c_imp)
CONTACT_ARRAY_ENTRIES = [0, 1, 2, 3, 4, 5, 6, 7] + list(range(11, 33)) + [34, 35, 36, 37]
SLOT_REST = 48             # 17: controls, reaction, fixed nodes, counters, guard, sub-cycling
REST_KINDS = ["f8_1", "f8_1", "f8_1", "b1_1",      # ctrl, goal, rate, moving
              "f8_2", "i8_1", "f8_2",              # xfrc_applied, bodies, wrench
              "i8_1", "f8_2",                      # fixed nodes, fixed_targets
              "f8_1", "i8_1",                      # clock, counts
              "f8_1", "f8_1", "f8_2", "f8_2", "b1_1",   # masses, energy, good_pos, good_vel, snap
              "f8_2"]                              # gpos0
LOOP_KINDS = GATHER_KINDS + CONTACT_KINDS + REST_KINDS
assert len(LOOP_KINDS) == SLOT_REST + len(REST_KINDS)
#: row of the tissue positions (the step rows come first, tissue/compiled.py)
POSITIONS_ROW = 0


@njit(cache=True)
def _gather_state(tab, base):
    at = base + SLOT_GATHER
    return (i8_1(tab, at), i8_1(tab, at + 1), i8_1(tab, at + 2), i8_1(tab, at + 3), f8_2(tab, at + 4),
            f8_2(tab, at + 5), f8_2(tab, at + 6), f8_2(tab, at + 7), f8_2(tab, at + 8), f8_2(tab, at + 9),
            f8_2(tab, at + 10), f8_2(tab, at + 11), f8_2(tab, at + 12))


@njit(cache=True)
def _contact_state(tab, base):
    """``ContactModel.kernel_state()`` rebuilt from the table (the scalars from the last slot)."""
    at = base + SLOT_CONTACT
    sc = f8_1(tab, at + 34)
    return (i8_1(tab, at), i8_2(tab, at + 1), f8_2(tab, at + 2), i8_1(tab, at + 3), i8_1(tab, at + 4),
            i8_1(tab, at + 5), f8_2(tab, at + 6), f8_1(tab, at + 7), sc[0], sc[1], sc[2], f8_3(tab, at + 8),
            u1_2(tab, at + 9), f8_2(tab, at + 10), f8_1(tab, at + 11), f8_2(tab, at + 12), f8_2(tab, at + 13),
            f8_2(tab, at + 14), f8_1(tab, at + 15), f8_1(tab, at + 16), f8_2(tab, at + 17), f8_1(tab, at + 18),
            f8_1(tab, at + 19), f8_2(tab, at + 20), i8_1(tab, at + 21), i8_1(tab, at + 22), f8_1(tab, at + 23),
            i8_1(tab, at + 24), i8_1(tab, at + 25), i8_1(tab, at + 26), f8_2(tab, at + 27), f8_2(tab, at + 28),
            f8_1(tab, at + 29), sc[3], f8_1(tab, at + 30), f8_2(tab, at + 31), i8_1(tab, at + 32), f8_3(tab, at + 33))


@njit(cache=True)
def _recheck_due(auto, dt, steps):
    """``TissueModel._auto_choice``'s condition to re-evaluate ``critical_dt()`` (done in Python)."""
    return dt != auto[1] or steps - auto[2] >= AUTO_RECHECK_STEPS or not (auto[0] > 0)


@njit(cache=True)
def _pick_implicit(dt, crit, kc, masses):
    """``TissueModel._pick`` with ``_contact_rate(kc)``: True if "auto" takes the implicit step."""
    if not (crit > 0):
        return True
    rate = max_ratio(kc, masses)
    if not (math.isfinite(rate) and rate > 0):
        rate = 0.0
    if rate > 0 and math.isfinite(crit):
        omega = 2.0 / crit
        crit = 2.0 / math.sqrt(omega * omega + rate)
    return not (dt <= DT_SAFETY * crit)


@njit(cache=True)
def _kinetic_energy(vel, masses):
    ke = 0.0
    for i in range(vel.shape[0]):
        ke += masses[i] * (vel[i, 0] * vel[i, 0] + vel[i, 1] * vel[i, 1] + vel[i, 2] * vel[i, 2])
    return 0.5 * ke


@njit(cache=True)
def _keep_good_state(total, pos, vel, energy, good_pos, good_vel, clock, snap):
    """The guard after a passed costly check: energy_ref raised to ``total``, the state kept."""
    if total > energy[0]:
        energy[0] = total
    for i in range(pos.shape[0]):
        for j in range(3):
            good_pos[i, j] = pos[i, j]
            good_vel[i, j] = vel[i, j]
    clock[1] = clock[0]
    snap[0] = True


@njit(cache=True, nogil=True)
def run_substeps(tab, base, ctrl_ids, ctrl_values, step1, step2, m_ptr, d_ptr, k, j, count, resume, dt, n,
                 max_speed2, check_every, auto_on, step_fn, energy_fn):
    """``count`` physics steps as MuJoCo steps ``k .. count/n - 1`` of ``n`` tissue steps each (see the
    module docstring; n = 1 is the documented one-to-one loop), starting at tissue step ``j`` of
    MuJoCo step ``k``. ``resume``: 0, or 1 = that tissue step is done (after a check in Python):
    continue with its reaction; 2 = Python has just re-evaluated the critical dt for it (integrator
    "auto", ``auto_on``): do it without asking again. counts: [tissue steps, simulation steps, tissue steps taken in this batch];
    clock: [tissue time, time of the last good state]; energy: [reference, factor, floor].
    ``base``: the first row of the loop's section. Returns (status, MuJoCo step index, tissue step
    index within it)."""
    gather = _gather_state(tab, base)
    contact = _contact_state(tab, base)
    pos, vel, _, _, integrated, auto = step_arrays(tab)
    at = base + SLOT_REST
    ctrl, goal, rate, moving = f8_1(tab, at), f8_1(tab, at + 1), f8_1(tab, at + 2), b1_1(tab, at + 3)
    xfrc, bodies, wrench = f8_2(tab, at + 4), i8_1(tab, at + 5), f8_2(tab, at + 6)
    fixed_idx, fixed_targets = i8_1(tab, at + 7), f8_2(tab, at + 8)
    clock, counts = f8_1(tab, at + 9), i8_1(tab, at + 10)
    masses, energy, good_pos, good_vel, snap = (f8_1(tab, at + 11), f8_1(tab, at + 12), f8_2(tab, at + 13),
                                                f8_2(tab, at + 14), b1_1(tab, at + 15))
    gpos0 = f8_2(tab, at + 16)
    address, rows = np.int64(tab.ctypes.data), np.int64(tab.shape[0])
    big_dt = dt * n
    gpos, gmat, gvel, tcom = gather[9], gather[10], gather[11], gather[12]
    forces, stiffness, tool_force, tool_torque = contact[13], contact[14], contact[16], contact[17]
    touched, node_tool_k, com_copy, pos_copy = contact[3], contact[15], contact[30], contact[31]
    a0 = contact_rows_start(contact[0].shape[0], contact[1].shape[0])
    rigid = count // n
    while k < rigid:
        if j == 0 and resume != 1:
            if resume == 0 and auto_on and _recheck_due(auto, dt, counts[0]):
                return AUTO_RECHECK, k, 0
            for q in range(ctrl_ids.shape[0]):
                ctrl[ctrl_ids[q]] = ctrl_values[k, q]
            if moving[0]:
                moving[0] = rate_limit(ctrl, goal, rate, big_dt)
            call_model_data(step1, m_ptr, d_ptr)
            gather_geoms(*gather)
            for g in range(gpos.shape[0]):
                for q in range(3):
                    gpos0[g, q] = gpos[g, q]
            for t in range(wrench.shape[0]):
                for q in range(6):
                    wrench[t, q] = 0.0
        while j < n:
            if resume != 1:
                if j > 0 and resume == 0 and auto_on and _recheck_due(auto, dt, counts[0]):
                    return AUTO_RECHECK, k, j
                if j > 0:
                    advance_geoms(gpos, gpos0, gvel, j * dt)
                if contact_kernel_prepared(pos, vel, gpos, gmat, gvel, tcom, contact) != 0:
                    return CONTACT_ERROR, k, j
                if not (all_finite(forces) and all_finite(stiffness)):
                    return NON_FINITE_INPUT, k, j
                for i in range(forces.shape[0]):
                    for q in range(3):
                        integrated[i, q] = forces[i, q]
                implicit = auto_on and _pick_implicit(dt, auto[0], stiffness, masses)
                auto[3] = 1.0 if implicit else 0.0
                if call_step(step_fn, address, rows, dt, 1 if counts[2] == 0 else 0, 1 if implicit else 0):
                    # the integrator added to the contact force: the tools get the reaction of it too
                    attribute_increment_kernel(touched, integrated, forces, stiffness, node_tool_k, pos_copy, com_copy,
                                         tool_force, tool_torque)
                    integrated_readings_kernel(contact[0], contact[1], contact[2], contact[36], a0, contact[12],
                                               contact[37], contact[5], integrated, forces, stiffness, contact[18],
                                               contact[19], contact[20], contact[21], contact[22], contact[23])
                counts[2] += 1
                for q in range(fixed_idx.shape[0]):
                    i = fixed_idx[q]
                    for c in range(3):
                        pos[i, c] = fixed_targets[i, c]
                        vel[i, c] = 0.0
                clock[0] += dt
                counts[0] += 1
                if not speed_within(pos, vel, max_speed2):
                    return GUARD_FAILED, k, j
                if counts[0] % check_every == 0:
                    ke = _kinetic_energy(vel, masses)
                    if ke > energy[1] * (energy[0] + energy[2]):
                        return GUARD_FAILED, k, j     # nothing updated: Python repeats the check and raises
                    _keep_good_state(ke + call_energy(energy_fn, address, rows), pos, vel, energy, good_pos,
                                     good_vel, clock, snap)
            resume = 0
            add_wrench(wrench, tool_force, tool_torque)
            j += 1
        if n > 1:
            for t in range(wrench.shape[0]):
                for q in range(6):
                    wrench[t, q] /= n
        write_rows(xfrc, bodies, wrench)
        call_model_data(step2, m_ptr, d_ptr)
        zero_rows(xfrc, bodies)
        counts[1] += n
        k += 1
        j = 0
    return DONE, k, 0


class SubstepsRunner:
    """Runs the loop with a model's compiled step for one :class:`Simulation` and does the Python
    side: keeps the address table current (repacked when an array was replaced: the tissue's
    ``CompiledStep.table_key``, the contact's ``prepared_version``, the guard's good-state arrays by
    identity), hands the counters and the guard's state back to the model, the guard and the
    simulation, and turns the hand-backs into the reference loop's checks and errors (the Python check
    is repeated on the same state, so the error and its message are the ones ``TissueModel.step``
    raises)."""

    def __init__(self, sim, tissue, contact, fns, ops: CompiledStep):
        self.sim, self.tissue, self.contact, self.ops = sim, tissue, contact, ops
        self._fns = fns
        self._clock = np.zeros(2)
        self._counts = np.zeros(3, dtype=np.int64)
        self._moving = np.zeros(1, dtype=np.bool_)
        self._energy = np.zeros(3)
        self._snap = np.zeros(1, dtype=np.bool_)
        self._cscal = np.zeros(4)
        self._auto = np.zeros(5)       # [critical dt, its dt, its step, last step implicit, CG iterations]
        self._scratch = None
        self._contact_key = None
        self._contact_arrays: list = []
        self._buffers = sim.step_buffers
        self._gpos0 = np.empty_like(self._buffers.geom_positions)
        self._kinds = STEP_KINDS + ops.kinds + LOOP_KINDS
        self._base = MODEL_ROW + len(ops.kinds)
        self._table = ArrayTable()
        self._loop = run_substeps
        self._fn_addresses = (ops.step.address, ops.energy.address)
        self._mj_memo = (None, None, 0, 0)      # (model, data, their addresses)

    def _contact_section(self) -> list:
        contact = self.contact
        if self._contact_key != contact.prepared_version:      # rebuilt only after a new prepare()
            cs = contact.kernel_state()
            self._contact_arrays = [cs[i] for i in CONTACT_ARRAY_ENTRIES] + [self._cscal]
            self._cscal[:] = (cs[8], cs[9], cs[10], cs[33])
            self._contact_key = contact.prepared_version
        return self._contact_arrays

    def _good_state(self, good_pos, good_vel):
        positions = self.tissue.positions
        if good_pos is not None and good_pos.shape == positions.shape:
            return good_pos, good_vel
        if self._scratch is None or self._scratch[0].shape != positions.shape:
            self._scratch = (np.zeros_like(positions), np.zeros_like(positions))
        return self._scratch

    def _table_now(self, dt: float, good_pos, good_vel) -> np.ndarray:
        """The address table, repacked only when an array was replaced: the simulation's and the
        runner's own arrays never are, the contact's only by a new prepare(), the tissue's when its
        ``table_key`` moved (``notify_changed()``: reset(), a material change, new buffers; a new
        positions or velocities array); the guard's (the first snapshot) are compared by identity."""
        tissue = self.tissue
        self._contact_section()
        key = (self.ops.table_key(tissue, dt), id(good_pos), id(good_vel), self._contact_key)
        table = self._table
        if key == table.key:
            return table.table
        return table.update(key, lambda: self._arrays(dt, good_pos, good_vel), self._kinds)

    def _arrays(self, dt: float, good_pos, good_vel) -> list:
        """Every array of the table, in ``STEP_KINDS`` + ``ops.kinds`` + ``LOOP_KINDS`` order."""
        tissue, b = self.tissue, self._buffers
        res = self.contact.result
        return [tissue.positions, tissue.velocities, res.forces, res.stiffness, tissue.integrated_external_forces,
                self._auto, *self.ops.arrays(tissue, dt), *b.gather, *self._contact_arrays, b.ctrl, b.goal, b.rate,
                self._moving, b.xfrc, b.bodies, b.wrench, tissue.fixed_nodes, tissue.fixed_targets, self._clock,
                self._counts, tissue.masses, self._energy, good_pos, good_vel, self._snap, self._gpos0]

    def run(self, count: int, ctrl_ids=NO_IDS, ctrl_values=NO_VALUES) -> None:
        """``count`` physics steps; before the k-th MuJoCo step ``ctrl[ctrl_ids] = ctrl_values[k]``.
        A model that must re-evaluate something in Python (``CompiledStep.plan``) gets the run in
        chunks."""
        tissue, dt = self.tissue, self.sim.dt
        limit = self.ops.plan(tissue, dt)
        if limit is None:
            self._run(count, ctrl_ids, ctrl_values)
            return
        done = 0
        try:
            while done < count:
                chunk = min(count - done, limit)
                values = ctrl_values[done:done + chunk] if len(ctrl_ids) else ctrl_values
                self._run(chunk, ctrl_ids, values)
                done += chunk
                if done < count:
                    limit = self.ops.plan(tissue, dt)
        finally:
            self.ops.finish(tissue)

    def _run(self, count: int, ctrl_ids, ctrl_values) -> None:
        sim, tissue, contact = self.sim, self.tissue, self.contact
        guard = tissue.guard
        dt = sim.dt
        mem = self._mj_memo
        if mem[0] is not sim.model or mem[1] is not sim.data:
            mem = self._mj_memo = (sim.model, sim.data, *model_data_addresses(sim.model, sim.data))
        m_ptr, d_ptr = mem[2], mem[3]
        step1, step2 = self._fns
        self._moving[0] = sim.controls_moving
        clock, counts, e = self._clock, self._counts, self._energy
        clock[0] = tissue.time
        counts[0], counts[1], counts[2] = tissue.steps, sim.steps, 0
        max_speed2 = guard.speed_limit(dt) ** 2
        check_every = guard.check_every
        n = sim.tissue_subcycles
        auto_on = tissue.integrator == "auto"
        if auto_on:
            self._auto[:3] = tissue.auto_decision()
        self._auto[4] = -1.0
        k, j, resume = 0, 0, 0
        done = False
        try:
            while True:
                energy_ref, good_pos, good_vel, _ = guard.state()
                e[0], e[1], e[2] = energy_ref, guard.energy_factor, guard.energy_floor
                self._snap[0] = False
                good_pos, good_vel = self._good_state(good_pos, good_vel)
                tab = self._table_now(dt, good_pos, good_vel)
                status, k, j = self._loop(tab, self._base, ctrl_ids, ctrl_values, step1, step2, m_ptr, d_ptr, k, j,
                                          count, resume, dt, n, max_speed2, check_every, auto_on, *self._fn_addresses)
                self._sync(dt)
                if status == DONE:
                    done = True
                    return
                if status == GUARD_FAILED:
                    guard.check(tissue, dt)    # raises the reference loop's error; else (a rounding tie) go on
                    resume = 1
                    continue
                if status == AUTO_RECHECK:     # as TissueModel's "auto" choice, on the same state
                    self._auto[:3] = tissue.refresh_critical_dt(dt)
                    resume = 2
                    continue
                if status == CONTACT_ERROR:
                    contact.raise_kernel_error()
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
        sim.controls_moving = bool(self._moving[0])
        _, good_pos, good_vel, good_time = guard.state()
        if self._snap[0]:
            self._snap[0] = False
            good_time = float(self._clock[1])
            if good_pos is None or good_pos.shape != tissue.positions.shape:
                good_pos, good_vel = self._scratch
                self._scratch = None
        guard.load_state(float(self._energy[0]), good_pos, good_vel, good_time)
        if self._counts[2]:
            self.ops.commit(tissue, dt, bool(self._auto[3]))
        if self._auto[4] >= 0:
            tissue.last_cg_iterations = int(self._auto[4])
            self._auto[4] = -1.0

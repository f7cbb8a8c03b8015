"""The compiled substep loop shared by every registered tissue model, and its Python runner.

One numba call runs the substeps of a control step; per substep, in the generic loop's order and
with the same kernels (so the result is bit-for-bit the generic loop's, tests/test_compiled_substeps.py):

1. scheduled controls (``ctrl_ids``/``ctrl_values``, e.g. Slippage's jaw and pull), then the rate
   limiter while a tool target moves;
2. ``mj_step1``; the tool geoms' poses and velocities (``gather_geoms``);
3. contact (``contact_kernel_prepared``: ``ContactModel.compute_prepared``'s kernel);
4. tissue: refuse non-finite contact input (hand back, Python raises ``NonFiniteInputError``), the
   model's step (a C function pointer, below), fixed nodes, time and step count, the guard's cheap checks
   (non-finite state, runaway speed: hand back, Python raises ``TissueUnstableError``) and, every
   ``check_every`` steps, its costly ones (kinetic energy against the reference; the reference
   raised to kinetic + the model's elastic energy; the state kept as the last good one);
5. the reaction wrench into ``xfrc_applied``; ``mj_step2``; the rows zeroed again.

**Pluggable tissue step.** The loop is one compiled function for every model; the model's step
and energy are C function pointers it calls (``@cfunc``, :func:`step_signature`,
:func:`energy_signature`, given as integer addresses, so the loop stays cacheable: numba keys a
jitted-function *argument* by its address, which would recompile in every process). A model's
step ``step(tab_address, rows, dt, first, implicit) -> int`` reads its arrays from the address
table (:func:`step_arrays` gives the loop's part: positions, velocities, contact forces and
stiffness, ``integrated_external_forces``, the "auto" state; the model's own section starts at
``COMMON_SLOTS``), steps once in place (``first``: the first step of this call, whose Maxwell
coefficients span the interval since the last commit; ``implicit``: the step "auto" picked; it
writes the CG iterations to ``auto[4]``) and returns 1 if it changed ``integrated`` (the forces it
integrated), whose difference to the contact forces the loop then gives the tools as
``ContactModel.attribute_increment`` does. ``energy(tab_address, rows) -> float`` is the stored
elastic energy (J) as the model's ``elastic_energy()``. Being calls through a pointer, the model's
kernels are never inlined into the loop: with fastmath kernels, inlining into the loop changed the
last bit of the calibrated model's volume forces; through the pointer the step runs the same code
as when Python calls it (bit for bit the generic loop). The symplectic integrator integrates
exactly the contact forces given, so the increment ``ContactModel.attribute_increment`` would add
is zero and is not computed.

**Arguments.** All arrays travel in one :class:`~surgsim_envs.scene.array_table.ArrayTable`
(numba unboxes ~0.2 us per array argument: 16-30 us per control step for the ~90 arrays when they
were passed one by one); its layout is the ``SLOT_*`` constants below, then the model's section
from ``COMMON_SLOTS`` on. The loop releases the GIL (``nogil``), as the bindings' ``mj_step`` does,
so a haptic servo thread keeps running during a control step.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import carray, njit, types
from numba.extending import intrinsic

from surgsim_envs.contact.model import contact_kernel_prepared
from surgsim_envs.scene.array_table import ArrayTable, _pointer, b1_1, f8_1, f8_2, f8_3, i8_1, i8_2, u1_2
import math

from surgsim_envs.contact.model import _attribute_increment
from surgsim_envs.scene.step.compiled import (AUTO_RECHECK, CONTACT_ERROR, DONE, GUARD_FAILED, NO_IDS, NO_VALUES,
                                              NON_FINITE_INPUT)
from surgsim_envs.scene.step.kernels import add_wrench, advance_geoms, gather_geoms, rate_limit, write_rows, zero_rows
from surgsim_envs.scene.step.mujoco_native import call_model_data, model_data_addresses
from surgsim_envs.tissue.base import AUTO_RECHECK_STEPS, DT_SAFETY, _max_ratio
from surgsim_envs.tissue.guard import all_finite, speed_within

# ---------------------------------------------------------------------------------------------
# address table layout (rows); the model's own section starts at COMMON_SLOTS
SLOT_GATHER = 0            # 13: the arguments of gather_geoms
GATHER_KINDS = ["i8_1"] * 4 + ["f8_2"] * 9
SLOT_CONTACT = 13          # 34: ContactModel.kernel_state() arrays (scalars in the last one)
CONTACT_KINDS = ["i8_1", "i8_2", "f8_2", "i8_1", "i8_1", "i8_1", "f8_2", "f8_1", "f8_3", "u1_2", "f8_2", "f8_1",
                 "f8_2", "f8_2", "f8_2", "f8_1", "f8_1", "f8_2", "f8_1", "f8_1", "f8_2", "i8_1", "i8_1", "f8_1",
                 "i8_1", "i8_1", "i8_1", "f8_2", "f8_2", "f8_1", "f8_1", "f8_2", "i8_1", "f8_1"]
#: kernel_state() entries that are arrays, in table order (8, 9, 10, 33 are the scalars k_n, c_n, k_t, c_imp)
CONTACT_ARRAY_ENTRIES = [0, 1, 2, 3, 4, 5, 6, 7] + list(range(11, 33)) + [34, 35, 36]
SLOT_REST = 47             # 21: controls, reaction, fixed nodes, counters, guard, sub-cycling, positions, auto
REST_KINDS = ["f8_1", "f8_1", "f8_1", "b1_1",      # ctrl, goal, rate, moving
              "f8_2", "i8_1", "f8_2",              # xfrc_applied, bodies, wrench
              "i8_1", "f8_2", "f8_2",              # fixed_idx, fixed_targets, integrated_external_forces
              "f8_1", "i8_1",                      # clock, counts
              "f8_1", "f8_1", "f8_2", "f8_2", "b1_1",   # masses, energy, good_pos, good_vel, snap
              "f8_2", "f8_2", "f8_2",              # gpos0, positions, velocities
              "f8_1"]                              # integrator "auto": [crit, crit dt, crit step, implicit, CG its]
COMMON_SLOTS = SLOT_REST + len(REST_KINDS)
COMMON_KINDS = GATHER_KINDS + CONTACT_KINDS + REST_KINDS
assert len(COMMON_KINDS) == COMMON_SLOTS


@njit(cache=True)
def _gather_state(tab):
    at = SLOT_GATHER
    return (i8_1(tab, at), i8_1(tab, at + 1), i8_1(tab, at + 2), i8_1(tab, at + 3), f8_2(tab, at + 4),
            f8_2(tab, at + 5), f8_2(tab, at + 6), f8_2(tab, at + 7), f8_2(tab, at + 8), f8_2(tab, at + 9),
            f8_2(tab, at + 10), f8_2(tab, at + 11), f8_2(tab, at + 12))


@njit(cache=True)
def _contact_state(tab):
    """``ContactModel.kernel_state()`` rebuilt from the table (the scalars from the last slot)."""
    at = SLOT_CONTACT
    sc = f8_1(tab, at + 33)
    return (i8_1(tab, at), i8_2(tab, at + 1), f8_2(tab, at + 2), i8_1(tab, at + 3), i8_1(tab, at + 4),
            i8_1(tab, at + 5), f8_2(tab, at + 6), f8_1(tab, at + 7), sc[0], sc[1], sc[2], f8_3(tab, at + 8),
            u1_2(tab, at + 9), f8_2(tab, at + 10), f8_1(tab, at + 11), f8_2(tab, at + 12), f8_2(tab, at + 13),
            f8_2(tab, at + 14), f8_1(tab, at + 15), f8_1(tab, at + 16), f8_2(tab, at + 17), f8_1(tab, at + 18),
            f8_1(tab, at + 19), f8_2(tab, at + 20), i8_1(tab, at + 21), i8_1(tab, at + 22), f8_1(tab, at + 23),
            i8_1(tab, at + 24), i8_1(tab, at + 25), i8_1(tab, at + 26), f8_2(tab, at + 27), f8_2(tab, at + 28),
            f8_1(tab, at + 29), sc[3], f8_1(tab, at + 30), f8_2(tab, at + 31), i8_1(tab, at + 32))


@njit(cache=True)
def _recheck_due(auto, dt, steps):
    """``TissueModel._auto_choice``'s condition to re-evaluate ``critical_dt()`` (done in Python)."""
    return dt != auto[1] or steps - auto[2] >= AUTO_RECHECK_STEPS or not (auto[0] > 0)


@njit(cache=True)
def _pick_implicit(dt, crit, kc, masses):
    """``TissueModel._pick`` with ``_contact_rate(kc)``: True if "auto" takes the implicit step."""
    if not (crit > 0):
        return True
    rate = _max_ratio(kc, masses)
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


def step_signature():
    """numba signature of a model's step function (see the module docstring)."""
    return types.int64(types.int64, types.int64, types.float64, types.int64, types.int64)


def energy_signature():
    """numba signature of a model's energy function (see the module docstring)."""
    return types.float64(types.int64, types.int64)


@njit(cache=True, inline="always")
def table_at(address, rows):
    """The (rows, 4) address table at ``address`` (inside a model's step / energy function)."""
    return carray(_pointer(address, np.int64), (rows, 4))


@njit(cache=True, inline="always")
def step_arrays(tab):
    """(positions, velocities, contact forces, contact stiffness, integrated_external_forces, auto)
    from the loop's part of the table, for a model's step function."""
    return (f8_2(tab, SLOT_REST + 18), f8_2(tab, SLOT_REST + 19), f8_2(tab, SLOT_CONTACT + 10),
            f8_1(tab, SLOT_CONTACT + 11), f8_2(tab, SLOT_REST + 9), f8_1(tab, SLOT_REST + 20))


@intrinsic
def _call_step(typingctx, fn, address, rows, dt, first, implicit):
    sig = types.int64(types.int64, types.int64, types.int64, types.float64, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        i64, f64 = ir.IntType(64), ir.DoubleType()
        fnty = ir.FunctionType(i64, [i64, i64, f64, i64, i64])
        return builder.call(builder.inttoptr(args[0], fnty.as_pointer()), list(args[1:]))

    return sig, codegen


@intrinsic
def _call_energy(typingctx, fn, address, rows):
    sig = types.float64(types.int64, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        fnty = ir.FunctionType(ir.DoubleType(), [i64, i64])
        return builder.call(builder.inttoptr(args[0], fnty.as_pointer()), list(args[1:]))

    return sig, codegen


@njit(cache=True, nogil=True)
def run_substeps(tab, ctrl_ids, ctrl_values, step1, step2, m_ptr, d_ptr, k, j, count, resume, dt, n, max_speed2,
                 check_every, auto_on, step_fn, energy_fn):
    """``count`` physics steps as MuJoCo steps ``k .. count/n - 1`` of ``n`` tissue steps each (see the
    module docstring; n = 1 is the documented one-to-one loop), starting at tissue step ``j`` of
    MuJoCo step ``k``. ``resume``: 0, or 1 = that tissue step is done (after a check in Python):
    continue with its reaction; 2 = Python has just re-evaluated the critical dt for it (integrator
    "auto", ``auto_on``): do it without asking again. counts: [tissue steps, simulation steps, tissue steps taken in this batch];
    clock: [tissue time, time of the last good state]; energy: [reference, factor, floor].
    Returns (status, MuJoCo step index, tissue step index within it)."""
    gather = _gather_state(tab)
    contact = _contact_state(tab)
    at = SLOT_REST
    ctrl, goal, rate, moving = f8_1(tab, at), f8_1(tab, at + 1), f8_1(tab, at + 2), b1_1(tab, at + 3)
    xfrc, bodies, wrench = f8_2(tab, at + 4), i8_1(tab, at + 5), f8_2(tab, at + 6)
    fixed_idx, fixed_targets, integrated = i8_1(tab, at + 7), f8_2(tab, at + 8), f8_2(tab, at + 9)
    clock, counts = f8_1(tab, at + 10), i8_1(tab, at + 11)
    masses, energy, good_pos, good_vel, snap = (f8_1(tab, at + 12), f8_1(tab, at + 13), f8_2(tab, at + 14),
                                                f8_2(tab, at + 15), b1_1(tab, at + 16))
    gpos0, pos, vel = f8_2(tab, at + 17), f8_2(tab, at + 18), f8_2(tab, at + 19)
    auto = f8_1(tab, at + 20)
    address, rows = np.int64(tab.ctypes.data), np.int64(tab.shape[0])
    big_dt = dt * n
    gpos, gmat, gvel, tcom = gather[9], gather[10], gather[11], gather[12]
    forces, stiffness, tool_force, tool_torque = contact[13], contact[14], contact[16], contact[17]
    touched, node_tool_k, com_copy, pos_copy = contact[3], contact[15], contact[30], contact[31]
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
                if _call_step(step_fn, address, rows, dt, 1 if counts[2] == 0 else 0, 1 if implicit else 0):
                    # the integrator added to the contact force: the tools get the reaction of it too
                    _attribute_increment(touched, integrated, forces, stiffness, node_tool_k, pos_copy, com_copy,
                                         tool_force, tool_torque)
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
                    _keep_good_state(ke + _call_energy(energy_fn, address, rows), pos, vel, energy, good_pos,
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


class TissueOps:
    """What a registered model supplies (see the module docstring): its ``step`` and ``energy``
    (numba ``cfunc`` objects of :func:`step_signature` / :func:`energy_signature`), ``kinds`` of its
    table section and ``arrays(tissue, dt)`` returning that section's arrays (the model's own, valid
    until they are replaced), and ``committed(tissue, dt)``: bookkeeping after the loop stepped the
    model at least once. Optional ``key(tissue, dt)``: a hashable that, with the tissue's
    ``_array_version``, changes whenever ``arrays(tissue, dt)`` would return other arrays (e.g. the
    interval its coefficients span); without it the arrays are compared by identity every call."""

    def __init__(self, step, energy, kinds, arrays, committed, key=None):
        self.step, self.energy = step, energy
        self.kinds, self.arrays, self.committed = list(kinds), arrays, committed
        self.key = key


class SubstepsRunner:
    """Runs the loop with a model's step for one :class:`Simulation` and does the Python side: keeps
    the address table current (rebuilt when an array was replaced, e.g. by reset()), mirrors the
    counters and the guard's state back into the model, the guard and the simulation, and turns the
    hand-backs into the generic loop's checks and errors (the Python check is repeated on the same
    state, so the error and its message are the ones ``TissueModel.step`` raises)."""

    def __init__(self, sim, tissue, contact, fns, ops: TissueOps):
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
        self._gpos0 = np.empty_like(sim._gpos)
        self._kinds = COMMON_KINDS + ops.kinds
        self._table = ArrayTable()
        self._loop = run_substeps
        self._fn_addresses = (ops.step.address, ops.energy.address)
        self._mj_memo = (None, None, 0, 0)      # (model, data, their addresses)

    def _contact_section(self) -> list:
        contact = self.contact
        if self._contact_key is not contact._prepared:      # rebuilt only after a new prepare()
            cs = contact.kernel_state()
            self._contact_arrays = [cs[i] for i in CONTACT_ARRAY_ENTRIES] + [self._cscal]
            self._cscal[:] = (cs[8], cs[9], cs[10], cs[33])
            self._contact_key = contact._prepared
        return self._contact_arrays

    def _good_state(self):
        guard, tissue = self.tissue.guard, self.tissue
        good = guard._good_pos
        if good is not None and good.shape == tissue.positions.shape:
            return good, guard._good_vel
        if self._scratch is None or self._scratch[0].shape != tissue.positions.shape:
            self._scratch = (np.zeros_like(tissue.positions), np.zeros_like(tissue.positions))
        return self._scratch

    def _table_now(self, dt: float) -> np.ndarray:
        """The address table, repacked only when an array was replaced: the simulation's and the
        runner's own arrays never are, the contact's only by a new prepare(); the tissue's when its
        ``_array_version`` moved (every non-scalar attribute assignment bumps it: reset(), a material
        change, new buffers) or the model's ``ops.key`` changed; the guard's (the first snapshot)
        are compared by identity. A model without ``ops.key`` has its arrays compared by identity."""
        tissue = self.tissue
        good_pos, good_vel = self._good_state()
        self._contact_section()
        key_of = self.ops.key
        if key_of is not None:
            key = (tissue._array_version, id(good_pos), id(good_vel), id(self._contact_key), key_of(tissue, dt))
            table = self._table
            if key == table._key:
                return table.table
            return table.update(key, lambda: self._arrays(dt, good_pos, good_vel, self.ops.arrays(tissue, dt)),
                                self._kinds)
        own = self.ops.arrays(tissue, dt)
        volatile = [tissue._fixed_idx, tissue.fixed_targets, tissue.integrated_external_forces, tissue.masses, good_pos,
                    good_vel, tissue.positions, tissue.velocities, *own]
        key = (id(self._contact_key), *map(id, volatile))
        return self._table.update(key, lambda: self._arrays(dt, good_pos, good_vel, own), self._kinds)

    def _arrays(self, dt: float, good_pos, good_vel, own) -> list:
        """Every array of the table, in ``COMMON_KINDS`` + ``ops.kinds`` order."""
        sim, tissue = self.sim, self.tissue
        v = sim._views
        return [*sim._gather_args, *self._contact_arrays, v["ctrl"], sim._goal, sim._rate, self._moving,
                v["xfrc_applied"], sim._bodies, sim._wrench, tissue._fixed_idx, tissue.fixed_targets,
                tissue.integrated_external_forces, self._clock, self._counts, tissue.masses, self._energy, good_pos,
                good_vel, self._snap, self._gpos0, tissue.positions, tissue.velocities, self._auto, *own]

    def run(self, count: int, ctrl_ids=NO_IDS, ctrl_values=NO_VALUES) -> None:
        sim, tissue, contact = self.sim, self.tissue, self.contact
        guard = tissue.guard
        dt = sim.dt
        mem = self._mj_memo
        if mem[0] is not sim.model or mem[1] is not sim.data:
            mem = self._mj_memo = (sim.model, sim.data, *model_data_addresses(sim.model, sim.data))
        m_ptr, d_ptr = mem[2], mem[3]
        step1, step2 = self._fns
        self._moving[0] = sim._moving
        clock, counts, e = self._clock, self._counts, self._energy
        clock[0] = tissue.time
        counts[0], counts[1], counts[2] = tissue.steps, sim.steps, 0
        max_speed2 = float(guard.max_speed) ** 2
        check_every = guard.check_every
        n = sim.tissue_subcycles
        auto_on = tissue.integrator == "auto"
        if auto_on:
            nan = float("nan")
            self._auto[:3] = (getattr(tissue, "_auto_crit", nan), getattr(tissue, "_auto_dt", nan),
                              getattr(tissue, "_auto_step", 0))
        self._auto[4] = -1.0
        k, j, resume = 0, 0, 0
        done = False
        try:
            while True:
                e[0], e[1], e[2] = guard._energy_ref, guard.energy_factor, guard.energy_floor
                self._snap[0] = False
                tab = self._table_now(dt)
                status, k, j = self._loop(tab, ctrl_ids, ctrl_values, step1, step2, m_ptr, d_ptr, k, j, count, resume,
                                          dt, n, max_speed2, check_every, auto_on, *self._fn_addresses)
                self._sync(dt)
                if status == DONE:
                    done = True
                    return
                if status == GUARD_FAILED:
                    guard.check(tissue, dt)    # raises the generic loop's error; else (a rounding tie) go on
                    resume = 1
                    continue
                if status == AUTO_RECHECK:     # as TissueModel._auto_choice, on the same state
                    tissue._auto_crit = float(tissue.critical_dt())
                    tissue._auto_dt, tissue._auto_step = dt, tissue.steps
                    self._auto[:3] = (tissue._auto_crit, dt, tissue.steps)
                    resume = 2
                    continue
                if status == CONTACT_ERROR:
                    cs = contact.kernel_state()
                    contact._raise_kernel_error(*cs[4:7])
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
        state = tissue.__dict__            # scalars: set directly (no array-version bookkeeping needed)
        state["time"] = float(self._clock[0])
        state["steps"] = int(self._counts[0])
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
            state["_last_dt"] = dt
            self.ops.committed(tissue, dt)
            if tissue.integrator == "auto":
                tissue._active = tissue.auto_pair[1] if self._auto[3] else tissue.auto_pair[0]
        if self._auto[4] >= 0:
            tissue.last_cg_iterations = int(self._auto[4])
            self._auto[4] = -1.0

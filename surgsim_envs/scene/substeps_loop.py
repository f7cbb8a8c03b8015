"""The compiled substep loop shared by every registered tissue model, and its Python runner.

One numba call runs the substeps of a control step; per substep, in the generic loop's order and
with the same kernels (so the result is bit-for-bit the generic loop's, tests/test_compiled_substeps.py):

1. scheduled controls (``ctrl_ids``/``ctrl_values``, e.g. Slippage's jaw and pull), then the rate
   limiter while a tool target moves;
2. ``mj_step1``; the tool geoms' poses and velocities (``_gather_geoms``);
3. contact (``contact_kernel_prepared``: ``ContactModel.compute_prepared``'s kernel);
4. tissue: refuse non-finite contact input (hand back, Python raises ``NonFiniteInputError``), the
   model's step (``tissue_step``), fixed nodes, time and step count, the guard's cheap checks
   (non-finite state, runaway speed: hand back, Python raises ``TissueUnstableError``) and, every
   ``check_every`` steps, its costly ones (kinetic energy against the reference; the reference
   raised to kinetic + ``tissue_energy``; the state kept as the last good one);
5. the reaction wrench into ``xfrc_applied``; ``mj_step2``; the rows zeroed again.

**Pluggable tissue step.** :func:`run_substeps` is a template: it names three functions it does
not define, ``tissue_unpack(tab, at)`` (the model's arrays from the address table, a tuple),
``tissue_step(pos, vel, fext, dt, first, tissue)`` (one step in place under external forces
``fext``; ``first``: the first step since the model was last stepped by anyone, whose Maxwell
coefficients span the interval since the last commit) and ``tissue_energy(pos, tissue)`` (stored
elastic energy, J, as the model's ``elastic_energy()``). :func:`specialise` compiles one copy of the
template's code per model with those names bound (no copy of the loop's source; one numba cache
entry per model, keyed by its name). The symplectic integrator integrates exactly the contact
forces given, so the increment ``ContactModel.attribute_increment`` would add is zero and is not
computed.

**Arguments.** All arrays travel in one :class:`~surgsim_envs.scene.array_table.ArrayTable`
(numba unboxes ~0.2 us per array argument: 16-30 us per control step for the ~90 arrays when they
were passed one by one); its layout is the ``SLOT_*`` constants below, then the model's section
from ``COMMON_SLOTS`` on. The loop releases the GIL (``nogil``), as the bindings' ``mj_step`` does,
so a haptic servo thread keeps running during a control step.
"""

from __future__ import annotations

import types as pytypes

import numpy as np
from numba import njit

from surgsim_envs.contact.model import contact_kernel_prepared
from surgsim_envs.scene.array_table import ArrayTable, b1_1, f8_1, f8_2, f8_3, i8_1, i8_2, u1_2
from surgsim_envs.scene.compiled_substeps import CONTACT_ERROR, DONE, GUARD_FAILED, NO_IDS, NO_VALUES, NON_FINITE_INPUT
from surgsim_envs.scene.mujoco_native import call_model_data, model_data_addresses
from surgsim_envs.scene.simulation import (_add_wrench, _advance_geoms, _gather_geoms, _rate_limit, _write_rows,
                                           _zero_rows)
from surgsim_envs.tissue.guard import first_non_finite, max_speed_squared

# ---------------------------------------------------------------------------------------------
# address table layout (rows); the model's own section starts at COMMON_SLOTS
SLOT_GATHER = 0            # 13: the arguments of _gather_geoms
GATHER_KINDS = ["i8_1"] * 4 + ["f8_2"] * 9
SLOT_CONTACT = 13          # 33: ContactModel.kernel_state() arrays (scalars in the last one)
CONTACT_KINDS = ["i8_1", "i8_2", "f8_2", "i8_1", "i8_1", "i8_1", "f8_2", "f8_1", "f8_3", "u1_2", "f8_2", "f8_1",
                 "f8_2", "f8_2", "f8_2", "f8_1", "f8_1", "f8_2", "f8_1", "f8_1", "f8_2", "i8_1", "i8_1", "f8_1",
                 "i8_1", "i8_1", "i8_1", "f8_2", "f8_2", "f8_1", "f8_1", "f8_2", "f8_1"]
#: kernel_state() entries that are arrays, in table order (8, 9, 10, 33 are the scalars k_n, c_n, k_t, c_imp)
CONTACT_ARRAY_ENTRIES = [0, 1, 2, 3, 4, 5, 6, 7] + list(range(11, 33)) + [34, 35]
SLOT_REST = 46             # 20: controls, reaction, fixed nodes, counters, guard, sub-cycling, positions
REST_KINDS = ["f8_1", "f8_1", "f8_1", "b1_1",      # ctrl, goal, rate, moving
              "f8_2", "i8_1", "f8_2",              # xfrc_applied, bodies, wrench
              "i8_1", "f8_2", "f8_2",              # fixed_idx, fixed_targets, integrated_external_forces
              "f8_1", "i8_1",                      # clock, counts
              "f8_1", "f8_1", "f8_2", "f8_2", "b1_1",   # masses, energy, good_pos, good_vel, snap
              "f8_2", "f8_2", "f8_2"]              # gpos0, positions, velocities
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
    sc = f8_1(tab, at + 32)
    return (i8_1(tab, at), i8_2(tab, at + 1), f8_2(tab, at + 2), i8_1(tab, at + 3), i8_1(tab, at + 4),
            i8_1(tab, at + 5), f8_2(tab, at + 6), f8_1(tab, at + 7), sc[0], sc[1], sc[2], f8_3(tab, at + 8),
            u1_2(tab, at + 9), f8_2(tab, at + 10), f8_1(tab, at + 11), f8_2(tab, at + 12), f8_2(tab, at + 13),
            f8_2(tab, at + 14), f8_1(tab, at + 15), f8_1(tab, at + 16), f8_2(tab, at + 17), f8_1(tab, at + 18),
            f8_1(tab, at + 19), f8_2(tab, at + 20), i8_1(tab, at + 21), i8_1(tab, at + 22), f8_1(tab, at + 23),
            i8_1(tab, at + 24), i8_1(tab, at + 25), i8_1(tab, at + 26), f8_2(tab, at + 27), f8_2(tab, at + 28),
            f8_1(tab, at + 29), sc[3], f8_1(tab, at + 30), f8_2(tab, at + 31))


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


# names the template calls; bound per model by specialise() (these placeholders are never called)
tissue_unpack = tissue_step = tissue_energy = None


def run_substeps(tab, ctrl_ids, ctrl_values, step1, step2, m_ptr, d_ptr, k, j, count, resume, dt, n, max_speed2,
                 check_every):
    """``count`` physics steps as MuJoCo steps ``k .. count/n - 1`` of ``n`` tissue steps each (see the
    module docstring; n = 1 is the documented one-to-one loop), starting at tissue step ``j`` of
    MuJoCo step ``k``. ``resume``: that tissue step is done (after a check in Python): continue
    with its reaction. counts: [tissue steps, simulation steps, tissue steps taken in this batch];
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
    tissue = tissue_unpack(tab, COMMON_SLOTS)
    big_dt = dt * n
    gpos, gmat, gvel, tcom = gather[9], gather[10], gather[11], gather[12]
    forces, stiffness, tool_force, tool_torque = contact[13], contact[14], contact[16], contact[17]
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
                tissue_step(pos, vel, forces, dt, counts[2] == 0, tissue)
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
                    ke = _kinetic_energy(vel, masses)
                    if ke > energy[1] * (energy[0] + energy[2]):
                        return GUARD_FAILED, k, j     # nothing updated: Python repeats the check and raises
                    _keep_good_state(ke + tissue_energy(pos, tissue), pos, vel, energy, good_pos, good_vel, clock,
                                     snap)
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


_SPECIALISED: dict[str, object] = {}


def specialise(name: str, unpack, step, energy):
    """The loop of :func:`run_substeps` compiled with ``tissue_unpack``/``tissue_step``/``tissue_energy``
    bound to the given numba functions, as the function ``name`` (a valid identifier, unique per
    model: it names the numba cache entry). One compiled loop per name."""
    if name in _SPECIALISED:
        return _SPECIALISED[name]
    template = run_substeps
    scope = dict(template.__globals__, tissue_unpack=unpack, tissue_step=step, tissue_energy=energy)
    fn = pytypes.FunctionType(template.__code__, scope, name, template.__defaults__, template.__closure__)
    fn.__qualname__ = name
    fn.__doc__ = template.__doc__
    fn.__module__ = template.__module__
    loop = njit(cache=True, nogil=True)(fn)
    _SPECIALISED[name] = loop
    return loop


class TissueOps:
    """What a registered model supplies (see the module docstring): ``name`` of its loop, the
    numba ``unpack``/``step``/``energy``, ``kinds`` of its table section and ``arrays(tissue, dt)``
    returning that section's arrays (the model's own, valid until they are replaced), and
    ``committed(tissue, dt)``: bookkeeping after the loop stepped the model at least once."""

    def __init__(self, name, unpack, step, energy, kinds, arrays, committed):
        self.name, self.kinds, self.arrays, self.committed = name, list(kinds), arrays, committed
        self._fns = (unpack, step, energy)
        self._loop = None

    @property
    def loop(self):
        if self._loop is None:
            self._loop = specialise(self.name, *self._fns)
        return self._loop


class SubstepsRunner:
    """Runs a model's specialised loop for one :class:`Simulation` and does the Python side: keeps
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
        self._scratch = None
        self._contact_key = None
        self._contact_arrays: list = []
        self._gpos0 = np.empty_like(sim._gpos)
        self._kinds = COMMON_KINDS + ops.kinds
        self._table = ArrayTable()
        self._loop = ops.loop

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
        runner's own arrays never are, the contact's only by a new prepare(); the tissue's and the
        guard's (reset(), a material change, the first snapshot) are compared by identity."""
        sim, tissue = self.sim, self.tissue
        good_pos, good_vel = self._good_state()
        volatile = [tissue._fixed_idx, tissue.fixed_targets, tissue.integrated_external_forces, tissue.masses, good_pos,
                    good_vel, tissue.positions, tissue.velocities, *self.ops.arrays(tissue, dt)]
        self._contact_section()
        key = (id(self._contact_key), *map(id, volatile))
        v = sim._views

        def arrays():
            return [*sim._gather_args, *self._contact_arrays, v["ctrl"], sim._goal, sim._rate, self._moving,
                    v["xfrc_applied"], sim._bodies, sim._wrench, *volatile[:3], self._clock, self._counts,
                    volatile[3], self._energy, good_pos, good_vel, self._snap, self._gpos0, *volatile[6:]]

        return self._table.update(key, arrays, self._kinds)

    def run(self, count: int, ctrl_ids=NO_IDS, ctrl_values=NO_VALUES) -> None:
        sim, tissue, contact = self.sim, self.tissue, self.contact
        guard = tissue.guard
        dt = sim.dt
        m_ptr, d_ptr = model_data_addresses(sim.model, sim.data)
        step1, step2 = self._fns
        self._moving[0] = sim._moving
        clock, counts, e = self._clock, self._counts, self._energy
        clock[0] = tissue.time
        counts[0], counts[1], counts[2] = tissue.steps, sim.steps, 0
        max_speed2 = float(guard.max_speed) ** 2
        check_every = guard.check_every
        n = sim.tissue_subcycles
        k, j, resume = 0, 0, False
        done = False
        try:
            while True:
                e[0], e[1], e[2] = guard._energy_ref, guard.energy_factor, guard.energy_floor
                self._snap[0] = False
                tab = self._table_now(dt)
                status, k, j = self._loop(tab, ctrl_ids, ctrl_values, step1, step2, m_ptr, d_ptr, k, j, count, resume,
                                          dt, n, max_speed2, check_every)
                self._sync(dt)
                if status == DONE:
                    done = True
                    return
                if status == GUARD_FAILED:
                    guard.check(tissue, dt)    # raises the generic loop's error; else (a rounding tie) go on
                    resume = True
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
            self.ops.committed(tissue, dt)

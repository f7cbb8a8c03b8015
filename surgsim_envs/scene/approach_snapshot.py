"""A reset's contact-free approach, replayed from a snapshot instead of simulated again.

Slippage-v0's reset closes the grasper on the organ for ``settle_time`` s (1,000 physics steps).
For the first half of that the jaws travel through air: no tissue node feels a tool, the tissue
sits at its rest state (its motion there is round-off, ~1e-17 m) and the rigid bodies move the
same whatever the episode's friction or stiffness, since nothing couples them to the tissue.
Simulating that every episode is ~half of the reset's cost, and a reset that takes 20-30 ms
while the other vector-env worker waits is what bounds the vector speed-up of Slippage.

:class:`ApproachSnapshot` runs the approach once per simulation and schedule key, in chunks,
checking after each that no contact force was felt and the tissue has not moved (positions within
``tolerance_m`` of the reset state, speeds within ``tolerance_m`` per second). It keeps MuJoCo's
integration state (``mjSTATE_INTEGRATION``: time, qpos, qvel, act, warm start, controls, applied
forces) ``margin_steps`` before the first chunk that failed either check; at every reset it
restores that state on the freshly reset simulation, whose tissue is then exactly at rest, and
tells the caller how many steps are done. The rigid state restored is bit for bit the one the full
run reaches (tested); the tissue differs from the full run only by that run's round-off drift.

Where the tissue moves before any contact (a model that is not at equilibrium at rest, a tool that
starts in contact), nothing is kept and every reset simulates the whole approach, as before.

Call :meth:`ApproachSnapshot.skip` right after ``Simulation.reset``: recording resets the
simulation again (same seed) and the restore assumes the reset state. A change of the rigid model
(tool geometry, actuator gains) after the first record needs :meth:`clear`.
"""

from __future__ import annotations

import weakref
from typing import Callable, Hashable, NamedTuple

import mujoco
import numpy as np

from surgsim_envs import validate

_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION


class _Snapshot(NamedTuple):
    steps: int                 # physics steps the snapshot stands for (0: nothing kept); Simulation.steps after them
    state: np.ndarray | None   # MuJoCo integration state after them


def _tissue_at_rest(sim, rest, tolerance: float) -> bool:
    for tissue, (p0, _) in zip(sim.tissues.values(), rest):
        if np.max(np.abs(tissue.positions - p0), initial=0.0) > tolerance:
            return False
        if np.max(np.abs(tissue.velocities), initial=0.0) > tolerance:    # m/s, the same number
            return False
    for contact in sim.contacts.values():
        if np.any(contact.result.forces != 0.0):
            return False
    return True


class ApproachSnapshot:
    """Snapshots of contact-free approaches, per simulation (weakly held) and schedule key."""

    def __init__(self, margin_steps: int = 50, chunk_steps: int = 10, tolerance_m: float = 1e-9):
        for name, v, least in (("margin_steps", margin_steps, 0), ("chunk_steps", chunk_steps, 1)):
            validate.integer(v, f"ApproachSnapshot: {name}", lo=least, unit="physics steps",
                             fix="give a whole number of physics steps")
        validate.positive(tolerance_m, "ApproachSnapshot: tolerance_m", unit="m", fix="e.g. 1e-9")
        self.margin_steps = int(margin_steps)
        self.chunk_steps = int(chunk_steps)
        self.tolerance_m = float(tolerance_m)
        self._kept: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def clear(self) -> None:
        """Forget every snapshot (after changing a simulation's rigid model)."""
        self._kept.clear()

    def steps_kept(self, sim, key: Hashable) -> int | None:
        """Physics steps the snapshot of ``(sim, key)`` stands for; None before it is recorded."""
        snap = self._kept.get(sim, {}).get(key)
        return None if snap is None else snap.steps

    def state(self, sim, key: Hashable) -> np.ndarray | None:
        """A copy of the MuJoCo integration state (``mjSTATE_INTEGRATION``) the snapshot of
        ``(sim, key)`` restores; None before it is recorded or where nothing was kept (e.g. for a
        batched backend that restores it into its own worlds)."""
        snap = self._kept.get(sim, {}).get(key)
        return None if snap is None or snap.state is None else snap.state.copy()

    def skip(self, sim, key: Hashable, run: Callable[[int], None], steps: int) -> int:
        """On ``sim`` just reset: restore the snapshot of the approach ``run`` (``run(n)`` advances
        the caller's schedule by n physics steps, continuing from the current controls) and return
        the physics steps it stands for, at most ``steps``; the caller runs the rest. The first call
        for ``(sim, key)`` records the snapshot (one run of the approach, then ``sim.reset()``)."""
        per_sim = self._kept.setdefault(sim, {})
        snap = per_sim.get(key)
        if snap is None:
            snap = per_sim[key] = self._record(sim, run, int(steps))
        if snap.steps == 0 or snap.steps > steps:
            return 0
        mujoco.mj_setState(sim.model, sim.data, snap.state, _SPEC)
        sim.steps = snap.steps          # Simulation.reset set it to 0 and every physics step adds one
        return snap.steps

    def _record(self, sim, run, steps: int) -> _Snapshot:
        m, d = sim.model, sim.data
        size = mujoco.mj_stateSize(m, _SPEC)
        rest = [(t.positions.copy(), t.velocities.copy()) for t in sim.tissues.values()]
        kept: list[_Snapshot] = []
        done, failed_at = 0, None
        sub = sim.tissue_subcycles              # the approach advances in whole MuJoCo steps
        chunk = -(-self.chunk_steps // sub) * sub
        while done + chunk <= steps:
            n = chunk
            run(n)
            done += n
            if not _tissue_at_rest(sim, rest, self.tolerance_m):
                failed_at = done - n        # the chunk ending at `done` saw a contact or a motion
                break
            state = np.empty(size)
            mujoco.mj_getState(m, d, state, _SPEC)
            kept.append(_Snapshot(done, state))
        sim.reset()                          # the same seed: back to the state the caller reset to
        limit = (steps if failed_at is None else failed_at) - self.margin_steps
        usable = [s for s in kept if s.steps <= limit]
        return usable[-1] if usable else _Snapshot(0, None)

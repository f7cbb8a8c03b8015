"""Grasp-v0's probe set: the three-jaw grasper closed on the organ tip to fixed closures and held.

The task's scene is its own (``gym.make("SurgSim/Grasp-v0", model=..., resolution=...)``): the
spleen held by its ligaments, the grasper open around its tip, the task's dt (0.4 ms), tissue
sub-cycles, closing speed (30 mm/s) and control rate (50 Hz). The material is the task's made
elastic (``relax_fraction`` 0, friction kept; the option ``material``): relaxation is each model's
material law, checked elsewhere; here the scene's geometry, contact and friction are tested.

Each closure starts from a fresh reset (seed 0, mu :data:`MU` for both coefficients, Young's
modulus scale 1) and sends the task's action ``[0, 0, 0, close]`` (the wrist held at home, the jaws
closing at the task's speed to the opening of ``close``) for ``hold`` s; the reading is the mean of
each jaw's normal force over the last :data:`WINDOW` s, read by ``env.readings()``: the per-jaw
normal forces the reward's ``contact`` (above ``hold_force`` 0.03 N) and ``excess_force`` (above
``damage_force`` 1 N) terms switch on. Keys ``"<close>/jaw<j>"`` and ``"<close>/sum"``.

Errors: per reading ``|F - F_ref| / max(F_ref, hold_force)``: a jaw the reference reads under the
task's 0.03 N holding threshold is scored on that threshold (the reward cannot tell such forces
apart; a relative error of a near-zero force would be noise). The row also states whether the jaws'
summed normal force rises with closure, the largest tensile (negative) jaw normal force seen, how
much the last window differs from the one :data:`SETTLE_GAP` s before it (quasi-static: the
holds are long enough when that is small), and the median wall time of one env step.

Reference: :mod:`surgsim_envs.bench.grasp_reference` (``fem_static``, elastic, friction on, contact
stiffness per area) on the organ's lattice refined from 11 mm by 1/sqrt 2, driven by the same jaw
commands and read by the same jaw-force readout.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from surgsim_envs.bench import reading_table as rt
from surgsim_envs.errors import ConfigError

TASK = "SurgSim/Grasp-v0"
#: tool-tissue friction of every closure (the middle of the task's 0.6-1.0 randomisation)
MU = 0.8
#: s, the window of each reading at the end of its hold, and the gap to the window it is checked against
WINDOW = 0.1
SETTLE_GAP = 0.5


@dataclass(frozen=True)
class ClosureSet:
    """Grasp closures: the task's close actions (from open -1 to ``min_radius`` +1, rising), the
    hold (s), the lattice spacings (m) the models run at and the reference's (descending)."""

    closures: tuple[float, ...]
    hold: float
    spacings: tuple[float, ...]
    reference_spacings: tuple[float, ...]


FULL = ClosureSet(closures=(0.0, 0.1, 0.2), hold=2.0, spacings=(0.015, 0.011, 0.008),
                  reference_spacings=(0.011, 0.011 / math.sqrt(2), 0.0055, 0.0055 / math.sqrt(2), 0.00275,
                                      0.00275 / math.sqrt(2)))
QUICK = ClosureSet(closures=(0.0, 0.2), hold=2.0, spacings=(0.015,), reference_spacings=(0.015, 0.011))


def _key(close: float, what: str) -> str:
    return f"{close:+g}/{what}"


def task_material():
    """The task's material made elastic (its friction kept)."""
    from surgsim_envs.bench.task_reference import elastic
    from surgsim_envs.envs.grasp import GraspConfig

    return elastic(GraspConfig().material)


def make_env(model: str, spacing: float | None):
    """Grasp-v0 (unwrapped) with ``model`` at lattice ``spacing`` (m; None: the task's default) and the
    elastic material."""
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401  (registers the tasks)

    return gym.make(TASK, model=model, resolution=None if spacing is None else float(spacing), material=task_material(),
                    disable_env_checker=True).unwrapped


class Readings:
    """Per-step jaw normal forces (N) of one hold, reduced to the reading and its settling."""

    def __init__(self, control_dt: float):
        self.control_dt = float(control_dt)
        self.rows: list[np.ndarray] = []

    def add(self, normal) -> None:
        self.rows.append(np.array(normal, dtype=float))

    def reading(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(mean per-jaw normal over the last WINDOW s, the same SETTLE_GAP s earlier, min seen)."""
        f = np.array(self.rows)
        n = max(1, int(round(WINDOW / self.control_dt)))
        gap = int(round(SETTLE_GAP / self.control_dt))
        if len(f) < n + gap:
            raise ConfigError(f"{TASK}: a hold of {len(f) * self.control_dt:g} s is shorter than the reading window "
                              f"{WINDOW:g} s plus the settling gap {SETTLE_GAP:g} s; hold longer")
        return f[-n:].mean(axis=0), f[-n - gap:-gap].mean(axis=0), float(f.min())


def store(forces: dict, settle: dict, close: float, readings: Readings, threshold: float) -> float:
    """Write one closure's readings into ``forces`` / ``settle``; return the smallest normal seen."""
    now, before, low = readings.reading()
    for j, f in enumerate(now):
        forces[_key(close, f"jaw{j + 1}")] = float(f)
    forces[_key(close, "sum")] = float(now.sum())
    settle[_key(close, "sum")] = float(abs(now.sum() - before.sum()) / max(now.sum(), threshold))
    return low


def measure(task: str, model: str, spacing: float, probes: ClosureSet) -> dict:
    """One row: ``probes``' closures in Grasp-v0 built with ``model`` at ``spacing`` (m)."""
    from surgsim_envs.tissue import TissueUnstableError

    head = {"task": task, "model": model, "spacing": float(spacing)}
    try:
        env = make_env(model, spacing)
    except ConfigError as exc:
        return {**head, "refused": str(exc).split("\n")[0]}
    forces, settle, step_us, low = {}, {}, [], math.inf
    steps = int(round(probes.hold / env.control_dt))
    try:
        for close in probes.closures:
            env.reset(seed=0, options={"mu": (MU, MU), "young_scale": (1.0, 1.0)})
            action = np.array([0.0, 0.0, 0.0, close], dtype=np.float32)
            readings = Readings(env.control_dt)
            for _ in range(steps):
                t0 = time.perf_counter()
                env.step(action)
                step_us.append((time.perf_counter() - t0) * 1e6)
                readings.add(env.readings()[1])
            low = min(low, store(forces, settle, close, readings, env.config.hold_force))
    except TissueUnstableError as exc:
        env.close()
        return {**head, "refused": "unstable in the task's scene: " + str(exc).split("\n")[0], "spacing_specific": True}
    row = {**head, "nodes": int(len(env.sim.tissue().positions)), "forces_N": forces, "settle_change": settle,
           "max_tensile_N": max(0.0, -low), "us_per_env_step": float(np.median(step_us)),
           "control_dt": float(env.control_dt), "dt": float(env.sim.dt), "hold_force_N": float(env.config.hold_force)}
    env.close()
    row["us_per_ms"] = row["us_per_env_step"] / (row["control_dt"] * 1e3)
    return row


def reference_row(task: str, probes: ClosureSet, fine: float, **contact) -> dict:
    """The reference readings of ``probes`` at lattice spacing ``fine`` (m) (module docstring); ``contact``
    (``jaw_edges``, ``surface_samples``, ``cache_mb``, ``graded_tip``) changes the reference's contact
    (:func:`surgsim_envs.bench.grasp_reference.reference_simulation`)."""
    from surgsim_envs.bench import grasp_reference as ref
    from surgsim_envs.envs.terms.action import jaw_opening
    from surgsim_envs.tissue import TissueUnstableError

    t0 = time.perf_counter()
    env = make_env(ref.REFERENCE_MODEL, None)
    sim = ref.reference_simulation(env, fine, **contact)
    name, home, g = env.tool_name, env.home.copy(), env.gcfg
    steps = int(round(probes.hold / env.control_dt))
    forces, settle, low = {}, {}, math.inf
    try:
        for close in probes.closures:
            sim.reset(seed=0)
            ref.set_friction(sim, MU, env.config.static_friction_ratio)
            radius = jaw_opening(float(close), g.open_radius, g.min_radius)
            readings = Readings(env.control_dt)
            for _ in range(steps):
                sim.set_tool_target(name, home)
                sim.set_jaw_opening(name, radius)
                sim.step()
                readings.add(sim.jaw_forces(name)["normal"])
            low = min(low, store(forces, settle, close, readings, env.config.hold_force))
    except TissueUnstableError as exc:
        raise ConfigError(f"{task}: the reference {ref.REFERENCE_MODEL} at {fine * 1e3:.3g} mm failed: "
                          f"{str(exc).splitlines()[0]}") from None
    finally:
        env.close()
    return {"task": task, "model": ref.REFERENCE_MODEL, "spacing": float(fine), "nodes": int(len(sim.tissue().positions)),
            "forces_N": forces, "settle_change": settle, "max_tensile_N": max(0.0, -low),
            "seconds": time.perf_counter() - t0}


def errors(forces: dict, reference: dict, threshold: float) -> dict:
    """Per reading ``|F - F_ref| / max(F_ref, threshold)`` (module docstring)."""
    return {k: abs(forces[k] - r) / max(abs(r), threshold) for k, r in reference.items()}


def compare(row: dict, reference: dict, probes: ClosureSet) -> dict:
    """``row`` with its errors against ``reference`` and whether its summed normal rises with closure."""
    if "forces_N" not in row:
        return row
    f = row["forces_N"]
    err = np.array(list(errors(f, reference["forces_N"], row["hold_force_N"]).values()))
    sums = [f[_key(c, "sum")] for c in probes.closures]
    return {**row, "error_median": float(np.median(err)), "error_p95": float(np.percentile(err, 95)),
            "error": float(np.percentile(err, 95)), "contrast": [], "contrast_reference": [],
            "monotone": bool(all(a < b for a, b in zip(sums, sums[1:]))), "scene": row["task"],
            "integrator": "default"}


def markdown(reference: dict, rows: list[dict]) -> str:
    """The task's block of the task-accuracy table: the reference ladder, its readings per level and
    one row per model and spacing (whether the summed normal rises with closure, the settle change of
    the slowest reading, the largest tensile jaw force and the cost per env step and simulated ms)."""
    columns = [("sum N rises with closure", lambda r: rt.yes_no(r["monotone"])),
               ("settle change %", lambda r: f"{100 * max(r['settle_change'].values()):.2g}"),
               ("max tensile N", lambda r: f"{r['max_tensile_N']:.3g}"),
               ("us / env step", lambda r: f"{r['us_per_env_step']:.0f}"),
               ("us / sim ms", lambda r: f"{r['us_per_ms']:.1f}")]
    return "\n\n".join([rt.reference_summary(reference), rt.reference_readings(reference), rt.model_rows(rows, columns)])


def _description() -> str:
    from surgsim_envs.bench import grasp_reference as ref

    return (f"`{ref.REFERENCE_MODEL}` in the task's scene (the spleen on its uniform lattice, refined whole), elastic, "
            f"friction mu {MU:g} on, contact stiffness {ref.CONTACT_STIFFNESS_PER_AREA:.0e} N/m^3 per area (nodes only), "
            "driven by the task's jaw commands")


REFERENCE_DESCRIPTION = _description()

__all__ = ["TASK", "MU", "ClosureSet", "FULL", "QUICK", "REFERENCE_DESCRIPTION", "make_env", "measure",
           "reference_row", "compare", "errors", "markdown"]

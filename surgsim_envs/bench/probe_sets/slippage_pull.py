"""Slippage-v0's probe set: the task's closure held, then a slow pull until the grasp slides.

The task's scene is its own (``gym.make("SurgSim/Slippage-v0", model=..., resolution=...)``): the
spleen held by its ligaments, the three-jaw grasper closed on its tip by the reset's settle (at the
task's closing speed, to :data:`CLOSURE`, set as the task's ``initial_closure``), then pulled out along the tool axis by the
task's force motor (with its joint damping). The material is the task's made elastic
(``relax_fraction`` 0, friction kept; the option ``material``), and the settle is lengthened to
:data:`HOLD` s (the option ``settle_time``) so the closure is held before the pull starts.

Each pull starts from a fresh reset (seed 0, Young's modulus scale 1, friction mu for both
coefficients, a steady ramp of :data:`PULL_RATE` N/s with no oscillation) and keeps the jaws at
that closure. Readings, all from the task's own readouts (the ones its reward terms use):

* ``"mu<mu>/normal"``: the jaws' summed normal force (N) at the end of the hold (the reset's
  observation, before any pull);
* ``"mu<mu>/held"``: the largest pull (N, ``info["pull_force_N"]``) over the control steps before
  the task's slip distance (``env.slip_distance``: the grasped nodes' centroid relative to the
  wrist, the slip reward's input) first exceeds :data:`SLIP_ONSET`. Below it the grasp deforms and
  slips partially at the edges of each jaw's contact (0.3-1.5 mm with mass_spring at 11 mm, closure
  0.7, mu 0.6); past it the tissue ran away from the jaws within two control steps (1.5 -> 10 mm);
* ``"mu<mu>/held_contact"``: the largest contact force of the tissue on the grasper against the pull
  (N, ``Simulation.tool_force`` along the pull) over the same steps. The motor's pull exceeds it by
  what the wrist's joint damping (2 N s/m) and inertia take while the grasp creeps.

Per mu the row also gives held / (mu x summed normal at the hold) and at the onset
(``held_ratio``, ``held_ratio_at_onset``), the held contact force / (mu x summed normal at the hold)
(``contact_ratio``) and the largest contact force / (mu x summed normal) of any one step before the
onset (``coulomb_ratio``: Coulomb friction bounds it by 1 where the jaws' normals are across the
pull), the largest tensile jaw normal force seen (N) and the
median wall time of one env step. Errors: ``|F - F_ref| / F_ref`` over the normal, held and
held-contact readings. A pull that never slides (up to the motor's ``max_pull``) gives no held reading and the
row says so.

Reference: :mod:`surgsim_envs.bench.grasp_reference` (``fem_static``, elastic, friction on, contact
stiffness per area) on the organ's lattice refined from 11 mm by 1/sqrt 2, the jaw and pull-motor
controls computed by the task's own schedule (:func:`~surgsim_envs.envs.slippage.terms.control_schedule`),
the slip read by the task's :class:`~surgsim_envs.envs.grasp.terms.SlipTracker`. When the grasp
lets go, the quasi-static organ springs back within one step and its stability guard stops the
step (node speed above 20 m/s): that counts as the slide (the pull of the control step before it is
the held one), and the row lists those mu in ``released_mu``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from surgsim_envs.bench import reading_table as rt
from surgsim_envs.errors import ConfigError

TASK = "SurgSim/Slippage-v0"
#: s, the closure's hold before the pull (the task's settle, lengthened from its 0.4 s)
HOLD = 1.0
#: N/s, the pull's ramp: slow against the grasp's dynamics (4 mN per 20 ms control step)
PULL_RATE = 0.2
#: m, the slip distance at which the grasp counts as sliding (module docstring)
SLIP_ONSET = 0.002
#: the jaw closure held (action value): the task's own settle closure (0.7) squeezes the spleen tip to
#: about 8 N in the reference, where its small-strain equilibrium is lost at 5.5 mm (a node jumped
#: 11 mm in one step, t = 0.49 s of the closing); 0.3 (about 3 N) is within what the agent commands
CLOSURE = 0.3


@dataclass(frozen=True)
class PullSet:
    """Slippage pulls: the jaw closure held (the task's action value, set as its ``initial_closure``),
    the friction coefficients (one pull each), the lattice spacings (m) the models run at and the
    reference's (descending)."""

    closure: float
    mus: tuple[float, ...]
    spacings: tuple[float, ...]
    reference_spacings: tuple[float, ...]


#: the reference stops at 3.9 mm: a pull to the onset runs up to about 15,000 quasi-static steps per mu
#: (1 s of hold and up to 5 s of ramp at 0.4 ms), against 5,000 per closure of Grasp-v0's probe set,
#: whose 2.75 mm level (8,500 nodes) took 238 s
FULL = PullSet(closure=CLOSURE, mus=(0.3, 0.6), spacings=(0.015, 0.011, 0.008),
               reference_spacings=(0.011, 0.011 / math.sqrt(2), 0.0055, 0.0055 / math.sqrt(2)))
QUICK = PullSet(closure=CLOSURE, mus=(0.6,), spacings=(0.015,), reference_spacings=(0.015, 0.011))


def task_material():
    """The task's material made elastic (its friction kept)."""
    from surgsim_envs.bench.task_reference import elastic
    from surgsim_envs.envs.slippage import SlippageConfig

    return elastic(SlippageConfig().material)


def make_env(model: str, spacing: float | None, closure: float = CLOSURE):
    """Slippage-v0 (unwrapped) with ``model`` at lattice ``spacing`` (m; None: the task's default), the elastic material, the
    hold :data:`HOLD` and the settle closing the jaws to ``closure`` (action value)."""
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401  (registers the tasks)

    return gym.make(TASK, model=model, resolution=None if spacing is None else float(spacing), material=task_material(), settle_time=HOLD,
                    initial_closure=float(closure), disable_env_checker=True).unwrapped


def options(mu: float) -> dict:
    """The reset options of a pull at friction ``mu``: a steady ramp, Young's modulus scale 1."""
    return {"mu": (mu, mu), "young_scale": (1.0, 1.0), "pull_rate": (PULL_RATE, PULL_RATE),
            "pull_amplitude": (0.0, 0.0), "pull_frequency": (1.0, 1.0)}


class Pull:
    """One pull's readings: the normal at the hold, then per control step the pull, the slip distance,
    the jaws' summed normal and the contact force on the grasper along the pull, until the slip
    passes :data:`SLIP_ONSET`."""

    def __init__(self, normal_at_hold: float, mu: float):
        self.normal, self.mu = float(normal_at_hold), float(mu)
        self.held = self.held_contact = self.normal_at_onset = None
        self.last_pull, self.last_contact, self.last_normal = 0.0, 0.0, self.normal
        self.coulomb = 0.0          # the largest contact / (mu x summed normal) of one step

    def add(self, pull: float, slip: float, normal: float, contact: float) -> bool:
        """Record one control step (``contact``: N, the tissue's force on the grasper against the pull);
        True once the grasp has slid (the held forces are then set)."""
        if slip > SLIP_ONSET:
            self.held, self.held_contact, self.normal_at_onset = self.last_pull, self.last_contact, self.last_normal
            return True
        self.last_pull = max(self.last_pull, float(pull))
        self.last_contact = max(self.last_contact, float(contact))
        self.last_normal = float(normal)
        if normal > 0.0:
            self.coulomb = max(self.coulomb, float(contact) / (self.mu * float(normal)))
        return False

    def store(self, forces: dict, ratios: dict) -> None:
        key = f"mu{self.mu:g}"
        forces[f"{key}/normal"] = self.normal
        if self.held is not None:
            forces[f"{key}/held"] = self.held
            forces[f"{key}/held_contact"] = self.held_contact
            mu_n = self.mu * self.normal
            ratios[key] = {"held_ratio": self.held / mu_n, "held_ratio_at_onset": self.held / (self.mu * self.normal_at_onset),
                           "contact_ratio": self.held_contact / mu_n, "coulomb_ratio": self.coulomb}


def max_steps(max_pull: float, control_dt: float) -> int:
    """Control steps for the ramp to reach the motor's ``max_pull`` (N), plus one second."""
    return int(math.ceil((max_pull / PULL_RATE + 1.0) / control_dt))


def measure(task: str, model: str, spacing: float, probes: PullSet) -> dict:
    """One row: ``probes``' pulls in Slippage-v0 built with ``model`` at ``spacing`` (m)."""
    from surgsim_envs.tissue import TissueUnstableError

    head = {"task": task, "model": model, "spacing": float(spacing)}
    try:
        env = make_env(model, spacing, probes.closure)
    except ConfigError as exc:
        return {**head, "refused": str(exc).split("\n")[0]}
    forces, ratios, step_us, low, never, released = {}, {}, [], math.inf, [], []
    action = np.array([env.config.initial_closure], dtype=np.float32)
    try:
        for mu in probes.mus:
            env.reset(seed=0, options=options(mu))
            fn = env.readings()[1]
            low = min(low, float(np.min(fn)))
            pull = Pull(float(np.sum(fn)), mu)
            for _ in range(max_steps(env.config.max_pull, env.control_dt)):
                t0 = time.perf_counter()
                try:
                    _, _, terminated, _, info = env.step(action)
                except TissueUnstableError:     # released (a quasi-static model springs back): the slide
                    released.append(mu)
                    pull.add(math.nan, math.inf, math.nan, math.nan)
                    break
                step_us.append((time.perf_counter() - t0) * 1e6)
                fn = env.readings()[1]
                low = min(low, float(np.min(fn)))
                contact = -float(env.sim.tool_force(env.tool_name) @ env.pull_dir)
                if pull.add(info["pull_force_N"], env.slip_distance, info["normal_force_N"], contact) or terminated:
                    break
            if pull.held is None:
                never.append(mu)
            pull.store(forces, ratios)
    except (TissueUnstableError, ConfigError) as exc:
        env.close()
        return {**head, "refused": "fails in the task's scene: " + str(exc).split("\n")[0], "spacing_specific": True}
    row = {**head, "nodes": int(len(env.sim.tissue().positions)), "forces_N": forces, "held_ratio": ratios,
           "never_slid_mu": never, "released_mu": released, "max_tensile_N": max(0.0, -low), "us_per_env_step": float(np.median(step_us)),
           "control_dt": float(env.control_dt), "dt": float(env.sim.dt)}
    env.close()
    row["us_per_ms"] = row["us_per_env_step"] / (row["control_dt"] * 1e3)
    return row


def motorise(sim, tool, max_pull: float, damping: float) -> tuple[int, int]:
    """Turn ``tool``'s along-axis wrist drive in ``sim`` into the task's pull motor (a force actuator
    limited to ``max_pull`` N, ``damping`` N s/m on its joint), as Slippage-v0 does to its scene.
    Returns (jaw actuator, pull actuator)."""
    m = sim.model
    a, dof = int(tool.actuator_ids[2]), int(tool.dof_adr[2])
    m.actuator_gainprm[a, :] = 0.0
    m.actuator_gainprm[a, 0] = 1.0
    m.actuator_biasprm[a, :] = 0.0
    m.actuator_ctrlrange[a] = [-max_pull, max_pull]
    m.dof_damping[dof] = damping
    return int(tool.jaw_actuator_id), a


def reference_row(task: str, probes: PullSet, fine: float, **contact) -> dict:
    """The reference readings of ``probes`` at lattice spacing ``fine`` (m) (module docstring); ``contact``
    (``jaw_edges``, ``surface_samples``, ``cache_mb``, ``graded_tip``) changes the reference's contact
    (:func:`surgsim_envs.bench.grasp_reference.reference_simulation`)."""
    from surgsim_envs.bench import grasp_reference as ref
    from surgsim_envs.envs.grasp.terms import SlipTracker, contact_nodes
    from surgsim_envs.envs.slippage.terms import control_schedule
    from surgsim_envs.envs.terms.action import jaw_closure
    from surgsim_envs.tissue import TissueUnstableError

    t0 = time.perf_counter()
    env = make_env(ref.REFERENCE_MODEL, None, probes.closure)
    c, g, name = env.config, env.gcfg, env.tool_name
    sim = ref.reference_simulation(env, fine, **contact)
    jaw_act, pull_act = motorise(sim, sim.tool(name), float(c.max_pull), float(c.pull_damping))
    n = sim.tissue_subcycles
    dt = sim.dt * n
    lim = float(c.closing_speed) * dt
    goal = jaw_closure(float(c.initial_closure), g.open_radius, g.min_radius)
    per_step = -(-sim.substeps // n)
    forces, ratios, never, released, low = {}, {}, [], [], math.inf

    def run(rows: int, pulling: bool, rate: float, start: float) -> float:
        values = np.zeros((rows, 2))
        control_schedule(values, float(sim.data.ctrl[jaw_act]), goal, lim, float(sim.data.time), dt, pulling,
                         rate, 0.0, 0.0, 0.0, start, float(c.max_pull))
        sim.step_with_controls([jaw_act, pull_act], values)
        return float(values[-1, 1])

    try:
        for mu in probes.mus:
            sim.reset(seed=0)
            ref.set_friction(sim, mu, c.static_friction_ratio)
            run(-(-int(round(HOLD / sim.dt)) // n), False, 0.0, 0.0)
            fn = sim.jaw_forces(name)["normal"]
            low = min(low, float(np.min(fn)))
            tracker = SlipTracker()
            nodes = contact_nodes(sim)
            if len(nodes) == 0:
                raise ConfigError(f"{task}: the reference's jaws closed on nothing at {fine * 1e3:.3g} mm")
            tracker.start(sim.tool_position(name), sim.tissue().positions, nodes)
            pull, start = Pull(float(np.sum(fn)), mu), float(sim.time)
            for _ in range(max_steps(c.max_pull, env.control_dt)):
                try:
                    force = run(per_step, True, PULL_RATE, start)
                except TissueUnstableError:     # released: the organ springs back within the step
                    released.append(mu)
                    pull.add(math.nan, math.inf, math.nan, math.nan)
                    break
                fn = sim.jaw_forces(name)["normal"]
                low = min(low, float(np.min(fn)))
                slip = tracker.distance(sim.tool_position(name), sim.tissue().positions)
                contact = -float(sim.tool_force(name) @ env.pull_dir)
                if pull.add(force, slip, float(np.sum(fn)), contact):
                    break
            if pull.held is None:
                never.append(mu)
            pull.store(forces, ratios)
    except TissueUnstableError as exc:
        raise ConfigError(f"{task}: the reference {ref.REFERENCE_MODEL} at {fine * 1e3:.3g} mm failed: "
                          f"{str(exc).splitlines()[0]}") from None
    finally:
        env.close()
    if never:
        raise ConfigError(f"{task}: the reference at {fine * 1e3:.3g} mm never slid at mu {never} up to the motor's "
                          f"{c.max_pull:g} N; lower mu in the probe set")
    return {"task": task, "model": ref.REFERENCE_MODEL, "spacing": float(fine), "nodes": int(len(sim.tissue().positions)),
            "forces_N": forces, "held_ratio": ratios, "released_mu": released, "max_tensile_N": max(0.0, -low),
            "seconds": time.perf_counter() - t0}


def compare(row: dict, reference: dict, probes: PullSet) -> dict:
    """``row`` with its errors against ``reference`` (the readings both have; a pull that never slid
    is stated in ``never_slid_mu`` and makes the row's error unbounded) and whether its held pull
    rises with mu (``monotone``)."""
    if "forces_N" not in row:
        return row
    f, ref = row["forces_N"], reference["forces_N"]
    err = np.array([abs(f[k] - r) / abs(r) for k, r in ref.items() if k in f])
    missing = [k for k in ref if k not in f]
    held = [f[f"mu{mu:g}/held"] for mu in probes.mus if f"mu{mu:g}/held" in f]
    return {**row, "error_median": float(np.median(err)), "error_p95": float(np.percentile(err, 95)),
            "error": float(np.percentile(err, 95)) if not missing else math.inf, "missing_readings": missing,
            "contrast": [], "contrast_reference": [],
            "monotone": bool(all(a < b for a, b in zip(held, held[1:]))), "scene": row["task"], "integrator": "default"}


def _ratios(row: dict, what: str) -> str:
    """One of a row's held ratios (``held_ratio``, ``contact_ratio``, ``coulomb_ratio``) per mu."""
    return ", ".join(f"{v[what]:.2f}" if v.get(what) is not None else "-" for v in row["held_ratio"].values())


def markdown(reference: dict, rows: list[dict]) -> str:
    """The task's block of the task-accuracy table: the reference ladder, its readings per level and
    one row per model and spacing (the pull held over mu x the summed normal, by the motor and at the
    contacts, the largest contact ratio of a step, the mus at which the grasp let go before the pull
    or never slid, whether the held pull rises with mu, the largest tensile jaw force and the cost)."""
    mus = ", ".join(k.removeprefix("mu") for k in next((r["held_ratio"] for r in rows if "held_ratio" in r), {}))
    columns = [(f"motor held / (mu sum N), mu {mus}", lambda r: _ratios(r, "held_ratio")),
               ("contact held / (mu sum N)", lambda r: _ratios(r, "contact_ratio")),
               ("largest contact / (mu sum N) of a step", lambda r: _ratios(r, "coulomb_ratio")),
               ("released (mu)", lambda r: ", ".join(f"{m:g}" for m in r["released_mu"]) or "-"),
               ("never slid (mu)", lambda r: ", ".join(f"{m:g}" for m in r.get("never_slid_mu", [])) or "-"),
               ("held rises with mu", lambda r: rt.yes_no(r["monotone"])),
               ("max tensile N", lambda r: f"{r['max_tensile_N']:.3g}"),
               ("us / env step", lambda r: f"{r['us_per_env_step']:.0f}"),
               ("us / sim ms", lambda r: f"{r['us_per_ms']:.1f}")]
    return "\n\n".join([rt.reference_summary(reference), rt.reference_readings(reference), rt.model_rows(rows, columns)])


def _description() -> str:
    from surgsim_envs.bench import grasp_reference as ref

    return (f"`{ref.REFERENCE_MODEL}` in the task's scene (the spleen on its uniform lattice, refined whole), elastic, "
            f"the pulls' friction on, contact stiffness {ref.CONTACT_STIFFNESS_PER_AREA:.0e} N/m^3 per area (nodes only), "
            "driven by the task's jaw and pull-motor schedule")


REFERENCE_DESCRIPTION = _description()

__all__ = ["TASK", "HOLD", "PULL_RATE", "SLIP_ONSET", "PullSet", "FULL", "QUICK", "REFERENCE_DESCRIPTION", "make_env",
           "options", "Pull", "measure", "motorise", "reference_row", "compare", "markdown"]

"""A converged force reference in a task's own scene: quasi-static FEM refined, then extrapolated.

The reference answers "what force does the continuum give for this press in this scene": the
task's slab, bed, inclusion, probe, friction and elastic material, solved by ``fem_static``
(linear tets with averaged nodal pressure, equilibrium at every step) at a sequence of lattice
spacings, and Richardson-extrapolated to zero spacing.

Why not a dynamic ``fem`` refined until it stops changing: with the task's contact law (a
penalty of 200 N/m per node, whatever the spacing) the stiffness per unit surface area grows as
1/h^2, so refining changes the contact law as well as the mesh (21 % from 7.5 to 5 mm), and the
explicit step shrinks with h until the elements under the 10 mm tip invert (3.3 mm). The
reference therefore changes three things, each for its cause:

* **contact stiffness per unit area** held at :data:`CONTACT_STIFFNESS_PER_AREA` (the node's
  penalty k = this x h^2, shared by surface samples at most 1 mm apart): the penalty's own error
  does not depend on the spacing, and a rigid sphere meets the faces, not only the nodes;
* **quasi-static equilibrium** (``fem_static``): no step-size limit and nothing to invert; the
  press is load-stepped by the probe's own motion (0.2 mm per 1 ms step at the task's speed);
* **elastic material** (the task's material with ``relax_fraction`` 0, friction kept): the
  reference is the elastic response of the scene; relaxation is each model's material law,
  checked against its exact solution in ``surgsim bench viscoelastic`` / ``fractional-memory``.

Friction stays on (the task's mu): a straight-down press is monotone loading, and the descent
reads every depth of one site in one pass (quasi-static and rate-independent: pressing to 3 mm,
holding, then on to 5 mm is the same path as straight to 5 mm).

Richardson extrapolation: for each press, F(h) = F0 + C h^p through the three finest spacings
gives F0 and the observed order p; the coarsest spacing then checks it: the extrapolation from
the three coarsest must agree with F0 (their difference is stated as ``extrapolation_change``;
the reference counts as converged when it is under :data:`CONVERGED_CHANGE` for every press).
A reference that is not converged is the finest solution computed, with the change of its last
refinement and the extrapolations stated beside it.
"""

from __future__ import annotations

import copy
import math
import time
from typing import Callable, Sequence

import numpy as np

from surgsim_envs.errors import ConfigError

#: N/m^3: normal (and tangential) contact stiffness per unit surface area of the reference. A contact
#: pressure of 2.5 kPa (0.5 N over the contact of a 7 mm press) penetrates 25 um, under 1 % of the
#: shallowest press. Much stiffer (2e9) locks: flat facets cannot wrap the sphere, every sample
#: holds them off it, and the force of one site jumped 23 % between 5 and 4 mm while the other did not
CONTACT_STIFFNESS_PER_AREA = 1e8
#: m, the largest distance between contact samples on the reference's surface: with nodes only, a
#: rigid sphere meets the lattice's nodes and not its faces, and the force jumps with where the tip
#: lands between nodes (measured: 5 -> 4 mm changed a 7 mm press by 21 %)
SAMPLE_SPACING = 0.001
#: the quasi-static reference model
REFERENCE_MODEL = "fem_static"
#: s, hold at each depth of a reference descent, and the reading window at its end
REFERENCE_HOLD = 0.1
REFERENCE_WINDOW = 0.02
#: the observed orders accepted by :func:`richardson` (linear tets with a curved contact: 1-2 expected);
#: outside them the coarsest spacing is not in the asymptotic range (measured: 0.3 for a 3 mm press
#: from 10, 5, 3.33 mm, which extrapolates to a negative force)
MIN_ORDER, MAX_ORDER = 0.5, 4.0
#: relative change of the extrapolated force when the coarsest spacing is swapped for the finest
CONVERGED_CHANGE = 0.01


def elastic(material) -> dict:
    """The task's material without relaxation, its friction kept."""
    base = {"preset": material} if isinstance(material, str) else dict(material)
    return {**base, "relax_fraction": 0.0}


def surface_subdivisions(spacing: float) -> int:
    """Edge subdivisions of the surface contact samples at lattice ``spacing`` (m): samples at most
    :data:`SAMPLE_SPACING` apart (at most 8 subdivisions)."""
    return int(min(8, max(1, math.ceil(float(spacing) / SAMPLE_SPACING - 1e-9))))


def stiff_contact(env, spacing: float) -> None:
    """Rebuild ``env.sim`` from its own scene config with the reference's contact: stiffness per
    area CONTACT_STIFFNESS_PER_AREA (k = that x spacing^2 per node, shared by the samples of
    :func:`surface_subdivisions`)."""
    from surgsim_envs.scene import Simulation, build_scene

    cfg = copy.deepcopy(env.sim.scene.config)
    cfg.contact.stiffness = CONTACT_STIFFNESS_PER_AREA * float(spacing) ** 2
    cfg.contact.tangential_stiffness = None          # = the normal one
    cfg.contact.surface_samples = surface_subdivisions(spacing)
    env.sim = Simulation(build_scene(cfg), dt=env.sim.dt, substeps=env.sim.substeps)


def descent_forces(env, xy, depths: Sequence[float], hold: float = REFERENCE_HOLD,
                   window: float = REFERENCE_WINDOW) -> list[float]:
    """From rest, hover over ``xy`` then descend to each of ``depths`` (m below the rest surface,
    rising) in turn, holding ``hold`` s at each: the mean F_z (N) over the last ``window`` s of
    each hold."""
    sim, c = env.sim, env.config
    top = env.surface_z + c.tip_radius
    dt = sim.dt

    def run(seconds: float, record: list | None = None) -> None:
        for _ in range(max(1, int(round(seconds / dt)))):
            sim.physics_step(1)
            if record is not None:
                record.append(float(sim.tool_force("probe")[2]))

    def go(target, extra: float) -> None:
        target = np.asarray(target, dtype=float)
        sim.set_tool_target("probe", target, speed=c.probe_speed)
        run(float(np.linalg.norm(target - sim.tool_position("probe"))) / c.probe_speed + extra)

    go([xy[0], xy[1], top + c.hover], 0.02)
    out = []
    n_read = max(1, int(round(window / dt)))
    for depth in depths:
        go([xy[0], xy[1], top - depth], 0.0)
        record: list[float] = []
        run(hold, record)
        out.append(float(np.mean(record[-n_read:])))
    return out


def reference_row(task: str, probes, spacing: float, material, make: Callable) -> dict:
    """The reference forces of ``probes`` at one ``spacing`` (m) with the task's ``material``
    (made elastic here): keys as :func:`surgsim_envs.bench.task_accuracy.measure`'s ``forces_N``.
    ``make(task, model, spacing, material=...)`` builds the task env (unwrapped)."""
    from surgsim_envs.tissue import TissueUnstableError

    t0 = time.perf_counter()
    env = make(task, REFERENCE_MODEL, spacing, material=elastic(material))
    stiff_contact(env, spacing)
    forces = {}
    try:
        for i, inc in enumerate(probes.inclusions):
            env.reset(seed=0, options=inc.options())     # the inclusion's material: factorised once
            for site in ("over", "mirror"):
                xy = inc.position if site == "over" else (-inc.position[0], -inc.position[1])
                env.sim.reset()                          # fresh contact and rest state, same material
                for depth, f in zip(probes.depths, descent_forces(env, xy, probes.depths)):
                    forces[f"{i}/{site}/{depth * 1e3:g}mm"] = f
    except TissueUnstableError as exc:
        raise ConfigError(f"{task}: the reference {REFERENCE_MODEL} at {spacing * 1e3:.3g} mm failed: "
                          f"{str(exc).splitlines()[0]}") from None
    finally:
        nodes = int(len(env.sim.tissue().positions))
        env.close()
    return {"task": task, "model": REFERENCE_MODEL, "spacing": float(spacing), "nodes": nodes, "forces_N": forces,
            "seconds": time.perf_counter() - t0}


def richardson(h: Sequence[float], f: Sequence[float]) -> tuple[float, float]:
    """(F0, p) of F(h) = F0 + C h^p through three points (h descending, any ratios).

    p solves (f1 - f2) / (f2 - f3) = (h1^p - h2^p) / (h2^p - h3^p) by bisection on
    [:data:`MIN_ORDER`, :data:`MAX_ORDER`]; a sequence that does not converge monotonically (the
    differences change sign), an observed order outside that range (the coarsest spacing is not in
    the asymptotic range) or a limit of the other sign than the forces raises ConfigError: no
    extrapolation is then honest."""
    h1, h2, h3 = (float(x) for x in h)
    f1, f2, f3 = (float(x) for x in f)
    if not h1 > h2 > h3 > 0:
        raise ConfigError(f"richardson needs three spacings in descending order, got {[h1, h2, h3]}")
    d12, d23 = f1 - f2, f2 - f3
    if d23 == 0.0 and d12 == 0.0:
        return f3, math.nan
    if d12 * d23 <= 0.0:
        raise ConfigError(f"forces {[f1, f2, f3]} at spacings {[h1, h2, h3]} m do not converge monotonically; "
                          "refine further before extrapolating")
    target = d12 / d23

    def ratio(p: float) -> float:
        return (h1 ** p - h2 ** p) / (h2 ** p - h3 ** p)

    lo, hi = MIN_ORDER, MAX_ORDER
    if not ratio(lo) <= target <= ratio(hi):          # the ratio rises with p
        raise ConfigError(f"forces {[f1, f2, f3]} at spacings {[h1, h2, h3]} m give an observed order outside "
                          f"[{lo}, {hi}] (difference ratio {target:.3g}); not in the asymptotic range")
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ratio(mid) < target else (lo, mid)
    p = 0.5 * (lo + hi)
    c = d23 / (h2 ** p - h3 ** p)
    f0 = f3 - c * h3 ** p
    if f0 * f3 <= 0.0:
        raise ConfigError(f"forces {[f1, f2, f3]} at spacings {[h1, h2, h3]} m extrapolate to {f0:.3g}, the other "
                          "sign; not in the asymptotic range")
    return f0, p


def extrapolate(rows: Sequence[dict]) -> dict:
    """The reference from rows at three or more spacings (any order): per press the extrapolation F0
    of the three finest and its observed order; with a fourth, the change against the three
    coarsest' extrapolation (with three only the change is unknown: not converged). Also the
    finest row's distance from F0. Returns a row (``forces_N`` = F0) with these per press."""
    rows = sorted(rows, key=lambda r: -r["spacing"])
    if len(rows) < 3:
        raise ConfigError(f"the reference needs forces at 3 or more spacings to extrapolate (4 to check the "
                          f"extrapolation), got {len(rows)}")
    h = [r["spacing"] for r in rows]
    forces, order, change, finest_gap, notes = {}, {}, {}, {}, {}
    for key in rows[-1]["forces_N"]:
        f = [r["forces_N"][key] for r in rows]
        try:
            f0, p = richardson(h[-3:], f[-3:])
            g0 = richardson(h[-4:-1], f[-4:-1])[0] if len(rows) > 3 else math.nan
        except ConfigError as exc:          # not in the asymptotic range: the finest force, flagged
            f0, p, g0 = f[-1], math.nan, math.nan
            notes[key] = str(exc)
        forces[key], order[key] = f0, p
        change[key] = abs(f0 - g0) / abs(f0) if math.isfinite(g0) else math.inf
        finest_gap[key] = abs(f[-1] - f0) / abs(f0)
    worst = max(change.values())
    converged = bool(worst < CONVERGED_CHANGE)
    last = max(abs(a - b) / abs(b) for a, b in zip(rows[-2]["forces_N"].values(), rows[-1]["forces_N"].values()))
    return {"task": rows[-1]["task"], "model": f"{REFERENCE_MODEL} extrapolated" if converged else REFERENCE_MODEL,
            "spacing": 0.0 if converged else h[-1], "spacings": h, "nodes": [r["nodes"] for r in rows],
            # not converged: the finest solution computed, labelled so, rather than an extrapolation
            # that its own check does not support
            "forces_N": forces if converged else dict(rows[-1]["forces_N"]), "extrapolated_N": forces,
            "last_refinement_change": float(last),
            "forces_by_spacing": [r["forces_N"] for r in rows], "seconds": [r["seconds"] for r in rows],
            "observed_order": order, "extrapolation_change": change, "finest_gap": finest_gap,
            "not_extrapolated": notes, "reference_change": float(worst), "reference_converged": converged}

"""A converged force reference in a task's own scene: quasi-static FEM on graded lattices.

The reference answers "what force does the continuum give for this press in this scene": the
task's slab, bed, inclusion, probe, friction and elastic material, solved by ``fem_static``
(linear tets with averaged nodal pressure, equilibrium at every step) on a sequence of lattices
refined where the press is; it counts as converged when the last refinement changes every press by
under :data:`CONVERGED_CHANGE` (1 %), and says by how much it changed otherwise.

Why not a dynamic ``fem`` refined until it stops changing: with the task's contact law (a
penalty of 200 N/m per node, whatever the spacing) the stiffness per unit surface area grows as
1/h^2, so refining changes the contact law as well as the mesh (21 % from 7.5 to 5 mm), and the
explicit step shrinks with h until the elements under the 10 mm tip invert (3.3 mm). The
reference therefore changes, each for its cause:

* **contact stiffness per unit area** held at :data:`CONTACT_STIFFNESS_PER_AREA` (the node's
  penalty k = this x h_f^2, shared by the surface samples): the penalty's own error does not
  depend on the spacing;
* **surface samples that scale with the spacing** (:data:`SURFACE_SUBDIVISIONS` per edge, h_f / 2
  apart): with nodes only a rigid sphere meets the lattice's nodes and not its faces (the force
  then rises under refinement); with samples a fixed 1 mm apart the samples per facet change with
  h, and the two effects mixed in one sequence (nodes only at 1 mm, samples above) moved a press by
  4 % in one refinement. Samples at h_f / 2 make the sequence self-similar;
* **graded lattices** (:mod:`surgsim_envs.geometry.graded_axis`, ``box_volume(grading=...)``):
  one mesh per press site, the site on a node, spacing h_f on a box around it
  (:func:`fine_half_widths`: the contact radius of the deepest press plus :data:`FINE_MARGIN`
  across, :data:`FINE_DEPTH` down), growing by :data:`GROWTH` per cell to :data:`COARSE_SPACING`.
  Uniform lattices could not get there: 2.5 mm was 15,129 nodes, and a press still moved 2.4-7.3 %
  from 3.33 mm; halving the coarse spacing of a graded lattice (5 -> 2.5 mm, h_f 2 mm) moved the
  presses by 0.3-0.5 %, so the error sits under the probe and only h_f is refined;
* **quasi-static equilibrium** (``fem_static``): no step-size limit and nothing to invert; the
  press is load-stepped by the probe's own motion (0.2 mm per 1 ms step at the task's speed);
  its stiffness is factorised by MKL PARDISO's Cholesky when the optional ``pypardiso`` is
  installed (``solver="auto"``: 7x faster factorisation and 6x faster columns than SuperLU,
  the same forces to round-off);
* **elastic material** (the task's material with ``relax_fraction`` 0, friction kept): the
  reference is the elastic response of the scene; relaxation is each model's material law,
  checked against its exact solution in ``surgsim bench viscoelastic`` / ``fractional-memory``.

Friction stays on (the task's mu): a straight-down press is monotone loading, and the descent
reads every depth of one site in one pass (quasi-static and rate-independent: pressing to 3 mm,
holding, then on to 5 mm is the same path as straight to 5 mm).

Convergence: the reference is the finest solution, converged when its last refinement (h_f by
1/sqrt 2) changed every press by under :data:`CONVERGED_CHANGE`. The finest spacing this host
reaches is 0.71 mm (about 52,000 nodes, 5-6 minutes per site): at 0.5 mm the contact of a 7 mm
press loads about 1,100 nodes, so each step's condensed solve is dense in 3,300 dofs and the
cached compliance columns need about 7 GB; a finer reference needs another contact solver (an
active-set solve on the full sparse system, not condensation). Richardson extrapolation
F(h) = F0 + C h^p through the three finest is stated beside it with the observed order, and is
used instead only when the extrapolation from the three coarsest agrees with it to
:data:`CONVERGED_CHANGE` for every press (otherwise its order is not yet the asymptotic one).
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
#: edge subdivisions of the surface contact samples: samples h_f / 2 apart at every refinement
SURFACE_SUBDIVISIONS = 2
#: m, the lattice spacing away from the press (the graded lattice grows to it)
COARSE_SPACING = 0.005
#: growth of the cell size per cell from the fine region outwards
GROWTH = 1.3
#: m, the fine region reaches this far beyond the contact radius of the deepest press
FINE_MARGIN = 0.0025
#: m, the fine region's depth below the rest surface
FINE_DEPTH = 0.005
#: the quasi-static reference model, and its options (the factorisation: PARDISO when installed;
#: the compliance column cache sized for the contact of a 7 mm press at h_f 0.7 mm)
REFERENCE_MODEL = "fem_static"
REFERENCE_OPTIONS = {"solver": "auto", "cache_mb": 4000.0}
#: s, hold at each depth of a reference descent, and the reading window at its end (measured, h_f 1.41 mm,
#: friction on: the reading after 0.04 s differs from the one after 0.1 s by at most 0.07 %)
REFERENCE_HOLD = 0.04
REFERENCE_WINDOW = 0.02
#: the observed orders accepted by :func:`richardson`; outside them the coarsest spacing is not in the
#: asymptotic range (measured on uniform lattices: 0.3 for a 3 mm press from 10, 5, 3.33 mm, which
#: extrapolates to a negative force)
MIN_ORDER, MAX_ORDER = 0.5, 4.0
#: the largest change of any press in the last refinement for a converged reference (and the agreement
#: of the two Richardson extrapolations for it to be used)
CONVERGED_CHANGE = 0.01


def elastic(material) -> dict:
    """The task's material without relaxation, its friction kept."""
    base = {"preset": material} if isinstance(material, str) else dict(material)
    return {**base, "relax_fraction": 0.0}


def fine_half_widths(tip_radius: float, deepest: float) -> tuple[float, float, float]:
    """(x, y, z) half extents (m) of the fine region about a press site: the chord radius of a sphere
    of ``tip_radius`` pressed ``deepest`` m in, plus :data:`FINE_MARGIN`; :data:`FINE_DEPTH` down."""
    d = min(float(deepest), float(tip_radius))
    r = math.sqrt(max(2.0 * tip_radius * d - d * d, 0.0)) + FINE_MARGIN
    return (r, r, FINE_DEPTH)


def _widened(half_widths, widen) -> tuple[float, float, float]:
    x, y, z = half_widths
    return (x + float(widen[0]), y + float(widen[1]), z)


def graded_scene(env, xy, fine: float, deepest: float, widen: tuple[float, float] = (0.0, 0.0)) -> int:
    """Rebuild ``env.sim`` from its own scene config on a lattice graded about the press site
    ``xy`` (m; spacing ``fine`` m there, :data:`COARSE_SPACING` away from it) with the reference's
    contact (stiffness per area :data:`CONTACT_STIFFNESS_PER_AREA`, :data:`SURFACE_SUBDIVISIONS`) and
    model options; ``widen`` (m, x and y) widens the fine region on both sides of the site (a press
    that slides in from that far). Returns the node count."""
    from surgsim_envs.scene import Simulation, build_scene

    cfg = copy.deepcopy(env.sim.scene.config)
    tissue = cfg.tissues[0]
    top = float(env.surface_z) - float(tissue.position[2])          # the rest surface in the box's frame
    tissue.spacing = COARSE_SPACING
    tissue.volume_options = {**dict(tissue.volume_options), "grading": {
        "fine": float(fine), "around": (float(xy[0]), float(xy[1]), top), "ratio": GROWTH,
        "half_widths": _widened(fine_half_widths(env.config.tip_radius, deepest), widen)}}
    tissue.options = {**dict(tissue.options), **REFERENCE_OPTIONS}
    cfg.contact.stiffness = CONTACT_STIFFNESS_PER_AREA * float(fine) ** 2   # per area of the fine cells
    cfg.contact.stiffness_per_area = None            # (the graded lattice's median edge is not h_f)
    cfg.contact.tangential_stiffness = None          # = the normal one
    cfg.contact.surface_samples = SURFACE_SUBDIVISIONS
    env.sim = Simulation(build_scene(cfg), dt=env.sim.dt, substeps=env.sim.substeps)
    return int(len(env.sim.tissue().positions))


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


def reference_row(task: str, probes, fine: float, material, make: Callable) -> dict:
    """The reference forces of ``probes`` at fine spacing ``fine`` (m) with the task's ``material``
    (made elastic here), one graded lattice per press site: keys as
    :func:`surgsim_envs.bench.task_accuracy.measure`'s ``forces_N``. ``make(task, model, spacing,
    material=...)`` builds the task env (unwrapped)."""
    from surgsim_envs.tissue import TissueUnstableError

    t0 = time.perf_counter()
    env = make(task, REFERENCE_MODEL, COARSE_SPACING, material=elastic(material))
    forces, nodes = {}, {}
    try:
        for i, inc in enumerate(probes.inclusions):
            for site in ("over", "mirror"):
                xy = inc.position if site == "over" else (-inc.position[0], -inc.position[1])
                nodes[f"{i}/{site}"] = graded_scene(env, xy, fine, max(probes.depths))
                env.reset(seed=0, options=inc.options())
                for depth, f in zip(probes.depths, descent_forces(env, xy, probes.depths)):
                    forces[f"{i}/{site}/{depth * 1e3:g}mm"] = f
    except TissueUnstableError as exc:
        raise ConfigError(f"{task}: the reference {REFERENCE_MODEL} at {fine * 1e3:.3g} mm failed: "
                          f"{str(exc).splitlines()[0]}") from None
    finally:
        env.close()
    return {"task": task, "model": REFERENCE_MODEL, "spacing": float(fine), "coarse_spacing": COARSE_SPACING,
            "nodes": max(nodes.values()), "nodes_by_site": nodes, "forces_N": forces,
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
    """The reference from rows at two or more spacings (any order): per press the change of the last
    refinement (converged when every one is under :data:`CONVERGED_CHANGE`); with three or more, the
    Richardson extrapolation F0 of the three finest and its observed order, and with four, its change
    against the three coarsest' extrapolation. The forces are F0 when that check holds for every
    press, else the finest row's. Returns a row with these per press."""
    rows = sorted(rows, key=lambda r: -r["spacing"])
    if len(rows) < 2:
        raise ConfigError(f"the reference needs forces at 2 or more spacings to state a refinement's change (3 to "
                          f"extrapolate, 4 to check the extrapolation), got {len(rows)}")
    h = [r["spacing"] for r in rows]
    forces, order, change, finest_gap, notes, last = {}, {}, {}, {}, {}, {}
    for key in rows[-1]["forces_N"]:
        f = [r["forces_N"][key] for r in rows]
        last[key] = abs(f[-1] - f[-2]) / abs(f[-1])
        f0, p, g0 = f[-1], math.nan, math.nan
        if len(rows) >= 3:
            try:
                f0, p = richardson(h[-3:], f[-3:])
                g0 = richardson(h[-4:-1], f[-4:-1])[0] if len(rows) > 3 else math.nan
            except ConfigError as exc:      # not in the asymptotic range: the finest force, flagged
                f0, p, g0 = f[-1], math.nan, math.nan
                notes[key] = str(exc)
        forces[key], order[key] = f0, p
        change[key] = abs(f0 - g0) / abs(f0) if math.isfinite(g0) else math.inf
        finest_gap[key] = abs(f[-1] - f0) / abs(f0)
    worst = max(last.values())
    converged = bool(worst < CONVERGED_CHANGE)
    extrapolated = bool(max(change.values()) < CONVERGED_CHANGE)
    return {"task": rows[-1]["task"], "model": f"{REFERENCE_MODEL} extrapolated" if extrapolated else REFERENCE_MODEL,
            "spacing": 0.0 if extrapolated else h[-1], "spacings": h, "nodes": [r["nodes"] for r in rows],
            # an extrapolation its own check does not support is stated, not used
            "forces_N": forces if extrapolated else dict(rows[-1]["forces_N"]), "extrapolated_N": forces,
            "last_refinement_change": float(worst), "last_change": last,
            "forces_by_spacing": [r["forces_N"] for r in rows], "seconds": [r["seconds"] for r in rows],
            "observed_order": order, "extrapolation_change": change, "finest_gap": finest_gap,
            "not_extrapolated": notes, "reference_change": float(worst), "reference_converged": converged,
            "reference_extrapolated": extrapolated, "coarse_spacing": rows[-1].get("coarse_spacing")}

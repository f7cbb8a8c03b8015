"""Forces in the scenes users meet, against a converged reference: ``surgsim bench task-accuracy``.

For a task, a fixed scripted probe set drives the task's own scene (built by ``gym.make``, with
the task's friction, time step and probe, and its material made elastic): presses straight down
at several depths over an inclusion and at its mirror site, for two inclusions. Each press starts
from a fresh reset (same seed and options), so presses do not see each other's history. Every
registered model the task accepts runs the same set at each candidate lattice spacing. A task whose
scene is driven otherwise (LayeredPalpation-v0: one quasi-static solve per press) has its probe
set, presser and reference in its own module, registered in :mod:`surgsim_envs.bench.probe_sets`.

The reference (:mod:`surgsim_envs.bench.task_reference`) is quasi-static ``fem_static`` with a
contact stiffness per unit area that does not change with the spacing and surface samples at half
the spacing, on one lattice per press site graded about it, refined there (fine spacing 2 mm to
0.71 mm, by 1/sqrt 2); converged when the last refinement changes every press by under 1 %.

The material is elastic (``relax_fraction`` 0) for every model and the reference: relaxation is
each model's material law, checked against exact solutions elsewhere (``surgsim bench
viscoelastic``, ``fractional-memory``); here the scene's geometry, contact and friction are tested.

Per task x model x spacing it reports:

* **force error** against the reference, median and 95th percentile over the presses;
* **inclusion contrast**: force over the inclusion / force at the mirror site at the deepest
  press, ours and the reference's (a stiff lump must feel stiffer);
* **monotone in depth**: whether the force rises with depth at every site;
* **unilateral**: the largest pulling (tensile) force on the probe seen during any press, N;
* **path independence**, frictionless: the same pose reached straight down and by a pressed
  slide from 6 mm away (relative difference);
* **cost**: median wall time of one env control step while pressing (us), and per simulated ms.

Rows carry ``scene`` = the task id, ``error`` (the 95th percentile) and ``us_per_ms``, so
:func:`surgsim_envs.bench.choose.choose_task_model` picks a task's cheapest model within its
tolerance from the table this writes (shipped as ``surgsim_envs/tissue/data/task_accuracy_table.json``).
Figures: ``docs/task_accuracy.md`` (table) and ``docs/img/task_accuracy.png`` (error against cost,
one panel per task).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from surgsim_envs.bench import probe_sets, task_reference
from surgsim_envs.bench.probe_set import Inclusion, ProbeSet, mirror
from surgsim_envs.bench.task_accuracy_doc import (  # noqa: F401  (reference_summary, reference_table: re-exported)
    check_doc, markdown, reference_summary, reference_table, update_doc)
from surgsim_envs.errors import ConfigError


PALPATION_FULL = ProbeSet(
    inclusions=(Inclusion("5x lump, r 7 mm, 11 mm deep", (0.02, 0.0), 0.011, 0.007, 5.0),
                Inclusion("3x lump, r 9 mm, 9 mm deep", (-0.01, 0.01), 0.009, 0.009, 3.0)),
    depths=(0.003, 0.005, 0.007), hold=0.5, spacings=(0.01, 0.0075, 0.005, 0.01 / 3),
    reference_spacings=(0.002, 0.002 / math.sqrt(2), 0.001, 0.001 / math.sqrt(2)))
PALPATION_QUICK = ProbeSet(inclusions=PALPATION_FULL.inclusions[:1], depths=(0.004, 0.007), hold=0.5,
                           spacings=(0.01,), reference_spacings=(0.004, 0.004 / math.sqrt(2), 0.002))

#: Every press site sits on a node of the reference's lattice (each is graded about its site) and of the
#: models' lattices (each site lies on a multiple of 10 mm from the slab's edge): a sphere on a lattice reads
#: a different force on a node and between nodes.

def _declared(task_id: str, **extra) -> dict:
    """The force tolerance ``task_id`` declares in the task registry (``TaskSpec.force_tolerance``)."""
    from surgsim_envs.envs.registry import task_spec

    tol = task_spec(task_id).force_tolerance
    return {"tolerance": float(tol.value), "reason": tol.why, **extra}


#: task id -> the force tolerance it declares (p95 force error against the reference, fraction) and why;
#: ``scene_of``: a task that builds another task's scene is measured there
FORCE_TOLERANCES: dict[str, dict] = {
    "SurgSim/Palpation-v0": _declared("SurgSim/Palpation-v0"),
    # Palpation-v0's scene and lumps, read as F / depth of single presses: the same contrast to keep
    "SurgSim/PalpationPress-v0": _declared("SurgSim/PalpationPress-v0", scene_of="SurgSim/Palpation-v0"),
}

#: task id -> (full probe set, quick probe set); tasks not listed are reported as not covered
PROBE_SETS: dict[str, tuple[ProbeSet, ProbeSet]] = {
    "SurgSim/Palpation-v0": (PALPATION_FULL, PALPATION_QUICK),
}
# the tasks whose probe sets are driven by their own module (:mod:`surgsim_envs.bench.probe_sets`)
PROBE_SETS.update({task: (d.FULL, d.QUICK) for task, d in probe_sets.DRIVERS.items()})
FORCE_TOLERANCES.update({task: _declared(task) for task in probe_sets.DRIVERS})


def make_task_env(task: str, model: str, spacing: float, material=None, dt: float | None = None):
    """``task`` (unwrapped) built with ``model`` at lattice ``spacing`` (m), optionally its ``material`` and
    physics step ``dt`` (s)."""
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401  (registers the tasks)

    kwargs = {"model": model, "resolution": float(spacing)}
    if material is not None:
        kwargs["material"] = material
    if dt is not None:
        kwargs["dt"] = float(dt)
    return gym.make(task, disable_env_checker=True, **kwargs).unwrapped


class Presser:
    """Drives the probe of a palpation env's scene: each press from a fresh reset."""

    def __init__(self, env, hold: float):
        self.env, self.hold = env, float(hold)
        self.sim = env.sim
        c = env.config
        self.top = env.surface_z + c.tip_radius          # tip centre z touching the rest surface
        self.hover = self.top + c.hover
        self.speed = c.probe_speed
        self.control_dt = env.control_dt
        self.step_us: list[float] = []
        self.max_tensile = 0.0

    def _run(self, seconds: float, record: list | None = None) -> None:
        for _ in range(max(1, int(round(seconds / self.control_dt)))):
            t0 = time.perf_counter()
            self.sim.step()
            self.step_us.append((time.perf_counter() - t0) * 1e6)
            fz = float(self.sim.tool_force("probe")[2])
            self.max_tensile = max(self.max_tensile, -fz)
            if record is not None:
                record.append(fz)

    def _go(self, target) -> None:
        target = np.asarray(target, dtype=float)
        self.sim.set_tool_target("probe", target, speed=self.speed)
        dist = float(np.linalg.norm(target - self.sim.tool_position("probe")))
        self._run(dist / self.speed + 0.02)

    def press(self, inclusion: Inclusion, xy, depth: float, approach=None) -> float:
        """Mean force (N, +z: the tissue pushing the probe up) over the last 0.1 s of the hold at
        ``depth`` m below the rest surface at ``xy``; ``approach`` (2,) m: reach the pose by a
        pressed slide from there instead of straight down."""
        self.env.reset(seed=0, options=inclusion.options())
        start = np.asarray(xy if approach is None else approach, dtype=float)
        self._go([start[0], start[1], self.hover])
        self._go([start[0], start[1], self.top - depth])
        if approach is not None:
            self._go([xy[0], xy[1], self.top - depth])
        record: list[float] = []
        self._run(self.hold, record)
        window = max(1, int(round(0.1 / self.control_dt)))
        force = float(np.mean(record[-window:]))
        self._go([xy[0], xy[1], self.hover])              # retract: a tensile pull would show here
        return force

    def press_all(self, probes: ProbeSet) -> dict[str, float]:
        """Every press of ``probes``: over each inclusion and at its mirror site, at each depth, each
        from a fresh reset; ``{press_key: N}``."""
        forces = {}
        for i, inc in enumerate(probes.inclusions):
            for site in ("over", "mirror"):
                xy = inc.position if site == "over" else mirror(inc.position)
                for depth in probes.depths:
                    forces[press_key(i, site, depth)] = self.press(inc, xy, depth)
        return forces


def press_key(inclusion_index: int, site: str, depth: float) -> str:
    """The name of a press in a row's ``forces_N``: "0/over/5mm"."""
    return f"{inclusion_index}/{site}/{depth * 1e3:g}mm"


def task_material(task: str):
    """The material a task builds its tissue from by default (its config's ``material``)."""
    import importlib

    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401

    module, name = gym.spec(task).entry_point.split(":")
    return getattr(importlib.import_module(module), name).config_cls().material


def measure(task: str, model: str, spacing: float, probes: ProbeSet, dt: float | None = None) -> dict:
    """One row: the presses of ``probes`` with ``model`` at ``spacing`` in ``task``'s scene (its
    physics step ``dt``, default the task's; its material made elastic). A model the task refuses,
    or one that goes unstable, gives a row saying so instead of numbers."""
    from surgsim_envs.tissue import TissueUnstableError

    if task in probe_sets.DRIVERS:
        return probe_sets.DRIVERS[task].measure(task, model, spacing, probes)
    head = {"task": task, "model": model, "spacing": float(spacing)}
    material = task_reference.elastic(task_material(task))
    try:
        env = make_task_env(task, model, spacing, material=material, dt=dt)
    except ConfigError as exc:
        return {**head, "refused": str(exc).split("\n")[0]}
    presser = Presser(env, probes.hold)
    try:
        forces = presser.press_all(probes)
    except TissueUnstableError as exc:
        env.close()
        return {**head, "refused": "unstable in the task's scene: " + str(exc).split("\n")[0]}
    row = {"task": task, "model": model, "spacing": float(spacing), "nodes": int(len(env.sim.tissue().positions)),
           "forces_N": forces, "max_tensile_N": presser.max_tensile,
           "us_per_env_step": float(np.median(presser.step_us)),
           "control_dt": float(env.control_dt), "dt": float(env.sim.dt)}
    env.close()
    # frictionless, elastic path independence at the middle depth over the first inclusion
    try:
        flat = make_task_env(task, model, spacing, material=_frictionless(material), dt=dt)
        p = Presser(flat, probes.hold)
        inc, depth = probes.inclusions[0], probes.depths[len(probes.depths) // 2]
        straight = p.press(inc, inc.position, depth)
        slid = p.press(inc, inc.position, depth, approach=(inc.position[0] - 0.006, inc.position[1]))
        row["path_difference"] = abs(slid - straight) / max(abs(straight), 1e-12)
        flat.close()
    except (ConfigError, TissueUnstableError) as exc:
        row["path_note"] = str(exc).split("\n")[0]
    row["us_per_ms"] = row["us_per_env_step"] / (row["control_dt"] * 1e3)
    return row


def _frictionless(material):
    """The task's material without friction and without relaxation: what is left of a difference
    between two ways to one pose is then the contact's own history, not physics."""
    base = {"preset": material} if isinstance(material, str) else dict(material)
    return {**base, "friction": 0.0, "relax_fraction": 0.0}


def monotone(forces: dict, depths: Iterable[float]) -> bool:
    """Whether the force rises with depth at every (inclusion, site) of a row's ``forces``."""
    depths = list(depths)
    sites = sorted({k.rsplit("/", 1)[0] for k in forces})
    return all(all(forces[f"{s}/{a * 1e3:g}mm"] < forces[f"{s}/{b * 1e3:g}mm"] for a, b in zip(depths, depths[1:]))
               for s in sites)


def contrast(forces: dict, n_inclusions: int, depth: float) -> list[float]:
    """Force over each inclusion / force at its mirror site, at ``depth``."""
    key = f"{depth * 1e3:g}mm"
    return [forces[f"{i}/over/{key}"] / max(forces[f"{i}/mirror/{key}"], 1e-12) for i in range(n_inclusions)]


def compare(row: dict, reference: dict, probes: ProbeSet) -> dict:
    """``row`` with its errors and contrasts against ``reference`` (same presses); a probe-set module
    with its own readings (closures, pulls) scores them with its ``compare``."""
    own = getattr(probe_sets.DRIVERS.get(row["task"]), "compare", None)
    if own is not None:
        return own(row, reference, probes)
    if "forces_N" not in row:
        return row
    f, ref = row["forces_N"], reference["forces_N"]
    # a probe set may score presses the reference does not solve against one it does (its reference_key)
    alias = getattr(probe_sets.DRIVERS.get(row["task"]), "reference_key", None)
    pairs = [(k, k) for k in ref] + [(k, alias(k)) for k in f if k not in ref and alias is not None and alias(k) in ref]
    err = np.array([abs(f[k] - ref[r]) / max(abs(ref[r]), 1e-9) for k, r in pairs])
    n, deep = len(probes.inclusions), probes.depths[-1]
    return {**row, "error_median": float(np.median(err)), "error_p95": float(np.percentile(err, 95)),
            "error": float(np.percentile(err, 95)), "contrast": contrast(f, n, deep),
            "contrast_reference": contrast(ref, n, deep), "monotone": monotone(f, probes.depths),
            "scene": row["task"], "integrator": "default"}


def converged_reference(task: str, probes: ProbeSet, progress: Callable[[str], None] = print) -> dict:
    """The reference of ``probes`` in ``task``: ``fem_static`` at ``probes.reference_spacings``,
    extrapolated (:func:`task_reference.extrapolate`)."""
    driver = probe_sets.DRIVERS.get(task)
    material = task_material(task) if driver is None else None
    check_memory = getattr(driver, "check_reference_memory", None)
    if check_memory is not None:          # refused before the coarse levels, not killed at the finest
        check_memory(task, probes)
    rows = []
    for spacing in probes.reference_spacings:
        progress(f"reference {task_reference.REFERENCE_MODEL} at {spacing * 1e3:.3g} mm")
        rows.append(task_reference.reference_row(task, probes, spacing, material, make_task_env) if driver is None
                    else driver.reference_row(task, probes, spacing))
    out = task_reference.extrapolate(rows)
    if driver is not None:
        out["description"] = driver.REFERENCE_DESCRIPTION
    return out


def build_table(tasks: Iterable[str], models: Iterable[str], quick: bool = False,
        progress: Callable[[str], None] = print, spacings: Iterable[float] | None = None) -> dict:
    """The table: ``{"rows": [...], "references": {task: row}, "not_covered": [...]}``; ``spacings``
    (m) replaces the probe sets' model spacings (a refinement row of one model)."""
    rows, references, not_covered = [], {}, []
    for task in tasks:
        if task not in PROBE_SETS:
            not_covered.append(task)
            continue
        probes = PROBE_SETS[task][1 if quick else 0]
        reference = converged_reference(task, probes, progress)
        references[task] = reference
        for model in models:
            for spacing in (probes.spacings if spacings is None else tuple(spacings)):
                progress(f"{task}: {model} at {spacing * 1e3:.3g} mm")
                rows.append(compare(measure(task, model, spacing, probes), reference, probes))
                if "refused" in rows[-1] and task in probe_sets.DRIVERS and not rows[-1].get("spacing_specific"):
                    break                   # a model the task does not build: said once, not per spacing
    tolerances = {t: v for t, v in FORCE_TOLERANCES.items() if v.get("scene_of", t) in references}
    return {"rows": rows, "references": references, "not_covered": not_covered, "quick": bool(quick),
            "tolerances": tolerances}


def rescore(table: dict, tasks: Iterable[str] | None = None, progress: Callable[[str], None] = print) -> dict:
    """``table`` (a task-accuracy table with each row's per-press ``forces_N``) with its references
    recomputed and every model row's errors and contrasts recomputed against them, without rerunning
    the models (their forces, costs and path differences are kept)."""
    references = dict(table["references"])
    rows = list(table["rows"])
    for task in (list(references) if tasks is None else list(tasks)):
        if task not in PROBE_SETS:
            raise ConfigError(f"rescore: {task!r} has no probe set; tasks with one: {sorted(PROBE_SETS)}")
        probes = PROBE_SETS[task][1 if table.get("quick") else 0]
        references[task] = converged_reference(task, probes, progress)
        rows = [compare(r, references[task], probes) if r["task"] == task else r for r in rows]
    return {**table, "rows": rows, "references": references}


def chart(table: dict, path: str | Path) -> None:
    """Error (p95) against cost per env step, one panel per task."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tasks = list(table["references"])
    fig, axes = plt.subplots(1, max(1, len(tasks)), figsize=(6 * max(1, len(tasks)), 4.5), squeeze=False)
    for ax, task in zip(axes[0], tasks):
        for r in table["rows"]:
            if r["task"] != task or "error" not in r:
                continue
            ax.scatter(r["us_per_env_step"], 100 * r["error"], s=30)
            ax.annotate(f"{r['model']} {r['spacing'] * 1e3:.3g} mm", (r["us_per_env_step"], 100 * r["error"]),
                        fontsize=7, xytext=(3, 3), textcoords="offset points")
        tolerance = table.get("tolerances", {}).get(task, {}).get("tolerance")
        if tolerance is not None:                     # the task's declared need: rows below it qualify
            ax.axhline(100 * tolerance, color="k", ls="--", lw=1)
            ax.annotate(f"task tolerance {100 * tolerance:g} %", (0.01, 100 * tolerance), xycoords=("axes fraction", "data"),
                        fontsize=8, xytext=(0, 3), textcoords="offset points")
            ax.set_ylim(bottom=0)
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("wall time per env step (us)")
        ax.set_ylabel("force error against the reference, p95 (%)")
        ref = table["references"][task]
        state = "converged" if ref.get("reference_converged") else "not converged"
        lattice = "graded" if ref.get("coarse_spacing") else "uniform"    # graded lattices keep a coarse spacing
        at = " at the site" if ref.get("coarse_spacing") else ""
        where = "extrapolated" if ref.get("reference_extrapolated") else f"{lattice}, {ref['spacings'][-1] * 1e3:.3g} mm{at}"
        ax.set_title(f"{task}\nreference: {task_reference.REFERENCE_MODEL} {where} ({state})", fontsize=10)
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _finite(value):
    """``value`` with every non-finite float as None (strict JSON: an unknown change, an order not found)."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write(table: dict, out: str | Path) -> dict[str, Path]:
    """``task_accuracy.json``, ``task_accuracy.md`` and ``task_accuracy.png`` in ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / "task_accuracy.json", "md": out / "task_accuracy.md", "png": out / "task_accuracy.png"}
    paths["json"].write_text(json.dumps(_finite(table), indent=1, allow_nan=False))
    paths["md"].write_text(markdown(table))
    chart(table, paths["png"])
    return paths


def add_arguments(parser) -> None:
    parser.add_argument("--tasks", default=",".join(PROBE_SETS),
                        help=f"comma-separated task ids (default: those with a probe set: {', '.join(PROBE_SETS)})")
    parser.add_argument("--models", default=None, help="comma-separated model names (default: all registered)")
    parser.add_argument("--quick", action="store_true",
                        help="one inclusion, two depths, the task's default spacing; the reference at three "
                             "fine spacings (4, 2.8, 2 mm): not converged")
    parser.add_argument("--spacings", default=None,
                        help="comma-separated model lattice spacings in m, instead of the probe set's (e.g. "
                             "0.0025 with --models fem_static for a refinement row); 10 mm / k puts every press "
                             "site on a node")
    parser.add_argument("--out", default="surgsim-out/task-accuracy", help="output directory (JSON, markdown, PNG)")
    parser.add_argument("--json", action="store_true", help="also print the table as JSON")
    parser.add_argument("--rescore", default=None, metavar="TABLE_JSON",
                        help="recompute only the references of --tasks and score the model rows of this table "
                             "(their stored per-press forces) against them, without rerunning the models")
    parser.add_argument("--render", default=None, metavar="TABLE_JSON",
                        help="run nothing: write the markdown, chart (and --doc blocks) of this stored table, e.g. "
                             "the shipped surgsim_envs/tissue/data/task_accuracy_table.json")
    parser.add_argument("--doc", default=None, metavar="MARKDOWN",
                        help="also rewrite each task's block of this page (between its markers "
                             "'<!-- task-accuracy table: TASK -->' and '<!-- end task-accuracy table -->'), "
                             "e.g. docs/task_accuracy.md")


def _names(text: str, known: Iterable[str], what: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in known]
    if not names or unknown:
        raise ConfigError(f"--{what} {text!r}: unknown {unknown or 'empty list'}; choose from {sorted(known)}")
    return names


def _spacings(text) -> tuple[float, ...] | None:
    """``--spacings``: model lattice spacings in m (1-20 mm), or None."""
    if text is None:
        return None
    out = []
    for part in str(text).split(","):
        try:
            h = float(part)
        except ValueError:
            raise ConfigError(f"--spacings {text!r}: {part.strip()!r} is not a number; give metres, e.g. 0.0025") from None
        if not (math.isfinite(h) and 1e-3 <= h <= 0.02):
            raise ConfigError(f"--spacings {text!r}: {h!r} m is outside 1-20 mm; give metres, e.g. 0.0025")
        out.append(h)
    return tuple(out)


def run(args) -> int:
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401
    from surgsim_envs import tissue

    task_ids = [k for k in gym.registry if k.startswith("SurgSim/")]
    tasks = _names(args.tasks, task_ids, "tasks")
    models = tissue.names() if args.models is None else _names(args.models, tissue.names(), "models")
    from surgsim_envs import validate

    def stored(value, name):
        path = validate.path(value, name, fix="a task_accuracy.json")
        try:
            table = json.loads(path.read_text())
        except (ValueError, UnicodeDecodeError) as exc:
            raise ConfigError(f"{name}={str(path)!r} is not JSON ({exc}); give a task_accuracy.json this command "
                              "wrote") from None
        if not (isinstance(table, dict) and {"rows", "references", "not_covered"} <= set(table)):
            raise ConfigError(f"{name}={str(path)!r} is not a task-accuracy table (it needs 'rows', 'references' and "
                              "'not_covered'); give a task_accuracy.json this command wrote")
        return table

    render = stored(args.render, "--render") if getattr(args, "render", None) is not None else None
    source = stored(args.rescore, "--rescore") if render is None and args.rescore is not None else None
    page = None
    if getattr(args, "doc", None) is not None:         # checked before anything runs
        page = validate.path(args.doc, "--doc", fix="a markdown page with the task-accuracy markers, e.g. docs/task_accuracy.md")
        stored_table = render if render is not None else source
        check_doc(page.read_text(), list(stored_table["references"]) if stored_table is not None else tasks)
    from tqdm import tqdm

    bar = tqdm(total=None, desc="task-accuracy", unit="run", leave=False)

    def progress(text: str) -> None:
        bar.set_postfix_str(text)
        bar.update(1)

    if render is not None:
        table = render
    elif source is not None:
        table = rescore(source, tasks, progress=progress)
    else:
        table = build_table(tasks, models, quick=args.quick, progress=progress,
                            spacings=_spacings(getattr(args, "spacings", None)))
    bar.close()
    paths = write(table, args.out)
    print(markdown(table))
    if page is not None:
        page.write_text(update_doc(page.read_text(), table))
        print(f"rewrote the blocks of {', '.join(table['references'])} in {page}")
    if args.json:
        print(json.dumps(table, indent=1))
    print(f"wrote {paths['json']}, {paths['md']} and {paths['png']}")
    return 0

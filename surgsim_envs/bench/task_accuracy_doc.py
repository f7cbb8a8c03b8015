"""The task-accuracy table as markdown, and its blocks in ``docs/task_accuracy.md``.

:func:`markdown` renders one block per task: a press probe set's (Palpation-v0, LayeredPalpation-v0:
force error, inclusion contrast, monotone in depth, path difference) here; a probe set whose readings
are not presses (closures, pulls) renders its own through its driver's ``markdown(reference, rows)``
(:mod:`surgsim_envs.bench.probe_sets`). :func:`update_doc` writes each task's block between the
markers ``<!-- task-accuracy table: TASK -->`` and ``<!-- end task-accuracy table -->`` of a markdown
page, so the published table is always the shipped JSON's (``surgsim bench task-accuracy --doc``).
"""

from __future__ import annotations

import math
import re

from surgsim_envs.bench import probe_sets, task_reference
from surgsim_envs.errors import ConfigError

#: the markers around a task's generated block in a markdown page
BEGIN = "<!-- task-accuracy table: {task} -->"
END = "<!-- end task-accuracy table -->"


def reference_summary(ref: dict) -> str:
    """One paragraph on a reference: its lattices, cost, the change of its last refinement and the
    Richardson check."""
    orders = [p for p in ref["observed_order"].values() if p is not None and math.isfinite(p)]
    spacings = ", ".join(f"{h * 1e3:.3g}" for h in ref["spacings"])
    nodes = ", ".join(str(n) for n in ref["nodes"])
    cost = ", ".join(f"{t:.0f}" for t in ref["seconds"])
    coarse = ref.get("coarse_spacing") or task_reference.COARSE_SPACING
    what = ref.get("description") or (
        f"`{task_reference.REFERENCE_MODEL}` (elastic, friction on, contact stiffness "
        f"{task_reference.CONTACT_STIFFNESS_PER_AREA:.0e} N/m^3 per area, surface samples at half the spacing)")
    text = (f"Reference: {what} "
            f"on one lattice per press site, graded from fine spacings {spacings} mm at the site to {coarse * 1e3:.3g} mm "
            f"(at most {nodes} nodes; {cost} s each for the {len(ref['forces_N'])} presses). ")
    last = 100 * ref["last_refinement_change"]
    if ref["reference_converged"]:
        text += (f"**Converged**: the last refinement ({ref['spacings'][-2] * 1e3:.3g} -> {ref['spacings'][-1] * 1e3:.3g} mm) "
                 f"changed every press by under 1 % (at most {last:.2g} %)")
    else:
        text += (f"**Not converged**: the last refinement changed the forces by up to {last:.2g} %")
    if ref.get("reference_extrapolated"):
        text += (f"; the forces are Richardson-extrapolated from the three finest (observed orders "
                 f"{min(orders):.2g}-{max(orders):.2g}), which the three coarsest confirm to "
                 f"{100 * max(ref['extrapolation_change'].values()):.2g} %")
    else:
        text += f"; the errors below are against the finest solution ({ref['spacings'][-1] * 1e3:.3g} mm)"
        if orders:
            check = [c for c in ref["extrapolation_change"].values() if c is not None and math.isfinite(c)]
            text += (f". Richardson extrapolation from the three finest gives observed orders "
                     f"{min(orders):.2g}-{max(orders):.2g}")
            if ref.get("not_extrapolated"):
                text += f" ({len(ref['not_extrapolated'])} presses outside {task_reference.MIN_ORDER}-{task_reference.MAX_ORDER})"
            if check:
                text += (f", and the extrapolation from the three coarsest differs from it by "
                         f"{100 * min(check):.2g}-{100 * max(check):.2g} %, so it is not used")
    return text + "."


def reference_table(ref: dict) -> str:
    """The reference's force per press at each spacing, each refinement's change (%) and the
    Richardson limit with its observed order."""
    head = ["press"] + [f"{h * 1e3:.3g} mm" for h in ref["spacings"]] + ["last change %", "Richardson F0 (order)"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for key in ref["forces_by_spacing"][-1]:
        f = [r[key] for r in ref["forces_by_spacing"]]
        cells = [f"{f[0]:.4f}"] + [f"{b:.4f} ({100 * (b - a) / b:+.1f} %)" for a, b in zip(f, f[1:])]
        p = ref["observed_order"].get(key)
        rich = (f"{ref['extrapolated_N'][key]:.4f} ({p:.2f})" if p is not None and math.isfinite(p) else
                "outside " f"{task_reference.MIN_ORDER:g}-{task_reference.MAX_ORDER:g}" if len(f) >= 3 else "-")
        out.append(f"| {key} | " + " | ".join(cells) + f" | {100 * ref['last_change'][key]:.2f} | {rich} |")
    return "\n".join(out)


def press_block(task: str, ref: dict, rows: list[dict]) -> str:
    """A press probe set's block: the reference paragraph, one row per model and spacing, and the
    reference's forces per press at each fine spacing."""
    out = [reference_summary(ref) + "\n",
           "| model | spacing mm | nodes | error median % | error p95 % | contrast (ref) | rises with depth "
           "| max pull N | path diff % | us / env step |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "refused" in r:
            out.append(f"| {r['model']} | {r['spacing'] * 1e3:.3g} | refused: {r['refused'][:80]} |||||||")
            continue
        con = ", ".join(f"{a:.2f} ({b:.2f})" for a, b in zip(r["contrast"], r["contrast_reference"]))
        path = f"{100 * r['path_difference']:.1f}" if "path_difference" in r else "-"
        out.append(f"| {r['model']} | {r['spacing'] * 1e3:.3g} | {r['nodes']} | {100 * r['error_median']:.1f} | "
                   f"{100 * r['error_p95']:.1f} | {con} | {'yes' if r['monotone'] else 'NO'} | "
                   f"{r['max_tensile_N']:.3g} | {path} | {r['us_per_env_step']:.0f} |")
    if "last_change" in ref:
        out += ["", "The reference's forces (N) per press (inclusion / site / depth) at each fine spacing, with the "
                "change of each refinement:\n", reference_table(ref)]
    return "\n".join(out)


def task_block(table: dict, task: str) -> str:
    """One task's block (its heading, the reference and its rows), by its probe set's own renderer
    where it has one."""
    if task not in table["references"]:
        raise ConfigError(f"the task-accuracy table has no reference for {task!r}; it has {sorted(table['references'])}")
    ref = table["references"][task]
    rows = [r for r in table["rows"] if r["task"] == task]
    own = getattr(probe_sets.DRIVERS.get(task), "markdown", None)
    return f"### {task}\n\n" + (own(ref, rows) if own is not None else press_block(task, ref, rows)) + "\n"


def markdown(table: dict) -> str:
    """The table as markdown (one block per task)."""
    out = [task_block(table, task) for task in table["references"]]
    if table["not_covered"]:
        out.append("Tasks without a probe set yet: " + ", ".join(table["not_covered"]) + ".\n")
    return "\n".join(out)


def check_doc(text: str, tasks) -> None:
    """Raise a ConfigError naming the markers to add if ``text`` lacks the block of any of ``tasks``
    (checked before a long run, so a page without them does not fail it at the end)."""
    missing = [t for t in tasks if not re.search(re.escape(BEGIN.format(task=t)) + r"\n.*?" + re.escape(END), text, re.S)]
    if missing:
        raise ConfigError("the page has no block for " + ", ".join(missing) + ": add the lines "
                          + ", ".join(repr(BEGIN.format(task=t)) for t in missing) + f" each followed later by {END!r} "
                          "where the table belongs")


def update_doc(text: str, table: dict) -> str:
    """``text`` (a markdown page) with the block between each task's markers replaced by that task's
    block from ``table``. A task of the table whose markers the page lacks raises a ConfigError
    naming the marker to add; markers of tasks the table lacks are left as they are."""
    for task in table["references"]:
        begin = BEGIN.format(task=task)
        pattern = re.compile(re.escape(begin) + r"\n.*?" + re.escape(END), re.S)
        check_doc(text, [task])
        block = task_block(table, task)
        text = pattern.sub(lambda _: f"{begin}\n{block}\n{END}", text, count=1)
    return text


__all__ = ["BEGIN", "END", "reference_summary", "reference_table", "press_block", "task_block", "markdown", "check_doc",
           "update_doc"]

"""Markdown tables of a task-accuracy block whose readings are not presses (closures, pulls).

A probe set whose scene is refined whole (one lattice per level, no press sites) and whose model rows
carry readings of their own (a grasp's settle change, a pull's held ratios) renders its block with
these: :func:`reference_summary` (one paragraph on the reference ladder), :func:`reference_readings`
(each reading at each level, with the change of each refinement) and :func:`model_rows` (one row per
model and spacing, with the probe set's own columns). Units: N, s, m (shown in mm).
"""

from __future__ import annotations

from typing import Callable, Sequence

#: a column of a model table: its header and the cell of a measured (not refused) row
Column = tuple[str, Callable[[dict], str]]


def reference_summary(ref: dict) -> str:
    """One paragraph: what the reference is, its levels and their cost, and whether it converged."""
    spacings = ", ".join(f"{h * 1e3:.3g}" for h in ref["spacings"])
    cost = ", ".join(f"{t:.0f}" for t in ref["seconds"])
    last = 100 * ref["last_refinement_change"]
    text = (f"Reference: {ref.get('description') or ref['model']}, at spacings {spacings} mm "
            f"({ref['nodes'][0]} to {ref['nodes'][-1]} nodes; {cost} s per level for all readings). ")
    if ref["reference_converged"]:
        return text + (f"**Converged**: the last refinement changed every reading by under 1 % (at most {last:.2g} %).")
    return text + (f"**Not converged**: the last refinement changed the readings by up to {last:.3g} %; the errors "
                   f"below are against the finest level ({ref['spacings'][-1] * 1e3:.3g} mm).")


def reference_readings(ref: dict) -> str:
    """Each reading (N) at each level, with the change of each refinement and the last change (%)."""
    head = ["reading"] + [f"{h * 1e3:.3g} mm ({n} nodes)" for h, n in zip(ref["spacings"], ref["nodes"])]
    head.append("last change %")
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for key in ref["forces_by_spacing"][-1]:
        f = [level[key] for level in ref["forces_by_spacing"]]
        cells = [f"{f[0]:.4f}"] + [f"{b:.4f} ({100 * (b - a) / b:+.0f} %)" for a, b in zip(f, f[1:])]
        out.append(f"| {key} | " + " | ".join(cells) + f" | {100 * ref['last_change'][key]:.1f} |")
    return "\n".join(out)


def model_rows(rows: Sequence[dict], columns: Sequence[Column]) -> str:
    """One markdown row per model and spacing: model, spacing, nodes, error median and p95 (%), then
    ``columns``; a refused row states its reason (cut to 150 characters)."""
    head = ["model", "spacing mm", "nodes", "error median %", "error p95 %"] + [name for name, _ in columns]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        if "refused" in r:
            out.append(f"| {r['model']} | {r['spacing'] * 1e3:.3g} | refused: {r['refused'][:150]} " + "|" * (len(head) - 2))
            continue
        cells = [r["model"], f"{r['spacing'] * 1e3:.3g}", str(r["nodes"]), f"{100 * r['error_median']:.0f}",
                 f"{100 * r['error_p95']:.0f}"] + [cell(r) for _, cell in columns]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def yes_no(flag: bool) -> str:
    """``yes`` or ``NO`` (capitals: a failed invariant should stand out in a table)."""
    return "yes" if flag else "NO"


__all__ = ["Column", "reference_summary", "reference_readings", "model_rows", "yes_no"]

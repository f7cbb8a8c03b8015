"""Shape error for ``surgsim bench accuracy``: the deformed surface against the converged FEM surface.

Next to the force error, every indentation row gets the signed distances (Vandewalle et al. 2003, section 2.2;
:mod:`surgsim_envs.geometry.surface_error`) of its deformed top surface at the deepest depth to the
reference surface under the same load: the finest row of the model whose finest row has the
smallest force error against the analytic reference (the converged continuum solution; in
practice the finest FEM), chosen from the data, not by name. Columns (m): ``shape_mu``,
``shape_sigma``, ``shape_rms`` and ``shape_max`` (largest |distance|), and ``shape_reference``.
Rows carry their surface as ``"_surface"`` = (positions, triangles) until :func:`add_shape_error`
removes it (it is not JSON).
"""

from __future__ import annotations

import math

import numpy as np

from surgsim_envs.geometry.surface_error import surface_error

def reference_row(rows: list[dict]) -> dict | None:
    """The reference: among the finest row of each model (rows with a surface), the one with the
    smallest force ``error`` (rows without an ``error`` rank last)."""
    finest = {}
    for r in rows:
        if r.get("_surface") is not None and (r["model"] not in finest or r["spacing"] < finest[r["model"]]["spacing"]):
            finest[r["model"]] = r
    if not finest:
        return None
    return min(finest.values(), key=lambda r: (r.get("error", math.inf), r["spacing"]))


def add_shape_error(rows: list[dict]) -> None:
    """Fill the shape columns of ``rows`` in place and drop their ``_surface`` entries."""
    ref_row = reference_row(rows)
    for r in rows:
        surf = r.get("_surface")
        if surf is None or ref_row is None:
            r.update(shape_mu=math.nan, shape_sigma=math.nan, shape_rms=math.nan, shape_max=math.nan)
            continue
        err = surface_error(surf[0], surf[1], ref_row["_surface"][0], ref_row["_surface"][1])
        r.update(shape_mu=err.mean, shape_sigma=err.std, shape_rms=err.rms,
                 shape_max=float(np.max(np.abs(err.distances))),
                 shape_reference=f"{ref_row['model']} h={ref_row['spacing'] * 1e3:g} mm")
    for r in rows:
        r.pop("_surface", None)


def plot_shape_axis(rows: list[dict], path: str) -> None:
    """Cost against shape error (RMS signed distance, mm) per model/integrator, next to the force chart."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 5.0))
    series = sorted({(r["model"], r["integrator"]) for r in rows})
    for m, integ in series:
        sub = sorted((r for r in rows if r["model"] == m and r["integrator"] == integ
                      and math.isfinite(r.get("shape_rms", math.nan)) and math.isfinite(r["us_per_ms"])),
                     key=lambda r: r["spacing"])
        if not sub:
            continue
        ax.plot([r["us_per_ms"] for r in sub], [max(r["shape_rms"] * 1e3, 1e-4) for r in sub], "o-", ms=5,
                label=f"{m} / {integ}")
        for r in sub:
            ax.annotate(r.get("label", f"{r['spacing'] * 1e3:g}"), (r["us_per_ms"], max(r["shape_rms"] * 1e3, 1e-4)),
                        fontsize=7, textcoords="offset points", xytext=(4, 3))
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("cost: us of compute per simulated ms")
    ax.set_ylabel("shape error: rms signed distance to the finest FEM surface (mm)")
    ax.set_title("Deformed top surface at the deepest indentation vs the converged FEM surface", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)

"""Validation reports of Vandewalle et al. 2003 (section 2.2): colour-coded distance maps and error histograms.

:func:`validation_report` compares a predicted surface with a reference surface
(:mod:`surgsim_envs.geometry.surface_error`), and writes ``distance_map.png`` (predicted surface
coloured by the signed distance, green positive / red negative, +-10 mm by default as in the
paper), ``histogram.png`` (with mu and sigma), ``validation.json`` (the summary) and
``distances.npz`` (per-vertex distances). :func:`comparison_figure` puts several predictions
(e.g. basic vs growth model) side by side over one colour scale, with overlaid histograms.
"""

from __future__ import annotations

import json
import os

import numpy as np

from surgsim_envs.geometry.surface_error import SurfaceError, surface_error

CMAP = "RdYlGn"            # red (negative: lack of material) - yellow (0) - green (positive)
DEFAULT_RANGE_MM = 10.0
DEFAULT_VIEW = (60.0, -70.0)  # matplotlib (elevation, azimuth) in degrees


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def draw_distance_map(ax, vertices, faces, distances, range_mm=DEFAULT_RANGE_MM, view=DEFAULT_VIEW, title=""):
    """Draw the surface (vertices m, faces) on a 3-D axis, faces coloured by the mean signed
    distance (m) of their vertices on a +-``range_mm`` scale. ``distances``: one per vertex, or one
    per vertex used by ``faces`` in ascending order (as :func:`surface_error` gives). Returns the
    colour mappable."""
    import matplotlib.colors as mcolors
    from matplotlib import cm
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    v = np.asarray(vertices) * 1e3
    f = np.asarray(faces)
    norm = mcolors.Normalize(-range_mm, range_mm)
    mappable = cm.ScalarMappable(norm=norm, cmap=CMAP)
    d = np.asarray(distances, dtype=np.float64)
    if len(d) != len(v):                     # one distance per vertex used by the faces (surface_error)
        full = np.zeros(len(v))
        full[np.unique(f)] = d
        d = full
    colours = mappable.to_rgba(d[f].mean(axis=1) * 1e3)
    ax.add_collection3d(Poly3DCollection(v[f], facecolors=colours, edgecolors=(0, 0, 0, 0.08), linewidths=0.2))
    lo, hi = v.min(axis=0), v.max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(np.maximum(hi - lo, 1e-3 * max(hi - lo)))
    ax.view_init(*view)
    ax.set_xlabel("x (mm)", fontsize=7)
    ax.set_ylabel("y (mm)", fontsize=7)
    ax.set_zlabel("z (mm)", fontsize=7)
    ax.tick_params(labelsize=6)
    if title:
        ax.set_title(title, fontsize=9)
    return mappable


def draw_histogram(ax, errors: list[tuple[str, SurfaceError]], range_mm=DEFAULT_RANGE_MM):
    bins = np.linspace(-range_mm, range_mm, 81)
    for label, err in errors:
        d = np.clip(err.distances * 1e3, -range_mm, range_mm)
        ax.hist(d, bins=bins, histtype="step", lw=1.5, density=True,
                label=f"{label}: mu = {err.mean * 1e3:.2f} mm, sigma = {err.std * 1e3:.2f} mm")
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set_xlabel("signed distance to the reference (mm; outside +, inside -)")
    ax.set_ylabel("fraction of vertices per mm")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)


def validation_report(pred, ref, out_dir: str, *, range_mm=DEFAULT_RANGE_MM, view=DEFAULT_VIEW,
                      title="predicted vs reference") -> dict:
    """Compare ``pred`` = (vertices, faces) with ``ref`` = (vertices, faces); write the files of the
    module doc into ``out_dir``; return the summary dict (metres)."""
    plt = _plt()
    err = surface_error(pred[0], pred[1], ref[0], ref[1])
    os.makedirs(out_dir, exist_ok=True)
    fig = plt.figure(figsize=(6.4, 5.0))
    ax = fig.add_subplot(111, projection="3d")
    m = draw_distance_map(ax, pred[0], pred[1], err.distances, range_mm, view, title)
    fig.colorbar(m, ax=ax, shrink=0.7, label="signed distance (mm)")
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "distance_map.png"), dpi=120)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    draw_histogram(ax, [(title, err)], range_mm)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "histogram.png"), dpi=120)
    plt.close(fig)
    summary = err.summary()
    summary["range_mm"] = range_mm
    with open(os.path.join(out_dir, "validation.json"), "w") as fh:
        json.dump(summary, fh, indent=1)
    np.savez_compressed(os.path.join(out_dir, "distances.npz"), vertices=np.asarray(pred[0]), faces=np.asarray(pred[1]),
                        distances=err.distances)
    return summary


def comparison_figure(path: str, entries, range_mm=DEFAULT_RANGE_MM, view=DEFAULT_VIEW, suptitle=""):
    """``entries``: list of (label, vertices, faces, SurfaceError). One distance map per entry on a
    common scale plus one panel of overlaid histograms (the paper's Figs. 6 and 7)."""
    plt = _plt()
    n = len(entries)
    fig = plt.figure(figsize=(4.4 * n + 6.0, 4.4))
    grid = fig.add_gridspec(1, n + 1, width_ratios=[1.0] * n + [1.25], wspace=0.35)
    mappable = None
    for i, (label, v, f, err) in enumerate(entries):
        ax = fig.add_subplot(grid[0, i], projection="3d")
        mappable = draw_distance_map(ax, v, f, err.distances, range_mm, view, label)
    fig.colorbar(mappable, ax=fig.axes, shrink=0.6, location="left", label="signed distance (mm)")
    ax = fig.add_subplot(grid[0, n])
    draw_histogram(ax, [(e[0], e[3]) for e in entries], range_mm)
    if suptitle:
        fig.suptitle(suptitle, fontsize=10)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)

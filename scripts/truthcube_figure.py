"""Bar chart of the truth-cube error budget (used by ``scripts/truthcube.py --figure PNG``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_rows(rows, strains, path) -> None:
    """rows: [(label, {strain: (total m, seconds, model part m)})]; the first row is the symmetry floor.

    One group of bars per strain: each model's total RMS (solid) with its model part (hatched,
    the distance to the symmetrised measurement), the floor as a dashed line, the 1.2 mm target
    target as a dotted line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    (_, floor), models = rows[0], rows[1:]
    fig, ax = plt.subplots(figsize=(9, 4.6))
    width = 0.8 / max(1, len(models))
    colors = plt.cm.tab10(np.arange(len(models)))
    for g, s in enumerate(strains):
        for m, (label, res) in enumerate(models):
            x = g + (m - (len(models) - 1) / 2) * width
            ax.bar(x, res[s][0] * 1e3, width * 0.9, color=colors[m], alpha=0.45, label=label if g == 0 else None)
            ax.bar(x, res[s][2] * 1e3, width * 0.9, color=colors[m], hatch="///", edgecolor="k", linewidth=0.3)
        ax.hlines(floor[s][0] * 1e3, g - 0.45, g + 0.45, colors="k", linestyles="--",
                  label="symmetry floor of the data" if g == 0 else None)
    ax.axhline(1.2, color="r", linestyle=":", label="target 1.2 mm")
    top = 3.0 * max(floor[s][0] for s in strains) * 1e3          # off-scale bars (a folded network) get a label
    ax.set_ylim(0, top)
    for g, s in enumerate(strains):
        for m, (label, res) in enumerate(models):
            if res[s][0] * 1e3 > top:
                x = g + (m - (len(models) - 1) / 2) * width
                ax.text(x, top * 0.97, f"{res[s][0] * 1e3:.1f}", ha="center", va="top", fontsize=7, rotation=90)
    ax.set_xticks(range(len(strains)), [f"{s * 100:g} % compression" for s in strains])
    ax.set_ylabel("bead RMS error (mm)")
    ax.set_title("Truth cube: total RMS (light) and model part (hatched); no model goes below the floor")
    ax.legend(fontsize=7, ncol=2, loc="upper left")
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)

"""Figure for docs/contact.md: Palpation-v0's probe-set force error of ``fem_static`` against the
task-accuracy reference, per lattice spacing, with the contact stiffness per unit area (the palpation
tasks' "auto", 1e8 N/m^3) and with the per-node penalty (200 N/m, ``contact_stiffness_per_area=None``).

    python scripts/contact_per_area_figure.py [--out docs/img/contact_per_area.png] [--spacings 0.01,0.0075,0.005]

About a minute on a 2-core host for the default spacings (each row is the probe set's 12 presses).
"""

from __future__ import annotations

import argparse
import json
from importlib import resources

import numpy as np

TASK = "SurgSim/Palpation-v0"


def errors(forces: dict, ref: dict) -> np.ndarray:
    return np.array([forces[k] / ref[k] - 1.0 for k in ref])


def row(spacing: float, per_area) -> dict:
    """The probe set's presses with fem_static at ``spacing`` m and ``contact_stiffness_per_area``."""
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401
    from surgsim_envs.bench import task_accuracy as ta
    from surgsim_envs.bench import task_reference as tr

    probes = ta.PROBE_SETS[TASK][0]
    env = gym.make(TASK, model="fem_static", resolution=spacing, contact_stiffness_per_area=per_area,
                   material=tr.elastic(ta.task_material(TASK)), disable_env_checker=True).unwrapped
    presser = ta.Presser(env, probes.hold)
    out = {}
    for i, inc in enumerate(probes.inclusions):
        for site in ("over", "mirror"):
            xy = inc.position if site == "over" else ta.mirror(inc.position)
            for depth in probes.depths:
                out[f"{i}/{site}/{depth * 1e3:g}mm"] = presser.press(inc, xy, depth)
    env.close()
    return out


def main(argv=None) -> int:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from tqdm import tqdm

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="docs/img/contact_per_area.png")
    p.add_argument("--spacings", default="0.01,0.0075,0.005", help="lattice spacings in m, comma separated")
    args = p.parse_args(argv)
    spacings = [float(s) for s in args.spacings.split(",")]
    table = json.loads(resources.files("surgsim_envs.tissue.data").joinpath("task_accuracy_table.json").read_text())
    ref = table["references"][TASK]["forces_N"]
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 4))
    results = {}
    runs = [(h, law) for law in ("auto", None) for h in spacings]
    for h, law in tqdm(runs, desc="probe set rows", unit="row"):
        results[(h, law)] = errors(row(h, law), ref)
    for law, label, colour in (("auto", "1e8 N/m^3 per area (the palpation tasks)", "C0"),
                               (None, "200 N/m per node", "C3")):
        p95 = [np.percentile(np.abs(results[(h, law)]), 95) * 100 for h in spacings]
        ax0.plot([h * 1e3 for h in spacings], p95, "o-", color=colour, label=label)
        for h in spacings:
            e = results[(h, law)] * 100
            ax1.plot(np.full(len(e), h * 1e3) + (0.12 if law is None else -0.12), e, "o", ms=4, color=colour,
                     alpha=0.7, label=label if h == spacings[0] else None)
    ax0.axhline(table["tolerances"][TASK]["tolerance"] * 100, color="k", ls="--", lw=1, label="task tolerance")
    ax0.set_xlabel("lattice spacing (mm)")
    ax0.set_ylabel("p95 force error against the reference (%)")
    ax0.invert_xaxis()
    ax0.legend(fontsize=8)
    ax1.axhline(0.0, color="k", lw=0.8)
    ax1.set_xlabel("lattice spacing (mm)")
    ax1.set_ylabel("force error per press (%)")
    ax1.invert_xaxis()
    ax1.legend(fontsize=8)
    fig.suptitle("fem_static in Palpation-v0's probe set: the contact law per node or per area")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

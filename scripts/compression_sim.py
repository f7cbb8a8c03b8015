"""Simulated uniaxial compression of the Ecoflex phantoms against the measured curves.

Each law of surgsim_envs.bench.hyperelastic_fit is fitted (closed form) on strains <= 0.30 of the
measured curve; the model that implements it is then compressed in the simulator
(surgsim_envs.bench.compression_sim: a 44.3 x 44.3 x 30 mm block, frictionless and bonded plates)
and compared with the measurement on the held-out strains > 0.30 (RMS relative to the largest
measured stress there).

    python scripts/compression_sim.py [--phantom EF10_50T_A1] [--spacing 0.01] [--models LABEL ...] [--figure PNG] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "tissue_mechanics" / "ecoflex_phantom_compression"
STRAINS = (0.05, 0.15, 0.3, 0.45, 0.6)
FIT_MAX = 0.30
#: (label, law fitted, registered model, model options from the fit's parameters)
MODELS = (
    ("fem linear (ANP)", "linear", "fem", lambda p: {"corotational": False, "formulation": "anp"}),
    ("fem corotational (ANP)", "linear", "fem", lambda p: {"corotational": True, "formulation": "anp"}),
    ("neo_hookean", "neo_hookean", "neo_hookean", lambda p: {}),
    ("neo_hookean c01_fraction (Mooney-Rivlin)", "mooney_rivlin", "neo_hookean",
     lambda p: {"c01_fraction": p["C01"] / (p["C10"] + p["C01"])}),
    ("mass_spring (its cubic law)", "mass_spring", "mass_spring", lambda p: {}),
)


def held_out_error(strains, stress, curve, lo=FIT_MAX) -> float:
    """RMS of (simulated - measured) over the simulated strains > lo, relative to the largest |measured|."""
    s = np.asarray(strains)
    meas = np.interp(s, 1.0 - curve.stretch, curve.stress)
    sel = (s > lo) & np.isfinite(stress)
    if sel.sum() < (s > lo).sum():
        return float("nan")
    return float(np.sqrt(np.mean((stress[sel] - meas[sel]) ** 2)) / np.max(np.abs(meas[s > lo])))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--phantom", default="EF10_50T_A1")
    ap.add_argument("--spacing", type=float, default=0.01)
    ap.add_argument("--figure", type=Path, default=None)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--models", nargs="*", default=None, help="labels to run (default: all of MODELS)")
    args = ap.parse_args(argv)
    from tqdm import tqdm

    from surgsim_envs.bench import compression_sim as cs
    from surgsim_envs.bench import hyperelastic_fit as hf

    curve = hf.load_phantom(DATA / f"{args.phantom}.csv")
    rows = []
    models = [m for m in MODELS if args.models is None or m[0] in args.models]
    jobs = [(m, plates) for m in models for plates in cs.PLATES]
    for (label, law, model, opts), plates in tqdm(jobs, desc="compression", file=sys.stderr):
        fit = hf.fit(curve, law, max_strain=FIT_MAX)
        closed = fit.stress(1.0 - np.asarray(STRAINS))
        t = time.perf_counter()
        stress, failures = cs.compression_curve(model, cs.material_from_fit(fit), STRAINS, plates,
                                                spacing=args.spacing, **opts(fit.params))
        rows.append({"label": label, "law": law, "model": model, "plates": plates, "params": fit.params,
                     "fit_rms": fit.rms_fit, "closed_form_held_out": hf.evaluate(fit, curve, FIT_MAX, 0.6),
                     "strains": list(STRAINS), "stress": [float(v) for v in stress],
                     "closed_form": [float(v) for v in closed],
                     "held_out": held_out_error(STRAINS, stress, curve), "failures": failures,
                     "seconds": time.perf_counter() - t})
    print(f"| model | law fitted on strain <= {FIT_MAX} (Pa) | plates | fit RMS | held-out RMS closed form | "
          "held-out RMS simulated | stress at 0.6 sim / closed / measured (kPa) | solve s |")
    print("|---|---|---|---|---|---|---|---|")
    meas06 = float(np.interp(0.6, 1.0 - curve.stretch, curve.stress))
    for r in rows:
        params = ", ".join(f"{k} {v:.3g}" for k, v in r["params"].items())
        held = "fails" if not np.isfinite(r["held_out"]) else f"{r['held_out']:.3f}"
        print(f"| {r['label']} | {params} | {r['plates']} | {r['fit_rms']:.3f} | {r['closed_form_held_out']:.3f} | "
              f"{held} | {r['stress'][-1] / 1e3:.2f} / {r['closed_form'][-1] / 1e3:.2f} / {meas06 / 1e3:.2f} | "
              f"{r['seconds']:.1f} |")
        for s, why in r["failures"].items():
            print(f"#   {r['label']} {r['plates']} strain {s}: {why[:160]}")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    if args.figure:
        plot(rows, curve, args.figure, models)
    return 0


def plot(rows, curve, path, models=MODELS) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), sharey=True)
    colors = plt.cm.tab10(np.arange(len(models)))
    for ax, plates in zip(axes, ("frictionless", "bonded")):
        ax.plot(1.0 - curve.stretch, -curve.stress / 1e3, "k-", lw=2, label=f"measured {curve.name}")
        for c, (label, *_rest) in zip(colors, models):
            r = next(r for r in rows if r["label"] == label and r["plates"] == plates)
            s = np.asarray(r["strains"])
            ax.plot(s, -np.asarray(r["stress"]) / 1e3, "o-", color=c, label=f"{label} (simulated)")
            if plates == "frictionless":
                ss = np.linspace(0, 0.6, 61)
                from surgsim_envs.bench import hyperelastic_fit as hf

                fit = hf.Fit(r["law"], r["params"], r["fit_rms"], FIT_MAX)
                ax.plot(ss, -fit.stress(1.0 - ss) / 1e3, ":", color=c)
        ax.axvline(FIT_MAX, color="grey", lw=0.8)
        ax.set_xlim(0, 0.62)
        ax.set_ylim(0, 1.6 * float(-curve.stress[(1.0 - curve.stretch) <= 0.6].min()) / 1e3)
        ax.set_xlabel("engineering compressive strain")
        ax.set_title(f"{plates} plates (fit on strain <= {FIT_MAX}, grey line)")
    axes[0].set_ylabel("nominal compressive stress (kPa)")
    axes[0].legend(fontsize=7)
    fig.suptitle("Uniaxial compression in the simulator (dots) vs closed-form law (dotted) vs measured")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())

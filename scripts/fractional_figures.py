"""Figures and tables of docs/models/fractional.md (the variable-order paper).

    python scripts/fractional_figures.py [--out docs/img] [--data ../shared/data/tissue_mechanics]

1. fractional_relax_creep.png: relaxation modulus and creep compliance of Kelvin-Voigt, the
   standard linear solid, Scott-Blair (q = 0.3, 0.6) and a variable-order element.
2. fractional_grid2d.png: 2-D layer (eqs. 19-21) and Kelvin-Voigt (eq. 10) relaxing to the same
   static field (eqs. 22-23) after a boundary displacement.
3. fractional_identification.png: synthetic ramp-and-hold record (1 % noise) and its identification.
4. fractional_phantoms.png + a table on stdout: identification on the three Ecoflex phantom ramps
   (whole ramp and up to 20 % strain), against an SLS fit.
5. fractional_relax3d.png: the 3-D model in the virtual relaxation test (bench.material.relax)
   with short memories L = 100, 1,000 and 3,400 steps (the whole record).

``--only NAME`` (relax_creep, grid2d, identification, phantoms, relax3d) makes one figure.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from surgsim_envs.bench import fractional_fit as ff  # noqa: E402
from surgsim_envs.bench import viscoelastic_1d as v1  # noqa: E402
from surgsim_envs.tissue import fractional_calculus as fc  # noqa: E402
from surgsim_envs.tissue.fractional_grid2d import FractionalGrid2D, Grid2D, KelvinVoigtGrid2D, static_solution  # noqa: E402

E, G1, TAU = 4000.0, 0.5, 1.5      # liver preset: young (Pa), relax_fraction, relax_time (s)


def relax_creep(out: Path) -> None:
    t = np.logspace(-3, 1.5, 400)
    e_inf, e1 = (1 - G1) * E, G1 * E
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8))
    a.loglog(t, v1.relaxation_modulus("kelvin_voigt", t, k=e_inf), label=f"Kelvin-Voigt k = {e_inf:.0f} Pa (+ b delta(t))")
    a.loglog(t, v1.relaxation_modulus("sls", t, e_inf=e_inf, e1=e1, tau=TAU), label=f"SLS E0 = {E:.0f} Pa, g = {G1}, tau = {TAU} s")
    for q in (0.3, 0.6):
        a.loglog(t, v1.relaxation_modulus("scott_blair", t, eta=E * TAU ** q, q=q), "--", label=f"Scott-Blair q = {q}, eta = E tau^q")
    # variable order: q = 0.6 for t < 0.5 s, then 0.2 (RL of a unit step, exact: t^-q(t) / Gamma(1 - q(t)))
    order = fc.PiecewiseOrder((0.5,), (0.6, 0.2))
    qv = order(t)
    gv = E * t ** -qv / np.array([math.gamma(1 - q) for q in qv])
    a.loglog(t, gv, "k-", lw=1.8, label="variable order q: 0.6 -> 0.2 at 0.5 s, eta = E (1 s)^q")
    a.set_xlabel("time after a strain step (s)")
    a.set_ylabel("relaxation modulus G(t) (Pa)")
    a.legend(fontsize=6.5)
    a.grid(True, which="both", alpha=0.3)
    b_kv = e1 * TAU
    b.loglog(t, v1.creep_compliance("kelvin_voigt", t, k=e_inf, b=b_kv) * 1e3, label=f"Kelvin-Voigt b = {b_kv:.0f} Pa s")
    b.loglog(t, v1.creep_compliance("sls", t, e_inf=e_inf, e1=e1, tau=TAU) * 1e3, label="SLS")
    for q in (0.3, 0.6):
        b.loglog(t, v1.creep_compliance("scott_blair", t, eta=E * TAU ** q, q=q) * 1e3, "--", label=f"Scott-Blair q = {q}")
    h = 1e-3
    tt = h * np.arange(1, int(30 / h) + 1)
    strain = fc.solve_for_input(np.ones(len(tt) + 1) / E, h, order)[1:]     # eta D^q(t) eps = 1 Pa, eta = E (GL)
    b.loglog(tt[::20], strain[::20] * 1e3, "k-", lw=1.8, label="variable order (GL, dt = 1 ms)")
    b.set_xlabel("time after a stress step (s)")
    b.set_ylabel("creep compliance J(t) (1/kPa)")
    b.legend(fontsize=6.5)
    b.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "fractional_relax_creep.png", dpi=120)
    plt.close(fig)


def grid2d(out: Path) -> dict:
    lam, mu = 15e3, 2e3
    grid = Grid2D(10, 8, 0.005)
    ub = np.zeros((11, 9, 2))
    y = grid.points[..., 1]
    ub[-1, :, 0] = 5e-4 * np.sin(np.pi * y[-1] / 0.04)
    ref = static_solution(grid, lam + 2 * mu, lam, mu, ub)
    probe = (7, 4)
    fig, ax = plt.subplots(figsize=(6, 3.6))
    res = {}
    for q in (0.3, 0.5):
        m = FractionalGrid2D(grid, lam + 2 * mu, lam, mu, density=1000.0, order=q, memory=2000)
        m.set_displacement(np.where(grid.interior[..., None], 0.0, ub))
        dt = 0.8 * m.critical_dt()
        ts, us = [], []
        for k in range(int(0.2 / dt)):
            m.step(dt)
            ts.append(m.time)
            us.append(m.displacement[probe][0])
        ax.plot(np.array(ts) * 1e3, np.array(us) * 1e3, label=f"fractional q = {q} (dt {dt * 1e6:.0f} us)")
        res[q] = float(np.abs(m.displacement - ref).max() / np.abs(ref).max())
    for b in (2.0, 20.0):
        kv = KelvinVoigtGrid2D(grid, lam, mu, b=b)
        kv.set_displacement(np.where(grid.interior[..., None], 0.0, ub))
        dt = 2e-5
        ts, us = [], []
        for k in range(int(0.2 / dt)):
            kv.step(dt)
            if k % 10 == 0:
                ts.append(kv.time)
                us.append(kv.displacement[probe][0])
        ax.plot(np.array(ts) * 1e3, np.array(us) * 1e3, ":", label=f"Kelvin-Voigt b = {b} Pa s")
        res[f"kv{b}"] = float(np.abs(kv.displacement - ref).max() / np.abs(ref).max())
    ax.axhline(ref[probe][0] * 1e3, color="k", lw=0.8, label="static solution (eqs. 22-23)")
    ax.set_xlabel("time (ms)")
    ax.set_ylabel("u_x at interior point (7, 4) (mm)")
    ax.set_title("2-D layer after a boundary displacement, lambda = 15 kPa, mu = 2 kPa", fontsize=8)
    ax.legend(fontsize=6.5)
    fig.tight_layout()
    fig.savefig(out / "fractional_grid2d.png", dpi=120)
    plt.close(fig)
    return res


def identification(out: Path) -> dict:
    duration, ramp = 6.0, 1.0
    t = np.linspace(0.0, duration, 8001)
    x = np.minimum(t / ramp, 1.0)
    eps = 0.05 * (x - np.sin(2 * np.pi * x) / (2 * np.pi))
    truth = (2.0e4, (0.3, 0.55, 0.4))
    sig = v1.fractional_stress(t, eps, truth[0], fc.PiecewiseOrder.uniform(truth[1], duration))
    rng = np.random.default_rng(1)
    rec = ff.StressRecord(t[::20], eps[::20], sig[::20] + 0.01 * sig.max() * rng.standard_normal(401), "synthetic, 1 % noise")
    frac = ff.fit_fractional(rec, pieces=3)
    sls = ff.fit_sls(rec)
    ff.plot_fits(rec, {"fractional, 3 pieces": frac, "SLS": sls}, str(out / "fractional_identification.png"),
                 title=f"synthetic: eta = {truth[0]:.3g}, q = {truth[1]}; fitted eta = {frac.eta:.4g}, "
                       f"q = {tuple(round(q, 3) for q in frac.orders)}")
    return {"frac": frac.params(), "frac_rel": frac.relative_residual, "sls": sls.params(), "sls_rel": sls.relative_residual}


def phantoms(out: Path, data: Path) -> list[dict]:
    names = ("EF10_100T_A1", "EF10_50T_A1", "EF10_25T_A1")
    fig, axes = plt.subplots(2, 3, figsize=(13, 6.5))
    rows = []
    for col, name in enumerate(names):
        rec_full = ff.read_record(str(data / "ecoflex_phantom_compression" / f"{name}.csv"))
        for row, (label, rec) in enumerate((("whole ramp (67 %)", rec_full), ("strain <= 20 %", rec_full.until_strain(0.2)))):
            frac = ff.fit_fractional(rec, pieces=3)
            one = ff.fit_fractional(rec, pieces=1)
            sls = ff.fit_sls(rec)
            ax = axes[row, col]
            ax.plot(rec.strain, rec.stress / 1e3, "k.", ms=1.5, label="measured")
            ax.plot(rec.strain, frac.predicted / 1e3, label=f"fractional 3 pieces ({100 * frac.relative_residual:.1f} %)")
            ax.plot(rec.strain, one.predicted / 1e3, "--", label=f"Scott-Blair, 1 piece ({100 * one.relative_residual:.1f} %)")
            ax.plot(rec.strain, sls.predicted / 1e3, ":", label=f"SLS ({100 * sls.relative_residual:.1f} %)")
            ax.set_title(f"{name}, {label}", fontsize=8)
            ax.set_xlabel("engineering strain")
            ax.set_ylabel("engineering stress (kPa)")
            ax.legend(fontsize=6.5)
            rows.append({"phantom": name, "range": label, "eta": frac.eta, "q": frac.orders, "frac_rel": frac.relative_residual,
                         "one_q": one.orders[0], "one_eta": one.eta, "one_rel": one.relative_residual,
                         "sls": sls.params(), "sls_rel": sls.relative_residual})
    fig.tight_layout()
    fig.savefig(out / "fractional_phantoms.png", dpi=110)
    plt.close(fig)
    return rows


def relax3d(out: Path) -> dict:
    from surgsim_envs.bench.material import relax

    fig, ax = plt.subplots(figsize=(6, 3.8))
    res = {}
    for mem in (100, 1000, 3400):
        r = relax("fractional", "liver", memory=mem, dt=1e-3, integrator="implicit")
        ax.plot(r.time, r.force, label=f"L = {mem} steps ({mem * 1e-3:g} s)")
        res[mem] = float(r.force[-1])
    r = relax("fractional", "liver", memory=100, coarse_blocks=33, coarse_step=100, dt=1e-3, integrator="implicit")
    ax.plot(r.time, r.force, "k--", lw=1, label="L = 100 + 33 block averages of 100 steps")
    res["nested"] = float(r.force[-1])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("plate force (N)")
    ax.set_title("3-D ramp (0.2 s, 5 %) and hold, liver, q = 0.3, implicit dt = 1 ms", fontsize=8)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "fractional_relax3d.png", dpi=120)
    plt.close(fig)
    return res


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="docs/img")
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[1].parent / "shared" / "data" / "tissue_mechanics"))
    parser.add_argument("--only", default=None, choices=["relax_creep", "grid2d", "identification", "phantoms", "relax3d"])
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.only == "relax3d":
        print("3-D relaxation force at 3.2 s:", relax3d(out))
        return
    if args.only:
        print(globals()[args.only](out) if args.only != "phantoms" else phantoms(out, Path(args.data)))
        return
    relax_creep(out)
    print("grid2d relative distance to the static solution after 0.2 s:", grid2d(out))
    print("identification:", identification(out))
    print("3-D relaxation force at 3.2 s:", relax3d(out))
    for r in phantoms(out, Path(args.data)):
        s = r["sls"]
        print(f"| {r['phantom']} | {r['range']} | {r['eta']:.4g} | {', '.join(f'{q:.3f}' for q in r['q'])} | "
              f"{100 * r['frac_rel']:.1f} % | q = {r['one_q']:.3f}, eta = {r['one_eta']:.4g} | {100 * r['one_rel']:.1f} % | "
              f"E0 = {s['young']:.4g}, g = {s['relax_fraction']:.3f}, tau = {s['relax_time']:.3g} s | {100 * r['sls_rel']:.1f} % |")


if __name__ == "__main__":
    main()

"""Figures of docs/models/diffusion.md: the paper-000 cases (Figs. 9.2-9.5) on the round-cornered
cube, their dent profiles, and the load-deformation curve (Fig. 9.6).

    PYTHONPATH=. python scripts/diffusion_figures.py [--out docs/img]

Each case is the equilibrium (``static_solve``) under the paper's 3 kg press on the +x face
(checked against explicit stepping in tests/test_diffusion.py). Displacements are drawn 1:1.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

from surgsim_envs.bench.diffusion_press import (CASES, CONTACT, FIGURE_MATERIAL, PAPER_FORCE, load_curve,  # noqa: E402
                                                node_near, paper_case, press, white_portions)

TITLES = {"isotropic": "Fig. 9.2  isotropic\nomega 0.08",
          "anisotropic": "Fig. 9.3  anisotropic\nomega lat 0.08 / long 0.24",
          "inhomogeneous": "Fig. 9.4  inhomogeneous\nwhite 0.08 / grey 0.24",
          "local": "Fig. 9.5  local\nwhite omega 1e-6 / grey 0.08"}


def _draw(ax, model, disp, colour_by, elev, azim, vmax):
    pos = model.rest_positions + disp
    tris = model.surface
    light = np.array([0.6, 0.3, 0.75])
    light /= np.linalg.norm(light)
    p = pos[tris]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    shade = 0.35 + 0.65 * np.clip(n @ light, 0, 1)
    if colour_by is None:
        val = np.linalg.norm(disp, axis=1)[tris].mean(axis=1) / vmax
        base = plt.cm.magma(0.15 + 0.8 * np.clip(val, 0, 1))[:, :3]
    else:
        white = colour_by[tris].mean(axis=1) > 0.5
        base = np.where(white[:, None], [0.95, 0.95, 0.95], [0.55, 0.55, 0.6])
    col = np.clip(base * shade[:, None], 0, 1)
    ax.add_collection3d(Poly3DCollection(p, facecolors=col, edgecolors=(0, 0, 0, 0.08), linewidths=0.2))
    r = 0.06
    ax.set_xlim(-r, r)
    ax.set_ylim(-r, r)
    ax.set_zlim(-r, r)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=elev, azim=azim)
    ax.set_axis_off()


def figure_cases(out: Path) -> dict:
    cases = {c: paper_case(c) for c in CASES}
    disps = {c: press(m) for c, m in cases.items()}
    vmax = max(np.linalg.norm(d, axis=1).max() for d in disps.values())
    fig = plt.figure(figsize=(12, 6.4))
    for k, c in enumerate(CASES):
        m = cases[c]
        colour = None if c in ("isotropic", "anisotropic") else white_portions(m.rest_positions).astype(float)
        for row, (elev, azim) in enumerate(((8, 0), (30, 35))):
            ax = fig.add_subplot(2, 4, 1 + k + 4 * row, projection="3d")
            _draw(ax, m, disps[c], colour, elev, azim, vmax)
            if row == 0:
                ax.set_title(TITLES[c], fontsize=9)
    fig.suptitle(f"Diffusion model (Zhong et al. 2016): 10 cm round-cornered cube, {cases['isotropic'].n_nodes} points, "
                 f"{PAPER_FORCE:.1f} N (3 kg) on the +x face; E {FIGURE_MATERIAL['young'] / 1e3:.0f} kPa. "
                 "Colour: |u| (isotropic, anisotropic) or white/grey omega regions", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "diffusion_cases.png", dpi=110)
    plt.close(fig)
    return {c: (cases[c], disps[c]) for c in CASES}


def figure_profiles(results, out: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    dists = np.arange(6) * (0.1 / 12)                      # the grid nodes of the pressed face
    for ax, (axis, label) in zip(axes, (((0, 1, 0), "along y (latitudinal)"), ((0, 0, 1), "along z (longitudinal)"))):
        for c, (m, u) in results.items():
            prof = [np.linalg.norm(u[node_near(m, CONTACT + d * np.asarray(axis))]) * 1e3 for d in dists]
            ax.plot(dists * 1e3, prof, marker="o", ms=3, label=c)
        ax.set_xlabel(f"distance from the contact {label} (mm)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("|displacement| (mm)")
    axes[0].legend(fontsize=8)
    fig.suptitle("Dent profiles on the pressed face (3 kg): anisotropy spreads along z, the white bands (|y| > 2 cm) "
                 "stop the local case", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "diffusion_profiles.png", dpi=110)
    plt.close(fig)


def figure_load_curve(out: Path) -> None:
    forces = np.linspace(0.0, 60.0, 13)
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for nl in (0.0, 2.0, 10.0):
        mat = dict(FIGURE_MATERIAL, nonlinear=nl)
        depth = load_curve(paper_case("isotropic", material=mat), forces)
        ax.plot(depth * 1e3, forces, marker="o", ms=3, label=f"nonlinear = {nl:g}")
    ax.set_xlabel("indentation under the contact (mm)")
    ax.set_ylabel("force (N)")
    ax.set_title("Fig. 9.6 analogue: load-deformation of the cube", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "diffusion_load_curve.png", dpi=110)
    plt.close(fig)


def figure_scene(out: Path) -> None:
    """MuJoCo render of the palpation scene with the diffusion tissue: probe pressed 6 mm."""
    from surgsim_envs.scene import Simulation, palpation_config, palpation_scene
    from surgsim_envs.scene.render import SceneRenderer

    cfg = palpation_config(organ="slab", model="diffusion")
    cfg.tissues[0].spacing = 0.005
    sim = Simulation(palpation_scene(cfg))
    top = float(sim.tissue().positions[:, 2].max())
    tip = float(cfg.tool("probe").tip_radius)
    sim.set_tool_target("probe", [0.0, 0.0, top + tip - 0.006], speed=0.05)
    sim.run(0.6)
    with SceneRenderer(sim, 640, 480) as r:
        img = r.render("overview")
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    ax.imshow(img)
    ax.set_axis_off()
    f = sim.tool_force("probe")
    ax.set_title(f"Palpation scene, diffusion model ({sim.tissue().n_nodes} nodes, surface only): "
                 f"probe 6 mm in, {f[2]:.2f} N", fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "diffusion_palpation.png", dpi=100)
    plt.close(fig)


def figure_chart(rows_json: Path, out: Path) -> None:
    """The shipped speed-accuracy chart with the calibrated diffusion rows added (their cost was
    measured under another machine load: see the JSON)."""
    import json

    from surgsim_envs.bench.accuracy import plot

    from surgsim_envs.tissue.resolution import TABLE_PATH

    shipped = json.loads(Path(TABLE_PATH).read_text())["rows"]    # the table choose() reads
    extra = json.loads(rows_json.read_text())["rows"]
    have = {(r["model"], r.get("integrator"), r["spacing"]) for r in shipped}
    rows = shipped + [r for r in extra if (r["model"], r.get("integrator"), r["spacing"]) not in have]
    plot(rows, str(out / "accuracy_with_diffusion.png"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/img")
    parser.add_argument("--accuracy-rows", default="docs/data/accuracy_diffusion_rows.json",
                        help="rows of `surgsim bench accuracy --models diffusion` to add to the shipped chart")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = figure_cases(out)
    figure_profiles(results, out)
    figure_load_curve(out)
    figure_scene(out)
    if Path(args.accuracy_rows).is_file():
        figure_chart(Path(args.accuracy_rows), out)
    print(f"wrote {out}/diffusion_cases.png, diffusion_profiles.png, diffusion_load_curve.png, diffusion_palpation.png")


if __name__ == "__main__":
    main()

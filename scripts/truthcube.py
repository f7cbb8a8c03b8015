"""Truth-cube validation (Kerdok et al. 2003): simulated vs measured bead positions.

An 80 mm silicone cube (E = 15.3 kPa, nu = 0.499, rho = 980 kg/m^3) is compressed between two
no-slip plates by 5 %, 12.5 % and 18.25 %. We simulate it with every registered tissue model
that can reach static equilibrium, interpolate the displacement at the 343 bead positions
(barycentric in the containing tet) and report the RMS distance to the measured positions,
next to the plain affine prediction (uniform compression along z, no lateral bulging).

Frame: the data's compression axis is z and the moving plate sits at the data's low-z side
moving +z. We centre the cube on the unloaded bead centroid and rotate it 180 deg about y, so
the fixed plate is at z = -40 mm and the moving plate at z = +40 mm moves down.

Each cell is "total (model part)": the measurement's part that breaks the symmetry of the stated
experiment (surgsim_envs.bench.truthcube_symmetry) is a floor every model shares; the model part is
the RMS distance to the symmetrised measurement (total^2 = floor^2 + model^2 for a symmetric prediction).

    python scripts/truthcube.py [--spacing 0.01] [--models fem mass_spring] [--write-docs] [--figure PNG]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "truthcube" / "uniaxial_positions.csv"
CUBE = 0.08                      # m
STRAINS = (0.05, 0.125, 0.1825)
MATERIAL = {"young": 15_300.0, "poisson": 0.499, "density": 980.0, "damping": 20.0, "name": "truthcube"}


def load_truthcube(path=DEFAULT_DATA):
    """Bead positions in the simulation frame (m): ``(rest (343,3), {strain: measured (343,3)})``."""
    data = np.genfromtxt(path, delimiter=",", skip_header=7)
    if data.shape != (343, 15) or np.isnan(data).any():
        raise ValueError(f"{path}: expected 343 rows x 15 columns of numbers after 7 comment lines, got {data.shape}")
    pos = data[:, 3:].reshape(-1, 4, 3) * 1e-3
    centre = pos[:, 0].mean(axis=0)
    flip = np.array([-1.0, 1.0, -1.0])                 # 180 deg about y
    pos = (pos - centre) * flip
    return pos[:, 0], {s: pos[:, i + 1] for i, s in enumerate(STRAINS)}


def affine_prediction(rest, strain):
    """Uniform compression along z between the plates, no lateral bulging."""
    out = rest.copy()
    out[:, 2] = -CUBE / 2 + (rest[:, 2] + CUBE / 2) * (1.0 - strain)
    return out


def rms(a, b) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def cube_model(name: str, spacing: float, **options):
    from surgsim_envs import tissue
    from surgsim_envs.geometry import box_volume

    vol = box_volume((CUBE, CUBE, CUBE), spacing, name="truthcube")
    model = tissue.make(name, vol, MATERIAL, **options)
    z = vol.nodes[:, 2]
    bottom = np.flatnonzero(z < z.min() + 1e-9)
    top = np.flatnonzero(z > z.max() - 1e-9)
    return model, vol, bottom, top


def compress(model, bottom, top, strain: float, settle_time: float = 3.0, dt: float = 1e-3) -> np.ndarray:
    """Equilibrium node positions with the top plate moved down by ``strain`` * 80 mm (no slip)."""
    model.set_fixed(bottom)
    target = model.rest_positions[top] - [0.0, 0.0, strain * CUBE]
    model.set_fixed(top, target)
    try:
        return model.static_solve()
    except NotImplementedError:
        pass
    # dynamic relaxation: ramp the plate over the first third, then let it settle
    model.reset()
    n = int(settle_time / dt)
    ramp = max(1, n // 3)
    for i in range(n):
        s = min(1.0, (i + 1) / ramp)
        model.set_fixed(top, model.rest_positions[top] - [0.0, 0.0, s * strain * CUBE])
        model.step(dt)
    return model.positions.copy()


def predict_beads(vol, positions, rest_beads):
    from surgsim_envs.tissue.fem_assembly import barycentric_locate, interpolate

    idx, w = barycentric_locate(vol.nodes, vol.tets, rest_beads)
    disp = interpolate(positions - vol.nodes, vol.tets, idx, w)
    return rest_beads + disp


def budget(pred, rest, measured, strain) -> dict:
    """Error budget (m) of predicted bead positions: total, floor, model, ... (see truthcube_symmetry)."""
    from surgsim_envs.bench.truthcube_symmetry import error_budget

    return error_budget(pred, measured[strain], rest, strain * CUBE)


def run_model(name, rest, measured, spacing, **options):
    """{strain: (rms m, seconds, model-part rms m)} for one model configuration."""
    model, vol, bottom, top = cube_model(name, spacing, **options)
    out = {}
    for strain in STRAINS:
        model.reset()
        t = time.perf_counter()
        x = compress(model, bottom, top, strain)
        seconds = time.perf_counter() - t
        b = budget(predict_beads(vol, x, rest), rest, measured, strain)
        out[strain] = (b["total"], seconds, b["model"])
    return out


def floor_row(rest, measured):
    """The symmetry floor per strain as a table row (no model with the stated plates can go below)."""
    from surgsim_envs.bench.truthcube_symmetry import symmetric_part, rms as rms_rows

    out = {}
    for s in STRAINS:
        u = measured[s] - rest
        out[s] = (rms_rows(u - symmetric_part(u, rest, s * CUBE)), 0.0, 0.0)
    return out


def configurations(models):
    from surgsim_envs.tissue import registry

    for name in models:
        try:
            cls = registry.get(name)
        except Exception as exc:  # a model still being written must not break the table
            print(f"# skip {name}: {exc}", file=sys.stderr)
            continue
        if name == "fem":
            yield "fem (corotational, ANP)", name, {"corotational": True, "formulation": "anp"}
            yield "fem (linear, ANP)", name, {"corotational": False, "formulation": "anp"}
            yield "fem (linear, standard)", name, {"corotational": False, "formulation": "standard"}
        else:
            opts = {"integrator": "implicit"} if "implicit" in getattr(cls, "integrators", ()) else {}
            yield name, name, opts


def table(rows) -> str:
    head = "| model | " + " | ".join(f"{s * 100:g} % RMS (model part) mm" for s in STRAINS) + " | solve time (s) |"
    sep = "|---" * (len(STRAINS) + 2) + "|"
    lines = [head, sep]
    for label, res in rows:
        floor = label.startswith("symmetry floor")
        cells = " | ".join(f"{res[s][0] * 1e3:.2f}" + ("" if floor else f" ({res[s][2] * 1e3:.2f})") for s in STRAINS)
        total = sum(res[s][1] for s in STRAINS)
        lines.append(f"| {label} | {cells} | {total:.2f} |")
    return "\n".join(lines)


def write_docs_section(text: str, path=REPO / "docs" / "benchmarks.md") -> None:
    """Replace (or append) the '## Truth cube' section of docs/benchmarks.md."""
    path.parent.mkdir(parents=True, exist_ok=True)
    old = path.read_text() if path.exists() else "# Benchmarks\n"
    start = old.find("\n## Truth cube")
    if start < 0:
        new = old.rstrip("\n") + "\n\n" + text.rstrip("\n") + "\n"
    else:
        nxt = old.find("\n## ", start + 1)
        new = old[:start].rstrip("\n") + "\n\n" + text.rstrip("\n") + "\n" + (old[nxt:] if nxt >= 0 else "")
    path.write_text(new)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--spacing", type=float, default=0.01, help="mesh spacing in m (default 0.01)")
    parser.add_argument("--models", nargs="*", default=None, help="registered model names (default: all)")
    parser.add_argument("--write-docs", action="store_true", help="write the table into docs/benchmarks.md")
    parser.add_argument("--figure", type=Path, default=None, help="bar chart of total / model part / floor (PNG)")
    args = parser.parse_args(argv)
    from surgsim_envs.tissue import registry

    rest, measured = load_truthcube(args.data)
    rows = [("symmetry floor of the data (no model goes below)", floor_row(rest, measured))]
    rows.append(("affine (no bulging)", {s: (lambda b: (b["total"], 0.0, b["model"]))(
        budget(affine_prediction(rest, s), rest, measured, s)) for s in STRAINS}))
    for label, name, opts in configurations(args.models or registry.names()):
        try:
            rows.append((label, run_model(name, rest, measured, args.spacing, **opts)))
        except Exception as exc:
            print(f"# {label} failed: {type(exc).__name__}: {exc}", file=sys.stderr)
    text = table(rows)
    print(text)
    if args.figure:
        from truthcube_figure import plot_rows

        plot_rows(rows, STRAINS, args.figure)
    if args.write_docs:
        cmd = "python scripts/truthcube.py " + " ".join(argv if argv is not None else sys.argv[1:])
        section = (
            "## Truth cube\n\n"
            "Kerdok et al. 2003 silicone cube (80 mm, E = 15.3 kPa, nu = 0.499), no-slip plates, 343 beads. "
            "RMS distance between simulated and measured bead positions (static equilibrium; models "
            f"without a static solver relax dynamically with their implicit integrator). Mesh spacing {args.spacing * 1e3:g} mm.\n\n"
            f"Command: `{cmd.strip()}`\n\n{text}\n\n"
            "The affine row is uniform compression with no lateral bulging; a model that beats it captures "
            "the barrel-shaped bulge between the no-slip plates. Residuals at large strain include the "
            "silicone's strain stiffening, which linear/corotational elasticity does not model.\n\n"
            "mass_spring: `static_solve` applies the plate travel in load steps and returns a *stable* "
            "equilibrium (energy minimum: it steps off saddles along negative-curvature modes). The spring "
            "network itself loses stability near 10 % compression between no-slip plates (the lowest "
            "eigenvalue of its tangent stiffness crosses zero; linear springs soften geometrically in "
            "compression and have no volume term), so at 12.5 and 18.25 % its stable states have folded "
            "(inverted) tets next to the plates and the error exceeds the affine prediction. This is the "
            "model, not the solver: the force residual is below 1e-8 of the support reactions. (A single jump to the "
            "final plate position, as before, converged to a state with the whole top tet layer folded: "
            "11.5 / 12.8 mm.)\n"
        )
        write_docs_section(section)
    return 0


if __name__ == "__main__":
    sys.exit(main())

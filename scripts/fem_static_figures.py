"""Figure for docs/models/fem_static.md: sphere indentation of a held-out case through fem_static's
own step (scene penalty contact, condensed compliance) and through the chart's exact contact solve,
against Dimitriadis et al. (2002).

    python scripts/fem_static_figures.py [--out docs/img/fem_static_indent.png]

Held-out case (not the chart's 4 kPa / 0.45 / 5 mm / 30 mm): E = 12 kPa, nu = 0.49, R = 7 mm,
H = 25 mm, spacing = contact radius at the deepest point / 2.5. About 1-3 min on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from surgsim_envs.bench import material as mt
from surgsim_envs.bench.references import dimitriadis_force, dimitriadis_valid_depth
from surgsim_envs.bench.stepped_indent import stepped_indent

CASE = {"young": 12e3, "poisson": 0.49, "radius": 0.007, "thickness": 0.025}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="docs/img/fem_static_indent.png")
    args = ap.parse_args()
    E, nu, R, H = CASE["young"], CASE["poisson"], CASE["radius"], CASE["thickness"]
    mat = {"young": E, "poisson": nu, "relax_fraction": 0.0}
    dv = dimitriadis_valid_depth(R, H)
    s = math.sqrt(R * dv) / 2.5
    t0 = time.perf_counter()
    own = stepped_indent("fem_static", mat, indenter_radius=R, depth=dv, thickness=H, spacing=s, n_depths=6,
                         contact="scene")
    t_own = time.perf_counter() - t0
    vert = stepped_indent("fem_static", mat, indenter_radius=R, depth=dv, thickness=H, spacing=s, n_depths=6,
                          contact="vertical")
    lcp = mt.indent("fem_static", mat, indenter_radius=R, depth=dv, thickness=H, spacing=s, n_depths=6, time_steps=0)
    dd = np.linspace(0.0, dv, 60)
    ref = dimitriadis_force(dd[1:], R, E, nu, H, bonded=True)
    err_own = own.force / dimitriadis_force(own.depth, R, E, nu, H, bonded=True) - 1.0
    err_vert = vert.force / dimitriadis_force(vert.depth, R, E, nu, H, bonded=True) - 1.0
    err_lcp = lcp.force / dimitriadis_force(lcp.depth, R, E, nu, H, bonded=True) - 1.0
    summary = {"case": CASE, "spacing": s, "nodes": own.nodes, "depth": own.depth.tolist(),
               "force_own_step": own.force.tolist(), "force_exact_contact": lcp.force.tolist(),
               "error_own_step": err_own.tolist(), "error_own_step_vertical": err_vert.tolist(),
               "steps_per_depth_vertical": vert.steps.tolist(), "error_exact_contact": err_lcp.tolist(),
               "steps_per_depth": own.steps.tolist(), "penetration": own.penetration.tolist(), "seconds_own": t_own}
    print(json.dumps(summary, indent=1))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4.2))
    ax.plot(dd[1:] * 1e3, ref * 1e3, "k-", label="Dimitriadis et al. 2002 (bonded)")
    ax.plot(own.depth * 1e3, own.force * 1e3, "o", label="own step, scene contact (sphere normals)")
    ax.plot(vert.depth * 1e3, vert.force * 1e3, "s", mfc="none", label="own step, vertical penalty (linear theory)")
    ax.plot(lcp.depth * 1e3, lcp.force * 1e3, "x", ms=8, label="fem_static stiffness, exact contact (chart)")
    ax.set_xlabel("depth (mm)")
    ax.set_ylabel("force (mN)")
    ax.set_title(f"held-out case: E {E / 1e3:g} kPa, nu {nu}, R {R * 1e3:g} mm, H {H * 1e3:g} mm\n"
                 f"spacing {s * 1e3:.2f} mm under the sphere, {own.nodes} nodes", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    bx.axhspan(-0.05, 0.05, color="tab:green", alpha=0.12, label="+-5 %")
    bx.axvspan(0.0, 0.25 * dv * 1e3, color="0.85", alpha=0.6, label="outside the error window")
    bx.plot(own.depth * 1e3, err_own, "o-", label="own step, scene contact")
    bx.plot(vert.depth * 1e3, err_vert, "s-", mfc="none", label="own step, vertical penalty")
    bx.plot(lcp.depth * 1e3, err_lcp, "x--", label="exact contact")
    bx.set_xlabel("depth (mm)")
    bx.set_ylabel("relative force error")
    bx.legend(fontsize=7)
    bx.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

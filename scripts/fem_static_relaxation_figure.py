"""Figure for docs/models/fem_static.md: a Palpation-v0 press held still, fem_static with the liver's
relaxation (g 0.5, tau 1.5 s) against the same press on the instantaneous and on the relaxed
material (frictionless, 10 mm lattice, no lump).

    python scripts/fem_static_relaxation_figure.py [--out docs/img/fem_static_relaxation.png]

About 10 s on one core.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401

NO_LUMP = {"stiffness_contrast": (1.0, 1.0), "young_scale": (1.0, 1.0)}


def press(material, depth=0.005, hold=6.0):
    """(times s, probe force N) of a press to ``depth`` m at the slab's centre, then held ``hold`` s."""
    env = gym.make("SurgSim/Palpation-v0", model="fem_static", spacing=0.01, material=material,
                   disable_env_checker=True).unwrapped
    env.reset(seed=0, options=NO_LUMP)
    sim, c = env.sim, env.config
    top = env.surface_z + c.tip_radius
    t, f = [], []

    def run(seconds):
        for _ in range(int(round(seconds / env.control_dt))):
            sim.step()
            t.append(sim.time)
            f.append(float(sim.tool_force("probe")[2]))

    sim.set_tool_target("probe", [0.0, 0.0, top + c.hover], speed=c.probe_speed)
    run(0.05)
    sim.set_tool_target("probe", [0.0, 0.0, top - depth], speed=c.probe_speed)
    run((c.hover + depth) / c.probe_speed + 0.01 + hold)
    env.close()
    return np.array(t), np.array(f)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="docs/img/fem_static_relaxation.png")
    args = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    base = {"preset": "liver", "friction": 0.0}
    g = 0.5
    curves = {"liver (g 0.5, tau 1.5 s), hereditary": press(base),
              "instantaneous material (E 4 kPa, elastic)": press({**base, "relax_fraction": 0.0}),
              "relaxed material (E 2 kPa, elastic)": press({**base, "young": 4000.0 * (1 - g), "relax_fraction": 0.0})}
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for (label, (t, f)), style in zip(curves.items(), ("-", "--", ":")):
        ax.plot(t, f, style, label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("probe force (N)")
    ax.set_title("Palpation-v0 press to 5 mm, held: fem_static relaxes", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    t, f = curves["liver (g 0.5, tau 1.5 s), hereditary"]
    print(f"wrote {args.out}; force at arrival {f[np.argmax(f)]:.4f} N, at the end {f[-1]:.4f} N, relaxed "
          f"material {curves['relaxed material (E 2 kPa, elastic)'][1][-1]:.4f} N")


if __name__ == "__main__":
    main()

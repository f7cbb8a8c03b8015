"""How much a LayeredPalpation-v0 press depends on where it lands on the lattice: the same press
beside the nodule (at the probe set's mirror site (-2, -1) cm, a node of every lattice it uses; the
nodule far away at (3, 2) cm) moved by 1.25 mm, 2.5 mm and (2.5, 2.5) mm, to 2.5, 3.5 and 4.5 mm.
A continuum reads nearly the same force at all four; a press meets the lattice's nodes only.

    python scripts/wall_press_offsets.py [--models fem_hex,layered] [--spacing 0.005]
"""
import argparse

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401

OFFSETS = ((0.0, 0.0), (0.00125, 0.0), (0.0025, 0.0), (0.0025, 0.0025))
parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--models", default="fem_hex,layered")
parser.add_argument("--spacing", type=float, default=0.005)
args = parser.parse_args()
for model in args.models.split(","):
    env = gym.make("SurgSim/LayeredPalpation-v0", model=model, spacing=args.spacing).unwrapped
    cfg = env.config
    env.reset(seed=0, options={"nodule_position": (0.03, 0.02)})
    for depth in (0.0025, 0.0035, 0.0045):
        forces = []
        for dx, dy in OFFSETS:
            env.wall.press((-0.02 + dx, -0.01 + dy, env.z_top + cfg.probe_radius - depth))
            forces.append(float(env.probe.force()[2]))
        print(f"{model} {args.spacing * 1e3:g} mm, press to {depth * 1e3:g} mm: "
              f"{' / '.join(f'{f:.4f}' for f in forces)} N at offsets {OFFSETS} m; "
              f"spread {100 * (max(forces) - min(forces)) / forces[0]:.0f} % of the on-node force")
    env.close()

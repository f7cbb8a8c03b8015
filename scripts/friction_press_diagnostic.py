"""Where the friction effect of a vertical press in Palpation-v0 comes from.

Presses the probe straight down (rate-limited, as the task does) at the slab centre to ``depth``
with the material's friction and frictionless, holds, and splits the probe's vertical force into
the part carried by the normal forces (sum f_n n_z) and the part carried by friction (sum f_t,z),
listing every contact node with its normal's angle from vertical and its contact state. Optionally
slides the pressed probe ``--slide`` m along x and back (the history effect).

python scripts/friction_press_diagnostic.py --model fem --depth 0.0064
"""
from __future__ import annotations

import argparse

import numpy as np

from surgsim_envs.contact import signed_distance, SPHERE


def run(model: str, mu: float | None, depth: float, hold: int, slide: float, spacing: float, seed: int = 0,
        samples=None):
    import surgsim_envs.scene as scene
    from surgsim_envs.envs.palpation import PalpationEnv

    if samples is not None:                 # override the scene's surface-sample choice
        make = scene.palpation_config

        def with_samples(*args, **kw):
            cfg = make(*args, **kw)
            cfg.contact.surface_samples = samples
            return cfg
        scene.palpation_config = with_samples

    material = {"preset": "liver"} if mu is None else {"preset": "liver", "friction": mu}
    env = PalpationEnv(model=model, material=material, spacing=spacing)
    env.reset(seed=seed, options={"stiffness_contrast": (1.0, 1.0), "young_scale": (1.0, 1.0)})
    sim = env.sim
    c = env.config
    top = env.surface_z
    start = np.array([0.0, 0.0, top + c.tip_radius + c.hover])
    sim.set_tool_target("probe", start, speed=np.inf)
    sim.step(50)
    goal = np.array([0.0, 0.0, top + c.tip_radius - depth])
    sim.set_tool_target("probe", goal, speed=0.05)
    sim.step(int(round((c.hover + depth) / 0.05 / c.dt)) + hold)
    out = {"pressed": split(sim, env)}
    if slide > 0:
        sim.set_tool_target("probe", goal + [slide, 0, 0], speed=0.02)
        sim.step(int(round(slide / 0.02 / c.dt)) + hold)
        sim.set_tool_target("probe", goal, speed=0.02)
        sim.step(int(round(slide / 0.02 / c.dt)) + hold)
        out["after_slide"] = split(sim, env)
    return out


def split(sim, env):
    tissue = sim.tissue()
    contact = next(iter(sim.contacts.values()))
    pos = sim.tool_position("probe")
    f_tool = sim.tool_force("probe")
    x = tissue.positions
    F = contact.result.forces
    rows = np.flatnonzero(np.linalg.norm(F, axis=1) > 0)
    d, n, _ = signed_distance(x[rows], SPHERE, [env.config.tip_radius, 0, 0], pos)
    fn = np.einsum("ij,ij->i", F[rows], n)
    ft = F[rows] - fn[:, None] * n
    ang = np.degrees(np.arccos(np.clip(-n[:, 2], -1, 1)))
    return {"tip_depth_mm": round((env.surface_z + env.config.tip_radius - pos[2]) * 1e3, 3),
            "tool_Fz": float(f_tool[2]), "normal_part": float(-(fn * n[:, 2]).sum()),
            "friction_part": float(-ft[:, 2].sum()), "nodes": [
                (int(i), round(float(a), 1), round(float(f), 4), round(float(-t[2]), 4), round(float(-dd) * 1e3, 3))
                for i, a, f, t, dd in zip(rows, ang, fn, ft, d)]}


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", default="fem")
    ap.add_argument("--depth", type=float, default=0.0064)
    ap.add_argument("--hold", type=int, default=200)
    ap.add_argument("--slide", type=float, default=0.0)
    ap.add_argument("--spacing", type=float, default=0.01)
    ap.add_argument("--samples", type=int, default=None, help="surface-sample edge subdivisions (default: the scene's)")
    a = ap.parse_args()
    for mu in (None, 0.0):
        r = run(a.model, mu, a.depth, a.hold, a.slide, a.spacing, samples=a.samples)
        for k, v in r.items():
            name = "liver" if mu is None else mu
            print(f"mu={name} {k}: depth {v['tip_depth_mm']} mm Fz {v['tool_Fz']:.4f} N = "
                  f"normal {v['normal_part']:.4f} + friction {v['friction_part']:.4f}")
            print("   nodes (id, normal angle deg, f_n N, friction up on tool N, penetration mm):")
            for row in v["nodes"]:
                print("    ", row)

"""Whether a grasp task's held squeeze depends on how the tissue got there: Slippage-v0's settle
(elastic spleen, jaws closed to ``--closure`` and held ``--hold`` s, no pull) read by the jaws'
summed normal force, for the explicit and the implicit step of a dynamic model, frictionless and at
mu 0.6, with the jaws meeting the lattice's nodes only and with contact samples between them.

    python scripts/grasp_hold_path.py [--model mass_spring] [--samples 1,2] [--closure 0.3] [--hold 3]

A frictionless equilibrium has one answer; the two integrators reach it along different paths, so
they must agree. With friction the path may legitimately change the hold. Prints one line per case
(N) and the largest speed of a tissue node at the end (mm/s: whether the hold has settled).
"""

from __future__ import annotations

import argparse
import os

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs.bench.probe_sets import slippage_pull
from surgsim_envs.scene import config as scene_config


def with_samples(n: int):
    """Make every ContactConfig built from now on use ``n`` surface-sample subdivisions (1: nodes only)."""
    base = scene_config.ContactConfig.__init__

    def init(self, *args, **kwargs):
        base(self, *args, **kwargs)
        self.surface_samples = n

    scene_config.ContactConfig.__init__ = init
    return base


def hold(model: str, integrator: str, mu: float, closure: float, seconds: float) -> tuple[float, float]:
    env = gym.make(slippage_pull.TASK, model=model, integrator=integrator, material=slippage_pull.task_material(),
                   settle_time=seconds, initial_closure=closure, disable_env_checker=True).unwrapped
    env.reset(seed=0, options=slippage_pull.options(mu))
    normal = float(np.sum(env.readings()[1]))
    speed = float(np.max(np.linalg.norm(env.sim.tissue().velocities, axis=1))) * 1e3
    env.close()
    return normal, speed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default="mass_spring")
    ap.add_argument("--samples", default="1,2", help="comma-separated edge subdivisions (1 = nodes only)")
    ap.add_argument("--closure", type=float, default=0.3)
    ap.add_argument("--hold", type=float, default=3.0, help="s")
    a = ap.parse_args()
    for n in (int(s) for s in a.samples.split(",")):
        base = with_samples(n)
        for mu in (0.0, 0.6):
            row = {integ: hold(a.model, integ, mu, a.closure, a.hold) for integ in ("symplectic", "implicit")}
            (fe, ve), (fi, vi) = row["symplectic"], row["implicit"]
            print(f"samples {n}  mu {mu:g}  explicit {fe:.4f} N ({ve:.2f} mm/s)  implicit {fi:.4f} N ({vi:.2f} mm/s)  "
                  f"difference {100 * abs(fe - fi) / max(fe, fi):.1f} %", flush=True)
        scene_config.ContactConfig.__init__ = base
    print(f"load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()

"""What LayeredPalpation-v0's continuum wall (``model="fem_static"`` or ``"fem_hex"``) costs a user: the wall time of
each reset (a new nodule: the stiffness factorised again) and of each press (at a site not pressed
since the reset: the press axis's compliance columns of the nodes under the probe; at a site
pressed before: only the small contact solve), with the 1-minute load average beside each reset.

    python scripts/wall_reset_press_cost.py [--model fem_static] [--spacing 0.002] [--resets 4]
    python scripts/wall_reset_press_cost.py --model fem_hex --spacing 0.005     # the task's default

Presses to 3.5 mm at four sites, then one re-press at the first site to 4.5 mm, after each reset;
the nodules are placed by the reset option ``nodule_position``. docs/task_accuracy.md quotes runs.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

SITES = ((0.02, 0.01), (-0.02, -0.01), (0.0, 0.0), (0.01, -0.02))
NODULES = ((0.02, 0.01), (-0.01, 0.015), (0.015, -0.01), (-0.02, -0.015))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default="fem_static", choices=("fem_static", "fem_hex"), help="the continuum wall")
    ap.add_argument("--spacing", type=float, default=0.002, help="lattice spacing, m (the task takes 0.002-0.01)")
    ap.add_argument("--resets", type=int, default=4, help=f"resets, each with a new nodule (at most {len(NODULES)})")
    args = ap.parse_args()

    import gymnasium as gym

    import surgsim_envs  # noqa: F401
    from surgsim_envs.tissue.compliance import pardiso_available

    t0 = time.perf_counter()
    env = gym.make("SurgSim/LayeredPalpation-v0", model=args.model, spacing=args.spacing).unwrapped
    cfg = env.config
    print(f"{env.tissue.n_nodes:,} nodes, built in {time.perf_counter() - t0:.1f} s; factorisation: "
          f"{'MKL PARDISO' if pardiso_available() else 'SuperLU (pip install pypardiso for PARDISO)'}")

    def action(xy, depth):
        return np.array([xy[0] / (cfg.size[0] / 2), xy[1] / (cfg.size[1] / 2), 2 * depth / cfg.max_depth - 1, -1.0],
                        np.float32)

    def timed(fn):
        t = time.perf_counter()
        fn()
        return time.perf_counter() - t

    for k, nodule in enumerate(NODULES[:max(1, min(args.resets, len(NODULES)))]):
        load = os.getloadavg()[0]
        t_reset = timed(lambda: env.reset(options={"nodule_position": nodule}))
        t_new = [timed(lambda s=s: env.step(action(s, 0.0035))) for s in SITES]
        t_again = timed(lambda: env.step(action(SITES[0], 0.0045)))
        print(f"reset {k} ({'first' if k == 0 else 'new nodule'}): {t_reset:.2f} s; presses at new sites "
              f"{', '.join(f'{1e3 * t:.0f}' for t in t_new)} ms; re-press {1e3 * t_again:.1f} ms; load {load:.1f}")


if __name__ == "__main__":
    main()

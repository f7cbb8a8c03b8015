"""Build LayeredPalpation-v0's shipped policy: a scripted raster-and-threshold expert, chosen by a
small search on training seeds and written as an exact ``surgsim-mlp-v1`` network (numpy only).

The expert presses a grid of ``nx x ny`` sites over the patch at full depth in boustrophedon
order. The observation (last press x, y, depth, force) is its only memory: the site it pressed
tells it which site comes next. If the force at a site exceeds ``ratio`` x that site's force on
the nodule-free wall (measured here once: the wall is the same every episode, only the nodule
moves), it presses the same site again and commits there; after the last site it commits at the
patch centre. The search tries a few grids and ratios on training seeds 0..N-1 (mean return) and
keeps the best; held-out evaluation is scripts/evaluate_policy.py on seeds 10001+.

The network (tanh hidden layers, identity output) computes the same function exactly on the
observations the policy produces: layer 1 are steep steps of x and y at the midpoints between
sites, a "pressed" flag (depth > max_depth / 2) and the force through tanh; layer 2 the one-hot
site (x cell AND y cell AND pressed) and a start flag; layer 3 per site "commit" (force above its
threshold) and "move on" (below); the output sums each unit's action. The script checks the
network against the expert on every observation of the training rollouts.

    python scripts/make_layered_policy.py --out surgsim_envs/policies/layered_palpation_v0.npz
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

#: steepness of the site and flag steps (tanh(10) = 1 - 4e-9 at the sites)
K = 20.0
#: steepness of the force threshold in the transformed force (a band of ~1e-5 N around it)
K_FORCE = 1e5
#: force gain of the first layer (tanh(G_FORCE f) is monotone; forces here are < 3 N)
G_FORCE = 0.5


def sites(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """Site coordinates in action units (cell centres of an nx x ny grid) and the boustrophedon order."""
    ax = (np.arange(nx) + 0.5) / nx * 2 - 1
    ay = (np.arange(ny) + 0.5) / ny * 2 - 1
    order = [(i, j) for j in range(ny) for i in (range(nx) if j % 2 == 0 else range(nx - 1, -1, -1))]
    return ax, ay, order


def baselines(env, ax, ay) -> np.ndarray:
    """(ny, nx) N: the force at full depth at each site of the nodule-free wall."""
    cfg = env.config
    env.reset(seed=0)
    env.tissue.scale_material("young", 1.0)
    out = np.zeros((len(ay), len(ax)))
    for j, y in enumerate(ay):
        for i, x in enumerate(ax):
            env.wall.press((x * 0.5 * cfg.size[0], y * 0.5 * cfg.size[1], env.z_top + cfg.probe_radius - cfg.max_depth))
            out[j, i] = float(env.probe.force()[2])
    return out


class Expert:
    """The scripted policy (module docstring); ``__call__(obs) -> action`` (4,) float32."""

    def __init__(self, env, nx: int, ny: int, ratio: float, base: np.ndarray):
        cfg = env.config
        self.ax, self.ay, self.order = sites(nx, ny)
        self.half = np.array([0.5 * cfg.size[0], 0.5 * cfg.size[1]])
        self.max_depth = cfg.max_depth
        self.threshold = ratio * base

    def __call__(self, obs) -> np.ndarray:
        x, y, d, f = (float(v) for v in obs)
        if d <= 0.5 * self.max_depth:      # no press yet: the first site
            i, j = self.order[0]
            return np.array([self.ax[i], self.ay[j], 1.0, -1.0], dtype=np.float32)
        i = int(np.argmin(np.abs(self.ax - x / self.half[0])))
        j = int(np.argmin(np.abs(self.ay - y / self.half[1])))
        if f > self.threshold[j, i]:
            return np.array([self.ax[i], self.ay[j], 1.0, 1.0], dtype=np.float32)
        k = self.order.index((i, j))
        if k == len(self.order) - 1:
            return np.array([0.0, 0.0, 1.0, 1.0], dtype=np.float32)
        i, j = self.order[k + 1]
        return np.array([self.ax[i], self.ay[j], 1.0, -1.0], dtype=np.float32)


def compile_network(expert: Expert):
    """The expert as (weights, biases) of a tanh MLP with an identity output (module docstring)."""
    ax, ay, order = expert.ax, expert.ay, expert.order
    nx, ny = len(ax), len(ay)
    hx, hy = expert.half
    md = expert.max_depth
    # layer 1: x steps, y steps, pressed, force
    bx = 0.5 * (ax[1:] + ax[:-1]) * hx       # m
    by = 0.5 * (ay[1:] + ay[:-1]) * hy
    sx, sy = (ax[1] - ax[0]) * hx / 2 if nx > 1 else hx, (ay[1] - ay[0]) * hy / 2 if ny > 1 else hy
    n1 = (nx - 1) + (ny - 1) + 2
    W0, b0 = np.zeros((4, n1)), np.zeros(n1)
    for k, b in enumerate(bx):
        W0[0, k], b0[k] = K / sx, -K * b / sx
    for k, b in enumerate(by):
        W0[1, nx - 1 + k], b0[nx - 1 + k] = K / sy, -K * b / sy
    ip, i_f = n1 - 2, n1 - 1
    W0[2, ip], b0[ip] = K / (0.5 * md), -K
    W0[3, i_f] = G_FORCE
    # layer 2: one-hot sites, start flag, force again
    sites_ij = [(i, j) for j in range(ny) for i in range(nx)]
    n2 = len(sites_ij) + 2
    W1, b1 = np.zeros((n1, n2)), np.zeros(n2)
    for s, (i, j) in enumerate(sites_ij):
        # cell indicator in x: (S_{i-1} - S_i) / 2 with S_{-1} = +1, S_{nx-1} = -1 (0 or 1 at the sites)
        bias = 0.0
        if i == 0:
            bias += 0.5
        else:
            W1[i - 1, s] += 0.5
        if i == nx - 1:
            bias += 0.5
        else:
            W1[i, s] -= 0.5
        if j == 0:
            bias += 0.5
        else:
            W1[nx - 1 + j - 1, s] += 0.5
        if j == ny - 1:
            bias += 0.5
        else:
            W1[nx - 1 + j, s] -= 0.5
        W1[ip, s] += 0.5            # pressed in {0, 1}
        bias += 0.5
        W1[:, s] *= K
        b1[s] = K * (bias - 2.5)
    i_start, i_force2 = n2 - 2, n2 - 1
    W1[ip, i_start] = -K
    W1[i_f, i_force2] = 1.0
    # layer 3: per site commit / move on; start passthrough
    n3 = 2 * len(sites_ij) + 1
    W2, b2 = np.zeros((n2, n3)), np.zeros(n3)
    for s, (i, j) in enumerate(sites_ij):
        phi = np.tanh(np.tanh(G_FORCE * expert.threshold[j, i]))
        # commit: K_FORCE (F2 - phi) when at the site, far below 0 elsewhere
        W2[i_force2, 2 * s], W2[s, 2 * s], b2[2 * s] = K_FORCE, K_FORCE, -K_FORCE * (phi + 1.0)
        W2[i_force2, 2 * s + 1], W2[s, 2 * s + 1], b2[2 * s + 1] = -K_FORCE, K_FORCE, K_FORCE * (phi - 1.0)
    W2[i_start, n3 - 1] = K
    # output: each active unit's action (a unit u in {-1, 1} contributes (u + 1) / 2 * value)
    W3, b3 = np.zeros((n3, 4)), np.zeros(4)

    def add(unit, value):
        W3[unit] += 0.5 * value
        b3[:] += 0.5 * value

    for s, (i, j) in enumerate(sites_ij):
        add(2 * s, np.array([ax[i], ay[j], 0.0, 2.0]))
        k = order.index((i, j))
        nxt = np.array([0.0, 0.0, 0.0, 2.0]) if k == len(order) - 1 else \
            np.array([ax[order[k + 1][0]], ay[order[k + 1][1]], 0.0, 0.0])
        add(2 * s + 1, nxt)
    i0, j0 = order[0]
    add(n3 - 1, np.array([ax[i0], ay[j0], 0.0, 0.0]))
    b3 += np.array([0.0, 0.0, 1.0, -1.0])
    return [W0, W1, W2, W3], [b0, b1, b2, b3]


def rollouts(env, policy, seeds, record=None):
    """Mean return and successes of ``policy`` over ``seeds``; observations appended to ``record``."""
    total, wins = [], 0
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        ret = 0.0
        while True:
            if record is not None:
                record.append(obs.copy())
            obs, r, term, trunc, info = env.step(policy(obs))
            ret += r
            if term or trunc:
                break
        total.append(ret)
        wins += bool(info["success"])
    return float(np.mean(total)), wins


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", default="surgsim_envs/policies/layered_palpation_v0.npz")
    p.add_argument("--train-seeds", type=int, default=30, help="training seeds 0..N-1 for the search")
    p.add_argument("--grids", default="4x3,5x3,6x4", help="comma separated NXxNY grids to try")
    p.add_argument("--ratios", default="1.15,1.2,1.25,1.3,1.4", help="comma separated force ratios to try")
    args = p.parse_args(argv)
    import gymnasium as gym

    import surgsim_envs  # noqa: F401
    from surgsim_envs.policies.npz_policy import NpzPolicy

    env = gym.make("SurgSim/LayeredPalpation-v0").unwrapped
    seeds = range(args.train_seeds)
    results, best = [], None
    for grid in args.grids.split(","):
        nx, ny = (int(v) for v in grid.lower().split("x"))
        ax, ay, _ = sites(nx, ny)
        base = baselines(env, ax, ay)
        for ratio in (float(r) for r in args.ratios.split(",")):
            expert = Expert(env, nx, ny, ratio, base)
            mean, wins = rollouts(env, expert, seeds)
            results.append({"grid": grid, "ratio": ratio, "train_mean_return": round(mean, 4), "train_successes": wins})
            print(json.dumps(results[-1]), file=sys.stderr)
            if best is None or mean > best[0]:
                best = (mean, expert, grid, ratio)
    _, expert, grid, ratio = best
    weights, biases = compile_network(expert)
    policy = NpzPolicy(weights, biases, activation="tanh", output_activation="identity",
                       action_low=-np.ones(4), action_high=np.ones(4))
    seen = []
    rollouts(env, expert, seeds, record=seen)
    diff = max(float(np.abs(policy(o) - expert(o)).max()) for o in seen)
    if diff > 1e-6:
        raise SystemExit(f"the network differs from the expert by {diff} on a training observation")
    policy.save(args.out)
    print(json.dumps({"chosen": {"grid": grid, "ratio": ratio}, "search": results, "network_vs_expert_max_diff": diff,
                      "out": args.out}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

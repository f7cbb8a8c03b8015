"""A minimal PPO in torch on the batched Palpation-v0 env; saves a learning curve (CSV + PNG).

    python scripts/train_batched.py --device cuda --worlds 4096 --iterations 200 --out runs/ppo_palpation
    python scripts/train_batched.py --device cpu --worlds 8 --iterations 10 --out /tmp/ppo_cpu

The env is ``gym.make_vec("SurgSim/Palpation-v0", num_envs=W, vectorization_mode="vector_entry_point",
device=..., device_outputs=True)``: observations, rewards and the episode flags come back as Warp arrays
on the device, which ``wp.to_torch`` hands to torch without copies (``--outputs host``: numpy arrays,
shared by ``torch.from_numpy`` on the CPU and copied to the GPU once per step; the same numbers). The
actions still go to the env as a numpy array (one device-to-host copy of (W, 4) numbers per step).

Why a hand-written PPO rather than an RL library: the batched env already is the vector env, so a
library's own env wrappers and worker processes would add copies and nothing else; ~150 lines of
clipped-surrogate PPO with GAE keep every array in one process and on one device.

Where torch (or CUDA, for ``--device cuda``, or the ``[batch]`` extra) is missing, the script says so
and exits 0, so a CI job without them does not fail on it.
"""

from __future__ import annotations

import argparse
import csv
import importlib
import os
import sys
import time


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description="Minimal PPO on the batched Palpation-v0 env (learning curve to --out).")
    p.add_argument("--device", choices=("cpu", "cuda"), default="cuda",
                   help="Warp and torch device (default cuda; cpu works everywhere, slowly)")
    p.add_argument("--worlds", type=int, default=4096, help="batched worlds W (default 4096)")
    p.add_argument("--iterations", type=int, default=200, help="PPO iterations (rollout + update), default 200")
    p.add_argument("--seed", type=int, default=0, help="seed of the env worlds and of torch (default 0)")
    p.add_argument("--rollout-steps", type=int, default=64, help="env steps per world per iteration (default 64)")
    p.add_argument("--episode-seconds", type=float, default=1.0,
                   help="Palpation-v0 episode length in s (default 1.0: 100 control steps)")
    p.add_argument("--lr", type=float, default=3e-4, help="Adam learning rate (default 3e-4)")
    p.add_argument("--epochs", type=int, default=4, help="update epochs per iteration (default 4)")
    p.add_argument("--minibatches", type=int, default=4, help="minibatches per epoch (default 4)")
    p.add_argument("--outputs", choices=("device", "host"), default="device",
                   help="device (default): the env's outputs as Warp arrays, taken by torch without copies; host: "
                   "numpy arrays (the same numbers)")
    p.add_argument("--out", default="runs/train_batched", help="output folder for curve.csv and curve.png")
    args = p.parse_args(argv)
    for name in ("worlds", "iterations", "rollout_steps", "epochs", "minibatches"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')}={getattr(args, name)} must be >= 1")
    if not args.episode_seconds > 0:
        p.error(f"--episode-seconds={args.episode_seconds} must be > 0")
    return args


def missing_dependency(device: str) -> str | None:
    """A sentence saying what is missing for a run on ``device``, or None."""
    try:
        torch = importlib.import_module("torch")
    except ImportError:
        return "torch is not installed: pip install torch (this script trains with it); nothing to do."
    if device == "cuda" and not torch.cuda.is_available():
        return "--device cuda but torch sees no CUDA GPU: run with --device cpu, or on a machine with a GPU."
    from surgsim_envs.batch.backend import available, cuda_available

    if not available():
        return "the batched backend needs the [batch] extra (pip install 'surgsim_envs[batch]'); nothing to do."
    if device == "cuda" and not cuda_available():
        return "--device cuda but Warp sees no CUDA device: run with --device cpu, or on a machine with a GPU."
    return None


def train(args) -> list[dict]:
    import gymnasium as gym
    import numpy as np
    import torch
    from torch import nn
    from tqdm import trange

    import surgsim_envs  # noqa: F401  (registers the SurgSim/ tasks)
    from surgsim_envs.envs.palpation import PalpationConfig

    torch.manual_seed(args.seed)
    dev = torch.device(args.device)
    env = gym.make_vec("SurgSim/Palpation-v0", num_envs=args.worlds, vectorization_mode="vector_entry_point",
                       device=args.device, episode_seconds=args.episode_seconds, device_outputs=args.outputs == "device",
                       # a report may come no earlier than min_report_seconds: never later than a short episode's end
                       min_report_seconds=min(PalpationConfig().min_report_seconds, args.episode_seconds),
                       max_episode_steps=round(args.episode_seconds * PalpationConfig().control_hz))
    n_obs = env.single_observation_space.shape[0]
    n_act = env.single_action_space.shape[0]

    def mlp(out):
        return nn.Sequential(nn.Linear(n_obs, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh(), nn.Linear(64, out))

    actor, critic = mlp(n_act).to(dev), mlp(1).to(dev)
    log_std = nn.Parameter(torch.full((n_act,), -0.5, device=dev))
    opt = torch.optim.Adam([*actor.parameters(), *critic.parameters(), log_std], lr=args.lr)
    # running observation normalisation (forces in N, positions in m and counters differ by orders of magnitude)
    mean, var, count = torch.zeros(n_obs, device=dev), torch.ones(n_obs, device=dev), 1e-4

    def to_dev(x):
        """A float32 tensor on ``dev`` of an env output; its own storage (the env reuses its output buffers)."""
        if args.outputs == "device":
            import warp as wp

            return wp.to_torch(x).to(torch.float32).clone()      # a copy on the device, never through the host
        return torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32)).to(dev)

    T, W, gamma, lam, clip = args.rollout_steps, args.worlds, 0.99, 0.95, 0.2
    obs_np, _ = env.reset(seed=args.seed)
    obs = to_dev(obs_np)
    ep_ret = torch.zeros(W, device=dev)
    curve = []
    t0 = time.perf_counter()
    bar = trange(args.iterations, desc="PPO", unit="it")
    for it in bar:
        buf_o, buf_a, buf_lp, buf_r, buf_d, buf_v = [], [], [], [], [], []
        finished = []
        for _ in range(T):
            batch_mean, batch_var = obs.mean(0), obs.var(0, unbiased=False)
            delta, total = batch_mean - mean, count + W
            mean = mean + delta * W / total
            var = (var * count + batch_var * W + delta ** 2 * count * W / total) / total
            count = total
            o = ((obs - mean) / torch.sqrt(var + 1e-8)).clamp(-10, 10)
            with torch.no_grad():
                dist = torch.distributions.Normal(actor(o), log_std.exp())
                a = dist.sample()
                lp = dist.log_prob(a).sum(-1)
                v = critic(o).squeeze(-1)
            obs_np, r, te, tr, _ = env.step(a.clamp(-1, 1).cpu().numpy())
            r_t, done = to_dev(r), torch.maximum(to_dev(te), to_dev(tr))
            ep_ret += r_t
            finished += ep_ret[done > 0].tolist()
            ep_ret = ep_ret * (1 - done)
            for buf, x in zip((buf_o, buf_a, buf_lp, buf_r, buf_d, buf_v), (o, a, lp, r_t, done, v)):
                buf.append(x)
            obs = to_dev(obs_np)
        with torch.no_grad():
            o = ((obs - mean) / torch.sqrt(var + 1e-8)).clamp(-10, 10)
            next_v = critic(o).squeeze(-1)
        adv = torch.zeros(T, W, device=dev)
        gae = torch.zeros(W, device=dev)
        for t in reversed(range(T)):
            nv = next_v if t == T - 1 else buf_v[t + 1]
            nonterminal = 1 - buf_d[t]
            delta = buf_r[t] + gamma * nv * nonterminal - buf_v[t]
            gae = delta + gamma * lam * nonterminal * gae
            adv[t] = gae
        ret = adv + torch.stack(buf_v)
        O, A, LP = torch.stack(buf_o).flatten(0, 1), torch.stack(buf_a).flatten(0, 1), torch.stack(buf_lp).flatten()
        ADV, RET = adv.flatten(), ret.flatten()
        ADV = (ADV - ADV.mean()) / (ADV.std() + 1e-8)
        n = O.shape[0]
        size = max(1, n // args.minibatches)
        for _ in range(args.epochs):
            perm = torch.randperm(n, device=dev)
            for start in range(0, n, size):
                idx = perm[start:start + size]
                dist = torch.distributions.Normal(actor(O[idx]), log_std.exp())
                ratio = (dist.log_prob(A[idx]).sum(-1) - LP[idx]).exp()
                pg = -torch.min(ratio * ADV[idx], ratio.clamp(1 - clip, 1 + clip) * ADV[idx]).mean()
                vf = ((critic(O[idx]).squeeze(-1) - RET[idx]) ** 2).mean()
                loss = pg + 0.5 * vf - 1e-3 * dist.entropy().sum(-1).mean()
                opt.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_([*actor.parameters(), *critic.parameters(), log_std], 0.5)
                opt.step()
        row = {"iteration": it + 1, "env_steps": (it + 1) * T * W, "seconds": round(time.perf_counter() - t0, 3),
               "mean_step_reward": float(torch.stack(buf_r).mean()),
               "episodes": len(finished),
               "mean_episode_return": float(np.mean(finished)) if finished else float("nan")}
        curve.append(row)
        bar.set_postfix(step_reward=f"{row['mean_step_reward']:.4f}", ep_return=f"{row['mean_episode_return']:.3f}")
    env.close()
    return curve


def save(curve: list[dict], out: str) -> None:
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "curve.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(curve[0]))
        w.writeheader()
        w.writerows(curve)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is missing: wrote curve.csv only")
        return
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot([r["env_steps"] for r in curve], [r["mean_step_reward"] for r in curve], marker="o")
    ax.set_xlabel("env steps (all worlds)")
    ax.set_ylabel("mean reward per env step")
    ax.set_title("PPO on batched Palpation-v0")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "curve.png"), dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    args = parse_args(argv)
    why = missing_dependency(args.device)
    if why:
        print(f"train_batched: {why}")
        return 0
    curve = train(args)
    save(curve, args.out)
    print(f"wrote {os.path.join(args.out, 'curve.csv')} and curve.png; mean reward per step "
          f"{curve[0]['mean_step_reward']:.4f} (iteration 1) -> {curve[-1]['mean_step_reward']:.4f} "
          f"(iteration {len(curve)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Behaviour cloning from recorded demonstrations: Grasp-v0 from 50 scripted-expert episodes.

    python scripts/train_bc.py [--episodes 50] [--eval-seeds 10000:10020] [--out surgsim-out/bc]

1. records ``--episodes`` expert episodes as a Minari dataset (``surgsim record``, seeds 0..n-1)
   with Gaussian noise on the applied actions (``--noise``, default 0.3), so the data shows how
   the expert acts in states off its own path; the labels are its clean actions
   (``infos["source_action"]``): behaviour cloning without it fails under the covariate shift;
2. fits a small MLP (numpy, tanh hidden layers, Adam, mean-squared error on the actions, inputs
   standardised) to the (observation, action) pairs;
3. evaluates the cloned policy, uniform random actions and the expert itself on held-out seeds
   and writes ``bc_learning_curve.png`` (training loss), ``bc_policy.npz`` (weights and input
   scaling) and ``bc_eval.json`` (return and success per seed, both policies).

Needs the [data] extra (Minari). numpy only: no torch.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def _init(sizes, rng):
    return [(rng.normal(0, 1 / np.sqrt(a), (a, b)), np.zeros(b)) for a, b in zip(sizes, sizes[1:])]


def _forward(params, x):
    acts = [x]
    for i, (w, b) in enumerate(params):
        x = x @ w + b
        if i < len(params) - 1:
            x = np.tanh(x)
        acts.append(x)
    return acts


def fit(obs, act, hidden=(64, 64), iters=3000, batch=256, lr=3e-3, seed=0):
    """MLP weights (list of (W, b)), input mean and scale, and the loss per iteration."""
    rng = np.random.default_rng(seed)
    mean, std = obs.mean(axis=0), obs.std(axis=0)
    # SI entries that barely vary in the demonstrations (the wrist's y) must not turn a 1 mm drift
    # in a rollout into a huge input: scales are floored at 1e-3 (1 mm, 1 mN)
    scale = np.maximum(std, 1e-3)
    x_all = (obs - mean) / scale
    params = _init([obs.shape[1], *hidden, act.shape[1]], rng)
    m = [(np.zeros_like(w), np.zeros_like(b)) for w, b in params]
    v = [(np.zeros_like(w), np.zeros_like(b)) for w, b in params]
    losses = []
    for t in range(1, iters + 1):
        idx = rng.integers(0, len(x_all), batch)
        acts = _forward(params, x_all[idx])
        err = acts[-1] - act[idx]
        losses.append(float(np.mean(err ** 2)))
        grad = 2 * err / err.size
        for i in range(len(params) - 1, -1, -1):
            w, b = params[i]
            gw, gb = acts[i].T @ grad, grad.sum(axis=0)
            if i:
                grad = (grad @ w.T) * (1 - acts[i] ** 2)
            (mw, mb), (vw, vb) = m[i], v[i]
            mw, mb = 0.9 * mw + 0.1 * gw, 0.9 * mb + 0.1 * gb
            vw, vb = 0.999 * vw + 0.001 * gw ** 2, 0.999 * vb + 0.001 * gb ** 2
            m[i], v[i] = (mw, mb), (vw, vb)
            c1, c2 = 1 - 0.9 ** t, 1 - 0.999 ** t
            params[i] = (w - lr * (mw / c1) / (np.sqrt(vw / c2) + 1e-8), b - lr * (mb / c1) / (np.sqrt(vb / c2) + 1e-8))
    return params, mean, scale, losses


def evaluate(task, policy_fn, seeds):
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401

    env = gym.make(task)
    out = []
    for s in seeds:
        obs, _ = env.reset(seed=s)
        total, done, info = 0.0, False, {}
        while not done:
            obs, r, term, trunc, info = env.step(policy_fn(env, obs))
            total += float(r)
            done = term or trunc
        out.append({"seed": s, "return": total, "success": bool(info.get("is_success", info.get("success", False)))})
    env.close()
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--task", default="SurgSim/Grasp-v0")
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--eval-seeds", default="10000:10020", help="held-out seeds A:B (default 10000:10020)")
    ap.add_argument("--iters", type=int, default=3000)
    ap.add_argument("--noise", type=float, default=0.3,
                    help="action noise while recording (the expert's clean actions are the labels; default 0.3)")
    ap.add_argument("--out", default="surgsim-out/bc")
    args = ap.parse_args(argv)
    from surgsim_envs.errors import ConfigError
    from surgsim_envs.integrations.minari_datasets import record

    try:
        a, b = (int(v) for v in args.eval_seeds.split(":"))
    except ValueError:
        raise ConfigError(f"--eval-seeds {args.eval_seeds!r} must be A:B with integers A < B") from None
    if not 0 <= a < b or a < args.episodes:
        raise ConfigError(f"--eval-seeds {args.eval_seeds!r} must be held out: A >= --episodes ({args.episodes}) and A < B")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        dataset = record(args.task, "expert", episodes=args.episodes, seed=0, out=out / "data", noise=args.noise)
    except ConfigError as exc:
        if "already exists" not in str(exc):
            raise
        import os

        import minari

        os.environ["MINARI_DATASETS_PATH"] = str((out / "data").resolve())
        short = args.task.split("/")[1].lower().replace("-v0", "")
        dataset = minari.load_dataset(f"surgsim/{short}/expert-v0")   # recorded by an earlier run
    obs = np.concatenate([ep.observations[:-1] for ep in dataset.iterate_episodes()]).astype(np.float64)
    # labels: the expert's own action at each observation (with --noise the applied one was perturbed)
    act = np.concatenate([ep.infos["source_action"][:-1] for ep in dataset.iterate_episodes()]).astype(np.float64)
    print(f"{len(obs)} (observation, action) pairs from {dataset.total_episodes} expert episodes")
    params, mean, scale, losses = fit(obs, act, iters=args.iters)
    np.savez(out / "bc_policy.npz", mean=mean, scale=scale, fixed=np.ptp(act, axis=0) == 0.0, fixed_value=act[0],
             **{f"w{i}": w for i, (w, _) in enumerate(params)}, **{f"b{i}": b for i, (_, b) in enumerate(params)})

    # an action entry the expert never varies (Grasp's jaw command) is that constant, not a fit that
    # drifts from it as the rollout leaves the demonstrated states
    fixed = np.ptp(act, axis=0) == 0.0

    def bc(env, o):
        y = _forward(params, (np.asarray(o, dtype=np.float64) - mean) / scale)[-1]
        y = np.where(fixed, act[0], y)
        return np.clip(y, -1, 1).astype(np.float32)

    seeds = range(a, b)
    from surgsim_envs.integrations.minari_datasets import action_source

    expert_factory, experts = action_source(args.task, "expert"), {}

    def expert(env, o):   # a fresh scripted expert per episode (it keeps a step counter)
        if env.unwrapped.steps == 0 or id(env) not in experts:
            experts[id(env)] = expert_factory(env)
        return experts[id(env)](o)

    result = {"bc": evaluate(args.task, bc, seeds),
              "random": evaluate(args.task, lambda env, o: env.action_space.sample(), seeds),
              "expert": evaluate(args.task, expert, seeds)}
    (out / "bc_eval.json").write_text(json.dumps(result, indent=1))
    for name, rows in result.items():
        r = np.array([x["return"] for x in rows])
        print(f"{name:>6}: return {r.mean():.2f} +- {r.std():.2f}, success {sum(x['success'] for x in rows)}/{len(rows)} "
              f"on held-out seeds {a}..{b - 1}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(np.convolve(losses, np.ones(50) / 50, mode="valid"))
    ax.set_xlabel("iteration (batch of 256)")
    ax.set_ylabel("action MSE (50-iteration mean)")
    ax.set_yscale("log")
    ax.set_title(f"behaviour cloning, {args.task}, {args.episodes} expert episodes")
    fig.tight_layout()
    fig.savefig(out / "bc_learning_curve.png", dpi=110)
    print(f"wrote {out / 'bc_policy.npz'}, {out / 'bc_eval.json'}, {out / 'bc_learning_curve.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

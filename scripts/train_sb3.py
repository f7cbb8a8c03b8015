"""Train PPO or SAC (stable-baselines3) on a SurgSim task; save the model, a learning curve and a
comparison against a random policy.

    pip install -e .[train]
    python scripts/train_sb3.py --task SurgSim/Palpation-v0 --algo ppo --steps 50000 --n-envs 2 --seed 0

Writes to ``--out`` (default ./surgsim-train/<task>-<algo>-<seed>/): ``model.zip``,
``vecnormalize.pkl``, ``learning_curve.png``, ``eval.json`` (mean return and success rate of the
trained policy and of a random policy over ``--eval-episodes`` episodes).
Observations are normalised with VecNormalize (the env itself reports SI units). Envs are made
with ``on_unstable="terminate"`` (``--on-unstable``): a diverging tissue ends the episode
(counted in ``eval.json``) instead of killing a long run.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path

# DESIGN.md: import triton before anything creates a MuJoCo renderer when torch is present
if importlib.util.find_spec("triton") is not None:
    import triton  # noqa: F401

import numpy as np


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--task", default="SurgSim/Palpation-v0")
    p.add_argument("--algo", choices=["ppo", "sac"], default="ppo")
    p.add_argument("--steps", type=int, default=50_000, help="environment steps in total")
    p.add_argument("--n-envs", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--eval-episodes", type=int, default=10)
    p.add_argument("--gamma", type=float, default=0.99, help="discount factor (SB3 default 0.99)")
    p.add_argument("--vec", choices=["sync", "async"], default="async", help="vector env mode (n-envs > 1)")
    p.add_argument("--out", default=None)
    p.add_argument("--on-unstable", choices=["terminate", "raise"], default="terminate",
                   help="a diverging tissue ends the episode (info['unstable']) instead of killing the run")
    args = p.parse_args(argv)
    if args.steps <= 0 or args.n_envs <= 0 or args.eval_episodes <= 0:
        p.error("--steps, --n-envs and --eval-episodes must be positive")
    if not 0.0 < args.gamma <= 1.0:
        p.error(f"--gamma must lie in (0, 1], got {args.gamma}")
    return args


def evaluate(policy, task, episodes, seed, env_kwargs=None):
    """Mean return, success rate and unstable episodes of ``policy(obs) -> action`` over ``episodes``."""
    import gymnasium as gym

    env = gym.make(task, **(env_kwargs or {}))
    returns, success, unstable = [], [], 0
    for k in range(episodes):
        obs, info = env.reset(seed=seed + 10_000 + k)
        total = 0.0
        while True:
            obs, r, term, trunc, info = env.step(policy(obs))
            total += r
            if term or trunc:
                break
        returns.append(total)
        success.append(bool(info.get("success", False)))
        unstable += bool(info.get("unstable", False))
    env.close()
    return {"mean_return": float(np.mean(returns)), "std_return": float(np.std(returns)),
            "success_rate": float(np.mean(success)), "episodes": episodes, "unstable_episodes": unstable}


def main(argv=None) -> int:
    args = parse(argv)
    try:
        import stable_baselines3 as sb3
        from stable_baselines3.common.callbacks import BaseCallback
        from stable_baselines3.common.env_util import make_vec_env
        from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize
    except ImportError:
        print("train_sb3.py needs stable-baselines3: pip install -e .[train]", file=sys.stderr)
        return 2
    import gymnasium as gym

    import torch

    import surgsim_envs  # noqa: F401
    from tqdm import tqdm

    torch.set_num_threads(1)  # small MLPs: extra threads only fight the simulation for the cores

    if args.task not in gym.registry:
        print(f"unknown task {args.task!r}; SurgSim tasks: {[k for k in gym.registry if k.startswith('SurgSim/')]}",
              file=sys.stderr)
        return 2
    out = Path(args.out or f"surgsim-train/{args.task.split('/')[-1]}-{args.algo}-{args.seed}")
    out.mkdir(parents=True, exist_ok=True)
    vec_cls = SubprocVecEnv if (args.vec == "async" and args.n_envs > 1) else DummyVecEnv
    # "module:id" makes worker processes (forkserver/spawn) import surgsim_envs, which registers the tasks
    env_kwargs = {"on_unstable": args.on_unstable}
    venv = make_vec_env(f"surgsim_envs:{args.task}", n_envs=args.n_envs, seed=args.seed, vec_env_cls=vec_cls,
                        env_kwargs=env_kwargs)
    venv = VecNormalize(venv, norm_obs=True, norm_reward=True)
    if args.algo == "ppo":
        model = sb3.PPO("MlpPolicy", venv, seed=args.seed, n_steps=512, batch_size=256, gamma=args.gamma, verbose=0,
                         device="cpu")
    else:
        model = sb3.SAC("MlpPolicy", venv, seed=args.seed, verbose=0, device="cpu", learning_starts=1000, gamma=args.gamma)

    curve = []
    unstable = [0]

    class Progress(BaseCallback):
        def _on_training_start(self):
            self.bar = tqdm(total=args.steps, unit="step", desc=f"{args.algo} {args.task}")

        def _on_step(self):
            self.bar.update(self.training_env.num_envs)
            for info in self.locals.get("infos", []):
                ep = info.get("episode")
                unstable[0] += bool(info.get("unstable", False))
                if ep:
                    curve.append((self.num_timesteps, float(ep["r"]), bool(info.get("success", False))))
            return True

        def _on_training_end(self):
            self.bar.close()

    model.learn(total_timesteps=args.steps, callback=Progress())
    model.save(out / "model.zip")
    venv.save(str(out / "vecnormalize.pkl"))
    venv.training = False
    venv.norm_reward = False

    def trained(obs):
        a, _ = model.predict(venv.normalize_obs(obs[None]), deterministic=True)
        return a[0]

    space = gym.make(args.task).action_space
    space.seed(args.seed)
    result = {"task": args.task, "algo": args.algo, "steps": args.steps, "n_envs": args.n_envs, "seed": args.seed,
              "gamma": args.gamma,
              "unstable_training_episodes": unstable[0],
              "trained": evaluate(trained, args.task, args.eval_episodes, args.seed, env_kwargs),
              "random": evaluate(lambda obs: space.sample(), args.task, args.eval_episodes, args.seed, env_kwargs)}
    with open(out / "eval.json", "w") as fh:
        json.dump(result, fh, indent=2)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    if curve:
        t, r, _ = zip(*curve)
        ax.plot(t, r, ".", alpha=0.3, label="episode return")
        k = max(1, len(r) // 20)
        ax.plot(t[k - 1:], np.convolve(r, np.ones(k) / k, mode="valid"), label=f"moving mean ({k})")
    ax.axhline(result["random"]["mean_return"], color="grey", ls="--", label="random policy")
    ax.set_xlabel("environment steps")
    ax.set_ylabel("episode return")
    ax.set_title(f"{args.algo.upper()} on {args.task}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "learning_curve.png", dpi=100)
    print(json.dumps(result, indent=2))
    print(f"wrote {out}/model.zip, learning_curve.png, eval.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

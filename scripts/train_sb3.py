"""Train PPO or SAC (stable-baselines3) on a SurgSim task; save the model, a learning curve and a
comparison against a random policy; optionally export the policy as a numpy ``.npz`` MLP
(``--export-npz``, format of surgsim_envs.policies.npz_policy, checked to give SB3's actions).

    pip install -e .[train]
    python scripts/train_sb3.py --task SurgSim/Palpation-v0 --algo ppo --steps 50000 --n-envs 2 --seed 0
    python scripts/train_sb3.py --task SurgSim/PalpationPress-v0 --algo sac --steps 6000 --n-envs 1 \
        --export-npz surgsim_envs/policies/palpation_press_v0.npz

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
    p.add_argument("--vec", choices=["sync", "async", "shared"], default="async",
                   help="vector env (n-envs > 1): sync = SB3 DummyVecEnv, async = SubprocVecEnv, shared = "
                        "surgsim_envs.integrations.sb3 (shared-memory workers, less overhead per step)")
    p.add_argument("--out", default=None)
    p.add_argument("--on-unstable", choices=["terminate", "raise"], default="terminate",
                   help="a diverging tissue ends the episode (info['unstable']) instead of killing the run")
    p.add_argument("--export-npz", default=None, help="also write the policy as a numpy .npz MLP here "
                   "(surgsim_envs.policies.npz_policy; evaluated too)")
    p.add_argument("--export-mode", choices=["deterministic", "stochastic"], default="deterministic",
                   help="how the exported .npz acts by default (it holds the Gaussian head either way; both "
                   "modes are evaluated)")
    p.add_argument("--net-arch", default="64,64", help="hidden layer sizes, comma separated")
    p.add_argument("--learning-rate", type=float, default=3e-4)
    p.add_argument("--resume", default=None, help="continue training the model.zip + vecnormalize.pkl in this folder "
                   "(same task and algo; SAC also reloads replay_buffer.pkl when the folder has one, else starts with an "
                   "empty buffer; --train-freq and --gradient-steps apply to the resumed SAC)")
    p.add_argument("--train-freq", type=int, default=1, help="SAC: one gradient step every N env steps (CPU budget)")
    p.add_argument("--gradient-steps", type=int, default=1,
                   help="SAC: gradient steps per update (updates every --train-freq env steps); slow envs such as "
                   "PalpationPress-v0 (~0.1 s per press) afford several")
    p.add_argument("--target-success", type=float, default=0.8,
                   help="report the wall time when the success rate of the last 20 training episodes first reaches this")
    p.add_argument("--stop-at-target", action="store_true",
                   help="end training once --target-success is reached (then save, export and evaluate)")
    p.add_argument("--max-wall", type=float, default=None,
                   help="wall-time budget in s: training ends after it (then save, export and evaluate)")
    args = p.parse_args(argv)
    if args.max_wall is not None and not args.max_wall > 0:
        p.error(f"--max-wall must be a positive number of seconds, got {args.max_wall}")
    if args.gradient_steps <= 0 or args.train_freq <= 0:
        p.error("--gradient-steps and --train-freq must be positive")
    if args.steps <= 0 or args.n_envs <= 0 or args.eval_episodes <= 0:
        p.error("--steps, --n-envs and --eval-episodes must be positive")
    if not 0.0 < args.gamma <= 1.0:
        p.error(f"--gamma must lie in (0, 1], got {args.gamma}")
    return args


def evaluate(policy, task, episodes, seed, env_kwargs=None):
    """Mean return, success rate and unstable episodes of ``policy(obs) -> action`` over ``episodes``
    (reset seeds ``seed + 10000 + k``: training resets use ``seed .. seed + n_envs - 1`` and then the
    env's own generator, so these are seeds it never trained on). A policy with ``reset(seed)`` (a
    stochastic ``.npz`` policy's sampler) is reseeded with each episode's seed."""
    import gymnasium as gym

    env = gym.make(task, **(env_kwargs or {}))
    returns, success, unstable = [], [], 0
    for k in range(episodes):
        if hasattr(policy, "reset"):
            policy.reset(seed + 10_000 + k)
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
    if args.vec == "shared" and args.n_envs > 1:
        from surgsim_envs.integrations.sb3 import make_sb3_vec_env

        venv = make_sb3_vec_env(args.task, args.n_envs, seed=args.seed, env_kwargs=env_kwargs,
                                info_keys=("is_success", "success", "unstable"))
    else:
        venv = make_vec_env(f"surgsim_envs:{args.task}", n_envs=args.n_envs, seed=args.seed, vec_env_cls=vec_cls,
                            env_kwargs=env_kwargs)
    if args.resume:
        venv = VecNormalize.load(str(Path(args.resume) / "vecnormalize.pkl"), venv)
    else:
        venv = VecNormalize(venv, norm_obs=True, norm_reward=True)
    arch = [int(n) for n in args.net_arch.split(",") if n.strip()]
    steps_per_episode = gym.spec(args.task).max_episode_steps or 1000
    if args.resume:
        model = getattr(sb3, args.algo.upper()).load(str(Path(args.resume) / "model.zip"), env=venv, device="cpu")
        if args.algo == "sac":
            from stable_baselines3.common.type_aliases import TrainFreq, TrainFrequencyUnit

            model.train_freq = TrainFreq(args.train_freq, TrainFrequencyUnit.STEP)
            model.gradient_steps = args.gradient_steps
            buffer = Path(args.resume) / "replay_buffer.pkl"
            if buffer.is_file():
                model.load_replay_buffer(str(buffer))
    elif args.algo == "ppo":
        n_steps = 512 if steps_per_episode > 100 else 128
        model = sb3.PPO("MlpPolicy", venv, seed=args.seed, n_steps=n_steps, batch_size=min(256, n_steps * args.n_envs),
                         gamma=args.gamma, verbose=0, device="cpu", learning_rate=args.learning_rate,
                         policy_kwargs={"net_arch": arch})
    else:
        model = sb3.SAC("MlpPolicy", venv, seed=args.seed, verbose=0, device="cpu",
                         learning_starts=min(1000, max(100, args.steps // 10)), gamma=args.gamma,
                         learning_rate=args.learning_rate, policy_kwargs={"net_arch": arch}, train_freq=args.train_freq,
                         gradient_steps=args.gradient_steps)

    import time

    import os

    load_start = os.getloadavg()
    curve = []
    unstable = [0]
    stopped = [None]
    t0 = time.perf_counter()

    class Progress(BaseCallback):
        def _on_training_start(self):
            self.bar = tqdm(total=args.steps, unit="step", desc=f"{args.algo} {args.task}")

        def _on_step(self):
            self.bar.update(self.training_env.num_envs)
            for info in self.locals.get("infos", []):
                ep = info.get("episode")
                unstable[0] += bool(info.get("unstable", False))
                if ep:
                    curve.append((self.num_timesteps, float(ep["r"]), bool(info.get("success", False)),
                                  time.perf_counter() - t0))
                    self.bar.set_postfix(success_last20=f"{np.mean([c[2] for c in curve[-20:]]):.2f}",
                                         episodes=len(curve), refresh=False)
            if args.stop_at_target and len(curve) >= 20 and np.mean([c[2] for c in curve[-20:]]) >= args.target_success:
                stopped[0] = "target reached"
                return False
            if args.max_wall is not None and time.perf_counter() - t0 > args.max_wall:
                stopped[0] = "max wall"
                return False
            return True

        def _on_training_end(self):
            self.bar.close()

    model.learn(total_timesteps=args.steps, callback=Progress(), reset_num_timesteps=not args.resume)
    model.save(out / "model.zip")
    venv.save(str(out / "vecnormalize.pkl"))
    if args.algo == "sac":
        model.save_replay_buffer(str(out / "replay_buffer.pkl"))    # --resume continues with it
    venv.training = False
    venv.norm_reward = False

    def trained(obs):
        a, _ = model.predict(venv.normalize_obs(obs[None]), deterministic=True)
        return a[0]

    train_wall = time.perf_counter() - t0
    reach = None
    for i in range(20, len(curve) + 1):
        if np.mean([c[2] for c in curve[i - 20:i]]) >= args.target_success:
            reach = {"env_steps": curve[i - 1][0], "wall_s": round(curve[i - 1][3], 1)}
            break
    space = gym.make(args.task).action_space
    space.seed(args.seed)
    result = {"task": args.task, "algo": args.algo, "steps": args.steps, "n_envs": args.n_envs, "seed": args.seed,
              "gamma": args.gamma, "net_arch": arch, "resumed_from": args.resume,
              "train_freq": args.train_freq if args.algo == "sac" else None,
              "gradient_steps": args.gradient_steps if args.algo == "sac" else None, "learning_rate": args.learning_rate,
              "train_wall_s": round(train_wall, 1), "training_episodes": len(curve),
              "trained_steps": int(model.num_timesteps), "stopped_early": stopped[0],
              "load_average_1_5_15_min": {"start": [round(v, 2) for v in load_start],
                                          "end": [round(v, 2) for v in os.getloadavg()]},
              f"first_reached_{args.target_success:g}_success_last20": reach,
              "unstable_training_episodes": unstable[0],
              "eval_seeds": [args.seed + 10_000, args.seed + 10_000 + args.eval_episodes - 1],
              "trained": evaluate(trained, args.task, args.eval_episodes, args.seed, env_kwargs),
              "random": evaluate(lambda obs: space.sample(), args.task, args.eval_episodes, args.seed, env_kwargs)}
    if args.export_npz:
        from surgsim_envs.integrations.sb3 import check_export, sb3_to_npz

        npz = sb3_to_npz(model, venv, source=args.export_npz, mode=args.export_mode)
        sample_env = gym.make(args.task, **env_kwargs)
        obs_samples = [sample_env.reset(seed=args.seed + 20_000 + k)[0] for k in range(4)]
        o = obs_samples[-1]
        for _ in range(16):
            o, *_ = sample_env.step(space.sample())
            obs_samples.append(o)
        result["npz_max_action_difference"] = check_export(model, npz, np.array(obs_samples), venv)
        path = npz.save(args.export_npz)
        result["npz"] = {"path": str(path), "mode": args.export_mode}
        for mode in ("deterministic", "stochastic"):
            result["npz"][f"eval_{mode}"] = evaluate(npz.with_mode(mode), args.task, args.eval_episodes, args.seed,
                                                     env_kwargs)
        npz.with_mode(args.export_mode)
    with open(out / "curve.json", "w") as fh:
        json.dump([list(c) for c in curve], fh)
    with open(out / "eval.json", "w") as fh:
        json.dump(result, fh, indent=2)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    if curve:
        t, r, ok, _ = zip(*curve)
        ax.plot(t, r, ".", alpha=0.3, label="episode return")
        k = max(1, len(r) // 20)
        ax.plot(t[k - 1:], np.convolve(r, np.ones(k) / k, mode="valid"), label=f"moving mean ({k})")
        k2 = min(20, len(ok))
        ax2.plot(t[k2 - 1:], np.convolve(np.asarray(ok, float), np.ones(k2) / k2, mode="valid"),
                 label=f"training episodes (mean of {k2})")
    ax.axhline(result["random"]["mean_return"], color="grey", ls="--", label="random policy")
    ax2.axhline(result["random"]["success_rate"], color="grey", ls="--", label="random (eval seeds)")
    ax2.axhline(result["trained"]["success_rate"], color="C2", ls=":", label="trained, deterministic (eval seeds)")
    if "npz" in result:
        ax2.axhline(result["npz"]["eval_stochastic"]["success_rate"], color="C3", ls="-.",
                    label="trained, stochastic .npz (eval seeds)")
    ax.set_xlabel("environment steps")
    ax.set_ylabel("episode return")
    ax2.set_xlabel("environment steps")
    ax2.set_ylabel("success rate")
    ax2.set_ylim(-0.02, 1.02)
    ax.set_title(f"{args.algo.upper()} on {args.task}")
    ax.legend()
    ax2.legend()
    fig.tight_layout()
    fig.savefig(out / "learning_curve.png", dpi=100)
    print(json.dumps(result, indent=2))
    print(f"wrote {out}/model.zip, learning_curve.png, eval.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

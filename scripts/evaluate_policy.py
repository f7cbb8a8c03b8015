"""Evaluate a ``.npz`` policy (or the shipped one of a task) on held-out seeds, deterministic
and/or stochastic, against a uniform random policy; numpy only (no torch).

    python scripts/evaluate_policy.py --task SurgSim/PalpationPress-v0 --policy shipped --seeds 10001:10021
    python scripts/evaluate_policy.py --task SurgSim/Grasp-v0 --policy runs/grasp.npz --modes deterministic
    python scripts/evaluate_policy.py --task SurgSim/Grasp-v0 --model mass_spring_calibrated --modes deterministic

Episode k is reset with seed k and the policy's sampler with the same seed (``NpzPolicy.reset``),
so every figure is reproducible episode by episode. Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--task", required=True)
    p.add_argument("--policy", default="shipped", help="a .npz file or 'shipped' (the task's shipped policy)")
    p.add_argument("--seeds", default="10001:10021", help="reset seeds START:STOP (stop exclusive)")
    p.add_argument("--modes", default="deterministic,stochastic", help="comma separated: deterministic, stochastic")
    p.add_argument("--noise-scales", default=None,
                   help="stochastic mode: comma separated temperatures (sd x scale) to compare, e.g. 0.5,1 "
                   "(choose on validation seeds, report on others); default: the file's")
    p.add_argument("--save", default=None, help="write the policy in stochastic mode with the single --noise-scales "
                   "value to this .npz")
    p.add_argument("--no-random", action="store_true", help="skip the random-policy baseline")
    p.add_argument("--model", default=None, help="tissue model for the task (default: the task's own, e.g. "
                   "mass_spring_calibrated)")
    args = p.parse_args(argv)
    try:
        a, b = (int(v) for v in args.seeds.split(":"))
    except ValueError:
        p.error(f"--seeds must be START:STOP integers, got {args.seeds!r}")
    if b <= a:
        p.error(f"--seeds {args.seeds!r}: STOP must exceed START")
    args.seed_range = range(a, b)
    return args


def rollout(env, policy, seed: int) -> tuple[bool, float, int]:
    """(success, return, steps) of one episode reset with ``seed`` (the policy reseeded too)."""
    if hasattr(policy, "reset"):
        policy.reset(seed)
    obs, _ = env.reset(seed=seed)
    total, steps = 0.0, 0
    while True:
        obs, r, term, trunc, info = env.step(policy(obs))
        total += float(r)
        steps += 1
        if term or trunc:
            return bool(info.get("success", False)), total, steps


def summary(results) -> dict:
    ok, ret, steps = zip(*results)
    return {"success_rate": float(np.mean(ok)), "successes": int(sum(ok)), "episodes": len(ok),
            "mean_return": round(float(np.mean(ret)), 4), "std_return": round(float(np.std(ret)), 4),
            "mean_steps": round(float(np.mean(steps)), 2)}


def evaluate(task: str, policy, seeds, progress: bool = True, model: str | None = None) -> dict:
    import gymnasium as gym

    import surgsim_envs  # noqa: F401
    from tqdm import tqdm

    env = gym.make(task, **({"model": model} if model else {}))
    res = [rollout(env, policy, s) for s in tqdm(seeds, desc=task, disable=not progress, leave=False)]
    env.close()
    return summary(res)


def main(argv=None) -> int:
    args = parse(argv)
    import gymnasium as gym

    import surgsim_envs  # noqa: F401
    from surgsim_envs.errors import ConfigError
    from surgsim_envs.envs.registry import shipped_policy_path
    from surgsim_envs.policies.npz_policy import NpzPolicy

    try:
        path = shipped_policy_path(args.task) if args.policy == "shipped" else args.policy
        out = {"task": args.task, "policy": str(path), "seeds": [args.seed_range.start, args.seed_range.stop - 1],
               "model": args.model or "task default"}
        scales = [None] if not args.noise_scales else [float(v) for v in args.noise_scales.split(",")]
        for mode in [m.strip() for m in args.modes.split(",") if m.strip()]:
            for scale in (scales if mode == "stochastic" else [None]):
                key = mode if scale is None else f"{mode}_x{scale:g}"
                out[key] = evaluate(args.task, NpzPolicy.load(path, mode=mode, noise_scale=scale), args.seed_range,
                                    model=args.model)
        if args.save:
            if len(scales) != 1 or scales[0] is None:
                raise ConfigError("--save needs exactly one --noise-scales value")
            NpzPolicy.load(path, mode="stochastic", noise_scale=scales[0]).save(args.save)
            out["saved"] = args.save
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not args.no_random:
        space = gym.make(args.task).action_space

        class Random:
            def reset(self, seed):      # not space.seed(seed): that stream would replay the env's randomisation
                space.seed(int(np.random.SeedSequence([seed, 0xBA5E]).generate_state(1)[0]))

            def __call__(self, obs):
                return space.sample()

        out["random"] = evaluate(args.task, Random(), args.seed_range, model=args.model)
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

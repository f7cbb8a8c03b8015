"""Train PPO with Ray RLlib on a SurgSim task: Ray's local mode here, a Ray cluster unchanged.

    pip install 'ray[rllib]'          # the [distributed] extra
    python scripts/train_rllib.py --task SurgSim/PalpationPress-v0 --iterations 2 --local
    # on a cluster (after `ray start --head` on one node and `ray start --address=HEAD:6379` on the others):
    RAY_ADDRESS=auto python scripts/train_rllib.py --task SurgSim/PalpationPress-v0 --workers 32 --iterations 200

``--local`` starts a private one-CPU Ray on this machine and samples in the driver process (the
successor of Ray's removed ``local_mode``). Each env is created by :func:`surgsim_envs.integrations.rllib.make_creator` and seeded from its
worker and vector index (``--seed`` is the base). Without ``--local`` the script joins the cluster
named by ``RAY_ADDRESS`` (or starts a single-node Ray). Prints one line per iteration (mean episode
return) and writes ``result.json`` in ``--out``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path

# DESIGN.md: import triton before anything loads MuJoCo's GL when torch is present
if importlib.util.find_spec("triton") is not None:
    import triton  # noqa: F401


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--task", default="SurgSim/PalpationPress-v0")
    p.add_argument("--iterations", type=int, default=2)
    p.add_argument("--workers", type=int, default=0, help="remote env runners (0 = sample in the driver)")
    p.add_argument("--envs-per-worker", type=int, default=1)
    p.add_argument("--batch", type=int, default=64, help="train batch size in env steps per iteration")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--local", action="store_true", help="local run: a private 1-CPU Ray, sampling in the driver "
                   "(Ray's old local_mode, removed in recent Ray; for tests and debugging)")
    p.add_argument("--out", default="surgsim-train/rllib")
    args = p.parse_args(argv)
    if args.iterations <= 0 or args.workers < 0 or args.envs_per_worker <= 0 or args.batch <= 0:
        p.error("--iterations, --envs-per-worker and --batch must be positive, --workers >= 0")
    return args


def build_config(args):
    """The RLlib PPOConfig of ``args`` (no Ray call; works on the old and new API stacks)."""
    from ray.rllib.algorithms.ppo import PPOConfig

    cfg = (PPOConfig()
           .environment(args.task, env_config={"seed": args.seed, "on_unstable": "terminate"})
           .framework("torch")
           .debugging(seed=args.seed))
    if hasattr(cfg, "env_runners"):
        cfg = cfg.env_runners(num_env_runners=args.workers, num_envs_per_env_runner=args.envs_per_worker,
                              rollout_fragment_length="auto")
    else:  # Ray < 2.10
        cfg = cfg.rollouts(num_rollout_workers=args.workers, num_envs_per_worker=args.envs_per_worker)
    mb = min(32, args.batch)
    try:
        cfg = cfg.training(train_batch_size=args.batch, minibatch_size=mb, num_epochs=2)
    except TypeError:  # older names
        cfg = cfg.training(train_batch_size=args.batch, sgd_minibatch_size=mb, num_sgd_iter=2)
    return cfg


def main(argv=None) -> int:
    args = parse(argv)
    try:
        import ray
    except ImportError:
        print("train_rllib.py needs Ray RLlib: pip install 'ray[rllib]' (the [distributed] extra)", file=sys.stderr)
        return 2
    from surgsim_envs.integrations.rllib import register_rllib_envs

    if args.local:
        # Ray's local_mode (one process) was removed in recent Ray (RuntimeError in 2.60); the
        # equivalent here is a private single-node Ray that samples in the driver (no env runners)
        args.workers = 0
        ray.init(num_cpus=1, include_dashboard=False, ignore_reinit_error=True, log_to_driver=False)
    else:
        ray.init(ignore_reinit_error=True)       # RAY_ADDRESS=auto joins a running cluster
    register_rllib_envs([args.task])
    algo = build_config(args).build()
    history = []
    for i in range(args.iterations):
        res = algo.train()
        runners = res.get("env_runners", res)
        ret = runners.get("episode_return_mean", runners.get("episode_reward_mean"))
        history.append({"iteration": i + 1, "episode_return_mean": None if ret is None else float(ret)})
        print(f"iteration {i + 1}: mean episode return {ret}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "result.json").write_text(json.dumps({"task": args.task, "seed": args.seed, "workers": args.workers,
                                                 "history": history}, indent=2))
    algo.stop()
    ray.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

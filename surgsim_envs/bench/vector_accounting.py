"""Where the time of one :class:`~surgsim_envs.vector.SurgSimVectorEnv` step goes, per number of envs
(``surgsim bench envs --vector-accounting``): :func:`surgsim_envs.vector.accounting.account` run
alternately over env counts, one row of medians per count (the phases are listed there).
"""

from __future__ import annotations

import statistics

import numpy as np

from surgsim_envs.vector.accounting import account


def accounting_rows(env, env_counts=(2, 8), workers: int = 2, steps: int = 300, repeats: int = 3,
                    palpation: bool = False, seed: int = 0, spin_us: float = 0.0,
                    worker_spin_us: float = 0.0) -> list:
    """:func:`account` of ``env`` (a task id or a callable returning an env) for each number of
    envs, alternating in ``repeats`` rounds; medians over rounds, one row per number of envs."""
    import functools

    from surgsim_envs.bench.random_actions import random_actions
    from surgsim_envs.vector import SurgSimVectorEnv

    single = _single_action_space(env)
    rng = np.random.default_rng(seed)
    runs = {n: [] for n in env_counts}
    for _ in range(repeats):
        for n in env_counts:
            make = functools.partial(SurgSimVectorEnv, env, num_envs=n, workers=workers, timeout_s=60.0,
                                     spin_us=spin_us, worker_spin_us=worker_spin_us)
            runs[n].append(account(make, random_actions(_batched(single, n), steps, rng, palpation)))
    counts = ("num_envs", "workers")          # the same in every round: kept as ints, not medians
    return [{k: rs[0][k] if k in counts else statistics.median(r[k] for r in rs) for k in rs[0]}
            for rs in runs.values()]


def _batched(space, n):
    from gymnasium.vector.utils import batch_space

    return batch_space(space, n)


def _single_action_space(env):
    import gymnasium as gym

    e = gym.make(env) if isinstance(env, str) else env()
    try:
        return e.action_space
    finally:
        e.close()


COLUMNS = ("main_actions_us", "main_send_us", "main_wait_us", "main_absorb_us", "main_copy_us", "main_infos_us",
           "main_total_us", "worker_wake_us", "worker_env_us", "worker_pack_us", "worker_pack_per_env_us",
           "worker_signal_us", "last_reply_us", "worker_idle_us")


def print_rows(rows) -> None:
    short = [c.replace("_us", "").replace("worker_", "w_") for c in COLUMNS]
    print(f"{'what':28s} {'n':>3s} " + " ".join(f"{c:>9s}" for c in short))
    for r in rows:
        print(f"{r['what']:28s} {r['num_envs']:3d} " + " ".join(f"{r[c]:9.1f}" for c in COLUMNS))

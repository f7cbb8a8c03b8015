"""The vector env benchmark's reference and options (``surgsim bench envs --vector``): the
independent-process ceiling steps what it is asked, in as many processes, and bad env counts are
refused naming the value. Behaviour only; the figures are in docs/benchmarks.md."""

from __future__ import annotations

import functools
import os

import numpy as np
import pytest

from surgsim_envs.bench.spin_env import SpinEnv
from surgsim_envs.bench.vector_speed import IndependentProcesses, alternate, contender_names, env_counts
from surgsim_envs.errors import ConfigError


def test_independent_processes_step_in_their_own_processes():
    """Two processes, one stand-in env each: a run of n steps each takes at least n x the step time
    (every step really ran) and the rate counts both processes' steps; the pids are two others."""
    ref = IndependentProcesses(functools.partial(SpinEnv, 500.0), 2)
    try:
        assert ref.num_envs == 2
        assert len(set(ref.worker_pids)) == 2 and os.getpid() not in ref.worker_pids
        rate = ref.run(40)                        # 40 x 500 us = 20 ms per process at least
        assert 0 < rate <= 2 / 500e-6 * 1.01      # two processes at most double one env's 2,000/s
        out = alternate({"single": SpinEnv(500.0), "independent": ref}, steps=20, repeats=2)
        assert out["independent_speedup"] > 0 and out["independent_worker_cpu_us_per_env_step"] > 0
    finally:
        ref.close()
    assert all(not p.is_alive() for p in ref._procs)


def test_env_counts_and_contender_names():
    assert env_counts(2) == (2, 4, 8)
    assert env_counts(2, [8, 16]) == (8, 16)
    assert contender_names(2, [8, 16]) == ("independent", "async", "vector_n8", "vector_n16", "in_main_n8",
                                           "in_main_n16", "rollout_n16", "one_process_n16")
    with pytest.raises(ConfigError, match=r"env counts >= --workers \(2\), got \[1, 8\]"):
        env_counts(2, [1, 8])


def test_rollout_contender_counts_every_env_step():
    """The rollout contender steps num_envs x steps env steps per run (its rate is their count over the
    wall time), with "report" held at -1 on Palpation-shaped actions."""
    from surgsim_envs.bench.vector_speed import RolloutRun, UniformPolicy
    from surgsim_envs.vector import SurgSimVectorEnv

    from gymnasium import spaces

    a = UniformPolicy(spaces.Box(-1.0, 1.0, (4,), np.float32), palpation=True)(np.zeros((3, 5)))
    assert a.shape == (3, 4) and np.all(a[:, -1] == -1.0) and np.all(np.abs(a[:, :3]) <= 1.0)
    run = RolloutRun(SurgSimVectorEnv(functools.partial(SpinEnv, 200.0), 4, workers=2))
    try:
        run.reset(seed=0)
        rate = run.run(25)                      # 25 steps x 200 us = 5 ms per env, 2 envs per worker
        assert 0 < rate <= 4 / 200e-6 * 1.01
    finally:
        run.close()


def test_over_one_process_is_the_median_of_same_round_ratios():
    """Each multi-process contender with n envs over one_process_n<n> in the same round, the median over
    rounds; contenders with other env counts, and rows without the baseline, get none."""
    from surgsim_envs.bench.vector_speed import over_one_process

    rates = {"single": [1.0, 1.0, 1.0], "one_process_n4": [100.0, 200.0, 50.0],
             "vector_n4": [180.0, 340.0, 95.0], "in_main_n4": [150.0, 400.0, 60.0],
             "rollout_n4": [200.0, 300.0, 100.0], "vector_n2": [500.0, 500.0, 500.0]}
    out = over_one_process(rates, 4)
    assert set(out) == {"vector_n4_over_one_process", "in_main_n4_over_one_process", "rollout_n4_over_one_process"}
    assert out["vector_n4_over_one_process"] == pytest.approx(1.8)     # ratios 1.8, 1.7, 1.9
    assert out["in_main_n4_over_one_process"] == pytest.approx(1.5)    # 1.5, 2.0, 1.2
    assert out["rollout_n4_over_one_process"] == pytest.approx(2.0)    # 2.0, 1.5, 2.0
    assert over_one_process(rates, 8) == {}


def test_vector_accounting_rows_and_a_too_short_run():
    """The accounting of a 200 us stand-in on 2 workers: its env time per round is at least the
    block's spin time, the counts stay ints over an even number of rounds (a median would give 2.0),
    and a run no longer than the warm-up is refused naming --steps."""
    from surgsim_envs.bench.vector_accounting import accounting_rows, print_rows

    env = functools.partial(SpinEnv, 200.0)
    rows = accounting_rows(env, env_counts=(4,), workers=2, steps=30, repeats=2)
    (row,) = rows
    assert type(row["num_envs"]) is int and row["num_envs"] == 4 and row["workers"] == 2
    assert row["worker_env_us"] >= 2 * 200.0 and row["main_total_us"] >= row["worker_env_us"]
    print_rows([{"what": "stand-in", **row}])
    with pytest.raises(ConfigError, match=r"more than 20 steps \(--steps\), got 20"):
        accounting_rows(env, env_counts=(2,), workers=2, steps=20, repeats=1)

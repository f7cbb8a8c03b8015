"""surgsim bench memory: the short-memory error falls with L and vanishes for the whole history."""

from __future__ import annotations

from surgsim_envs.bench.fractional_memory import creep_error, step_cost


def test_short_memory_error_falls_with_L_and_is_zero_with_the_whole_history():
    out = creep_error([5, 50, 200], nodes=64, duration=0.2, dt=1e-3, progress=False)
    err = out["error"]
    assert err[5] > err[50] > 0.0
    assert err[200] == 0.0                 # L >= number of steps: the whole history
    assert out["full"][-1] > out["curves"][5][-1] > 0.0   # truncation stalls the creep (stiffer)


def test_step_cost_reports_wall_and_cpu_medians():
    out = step_cost([5], nodes=64, repeats=2, steps=5, warmup=2, progress=False)
    assert out["us_per_step"][5] > 0 and out["cpu_us_per_step"][5] >= 0

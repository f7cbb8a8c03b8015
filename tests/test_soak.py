"""``surgsim bench soak``: a short soak of a real task finds nothing, and the counters
count what a deliberately faulty env does."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from surgsim_envs.bench.soak import soak
from surgsim_envs.errors import ConfigError, TissueUnstableError


class _Faulty(gym.Env):
    """Step k (1-based, counted over the env's life): raises every 7th, a tissue divergence every
    13th, NaN obs every 5th, an obs outside the space every 9th, 1 kN peak force every 11th."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float64)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self):
        self.k = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(2), {}

    def step(self, action):
        self.k += 1
        if self.k % 7 == 0:
            raise ValueError("boom")
        if self.k % 13 == 0:
            raise TissueUnstableError("fake", 1e-3, 1e-4, "test")
        obs = np.zeros(2)
        if self.k % 5 == 0:
            obs[0] = math.nan
        elif self.k % 9 == 0:
            obs[1] = 5.0
        peak = 1e3 if self.k % 11 == 0 else 0.5
        return obs, 0.0, False, self.k % 20 == 0, {"peak_force_N": peak}


def test_soak_counts_exactly_what_a_faulty_env_does():
    if "SurgSimTest/Faulty-v0" not in gym.registry:
        gym.register("SurgSimTest/Faulty-v0", entry_point=_Faulty, disable_env_checker=True)
    n = 1001
    row = soak("SurgSimTest/Faulty-v0", n, seed=0, sample_every=50)
    ks = np.arange(1, n + 1)
    raised, unstable = ks % 7 == 0, (ks % 13 == 0) & (ks % 7 != 0)
    ok = ~raised & ~unstable
    assert row["steps"] == n and row["exceptions"] == raised.sum() and row["unstable"] == unstable.sum()
    assert row["exception_types"] == {"step:ValueError": raised.sum()}
    assert row["nan"] == (ok & (ks % 5 == 0)).sum()
    assert row["obs_out_of_space"] == (ok & (ks % 5 != 0) & (ks % 9 == 0)).sum()
    assert row["force_out_of_bounds"] == (ok & (ks % 11 == 0)).sum()
    assert math.isfinite(row["rss_growth_mb"])


def test_short_soak_of_palpation_is_clean():
    row = soak("SurgSim/Palpation-v0", 120, seed=3)
    bad = {k: row[k] for k in ("nan", "exceptions", "unstable", "obs_out_of_space", "force_out_of_bounds")}
    assert bad == dict.fromkeys(bad, 0), row["exception_messages"]
    assert row["steps"] == 120 and row["episodes"] >= 1 and 0 <= row["max_peak_force_N"] <= 50.0


def test_short_soak_of_layered_palpation_reads_its_press_force():
    """LayeredPalpation-v0 reports the press force as ``force_N`` (no episode peak): the soak's force
    bound must read it, not pass it as unreported. (On the 5 mm lattice: what is checked is how the
    force is reported; a reset of the 3.33 mm default costs 0.8 s.)"""
    row = soak("SurgSim/LayeredPalpation-v0", 30, seed=3, env_kwargs={"spacing": 0.005})
    bad = {k: row[k] for k in ("nan", "exceptions", "unstable", "obs_out_of_space", "force_out_of_bounds")}
    assert bad == dict.fromkeys(bad, 0), row["exception_messages"]
    assert 0.0 < row["max_peak_force_N"] <= 50.0


def test_soak_rejects_bad_arguments():
    with pytest.raises(ConfigError, match="unknown task 'SurgSim/Nope-v0'"):
        soak("SurgSim/Nope-v0", 10)
    with pytest.raises(ConfigError, match="--steps"):
        soak("SurgSim/Palpation-v0", 0)

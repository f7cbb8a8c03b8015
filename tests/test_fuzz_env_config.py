"""Hostile task configs, reset options and actions: each is refused with a ConfigError naming
it, or works (finite observations and rewards), never a raw exception, NaN or a hang. One
Palpation-v0 env is reused by the env-level cases."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("hypothesis", reason="hypothesis is in the [test] extra")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import fuzz_surfaces as fs  # noqa: E402
from fuzz_harness import check  # noqa: E402
from surgsim_envs.errors import ConfigError  # noqa: E402

FAST = settings(max_examples=100, deadline=None, database=None, suppress_health_check=list(HealthCheck))
MORE = settings(max_examples=3000, deadline=None, database=None, suppress_health_check=list(HealthCheck))
ENV = settings(max_examples=40, deadline=None, database=None, suppress_health_check=list(HealthCheck))


@FAST
@given(fs.config_case())
def test_fuzz_config_fields(case):
    check(fs.run_config, case, timeout_s=20, names=(case[1],))


@pytest.mark.slow
@MORE
@given(fs.config_case())
def test_fuzz_config_fields_more(case):
    check(fs.run_config, case, timeout_s=20, names=(case[1],))


@pytest.mark.parametrize("task, kwargs, message", [
    ("PalpationPress-v0", {"settle_steps": 10**12}, r"settle_steps=1000000000000 steps is outside \[1, 100,000\]"),
    ("PalpationPress-v0", {"hold_steps": 10**12}, r"hold_steps=1000000000000 steps is outside \[1, 100,000\]"),
    ("PalpationPress-v0", {"move_speed": 1e-300}, r"move_speed=1e-300 m/s is outside \[0.001, 100\]"),
    ("Grasp-v0", {"force_weight": float("nan")}, "GraspConfig.force_weight=nan must be finite"),
    ("Grasp-v0", {"success_bonus": float("inf")}, "GraspConfig.success_bonus=inf must be finite"),
    ("Slippage-v0", {"hold_reward": 1e308}, r"hold_reward=1e\+308 is outside \[0, 1e\+06\]"),
    ("Slippage-v0", {"settle_time": 1e9}, r"settle_time=1000000000.0 s is outside \(0, 10\] s"),
    ("Palpation-v0", {"localisation_weight": float("nan")}, "localisation_weight=nan must be finite"),
    ("Palpation-v0", {"integrator": None}, "integrator=None must be a non-empty string"),
    ("Palpation-v0", {"integrator": 5}, "integrator=5 must be a non-empty string"),
    ("Palpation-v0", {"integrator": ""}, "integrator='' must be a non-empty string"),
    ("Palpation-v0", {"integrator": "leapfrog"}, "integrator='leapfrog' is not one of"),
    ("Grasp-v0", {"tissue_subcycles": 5}, "tissue_subcycles=5 makes the MuJoCo step 5 x dt = 0.002 s"),
    ("Palpation-v0", {"spacing": 1e-5}, "gives about 2e\\+11 nodes, above the limit of 1,000,000"),
    ("Palpation-v0", {"episode_seconds": 1e12}, r"episode_seconds=1000000000000.0 s is outside \(0, 3600\] s"),
    ("Palpation-v0", {"render_width": "ab"}, "render_width='ab' px must be an integer"),
    ("Palpation-v0", {"young_scale": (10**400, 1)}, "young_scale must be a .low, high. pair of numbers"),
    ("Slippage-v0", {"static_friction_ratio": 10**400}, "static_friction_ratio=.* must be finite"),
])
def test_gym_make_refuses_before_building(task, kwargs, message):
    with pytest.raises(ConfigError, match=message):
        gym.make(f"SurgSim/{task}", **kwargs)


@pytest.mark.parametrize("integrator", ["implicit", "auto"])
def test_integrator_names_other_models_have_are_still_accepted(integrator):
    from surgsim_envs.envs.palpation import PalpationConfig

    PalpationConfig(integrator=integrator).validate()     # the task falls back as documented


# -- env-level cases on one reused env -------------------------------------------------------
@pytest.fixture(scope="module")
def env():
    import surgsim_envs.envs  # noqa: F401

    e = gym.make("SurgSim/Palpation-v0")
    e.reset(seed=0)
    yield e
    e.close()


def _step_with_weight(env, field, value):
    u = env.unwrapped
    config = dataclasses.replace(u.config, **{field: value})
    config.validate()
    saved, u.config = u.config, config
    try:
        env.reset(seed=1)
        rewards = [env.step(np.array([0.3, -0.2, 1.0, -1.0]))[1] for _ in range(3)]
    finally:
        u.config = saved
    return rewards


@ENV
@given(st.tuples(st.sampled_from(fs.REWARD_FIELDS["Palpation-v0"]), fs.hostile_value))
def test_fuzz_reward_weights_are_refused_or_give_finite_rewards(env, case):
    check(_step_with_weight, env, *case, timeout_s=30, names=(case[0],))


@ENV
@given(fs.reset_case())
def test_fuzz_reset_options(env, case):
    check(fs.run_reset, env, case, timeout_s=30, names=(case[0],))


@ENV
@given(fs.action_case())
def test_fuzz_actions(env, case):
    env.reset(seed=0)
    check(fs.run_action, env, case, timeout_s=30)


@pytest.mark.slow
@settings(max_examples=400, deadline=None, database=None, suppress_health_check=list(HealthCheck))
@given(fs.action_case())
def test_fuzz_actions_more(env, case):
    env.reset(seed=0)
    check(fs.run_action, env, case, timeout_s=30)

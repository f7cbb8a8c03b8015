"""Terms declared once (surgsim_envs/envs/terms/): the action terms equal the numpy formulas they
stand for bit for bit, the reward is the declared terms summed in order, and every task's
``info["reward_terms"]`` lists exactly its declared terms."""

import math

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs.envs import TASKS
from surgsim_envs.envs.grasp.terms import progress_reward, total_normal_force
from surgsim_envs.envs.palpation.terms import localisation_potential, potential_shaping
from surgsim_envs.envs.registry import task_spec
from surgsim_envs.envs.terms import RewardManager, RewardTerm, TerminationTerm, any_terminated
from surgsim_envs.envs.terms.action import clip, jaw_closure, jaw_opening, probe_target, wrist_target
from surgsim_envs.envs.terms.force import damage_penalty, vector_norm
from surgsim_envs.errors import ConfigError

RNG = np.random.default_rng(7)


def _bits(x) -> bytes:
    return np.asarray(x, dtype=np.float64).tobytes()


def test_probe_target_is_the_numpy_formula():
    for _ in range(200):
        target, a = RNG.uniform(-0.06, 0.06, 2), RNG.uniform(-1.3, 1.3, 3)   # outside [-1, 1] too
        step, lim, top, hover, depth = 0.003, 0.045, 0.03, 0.002, 0.008
        xy = np.clip(target + a[:2] * step, -lim, lim)
        z = top + hover - (a[2] + 1.0) / 2.0 * (hover + depth)
        got = probe_target(target.tolist(), a.tolist(), step, lim, top, hover, depth)
        assert _bits(got) == _bits([xy[0], xy[1], z])


def test_wrist_target_is_the_numpy_formula():
    q, _ = np.linalg.qr(RNG.normal(size=(3, 3)))
    home = np.array([0.05, -0.01, 0.03])
    for _ in range(200):
        target, a = home + RNG.uniform(-0.08, 0.08, 3), RNG.uniform(-1, 1, 3)
        local = np.clip(q.T @ (target + a * 0.001 - home), -0.06, 0.06)
        assert _bits(wrist_target(target, a, 0.001, home, q, 0.06)) == _bits(home + q @ local)


def test_jaw_terms_span_open_to_closed():
    assert jaw_opening(-1.0, 0.02, 0.005) == 0.02 and math.isclose(jaw_opening(1.0, 0.02, 0.005), 0.005)
    assert jaw_opening(3.0, 0.02, 0.005) == 0.005                      # clipped to the smallest opening
    assert jaw_closure(-1.0, 0.02, 0.005) == 0.0 and jaw_closure(1.0, 0.02, 0.005) == 0.02 - 0.005
    for a in RNG.uniform(-1, 1, 50):                                    # opening + closure = open radius
        assert math.isclose(jaw_opening(a, 0.02, 0.005) + jaw_closure(a, 0.02, 0.005), 0.02, rel_tol=1e-12)
    assert clip(2.0, -1.0, 1.0) == 1.0 and clip(-2.0, -1.0, 1.0) == -1.0 and clip(0.25, -1.0, 1.0) == 0.25


def test_force_terms_are_the_numpy_formulas():
    for _ in range(200):
        f = RNG.normal(scale=2.0, size=3)
        assert vector_norm(f) == float(np.linalg.norm(f))
        assert damage_penalty(f, 1.5, 0.7) == -0.7 * max(0.0, float(np.linalg.norm(f)) - 1.5)
        fn = np.abs(f)
        assert total_normal_force(fn) == float(np.sum(fn))


def test_potential_shaping_telescopes():
    """Summed over any sequence of estimates the shaping is weight * (phi_final - phi_0)."""
    errors = RNG.uniform(0.0, 0.08, 40)
    phis = [0.0] + [localisation_potential(e, 0.04) for e in errors]
    total = sum(potential_shaping(b, a, 2.0) for a, b in zip(phis, phis[1:]))
    assert math.isclose(total, 2.0 * (phis[-1] - phis[0]), abs_tol=1e-12)
    assert localisation_potential(0.0, 0.04) == 1.0 and localisation_potential(0.05, 0.04) == 0.0
    assert progress_reward(0.002, 0.01, 5.0) == 5.0 * 0.002 / 0.01


class _Cfg:
    a_weight = 0.1
    b_weight = 0.2


class _Env:
    config = _Cfg()


def test_reward_manager_sums_in_declared_order():
    terms = (RewardTerm("a", lambda env, w: w, "a_weight"), RewardTerm("b", lambda env, w: w, "b_weight"),
             RewardTerm("c", lambda env, w: 0.3 * w))
    reward, values = RewardManager(terms, _Cfg()).compute(_Env())
    assert list(values) == ["a", "b", "c"] and values == {"a": 0.1, "b": 0.2, "c": 0.3}
    assert reward == (0.1 + 0.2) + 0.3 != 0.1 + (0.2 + 0.3)   # the order is part of the reward's bits
    reversed_reward, _ = RewardManager(terms[::-1], _Cfg()).compute(_Env())
    assert reversed_reward == (0.3 + 0.2) + 0.1


def test_reward_manager_refuses_bad_declarations():
    with pytest.raises(ConfigError, match="names weight field 'nope', which _Cfg does not have"):
        RewardManager((RewardTerm("a", lambda env, w: w, "nope"),), _Cfg())
    with pytest.raises(ConfigError, match="distinct names"):
        RewardManager((RewardTerm("a", lambda env, w: w), RewardTerm("a", lambda env, w: w)), _Cfg())


def test_any_terminated():
    yes, no = TerminationTerm("yes", lambda env: True), TerminationTerm("no", lambda env: False)
    assert any_terminated((no, yes), None) is True and any_terminated((no,), None) is False
    assert any_terminated((), None) is False


@pytest.mark.parametrize("task", sorted(TASKS))
def test_info_reward_terms_are_the_declared_terms_and_sum_to_the_reward(task):
    env = gym.make(task, **task_spec(task).quick)
    u = env.unwrapped
    declared = [t.name for t in u.REWARD_TERMS]
    assert declared and u.ACTION.size == env.action_space.shape[0]
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(4):
        _, reward, term, trunc, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        rt = info["reward_terms"]
        assert list(rt) == declared + (["final"] if trunc else [])
        assert reward == float(sum(rt.values()))              # bit for bit: summed in the declared order
        if term or trunc:
            break
    env.close()


def test_layered_commit_term_applies_only_on_the_committing_press():
    from surgsim_envs.envs.layered_palpation.terms import commit_reward

    spec = task_spec("SurgSim/LayeredPalpation-v0")
    env = gym.make(spec.id, **spec.quick)
    env.reset(seed=0)
    _, r, term, _, info = env.step(np.array([0.0, 0.0, 0.0, -1.0], dtype=np.float32))
    assert not term and list(info["reward_terms"]) == ["press_cost"] and r == -env.unwrapped.config.press_cost
    _, r, term, _, info = env.step(np.array([0.0, 0.0, 0.0, 1.0], dtype=np.float32))
    assert term and list(info["reward_terms"]) == ["press_cost", "commit"]
    assert info["reward_terms"]["commit"] == commit_reward(info["distance_m"], env.unwrapped.config.size_scale)
    assert r == float(sum(info["reward_terms"].values()))
    assert commit_reward(0.0, 0.03) == 1.0 and commit_reward(1.0, 0.03) == -1.0
    env.close()

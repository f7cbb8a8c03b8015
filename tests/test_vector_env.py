"""SurgSimVectorEnv (surgsim_envs/vector/env.py): the shared-memory multi-process vector env
behind ``gym.make_vec(task, n)``. Behaviour only (speed: ``surgsim bench envs --vector``):
the same numbers as Gymnasium's SyncVectorEnv for the same seeds (a toy env for every autoreset
mode and info shape in milliseconds, Palpation-v0 with an autoreset in the default run, the
other tasks in a slow sweep), fresh arrays every step, errors that name the env, a dead or hung
worker that raises instead of hanging, and close() that returns."""

from __future__ import annotations

import functools
import os
import signal
import time

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import surgsim_envs.envs  # noqa: F401  (registers the tasks)
from surgsim_envs.vector import SurgSimVectorEnv
from surgsim_envs.errors import ConfigError, NonFiniteInputError, VectorEnvWorkerError


class Toy(gym.Env):
    """Deterministic given its seed: random terminations, a time limit, numeric infos that come
    and go (``odd`` on odd steps only, ``terms`` nested), float32/int/bool infos and
    non-numeric ones (``name``, ``pos``, ``maybe``)."""

    observation_space = spaces.Box(-np.inf, np.inf, (3,), np.float32)
    action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)

    def __init__(self, horizon: int = 7, hang_at: int | None = None):
        self.horizon, self.hang_at = horizon, hang_at

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        self.x = self.np_random.normal(size=3).astype(np.float32)
        if options and "offset" in options:
            self.x += np.float32(options["offset"])
        return self.x.copy(), {"t": 0, "start": True, "name": "toy"}

    def step(self, action):
        if not np.all(np.isfinite(action)):
            raise NonFiniteInputError(f"action holds NaN: {action}")
        self.t += 1
        if self.hang_at is not None and self.t >= self.hang_at:
            time.sleep(3600)
        self.x = self.x * np.float32(0.9) + np.float32(action.sum())
        reward = float(self.x.sum()) + self.np_random.random()
        terminated = bool(self.np_random.random() < 0.15)
        truncated = self.t >= self.horizon
        info = {"t": self.t, "r2": reward ** 2, "ok": reward > 0, "terms": {"a": float(action[0]), "b": 1.5},
                "name": "toy", "pos": [self.t, 2], "maybe": None if self.t % 3 else "third"}
        if self.t % 2:
            info["odd"] = np.float32(self.x[0])
        return self.x.copy(), reward, terminated, truncated, info


def numeric_part(info: dict) -> dict:
    """The entries of a Gymnasium vector info dict that hold numbers (and their masks)."""
    out = {}
    for k, v in info.items():
        if isinstance(v, dict):
            sub = numeric_part(v)
            if sub:
                out[k] = sub
                out["_" + k] = info["_" + k]
        elif not k.startswith("_") and v.dtype != object:
            out[k], out["_" + k] = v, info["_" + k]
    return out


def assert_info_equal(ours: dict, theirs: dict, where=""):
    assert set(ours) == set(theirs), (where, sorted(set(ours) ^ set(theirs)))
    for k, v in theirs.items():
        if isinstance(v, dict):
            assert_info_equal(ours[k], v, f"{where}/{k}")
        elif v.dtype == object:
            assert list(ours[k]) == list(v), (where, k)
        else:
            assert ours[k].dtype == v.dtype and np.array_equal(ours[k], v), (where, k, ours[k], v)


def assert_same_run(ours, sync, steps: int, seed, rng, info_filter=numeric_part, expect_reset=True):
    o1, i1 = ours.reset(seed=seed)
    o2, i2 = sync.reset(seed=seed)
    assert np.array_equal(o1, o2)
    assert_info_equal(i1, info_filter(i2), "reset")
    shape = ours.action_space.shape
    ended = 0
    for k in range(steps):
        a = rng.uniform(-1, 1, shape).astype(np.float32)
        r1, r2 = ours.step(a), sync.step(a)
        for x, y, what in zip(r1[:4], r2[:4], ("obs", "reward", "terminated", "truncated")):
            assert x.dtype == y.dtype and np.array_equal(x, y), (k, what, x, y)
        assert_info_equal(r1[4], info_filter(r2[4]), f"step {k}")
        ended += int(np.sum(r1[2] | r1[3]))
    if expect_reset:
        assert ended > 0, "the run had no episode end: the autoreset was not exercised"


@pytest.mark.parametrize("mode, in_main", [(AutoresetMode.NEXT_STEP, False), (AutoresetMode.SAME_STEP, False),
                                           (AutoresetMode.NEXT_STEP, True), (AutoresetMode.SAME_STEP, True)])
def test_toy_matches_sync_every_step(mode, in_main):
    """3 envs on 2 workers (2 + 1; with in_main the block of 2 in this process): observations,
    rewards, terminations, truncations and the numeric infos (with their masks, dtypes and nested
    dicts) equal SyncVectorEnv's over 40 steps with several autoresets; SAME_STEP's final_obs /
    final_info too."""
    ours = SurgSimVectorEnv(Toy, 3, workers=2, autoreset_mode=mode, in_main=in_main)
    sync = SyncVectorEnv([Toy] * 3, autoreset_mode=mode)
    try:
        assert ours.worker_envs == [(0, 2), (2, 3)] and len(ours.worker_pids) == (1 if in_main else 2)
        assert ours.metadata["autoreset_mode"] == mode
        assert ours.single_observation_space == sync.single_observation_space
        assert ours.action_space == sync.action_space and ours.observation_space == sync.observation_space

        def numeric_with_final(info):
            out = numeric_part({k: v for k, v in info.items() if k not in ("final_obs", "_final_obs")})
            if "final_obs" in info:
                out["final_obs"], out["_final_obs"] = info["final_obs"], info["_final_obs"]
                out["final_info"], out["_final_info"] = numeric_part(info["final_info"]), info["_final_info"]
            return out

        if mode == AutoresetMode.SAME_STEP:
            rng = np.random.default_rng(1)
            ours.reset(seed=5)
            sync.reset(seed=5)
            saw_final = False
            for k in range(40):
                a = rng.uniform(-1, 1, (3, 2)).astype(np.float32)
                r1, r2 = ours.step(a), sync.step(a)
                for x, y in zip(r1[:4], r2[:4]):
                    assert np.array_equal(x, y), k
                i1, i2 = r1[4], numeric_with_final(r2[4])
                if "final_obs" in i2:
                    saw_final = True
                    assert np.array_equal(i1["_final_obs"], i2["_final_obs"])
                    for j in np.flatnonzero(i2["_final_obs"]):
                        assert np.array_equal(i1["final_obs"][j], i2["final_obs"][j])
                    assert_info_equal(i1["final_info"], i2["final_info"], f"final {k}")
                    i1 = {k_: v for k_, v in i1.items() if not k_.startswith(("final", "_final"))}
                    i2 = {k_: v for k_, v in i2.items() if not k_.startswith(("final", "_final"))}
                assert_info_equal(i1, i2, f"step {k}")
            assert saw_final
        else:
            assert_same_run(ours, sync, 40, [11, 12, 13], np.random.default_rng(0))
    finally:
        ours.close()
        sync.close()


def test_toy_info_keys_reset_mask_and_calls():
    """info_keys='all' adds the non-numeric entries exactly as Gymnasium merges them; a tuple keeps
    only those keys; reset_mask resets only the masked envs (with options); call/get_attr/set_attr
    reach every env in order."""
    sync = SyncVectorEnv([Toy] * 2)
    with_all = SurgSimVectorEnv(Toy, 2, info_keys="all")
    only = SurgSimVectorEnv(Toy, 2, info_keys=("t", "name"))
    none = SurgSimVectorEnv(Toy, 2, info_keys=())
    try:
        assert_same_run(with_all, sync, 12, 3, np.random.default_rng(2), info_filter=lambda i: i)
        _, info = only.reset(seed=3)
        assert set(info) == {"t", "_t", "name", "_name"} and list(info["name"]) == ["toy", "toy"]
        _, info = none.reset(seed=3)
        assert info == {}
        *_, info = none.step(np.zeros((2, 2), np.float32))
        assert info == {}

        obs0, _ = sync.reset(seed=[7, 8])
        obs, _ = with_all.reset(seed=[7, 8])
        mask = np.array([False, True])
        obs_m, info_m = with_all.reset(seed=[None, 9], options={"reset_mask": mask, "offset": 100.0})
        ref = Toy()
        ref_obs, _ = ref.reset(seed=9, options={"offset": 100.0})
        assert np.array_equal(obs_m[0], obs0[0]) and np.array_equal(obs_m[1], ref_obs)
        assert list(info_m["_t"]) == [False, True]

        assert with_all.get_attr("horizon") == (7, 7)
        with_all.set_attr("horizon", [2, 9])
        assert with_all.get_attr("horizon") == (2, 9)
        assert with_all.call("get_wrapper_attr", "hang_at") == (None, None)
    finally:
        for v in (sync, with_all, only, none):
            v.close()


class LateKeys(gym.Env):
    """Info layouts that change after the workers have settled on one (their fast write plan):
    ``late`` appears at step 5 in the odd-seeded env (and is gone there at steps 13-15) and at
    step 8 in the other, a nested
    ``terms/late_sub`` at step 3, ``x`` is missing at step 10, ``est`` turns from None to a list
    every fourth step. (A key that changes its numeric type is cast to its first type: not here.)"""

    observation_space = spaces.Box(-np.inf, np.inf, (1,), np.float32)
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t, self.odd = 0, bool((seed or 0) % 2)
        return np.zeros(1, np.float32), {"t": 0}

    def step(self, action):
        t = self.t = self.t + 1
        info = {"t": t, "x": float(action[0]) * t,
                "terms": {"a": 1.0 * t}, "est": None if t % 4 else [t, 1]}
        if t >= (5 if self.odd else 8) and not (self.odd and 13 <= t <= 15):
            info["late"] = np.float32(t / 3)
        if t >= 3:
            info["terms"]["late_sub"] = t * 0.5
        if t == 10:
            del info["x"]
        return np.full(1, t, np.float32), float(t), False, False, info


@pytest.mark.parametrize("info_keys, spin_us, worker_spin_us", [(None, 0.0, 0.0), ("all", 200.0, 300.0)])
def test_info_keys_appearing_late_match_sync(info_keys, spin_us, worker_spin_us):
    """Keys that appear, vanish or change type after many steps of the same layout (the workers
    write a known layout by a plan, anything else by the general path) give SyncVectorEnv's info
    every step: values, dtypes and masks, nested dicts too (also when the main process polls
    for replies before it sleeps, ``spin_us``, and the workers poll for commands, ``worker_spin_us``)."""
    ours = SurgSimVectorEnv(LateKeys, 3, workers=2, info_keys=info_keys, spin_us=spin_us,
                            worker_spin_us=worker_spin_us)
    sync = SyncVectorEnv([LateKeys] * 3)
    try:
        assert_same_run(ours, sync, 17, [2, 3, 4], np.random.default_rng(4), expect_reset=False,
                        info_filter=numeric_part if info_keys is None else (lambda i: i))
    finally:
        ours.close()
        sync.close()


def test_returned_arrays_are_fresh_copies():
    """Arrays a caller keeps are not overwritten by later steps (they are copies of the shared
    memory, not views of it), and writing into them does not reach the next step."""
    vec = SurgSimVectorEnv(Toy, 2)
    try:
        vec.reset(seed=0)
        a = np.ones((2, 2), np.float32)
        kept = vec.step(a)
        snapshot = [x.copy() for x in kept[:4]]
        new = vec.step(a)
        for x, y in zip(kept[:4], snapshot):
            assert np.array_equal(x, y)
        assert not np.array_equal(new[0], kept[0]) and not np.array_equal(new[1], kept[1])
        new[0][:] = -1e9
        reset_obs, _ = vec.reset(seed=0)
        assert reset_obs is not new[0] and np.all(np.abs(reset_obs) < 1e3)
        obs, *_ = vec.step(a)
        assert np.array_equal(obs, snapshot[0])        # same seed, same action: the first step again
    finally:
        vec.close()


@pytest.mark.parametrize("bad, in_main", [(2, False), (0, True), (2, True)])
def test_env_error_names_env_and_vector_env_recovers(bad, in_main):
    vec = SurgSimVectorEnv(Toy, 3, workers=2, in_main=in_main)
    try:
        vec.reset(seed=0)
        a = np.zeros((3, 2), np.float32)
        a[bad, 1] = np.nan
        with pytest.raises(NonFiniteInputError) as e:
            vec.step(a)
        assert f"env {bad} of SurgSimVectorEnv" in "".join(e.value.__notes__)
        obs, _ = vec.reset(seed=0)
        assert obs.shape == (3, 3)
        vec.step(np.zeros((3, 2), np.float32))
        with pytest.raises(ConfigError, match=r"shape \(3, 2\)"):
            vec.step(np.zeros((2, 2), np.float32))
    finally:
        vec.close()


def test_killed_worker_raises_naming_envs_and_close_returns():
    vec = SurgSimVectorEnv(Toy, 3, workers=2)
    vec.reset(seed=0)
    os.kill(vec.worker_pids[1], signal.SIGKILL)
    t0 = time.monotonic()
    with pytest.raises(VectorEnvWorkerError, match=r"worker 1 .*env 2 .*killed by signal 9"):
        vec.step(np.zeros((3, 2), np.float32))
    with pytest.raises(VectorEnvWorkerError, match="unusable"):
        vec.reset()
    vec.close()
    assert time.monotonic() - t0 < 10.0
    assert vec.closed


def test_hung_worker_times_out_and_close_terminates_it():
    vec = SurgSimVectorEnv(functools.partial(Toy, hang_at=2), 2, timeout_s=1.0, close_timeout_s=0.5)
    vec.reset(seed=0)
    vec.step(np.zeros((2, 2), np.float32))
    pids = vec.worker_pids
    t0 = time.monotonic()
    with pytest.raises(VectorEnvWorkerError, match=r"did not answer step within timeout_s=1 s"):
        vec.step(np.zeros((2, 2), np.float32))
    vec.close()
    assert time.monotonic() - t0 < 8.0
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


@pytest.mark.parametrize("kwargs, match", [
    ({"num_envs": 0}, r"num_envs=0 is outside \[1, 1,024\]; at most 1024 envs"),
    ({"num_envs": 2.5}, "num_envs=2.5 must be an integer, not float"),
    ({"num_envs": 10**6}, r"num_envs=1000000 is outside \[1, 1,024\]"),
    ({"num_envs": 2, "info_keys": 5}, "info_keys must be None .*got 5 of type int"),
    ({"num_envs": 2, "context": "bogus"}, "context='bogus' is not one of .*fork"),
    ({"num_envs": 2, "workers": 3}, r"workers=3 is outside \[1, 2\]; at most one worker per env \(2 envs\)"),
    ({"num_envs": 2, "workers": 0}, r"workers=0 is outside \[1, 2\]"),
    ({"num_envs": 2, "info_keys": "some"}, "info_keys must be None .*'all'.* got 'some'"),
    ({"num_envs": 2, "autoreset_mode": "Later"}, "autoreset_mode must be one of .* got 'Later'"),
    ({"num_envs": 2, "timeout_s": 0}, r"timeout_s=0 s is outside \[0.001, 86400\] s"),
    ({"num_envs": 2, "timeout_s": 10**400}, "timeout_s=1000000000.* s must be finite"),
    ({"num_envs": 2, "spin_us": -1.0}, r"spin_us=-1.0 us is outside \[0, 100000\] us"),
    ({"num_envs": 2, "worker_spin_us": True}, r"worker_spin_us=True us must be a real number \(int or float\), not bool"),
    ({"num_envs": 2, "worker_spin_us": float("nan")}, r"worker_spin_us=nan us must be finite"),
])
def test_bad_options_raise_config_error_naming_the_value(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        SurgSimVectorEnv(Toy, **kwargs)


def test_env_construction_error_reaches_the_caller():
    with pytest.raises(TypeError, match="no_such_option") as e:
        SurgSimVectorEnv(Toy, 2, no_such_option=1)
    assert "envs 0..0" in "".join(e.value.__notes__) or "env 0" in "".join(e.value.__notes__)


def test_make_vec_default_is_ours_and_matches_sync_on_palpation():
    """gym.make_vec(task, n) (no vectorization_mode) is SurgSimVectorEnv; 45 Palpation-v0 steps with
    an episode of 20 steps (autoresets at steps 20 and 41) equal SyncVectorEnv's, infos included."""
    # sync first: the workers fork a process that has loaded the task's modules and numba kernels
    sync = gym.make_vec("SurgSim/Palpation-v0", num_envs=2, vectorization_mode="sync", max_episode_steps=20)
    ours = gym.make_vec("SurgSim/Palpation-v0", num_envs=2, max_episode_steps=20)
    try:
        assert isinstance(ours, SurgSimVectorEnv)
        assert ours.spec.id == "SurgSim/Palpation-v0"
        assert gym.spec("SurgSim/Palpation-v0").to_json()       # the vector entry point is a string
        assert_same_run(ours, sync, 45, 3, np.random.default_rng(4))
    finally:
        ours.close()
        sync.close()


@pytest.mark.slow
@pytest.mark.parametrize("task, episode", [("SurgSim/Grasp-v0", 15), ("SurgSim/Slippage-v0", 15),
                                           ("SurgSim/PalpationPress-v0", 6)])
def test_tasks_match_sync(task, episode):
    sync = gym.make_vec(task, num_envs=3, vectorization_mode="sync", max_episode_steps=episode)
    ours = gym.make_vec(task, num_envs=3, workers=2, max_episode_steps=episode)
    try:
        assert_same_run(ours, sync, 2 * episode + 5, 0, np.random.default_rng(5))
    finally:
        ours.close()
        sync.close()


def test_disabled_autoreset_needs_a_masked_reset():
    """autoreset_mode=DISABLED: stepping an env whose episode ended raises naming the env and the
    fix; a reset with reset_mask for that env lets it run on."""
    vec = SurgSimVectorEnv(functools.partial(Toy, horizon=2), 2, autoreset_mode="Disabled")
    try:
        vec.reset(seed=0)
        a = np.zeros((2, 2), np.float32)
        ended = np.zeros(2, bool)
        for _ in range(2):
            _, _, term, trunc, _ = vec.step(a)
            ended |= term | trunc
            if ended.any():
                break
        assert ended.any()
        with pytest.raises(RuntimeError, match=r"env \d was stepped after its episode ended.*reset_mask"):
            vec.step(a)
        obs, info = vec.reset(options={"reset_mask": np.ones(2, bool)})
        assert list(info["_t"]) == [True, True] and list(info["t"]) == [0, 0]
        vec.step(a)
    finally:
        vec.close()


@pytest.mark.slow
def test_spawn_context_matches_sync():
    ours = SurgSimVectorEnv(Toy, 2, context="spawn")
    sync = SyncVectorEnv([Toy] * 2)
    try:
        assert_same_run(ours, sync, 20, 1, np.random.default_rng(3))
    finally:
        ours.close()
        sync.close()


def linear_policy(obs):
    """A deterministic row-wise policy (module level: picklable for the workers)."""
    return np.tanh(obs[:, :2] * np.float32(0.7) - np.float32(0.1)).astype(np.float32)


@pytest.mark.parametrize("mode, in_main", [(AutoresetMode.NEXT_STEP, False), (AutoresetMode.SAME_STEP, True)])
def test_rollout_matches_sync_stepping_the_same_policy(mode, in_main):
    """rollout(policy, T) records what SyncVectorEnv gives when stepped T times with the same policy
    (observations before each step and after the last, actions, rewards, flags; episodes end and
    autoreset inside it), and the vector env goes on from there: the next step() matches too, as do
    info keys first seen during the rollout."""
    ours = SurgSimVectorEnv(Toy, 5, workers=2, autoreset_mode=mode, in_main=in_main)
    sync = SyncVectorEnv([Toy] * 5, autoreset_mode=mode)
    try:
        o1, _ = ours.reset(seed=11)
        o2, _ = sync.reset(seed=11)
        rec = ours.rollout(linear_policy, 20)
        assert rec["observations"].shape == (21, 5, 3) and rec["actions"].shape == (20, 5, 2)
        assert np.array_equal(rec["observations"][0], o2)
        obs = o2
        for t in range(20):
            a = linear_policy(obs)
            assert np.array_equal(rec["actions"][t], a), t
            obs, r, te, tr, _ = sync.step(a)
            assert np.array_equal(rec["observations"][t + 1], obs), t
            assert np.array_equal(rec["rewards"][t], r) and rec["rewards"].dtype == r.dtype, t
            assert np.array_equal(rec["terminations"][t], te) and np.array_equal(rec["truncations"][t], tr), t
        assert (rec["terminations"] | rec["truncations"]).sum() >= 3, "no autoreset inside the rollout"
        a = linear_policy(obs)
        r1, r2 = ours.step(a), sync.step(a)
        for x, y in zip(r1[:4], r2[:4]):
            assert np.array_equal(x, y)
        assert_info_equal(r1[4], numeric_part(r2[4]), "after the rollout")
    finally:
        ours.close()
        sync.close()


class NoisyPolicy:
    """A stochastic policy with ``reset(seed)`` (as NpzPolicy): uniform actions from its own generator."""

    def __init__(self):
        self.rng = np.random.default_rng(0)

    def reset(self, seed=None):
        self.rng = np.random.default_rng(seed)

    def __call__(self, obs):
        return self.rng.uniform(-1, 1, (len(obs), 2)).astype(np.float32)


def test_rollout_seed_gives_each_block_its_own_reproducible_noise():
    """Without seed every block's copy of a stochastic policy draws the same actions; with seed each
    block's stream differs (reset(seed + first env index)) and the same seed repeats the rollout."""
    vec = SurgSimVectorEnv(Toy, 4, workers=2)
    try:
        vec.reset(seed=0)
        same = vec.rollout(NoisyPolicy(), 5)["actions"]
        assert np.array_equal(same[:, :2], same[:, 2:])
        vec.reset(seed=0)
        a = vec.rollout(NoisyPolicy(), 5, seed=7)["actions"]
        vec.reset(seed=0)
        b = vec.rollout(NoisyPolicy(), 5, seed=7)["actions"]
        assert np.array_equal(a, b) and not np.array_equal(a[:, :2], a[:, 2:])
        with pytest.raises(ConfigError, match=r"rollout\(seed=3\) reseeds the policy .* has none"):
            vec.rollout(linear_policy, 2, seed=3)
    finally:
        vec.close()


def test_rollout_errors_name_the_problem():
    vec = SurgSimVectorEnv(Toy, 2)
    try:
        vec.reset(seed=0)
        with pytest.raises(ConfigError, match=r"rollout steps=0 is outside \[1, inf\]"):
            vec.rollout(linear_policy, 0)
        with pytest.raises(ConfigError, match="rollout policy must be a callable"):
            vec.rollout("not a policy", 3)
        with pytest.raises(ValueError, match=r"returned actions of shape \(1, 3\) for 1 observations; expected \(1, 2\)"):
            vec.rollout(functools.partial(np.zeros_like), 3)       # (1, 3) from (1, 3) observations
        with pytest.raises(ConfigError, match=r"rollout of 100000000 steps x 2 envs needs .* GiB .* chunks of at most \d+ steps"):
            vec.rollout(linear_policy, 100_000_000)
        vec.reset(seed=0)                                          # usable after a policy error
        assert vec.rollout(linear_policy, 2)["rewards"].shape == (2, 2)
    finally:
        vec.close()
    disabled = SurgSimVectorEnv(Toy, 2, autoreset_mode=AutoresetMode.DISABLED)
    try:
        with pytest.raises(ConfigError, match="rollout\\(\\) needs autoreset"):
            disabled.rollout(linear_policy, 2)
    finally:
        disabled.close()


@pytest.mark.slow
def test_rollout_with_the_shipped_palpation_policy_matches_sync():
    """The shipped Palpation-v0 policy (NpzPolicy.batched) rolled out in the workers, one env each, over
    an episode end (15-step episodes, autoreset at step 16), equals SyncVectorEnv stepped with the same
    policy row by row."""
    from pathlib import Path

    import surgsim_envs.policies
    from surgsim_envs.policies.npz_policy import NpzPolicy

    policy = NpzPolicy.load(Path(surgsim_envs.policies.__file__).parent / "palpation_v0.npz")
    sync = gym.make_vec("SurgSim/Palpation-v0", num_envs=2, vectorization_mode="sync", max_episode_steps=15)
    ours = gym.make_vec("SurgSim/Palpation-v0", num_envs=2, max_episode_steps=15)
    try:
        obs, _ = sync.reset(seed=4)
        ours.reset(seed=4)
        rec = ours.rollout(policy.batched, 20)
        for t in range(20):
            a = np.concatenate([policy.act_batch(obs[i:i + 1]) for i in range(2)])
            assert np.array_equal(rec["actions"][t], a), t
            obs, r, te, tr, _ = sync.step(a)
            assert np.array_equal(rec["observations"][t + 1], obs) and np.array_equal(rec["rewards"][t], r), t
            assert np.array_equal(rec["truncations"][t], tr) and np.array_equal(rec["terminations"][t], te), t
        assert rec["truncations"][14].all()
    finally:
        ours.close()
        sync.close()

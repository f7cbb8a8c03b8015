"""Demonstrations as Minari datasets: ``surgsim record TASK --device ... --episodes N``.

A recording steps a task with a *source* of actions and writes one Minari dataset (Farama's
offline-RL format, HDF5): observations, actions, rewards, terminations and truncations, and per
step in ``infos``:

* ``tool_force_N``: for every tool of the scene, the contact force on it from the tissue, (3,) N;
* ``reward_terms``: the task's weighted reward terms (the same names as ``info["reward_terms"]``;
  zeros at reset);
* ``source_action``: the action the device chose at this observation (zeros at the last one); it
  differs from the recorded action when ``--noise`` perturbs the applied actions;
* with a haptic device (a teleoperation session, :mod:`~surgsim_envs.integrations.teleop_actions`):
  ``device_position_m`` and ``device_quaternion`` (the device pose read at this observation; zeros
  and identity at the last) and ``felt_force_N`` (the force sent back to the hand after the step
  that led here, N, limited by the device; zeros at reset).

Sources (``--device``): ``expert`` (the task's scripted expert), ``random`` (uniform actions from
the action space), ``policy:FILE.npz`` (a saved :class:`~surgsim_envs.policies.NpzPolicy`),
``scripted`` and ``replay:FILE`` (haptic devices whose pose drives the task: a teleoperation
session; Palpation-v0).
Episode *k* is reset with seed ``seed + k``, and the dataset's description names the package
version, the task, the source and the seed, so a recording can be made again.

Needs the ``[data]`` extra (``minari[hdf5]``).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Callable

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: episodes one recording may hold (each is kept in memory until the dataset is written)
MAX_EPISODES = 10_000


def _expert(task: str) -> Callable:
    """The task's scripted expert (``TaskSpec.expert`` in :mod:`surgsim_envs.envs.registry`)."""
    from surgsim_envs.envs.registry import TASKS, expert

    if task in TASKS and TASKS[task].expert is None:
        raise ConfigError(f"task {task!r} has no scripted expert; tasks with one: "
                          f"{sorted(t for t, s in TASKS.items() if s.expert)}. "
                          "Record it with --device random or --device policy:FILE.npz")
    return expert(task)


def action_source(task: str, device: str) -> Callable:
    """``factory(env) -> policy(obs) -> action``, made anew for every episode."""
    if not isinstance(device, str):
        raise ConfigError(f"device must be 'expert', 'random', 'policy:FILE.npz', 'scripted' or 'replay:FILE', "
                          f"got {device!r}")
    if device == "scripted" or device.startswith("replay:"):
        from surgsim_envs.integrations.teleop_actions import device_source

        if device.startswith("replay:") and not Path(device.split(":", 1)[1]).expanduser().is_file():
            raise ConfigError(f"replay file {device.split(':', 1)[1]!r} not found (relative paths resolve from the "
                              f"working directory {os.getcwd()!r})")
        return device_source(task, device)
    if device == "expert":
        return _expert(task)
    if device == "random":
        return lambda env: (lambda obs: env.action_space.sample())
    if device.startswith("policy:"):
        from surgsim_envs.policies.npz_policy import NpzPolicy

        path = Path(device.split(":", 1)[1]).expanduser()
        if not path.is_file():
            raise ConfigError(f"policy file {str(path)!r} not found (relative paths resolve from the working "
                              f"directory {os.getcwd()!r})")
        policy = NpzPolicy.load(path, mode="deterministic")
        return lambda env: policy
    raise ConfigError(f"unknown device {device!r}: use 'expert', 'random', 'policy:FILE.npz' (a saved policy), "
                      "'scripted' or 'replay:FILE' (a haptic device: a teleoperation session)")


def _step_info(env, info: dict, term_names: tuple) -> dict:
    """The recorded ``infos`` of one step: tool forces (N) and the reward terms (zeros at reset)."""
    u = env.unwrapped
    terms = info.get("reward_terms") or {}
    return {"tool_force_N": {name: np.asarray(u.sim.tool_force(name), dtype=np.float64) for name in sorted(u.sim.tools)},
            "reward_terms": {k: np.float64(terms.get(k, 0.0)) for k in term_names}}


def _stack(items: list):
    """A list of per-step infos (nested dicts of arrays) as a nested dict of stacked arrays."""
    if isinstance(items[0], dict):
        return {k: _stack([it[k] for it in items]) for k in items[0]}
    return np.stack([np.asarray(it) for it in items])


def _term_names(task: str, make_env) -> tuple:
    """The task's reward term names (one step of a throwaway episode)."""
    env = make_env()
    try:
        env.reset(seed=0)
        _, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=env.action_space.dtype))
        return tuple(sorted(info.get("reward_terms") or {}))
    finally:
        env.close()


def record(task: str, device: str = "expert", episodes: int = 10, seed: int = 0, out: str | Path = "surgsim-data",
           max_steps: int | None = None, progress: Callable[[int], None] | None = None, noise: float = 0.0,
           **env_kwargs):
    """Record ``episodes`` episodes of ``task`` driven by ``device`` into a Minari dataset under
    ``out``; returns the loaded :class:`minari.MinariDataset`.

    noise: standard deviation of Gaussian noise added to every action entry before it is applied
    (clipped to the action space); the recorded ``actions`` are the applied ones, and
    ``infos["source_action"]`` holds the device's own action at each observation (zeros at the
    last), so imitation learning sees how the expert recovers from states it would not reach."""
    try:
        import minari
    except ImportError:
        raise ConfigError("recording datasets needs the [data] extra: pip install -e \".[data]\"") from None
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401  (registers the tasks)

    if task not in gym.registry or not task.startswith("SurgSim/"):
        raise ConfigError(f"unknown task {task!r}; choose from {sorted(k for k in gym.registry if k.startswith('SurgSim/'))}")
    if not (isinstance(episodes, int) and not isinstance(episodes, bool) and 1 <= episodes <= MAX_EPISODES):
        raise ConfigError(f"episodes={episodes!r} must be an integer in 1..{MAX_EPISODES}")
    if not (isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed < 2**31):
        raise ConfigError(f"seed={seed!r} must be an integer in [0, 2^31)")
    if isinstance(noise, bool) or not isinstance(noise, (int, float)) or not 0.0 <= noise <= 1.0:
        raise ConfigError(f"noise={noise!r} must be a standard deviation in [0, 1] (actions span [-1, 1])")
    rng = np.random.default_rng(seed)
    factory = action_source(task, device)
    make_env = lambda: gym.make(task, **env_kwargs)  # noqa: E731
    names = _term_names(task, make_env)
    out = Path(out).resolve()
    short = task.split("/")[1].lower().replace("-v0", "")
    source = device.split(":")[0]
    dataset_id = f"surgsim/{short}/{source}-v0"
    if (out / "surgsim" / short / f"{source}-v0").exists():
        raise ConfigError(f"dataset {dataset_id!r} already exists in {str(out)!r}; choose another --out or delete it")
    from minari.data_collector import EpisodeBuffer

    env = make_env()
    limit = env.spec.max_episode_steps if max_steps is None else int(max_steps)
    buffers = []
    try:
        for k in range(episodes):
            obs, info = env.reset(seed=seed + k)
            policy = factory(env)
            haptic = hasattr(policy, "after_step")     # a haptic device: its pose and the felt force too
            observations, actions, rewards, terms, truncs = [obs], [], [], [], []
            infos = [_step_info(env, info, names)]
            if haptic:
                infos[0]["felt_force_N"] = np.zeros(3)
            for _ in range(limit if limit else 10**6):
                chosen = np.asarray(policy(obs), dtype=env.action_space.dtype)
                infos[-1]["source_action"] = chosen
                if haptic:
                    infos[-1]["device_position_m"], infos[-1]["device_quaternion"] = policy.last_device
                action = chosen
                if noise > 0.0:
                    action = np.clip(chosen + rng.normal(0.0, noise, chosen.shape), env.action_space.low,
                                     env.action_space.high).astype(env.action_space.dtype)
                obs, reward, terminated, truncated, info = env.step(action)
                observations.append(obs)
                actions.append(action)
                rewards.append(float(reward))
                terms.append(bool(terminated))
                truncs.append(bool(truncated))
                infos.append(_step_info(env, info, names))
                if haptic:
                    policy.after_step()
                    infos[-1]["felt_force_N"] = policy.felt.copy()
                if terminated or truncated:
                    break
            infos[-1]["source_action"] = np.zeros_like(actions[-1])
            if haptic:
                infos[-1]["device_position_m"], infos[-1]["device_quaternion"] = np.zeros(3), np.array([1.0, 0, 0, 0])
            truncs[-1] = truncs[-1] or not terms[-1]   # an episode cut by max_steps ends truncated
            buffers.append(EpisodeBuffer(id=k, seed=seed + k, observations=np.stack(observations),
                                         actions=np.stack(actions), rewards=rewards, terminations=terms,
                                         truncations=truncs, infos=_stack(infos)))
            if progress is not None:
                progress(k + 1)
        out.mkdir(parents=True, exist_ok=True)
        os.environ["MINARI_DATASETS_PATH"] = str(out)
        import warnings

        with warnings.catch_warnings():   # Minari's reminders to name a public code address and e-mail
            warnings.filterwarnings("ignore", message=r"`(code_permalink|author_email)` is set to None")
            dataset = _create(minari, dataset_id, buffers, env, task, device, episodes, seed, source, noise)
    finally:
        env.close()
    return dataset


def _create(minari, dataset_id, buffers, env, task, device, episodes, seed, source, noise):
    import surgsim_envs

    return minari.create_dataset_from_buffers(
        dataset_id=dataset_id, buffer=buffers, env=env.spec, eval_env=env.spec, algorithm_name=f"surgsim {source}",
        author="surgsim_envs", action_space=env.action_space, observation_space=env.observation_space,
        description=(f"{task} driven by {device}, {episodes} episodes, episode k reset with seed {seed} + k, action "
                     f"noise {noise:g}; surgsim_envs {surgsim_envs.__version__}; infos: tool_force_N (N per tool), "
                     "reward_terms, source_action"))


def returns(dataset) -> np.ndarray:
    """The undiscounted return of every episode of a dataset."""
    return np.array([float(np.sum(ep.rewards)) for ep in dataset.iterate_episodes()])


def add_arguments(parser) -> None:
    parser.add_argument("task", help="task id, e.g. SurgSim/Grasp-v0")
    parser.add_argument("--device", default="expert",
                        help="expert | random | policy:FILE.npz | scripted | replay:FILE (default expert; the last "
                             "two are haptic devices driving the task: a teleoperation session)")
    parser.add_argument("--episodes", type=int, default=10, help="episodes to record (default 10)")
    parser.add_argument("--seed", type=int, default=0, help="episode k is reset with seed + k (default 0)")
    parser.add_argument("--noise", type=float, default=0.0,
                        help="std of Gaussian noise added to the applied actions (default 0; the device's own "
                             "actions go to infos['source_action'])")
    parser.add_argument("--out", default="surgsim-data", help="folder of the Minari datasets (default ./surgsim-data)")


def run(args) -> int:
    from tqdm import tqdm

    validate.writable_folder(args.out, "--out", fix="give a writable folder for the Minari datasets")
    bar = tqdm(total=args.episodes, desc=f"recording {args.task}", unit="episode")
    dataset = record(args.task, args.device, args.episodes, args.seed, args.out, noise=args.noise,
                     progress=lambda k: bar.update(k - bar.n))
    bar.close()
    r = returns(dataset)
    print(f"wrote {dataset.spec.dataset_id} in {args.out}: {dataset.total_episodes} episodes, "
          f"{dataset.total_steps} steps, return {np.mean(r):.3g} +- {np.std(r):.2g}"
          + ("" if math.isfinite(float(np.mean(r))) else " (non-finite)"))
    return 0

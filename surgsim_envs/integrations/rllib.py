"""Ray RLlib env creators for the SurgSim tasks, with per-worker seeding.

RLlib builds envs in every rollout worker (env runner) from a registered *creator*
``creator(env_config) -> gymnasium.Env``, where ``env_config`` is an ``EnvContext``: a dict of the
user's settings plus ``worker_index`` (0 = the local worker, 1..N remote workers) and
``vector_index`` (the env's slot in the worker's vector). Every env must explore a different
stream of episodes and a run must be reproducible, so the creator derives the env's seed from
both indices (:func:`worker_seed`) and the env's *first* ``reset`` uses it (later resets continue
the env's own generator, as Gymnasium does after a seeded reset).

    from surgsim_envs.integrations.rllib import register_rllib_envs
    register_rllib_envs()          # names "SurgSim/PalpationPress-v0", ... for AlgorithmConfig.environment()

``env_config`` keys: ``seed`` (base seed, default 0) and any config field of the task
(``gym.make`` keywords, e.g. ``{"on_unstable": "terminate"}``). Ray is imported only by
:func:`register_rllib_envs`; the creator itself needs only gymnasium, so it runs unchanged in
worker processes on other machines (each imports ``surgsim_envs``).
"""

from __future__ import annotations

from typing import Any, Mapping

import gymnasium as gym

from surgsim_envs.errors import ConfigError

#: seeds of envs in different workers / vector slots never collide for up to this many slots per worker
SLOTS_PER_WORKER = 1000


def worker_seed(base: int, worker_index: int, vector_index: int) -> int:
    """Seed of the env in slot ``vector_index`` of worker ``worker_index``:
    ``base + SLOTS_PER_WORKER * worker_index + vector_index`` (distinct for every (worker, slot)
    with ``vector_index < SLOTS_PER_WORKER``)."""
    for name, v in (("base", base), ("worker_index", worker_index), ("vector_index", vector_index)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            raise ConfigError(f"worker_seed: {name} must be an integer >= 0, got {v!r}")
    if vector_index >= SLOTS_PER_WORKER:
        raise ConfigError(f"worker_seed: vector_index {vector_index} >= {SLOTS_PER_WORKER} slots per worker; "
                          "use fewer envs per worker")
    return base + SLOTS_PER_WORKER * worker_index + vector_index


class SeedFirstReset(gym.Wrapper):
    """Uses ``seed`` for the first ``reset`` that is given none (RLlib resets without a seed)."""

    def __init__(self, env: gym.Env, seed: int):
        super().__init__(env)
        self.first_seed = int(seed)
        self._seeded = False

    def reset(self, *, seed=None, options=None):
        if seed is None and not self._seeded:
            seed = self.first_seed
        self._seeded = True
        if seed is not None:
            self.env.action_space.seed(seed)
        return self.env.reset(seed=seed, options=options)


def make_creator(task: str):
    """An RLlib env creator for Gymnasium task id ``task``."""

    def creator(env_config: Mapping[str, Any] | None = None) -> gym.Env:
        import surgsim_envs  # noqa: F401  (registers the tasks in this worker process)

        cfg = dict(env_config or {})
        worker = int(getattr(env_config, "worker_index", cfg.pop("worker_index", 0)) or 0)
        vector = int(getattr(env_config, "vector_index", cfg.pop("vector_index", 0)) or 0)
        base = int(cfg.pop("seed", 0))
        if task not in gym.registry:
            raise ConfigError(f"unknown task {task!r}; SurgSim tasks: {[k for k in gym.registry if k.startswith('SurgSim/')]}")
        env = gym.make(task, **cfg)
        return SeedFirstReset(env, worker_seed(base, worker, vector))

    creator.__name__ = f"create_{task.split('/')[-1].replace('-', '_')}"
    return creator


def register_rllib_envs(tasks=None) -> list[str]:
    """Register an RLlib creator for every SurgSim task (or ``tasks``) under its Gymnasium id;
    returns the names. Needs Ray (``pip install surgsim_envs[distributed]``)."""
    try:
        from ray.tune.registry import register_env
    except ImportError as exc:
        raise ConfigError("Ray RLlib is not installed; pip install 'ray[rllib]' (the [distributed] extra)") from exc
    from surgsim_envs.envs import TASKS

    names = list(tasks or TASKS)
    for t in names:
        register_env(t, make_creator(t))
    return names

"""The SurgSim tasks for DeepMind's control stack: a dm_control environment per task
(:func:`load`), and a plain ``dm_env`` wrapper of one Gymnasium env (:func:`make_dm_env`).

>>> from surgsim_envs.integrations import dm_control
>>> env = dm_control.load("palpation")                        # doctest: +SKIP
>>> ts = env.reset(); ts = env.step(env.action_spec().generate_value())   # doctest: +SKIP
>>> from dm_control import viewer; viewer.launch(env)         # doctest: +SKIP  (needs a display)

**dm_control** (:func:`load`, ``dm_control.rl.control.Environment``). Physics, task and
environment are kept apart as dm_control does:

* :class:`SurgSimPhysics` is a ``dm_control.mujoco.Physics`` whose ``model``/``data`` are the
  scene's render twin (tools + the deformed tissue surfaces, :mod:`surgsim_envs.scene.visual`),
  so ``physics.render(...)`` and ``dm_control.viewer`` show the tissue; its :meth:`step` runs
  one control step of the SurgSim task (the task's substeps of :class:`~surgsim_envs.scene.Simulation`,
  tissue and contact included) and copies the state back into ``data``. Its ``timestep()`` is
  the task's control period, so one dm_control step is one task step.
* :class:`SurgSimTask` (a ``control.Task``) passes actions in and reads the observation (a dict
  of the task's named observation terms, SI units), the reward (``info["reward_terms"]`` are in
  ``physics.last_info``) and termination (discount 0) out.
* ``time_limit`` is the task's ``episode_seconds`` (truncation: discount 1).

Version check (this machine): dm-control 1.0.50 (the newest) requires ``mujoco>=3.17.0`` and
runs on our MuJoCo 4.0.0, except its named indexer (``physics.named``), which lists MjModel
fields MuJoCo 4.0 removed (``flex_vertedge``): here ``physics.named`` is None.

**dm_env** (:func:`make_dm_env`, ``pip install dm-env``): any ``gym.make`` keywords, one flat
observation array. Truncation (time limit) ends the episode with ``discount=1`` (dm_env's
truncation convention), termination with ``discount=0``.

>>> env = dm_control.make_dm_env("SurgSim/Palpation-v0", seed=0)   # doctest: +SKIP
>>> ts = env.reset(); ts = env.step(env.action_spec().generate_value())   # doctest: +SKIP
"""

from __future__ import annotations

import collections
import functools
import re

import numpy as np

from surgsim_envs.errors import ConfigError


def _short(task_id: str) -> str:
    """"SurgSim/PalpationPress-v0" -> "palpationpress"."""
    return task_id.split("/")[-1].split("-")[0].lower()


def _snake(task_id: str) -> str:
    """"SurgSim/PalpationPress-v0" -> "palpation_press"."""
    return re.sub(r"(?<!^)(?=[A-Z])", "_", task_id.split("/")[-1].split("-")[0]).lower()


def _names() -> dict[str, str]:
    """short name -> Gymnasium task id, for every task of the task registry."""
    from surgsim_envs.envs.registry import TASKS

    return {_short(tid): tid for tid in TASKS}


def _aliases() -> dict[str, str]:
    """Every name :func:`load` accepts: the short names and their snake_case spellings."""
    from surgsim_envs.envs.registry import TASKS

    table = _names()
    declared = {spec.dm_control: tid for tid, spec in TASKS.items() if spec.dm_control}   # TaskSpec.dm_control
    return {**{_snake(tid): tid for tid in table.values()}, **declared, **table}


def names() -> list[str]:
    """Short names of every task, one each ("palpation", "grasp", "slippage", "palpationpress",
    "layeredpalpation"); :func:`load` also accepts snake_case ("layered_palpation")."""
    return sorted(_names())


def _require_dm_control():
    try:
        from dm_control import mujoco as dm_mujoco
        from dm_control.rl import control
    except ImportError as exc:  # pragma: no cover - dm-control is a dependency
        raise ConfigError(f"the dm_control suite needs dm-control (pip install dm-control): {exc}") from exc
    return dm_mujoco, control


def load(name: str, task_kwargs: dict | None = None, environment_kwargs: dict | None = None):
    """A ``dm_control.rl.control.Environment`` of SurgSim task ``name`` (see :func:`names`).

    task_kwargs: config overrides of the task (as ``gym.make`` keywords, e.g. ``{"model": "fem"}``)
    plus ``random`` (an int seed for the episodes); environment_kwargs: extra keywords of
    ``control.Environment`` (e.g. ``flat_observation=True``)."""
    table = _aliases()
    if name not in table:
        raise ConfigError(f"unknown SurgSim task {name!r} for dm_control; choose one of {sorted(table)}")
    _, control = _require_dm_control()
    import gymnasium as gym

    import surgsim_envs  # noqa: F401  (registers the tasks)

    kwargs = dict(task_kwargs or {})
    seed = kwargs.pop("random", None)
    env = gym.make(table[name], **kwargs).unwrapped
    physics = SurgSimPhysics.from_env(env)
    task = SurgSimTask(env, random=seed)
    return control.Environment(physics, task, time_limit=env.config.episode_seconds, n_sub_steps=1,
                               **dict(environment_kwargs or {}))


@functools.lru_cache(maxsize=None)
def _physics_class():
    dm_mujoco, _ = _require_dm_control()
    from dm_control.mujoco import wrapper

    class _SurgSimPhysics(dm_mujoco.Physics):
        """dm_control Physics over a SurgSim task env (see the module docstring)."""

        @classmethod
        def from_env(cls, env):
            sim = env.sim
            physics = cls.from_model(wrapper.MjModel(sim.render_model))
            physics.env = env
            physics.pending_action = None
            physics.last_obs = None
            physics.last_reward = 0.0
            physics.last_terminated = False
            physics.last_truncated = False
            physics.last_info = {}
            return physics

        def _reload_from_data(self, data):
            # dm-control 1.0.50's named indexer lists MjModel fields MuJoCo 4.0 removed
            # (flex_vertedge, ...): it fails after everything else is set up. Then ``physics.named``
            # is None; stepping, rendering and the viewer work (tests/test_integration_dm_control.py).
            try:
                super()._reload_from_data(data)
            except AttributeError as exc:
                self._named = None
                self.named_indexing_error = str(exc)

        # -- dm_control.rl.control.Physics ---------------------------------------------------
        def step(self, nstep: int = 1) -> None:
            """``nstep`` SurgSim control steps with the pending action (zeros if none)."""
            env = self.env
            action = self.pending_action
            if action is None:
                action = np.zeros(env.action_space.shape, dtype=np.float32)
            for _ in range(int(nstep)):
                obs, reward, terminated, truncated, info = env.step(action)
                self.last_obs, self.last_reward, self.last_terminated, self.last_info = obs, reward, terminated, info
                self.last_truncated = bool(truncated)
                if terminated or truncated:
                    break
            self._sync()

        def reset(self, keyframe_id=None) -> None:
            """Nothing here: the episode starts in ``SurgSimTask.initialize_episode`` (one env reset
            with the task's seed, not two)."""

        def reset_episode(self, seed: int | None) -> None:
            """Reset the SurgSim task (domain randomisation with ``seed``)."""
            obs, info = self.env.reset(seed=seed)
            self.last_obs, self.last_reward, self.last_terminated, self.last_info = obs, 0.0, False, info
            self.last_truncated = False

        def after_reset(self) -> None:
            self._sync()

        def timestep(self) -> float:
            """The task's control period (s): one dm_control step is one task step."""
            return float(self.env.control_dt)

        def time(self) -> float:
            return float(self.env.sim.time)

        def check_invalid_state(self) -> None:  # the tissue guard raises TissueUnstableError itself
            return None

        def _sync(self) -> None:
            """Copy the task simulation's render state into this Physics' MjData."""
            import mujoco

            env = getattr(self, "env", None)
            if env is None:        # during dm_control's own construction (before from_env sets it)
                return
            sim = env.sim
            data = sim.sync_visual()
            if sim.render_model.nflexvert != self.model.nflexvert or sim.render_model.nbody != self.model.nbody:
                self._reload_from_model(wrapper.MjModel(sim.render_model))   # another organ's scene
            mujoco.mj_copyData(self.data.ptr, sim.render_model, data)

    return _SurgSimPhysics


@functools.lru_cache(maxsize=None)
def _task_class():
    _, control = _require_dm_control()
    from dm_env import specs

    class _SurgSimTask(control.Task):
        """dm_control Task over a SurgSim task env (see the module docstring)."""

        def __init__(self, env, random=None):
            self.env = env
            self._rng = np.random.default_rng(random)

        def initialize_episode(self, physics) -> None:
            physics.reset_episode(int(self._rng.integers(2**31)))

        def before_step(self, action, physics) -> None:
            physics.pending_action = np.asarray(action, dtype=np.float32)

        def action_spec(self, physics):
            a = self.env.action_space
            return specs.BoundedArray(a.shape, np.float32, a.low, a.high, name="action")

        def get_observation(self, physics):
            obs = np.asarray(physics.last_obs, dtype=np.float64)
            out, i = collections.OrderedDict(), 0
            for term in self.env.observation_terms:
                out[term.name] = obs[i:i + term.size].copy()
                i += term.size
            return out

        def get_reward(self, physics) -> float:
            return float(physics.last_reward)

        def get_termination(self, physics):
            # terminated: discount 0; the task's own step limit (e.g. PalpationPress-v0's max_presses,
            # where one step is a whole press) ends the episode with discount 1, like the time limit
            if physics.last_terminated:
                return 0.0
            return 1.0 if getattr(physics, "last_truncated", False) else None

    return _SurgSimTask


def SurgSimPhysics(*args, **kwargs):  # noqa: N802 - the class is built on first use (dm_control import)
    """The dm_control Physics class (see the module docstring)."""
    return _physics_class()(*args, **kwargs)


SurgSimPhysics.from_env = lambda env: _physics_class().from_env(env)  # type: ignore[attr-defined]


def SurgSimTask(env, random=None):  # noqa: N802
    """The dm_control Task class (see the module docstring)."""
    return _task_class()(env, random=random)


# -- dm_env ---------------------------------------------------------------------------------------
def make_dm_env(env_id: str, seed: int | None = None, **kwargs):
    """A dm_env.Environment wrapping ``gym.make(env_id, **kwargs)``."""
    try:
        import dm_env  # noqa: F401
    except ImportError as exc:
        raise ConfigError("the dm_env adapter needs dm-env: pip install dm-env (or the [test] extra)") from exc
    import gymnasium as gym

    import surgsim_envs  # noqa: F401  (registers the tasks)

    return DmEnvAdapter(gym.make(env_id, **kwargs), seed=seed)


def _adapter_class():
    import dm_env
    from dm_env import specs

    class _DmEnvAdapter(dm_env.Environment):
        def __init__(self, env, seed=None):
            self.env = env
            self._seed = seed
            self._reset_next = True
            space = env.observation_space
            self._obs_spec = specs.Array(space.shape, space.dtype, name="observation")
            a = env.action_space
            self._act_spec = specs.BoundedArray(a.shape, a.dtype, a.low, a.high, name="action")

        def reset(self):
            obs, _ = self.env.reset(seed=self._seed)
            self._seed = None
            self._reset_next = False
            return dm_env.restart(np.asarray(obs))

        def step(self, action):
            if self._reset_next:
                return self.reset()
            obs, reward, terminated, truncated, self.last_info = self.env.step(action)
            obs = np.asarray(obs)
            if terminated:
                self._reset_next = True
                return dm_env.termination(reward, obs)
            if truncated:
                self._reset_next = True
                return dm_env.truncation(reward, obs)
            return dm_env.transition(reward, obs)

        def observation_spec(self):
            return self._obs_spec

        def action_spec(self):
            return self._act_spec

        def close(self):
            self.env.close()

    return _DmEnvAdapter


def DmEnvAdapter(env, seed: int | None = None):
    """Wrap a Gymnasium env as a dm_env.Environment (the class is built on first use)."""
    return _adapter_class()(env, seed)

"""The base of the batched vector envs: one task's episodes in W batched worlds (:class:`BatchedTaskEnv`).

A task's batched env is one small module on this base (``batch/palpation_env.py``,
``batch/grasp_env.py``), registered through ``TaskSpec.batched``:
``gym.make_vec(task_id, num_envs=W, vectorization_mode="vector_entry_point", device="cpu")``
(``device="cuda"`` where a GPU exists). The base holds what every task shares:

* the single env built once as the template (its config, spaces, observation names, declared
  reward and termination terms) and the :class:`~surgsim_envs.batch.simulation.BatchSimulation` of
  its scene;
* seeding: world i of ``reset(seed=s)`` draws from its own generator seeded ``s + i``, as
  Gymnasium's vector envs seed their copies, so it is ``gym.make(task_id).reset(seed=s + i)``;
* reset options: the task's ``OPTIONS`` less those a batch cannot honour (``REFUSED``: option ->
  why), refused with a :class:`~surgsim_envs.errors.ConfigError` naming the option and the reason;
  ``reset_mask`` (Gymnasium's vector-env option) restarts only the masked worlds;
* the step: action checks, the task's commands for the live worlds, the physics, diverged worlds
  (``on_unstable``), the task's evaluation, and Gymnasium's NEXT_STEP autoreset per world (the step
  after a world's episode ended resets it: its action is ignored, reward 0, terminated/truncated
  False, and it returns its first observation);
* the term loop (:meth:`_term_loop`): the single env's declared reward terms run for each live
  world on a :class:`~surgsim_envs.batch.world_view.WorldView` of it, so the batched env computes
  the same functions, in the declared order, not a second copy of their arithmetic;
* :meth:`device_arrays`: the physics arrays on the device (Warp arrays: ``__dlpack__``,
  ``wp.to_torch``, ``wp.to_jax`` share them without copies). Observations and rewards come back
  as numpy arrays, unless the task computes them on the device (``DEVICE_OUTPUTS``) and the env
  is built with ``device_outputs=True``: then ``step`` and ``reset`` return Warp arrays on the
  device (the task's ``_device_step``; Palpation-v0, Grasp-v0 and Slippage-v0, docs/batch.md).

A task module supplies ``TEMPLATE`` (the single env's class), ``_reset_worlds``,
``_apply_actions``, ``_evaluate``, ``_observe`` and ``_reset_info`` (and ``_physics`` where its
actuators follow a control schedule rather than the rate limiter).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from surgsim_envs.batch.simulation import BatchSimulation
from surgsim_envs.batch.world_view import WorldView
from surgsim_envs.envs.terms.reward import RewardManager
from surgsim_envs.errors import ConfigError


class BatchedTaskEnv(VectorEnv):
    """A task's episodes in ``num_envs`` batched worlds on Warp device ``device`` (module docstring).

    num_envs: worlds W; device: "cpu" (Warp's CPU device, everywhere) or "cuda"; graphs: "auto"
    (the physics of a step replayed as a CUDA graph on a GPU, :mod:`~surgsim_envs.batch.step_graph`),
    "on" or "off"; config / overrides: as for ``gym.make(task_id, ...)`` (the task's config dataclass
    and field overrides).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}
    #: the single env's class (its config, spaces and declared terms)
    TEMPLATE: ClassVar[type]
    #: reset options of the single env a batch cannot honour: option -> why
    REFUSED: ClassVar[dict[str, str]] = {}
    #: config fields the batched worlds take when neither ``config`` nor an override sets them: the
    #: model (and lattice) the batched kernels step, where the single env defaults to another
    BATCHED_DEFAULTS: ClassVar[dict[str, Any]] = {}
    #: the task computes its observations, rewards and terms on the device (``device_outputs=True``)
    DEVICE_OUTPUTS: ClassVar[bool] = False

    def __init__(self, num_envs: int = 1, *, device: str = "cpu", config=None, max_episode_steps: int | None = None,
                 device_outputs: bool = False, graphs: str = "auto", **overrides):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ConfigError(f"num_envs={num_envs!r} must be a positive integer (batched worlds)")
        if not isinstance(device_outputs, (bool, np.bool_)):
            raise ConfigError(f"device_outputs={device_outputs!r} must be True (observations, rewards and terms as "
                              "Warp arrays on the device) or False (numpy arrays, the default)")
        if device_outputs and not self.DEVICE_OUTPUTS:
            raise ConfigError(f"device_outputs=True: {type(self).__name__} computes its observations and rewards on "
                              "the host (numpy); only BatchedPalpationEnv (SurgSim/Palpation-v0), "
                              "BatchedGraspEnv (SurgSim/Grasp-v0) and BatchedSlippageEnv (SurgSim/Slippage-v0) "
                              "compute them on the device. Leave device_outputs out for this task")
        self.device_outputs = bool(device_outputs)
        if config is None:
            overrides = {**self.BATCHED_DEFAULTS, **overrides}
        self.template = self.TEMPLATE(config=config, render_mode=None, **overrides)
        if max_episode_steps is not None and max_episode_steps != self.template.max_episode_steps:
            raise ConfigError(f"max_episode_steps={max_episode_steps!r}: the batched env ends episodes at the config's "
                              f"{self.template.max_episode_steps} control steps (episode_seconds x control_hz); "
                              "change episode_seconds instead")
        self.config = self.template.config
        self.sim = BatchSimulation(self.template.sim, int(num_envs), device=device, graphs=graphs)
        self.num_envs = W = int(num_envs)
        self.device = self.sim.device
        self.single_observation_space = self.template.observation_space
        self.single_action_space = self.template.action_space
        self.observation_space = batch_space(self.single_observation_space, W)
        self.action_space = batch_space(self.single_action_space, W)
        self.observation_names = self.template.observation_names
        # the reward and termination terms the single env declares (names, order, weight fields, functions)
        self.rewards = RewardManager(type(self.template).REWARD_TERMS, self.config)
        self.reward_term_names = self.rewards.names
        self.termination_terms = tuple(type(self.template).TERMINATION_TERMS)
        self._view = WorldView(self.config, self.template.control_dt)
        self.substeps = self.template.substeps
        self.control_dt = self.template.control_dt
        self.max_episode_steps = self.template.max_episode_steps
        self.OPTIONS = tuple(o for o in type(self.template).OPTIONS if o not in self.REFUSED)
        self._rngs = [seeding.np_random(None)[0] for _ in range(W)]
        self._steps = np.zeros(W, dtype=np.int64)
        self._autoreset = np.zeros(W, dtype=bool)
        self._obs = np.zeros((W,) + self.single_observation_space.shape, dtype=np.float32)
        self._readings = None

    # -- the task's part --------------------------------------------------------------------------
    def _reset_worlds(self, idx: np.ndarray, options: dict[str, Any]) -> None:
        """Randomise and reset worlds ``idx`` as the single env's reset does (same draws, same order)."""
        raise NotImplementedError

    def _apply_actions(self, a: np.ndarray, live: np.ndarray) -> None:
        """Commands of the (clipped) actions ``a`` (W, A) for the worlds where ``live`` is True."""
        raise NotImplementedError

    def _evaluate(self, a: np.ndarray, live: np.ndarray):
        """(rewards (W,), terminated (W,), truncated (W,), info) after the physics of a control step,
        for the ``live`` worlds (zeros and False elsewhere)."""
        raise NotImplementedError

    def _observe(self) -> np.ndarray:
        raise NotImplementedError

    def _reset_info(self, idx) -> dict:
        return {}

    def _physics(self) -> None:
        """The physics of one control step in every world (the rate limiter moves the controls the
        task set); a task that drives its actuators by a control schedule replaces it."""
        self.sim.step(self.substeps)

    # -- episodes ---------------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        """Reset every world, or with ``options={"reset_mask": mask}`` (a (W,) numpy bool array, as
        Gymnasium's vector envs take it) only the worlds where ``mask`` is True: the others keep their
        episodes, and the returned observations hold every world's current one. ``seed``: an int s
        seeds world i with s + i, or a list of W seeds (with a mask, only the masked worlds are reseeded)."""
        options = dict(options or {})
        mask = self._reset_mask(options.pop("reset_mask", None))
        refused = sorted(set(options) & set(self.REFUSED))
        if refused:
            name = refused[0]
            raise ConfigError(f"reset option {name!r} cannot be honoured by {type(self).__name__}: "
                              f"{self.REFUSED[name]}")
        unknown = sorted(set(options) - set(self.OPTIONS))
        if unknown:
            raise ConfigError(f"unknown reset option(s) {unknown} for {type(self).__name__}; accepted options: "
                              f"{list(self.OPTIONS)}")
        idx = np.arange(self.num_envs) if mask is None else np.flatnonzero(mask)
        if seed is not None:
            seeds = [int(seed) + i for i in range(self.num_envs)] if not hasattr(seed, "__len__") else list(seed)
            if len(seeds) != self.num_envs:
                raise ConfigError(f"seed must be an int or {self.num_envs} ints, got {len(seeds)}")
            for i in idx:
                self._rngs[i] = seeding.np_random(seeds[i])[0]
        self._reset_worlds(idx, options)
        self._autoreset[idx] = False
        obs = self._observe()                 # before the info: a device task's info reads what it observed
        info = self._reset_info(idx)
        if mask is not None:                  # Gymnasium's convention: which worlds the entries are new for
            info.update({f"_{key}": mask.copy() for key in list(info)})
        return obs, info

    def _reset_mask(self, mask):
        """``options["reset_mask"]`` checked: None, or a (W,) numpy bool array with a True."""
        if mask is None:
            return None
        W = self.num_envs
        if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.shape != (W,) or not mask.any():
            raise ConfigError(f"options['reset_mask'] must be a numpy bool array of shape ({W},) with at least one "
                              f"True (the worlds to reset), got {type(mask).__name__} "
                              f"{getattr(mask, 'dtype', '')} {getattr(mask, 'shape', '')}")
        return mask

    def _device_step(self, a: np.ndarray, live: np.ndarray, unstable: np.ndarray):
        """The rest of :meth:`step` (evaluation, autoreset, observation) on the device, for a task
        with ``DEVICE_OUTPUTS``: ``(obs, rewards, terminated, truncated, info)`` as device arrays.
        This is the grasp scene's flow: the task's ``_device_terms.evaluate(live, unstable)`` gives
        the step's outputs and the ended worlds, the autoreset worlds restart, ``_observe`` sets
        ``_device_metrics`` (the episode metrics, their rows the new episode's after a reset) and
        ``_device_info(out)`` names the task's own info entries."""
        out, done = self._device_terms.evaluate(live & ~unstable, unstable & live)   # an autoreset world is not terminated
        done_before = np.flatnonzero(self._autoreset)
        if len(done_before):                  # not live this step: reward 0, not terminated nor truncated
            self._reset_worlds(done_before, {})
        self._autoreset = done
        obs = self._observe()
        info = {k: v for k, v in self._device_metrics.items() if k != "steps"}
        info.update({"reward_terms": {name: out["terms"][j] for j, name in enumerate(self.reward_term_names)},
                     "steps": self._device_metrics["steps"], **self._device_info(out)})
        if unstable.any():
            info["unstable"], info["_unstable"] = unstable.copy(), unstable.copy()
        return obs, out["reward"], out["terminated"], out["truncated"], info

    def _device_info(self, out: dict) -> dict:
        """The task's own info entries of a device step, from ``out`` (its device terms' outputs)."""
        raise NotImplementedError

    def step(self, actions):
        a, live, unstable = self._advance(actions)
        if self.device_outputs:
            return self._device_step(a, live, unstable)
        rewards, terminated, truncated, info = self._evaluate(a, live & ~unstable)
        if unstable.any():
            terminated |= unstable
            info["unstable"], info["_unstable"] = unstable.copy(), unstable.copy()
        done_before = np.flatnonzero(self._autoreset)
        if len(done_before):
            self._reset_worlds(done_before, {})
            rewards[done_before] = 0.0
            terminated[done_before] = False
            truncated[done_before] = False
            for key, value in self._reset_info(done_before).items():    # their rows: the new episode's
                if key in info and np.shape(info[key]) == np.shape(value):
                    info[key] = np.array(info[key])
                    info[key][done_before] = np.asarray(value)[done_before]
        self._autoreset = terminated | truncated
        info["steps"] = self._steps.copy()          # control steps of each world's episode (0: just reset)
        return self._observe(), rewards, terminated, truncated, info

    def _advance(self, actions):
        """The step up to the task's evaluation: checked, clipped actions (W, A) float64, the task's
        commands for the live worlds, the physics, the step counts, the diverged worlds reset;
        returns ``(actions, live, unstable)`` (W,) masks."""
        c, W = self.config, self.num_envs
        shape = (W,) + self.single_action_space.shape
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != shape or not np.all(np.isfinite(a)):
            raise ConfigError(f"actions must be finite {shape} numbers in [-1, 1], got shape {a.shape}")
        a = np.clip(a, -1.0, 1.0)
        live = ~self._autoreset
        if live.any():
            self._apply_actions(a, live)
        self._physics()
        self._readings = None
        self._steps[live] += 1
        unstable = np.zeros(W, dtype=bool)
        bad = self.sim.diverged_worlds()
        if len(bad):
            if c.on_unstable != "terminate":
                self.sim.check_stable()
            unstable[bad] = True          # as the single env: the episode ends, the world restarts from rest
            self._reset_worlds(bad, {})
        return a, live, unstable

    def _term_loop(self, live: np.ndarray, view_of) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """(reward (W,), {term name: (W,) weighted values}) of the single env's declared reward terms,
        summed in declared order, for the ``live`` worlds (0 elsewhere); ``view_of(w)`` points the
        :class:`WorldView` at world w and returns it."""
        W = self.num_envs
        terms = {name: np.zeros(W) for name in self.reward_term_names}
        reward = np.zeros(W)
        for w in np.flatnonzero(live):
            reward[w], values = self.rewards.compute(view_of(w))
            for name, v in values.items():
                terms[name][w] = v
        return reward, terms

    def device_arrays(self) -> dict:
        """The physics arrays on the device (:meth:`BatchSimulation.arrays`), shared without copies."""
        return self.sim.arrays()

    def close(self, **kwargs) -> None:
        self.template.close()

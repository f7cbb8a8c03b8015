"""The one task registry: every SurgSim task is one folder (``envs/<task>/``) plus one :class:`TaskSpec`.

Gymnasium registration (:func:`register_envs`), the shipped policies, the scripted experts, the
dm_control loader names and every test table read :data:`TASKS`. A spec names its classes and
functions as ``"module:attribute"`` strings, so reading the registry imports no task (and no
MuJoCo); :meth:`TaskSpec.load` resolves one.

>>> from surgsim_envs.envs.registry import task_spec
>>> task_spec("SurgSim/Grasp-v0").max_episode_steps
150

Adding a task: write its folder (config, env, terms, expert; docs/adding_a_task.md walks through
one) and :func:`register` its spec (or add it to :data:`TASKS` here to ship it).
"""

from __future__ import annotations

import importlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

from surgsim_envs.errors import ConfigError
from surgsim_envs.policies import POLICY_DIR


@dataclass(frozen=True)
class ForceTolerance:
    """How far a task's contact forces may be off a converged reference and the task still mean what
    it says: ``value`` is a fraction of the force (``relative``) or newtons (not relative); ``why``
    says what in the task sets it. :func:`surgsim_envs.tissue.resolution.choose` picks the cheapest
    tissue resolution within a relative tolerance (the config's ``error_tolerance``)."""

    value: float
    relative: bool = True
    why: str = ""

    def __post_init__(self):
        if not (isinstance(self.value, (int, float)) and math.isfinite(self.value) and self.value > 0):
            raise ConfigError(f"ForceTolerance.value={self.value!r} must be a positive finite number "
                              "(a fraction with relative=True, else newtons)")
        if self.relative and self.value >= 1.0:
            raise ConfigError(f"ForceTolerance.value={self.value!r} is a relative tolerance of 100 % or more; "
                              "give a fraction below 1 (e.g. 0.1 for 10 %) or relative=False for newtons")

    def allows(self, force: float, reference: float) -> bool:
        """True if ``force`` (N) is within the tolerance of ``reference`` (N)."""
        bound = self.value * abs(reference) if self.relative else self.value
        return abs(force - reference) <= bound


@dataclass(frozen=True)
class TaskSpec:
    """Everything the package needs to know about a task, in one place (SI units).

    id: the Gymnasium id ("SurgSim/Name-vN"); entry_point / config: "module:Class" of the env and
    its config dataclass; scene: the ready-made scene it builds (:data:`surgsim_envs.scene.SCENES`;
    None: the task builds its own); tool: the tool the agent drives; model: the default tissue
    model; force_tolerance: see :class:`ForceTolerance`; max_episode_steps: control steps of an
    episode at the default config (Gymnasium's TimeLimit); policy: the shipped policy's file in
    ``surgsim_envs/policies`` (None: none shipped); quasi_static: one equilibrium solve per step
    (seconds, not microseconds: kept out of the physics-rate test tables); quick: config overrides
    that make a small, fast instance for tests; expert: "module:function" of the scripted expert
    (``expert(env) -> policy(obs) -> action``; None: none); dm_control: the name the dm_control
    loader knows it by; batched: "module:Class" of its batched Warp vector env (the [batch] extra,
    docs/batch.md; ``gym.make_vec(id, n, device=...)``), None: none yet.
    """

    id: str
    entry_point: str
    config: str
    scene: str | None
    tool: str
    model: str
    force_tolerance: ForceTolerance
    max_episode_steps: int
    policy: str | None = None
    quasi_static: bool = False
    quick: Mapping[str, Any] = field(default_factory=dict, hash=False)   # a read-only view: not hashable
    expert: str | None = None
    dm_control: str = ""
    batched: str | None = None

    def __post_init__(self):
        if not (isinstance(self.id, str) and self.id.count("/") == 1 and "-v" in self.id):
            raise ConfigError(f"TaskSpec.id={self.id!r} must look like 'Namespace/Name-v0'")
        for name in ("entry_point", "config") + tuple(n for n in ("expert", "batched") if getattr(self, n) is not None):
            value = getattr(self, name)
            if not (isinstance(value, str) and value.count(":") == 1 and all(value.split(":"))):
                raise ConfigError(f"TaskSpec({self.id}).{name}={value!r} must be 'module:attribute'")
        if isinstance(self.max_episode_steps, bool) or not isinstance(self.max_episode_steps, int) \
                or self.max_episode_steps < 1:
            raise ConfigError(f"TaskSpec({self.id}).max_episode_steps={self.max_episode_steps!r} must be a "
                              "positive integer (control steps per episode)")
        object.__setattr__(self, "quick", MappingProxyType(dict(self.quick)))
        if not self.dm_control:
            object.__setattr__(self, "dm_control", _snake_name(self.id))

    @staticmethod
    def load(ref: str):
        """The object a "module:attribute" string names (imports its module)."""
        module, _, name = ref.partition(":")
        return getattr(importlib.import_module(module), name)

    @property
    def env_class(self):
        """The env class (imports the task)."""
        return self.load(self.entry_point)

    @property
    def config_class(self):
        """The config dataclass (imports the task)."""
        return self.load(self.config)

    @property
    def policy_path(self) -> Path | None:
        """The shipped policy file (None if the task ships none)."""
        return None if self.policy is None else POLICY_DIR / self.policy


def _snake_name(task_id: str) -> str:
    """"SurgSim/PalpationPress-v0" -> "palpation_press"."""
    name = task_id.split("/")[-1].split("-")[0]
    return "".join("_" + ch.lower() if ch.isupper() and i else ch.lower() for i, ch in enumerate(name))


_PALPATION_WHY = ("the task is to find a lump by the force it adds: over the 5x lump of radius 7 mm, 11 mm "
                  "deep, the graded FEM reference reads 35 % more than at the mirror site (7 mm press; the 3x "
                  "lumps the task also draws add less), so a model must keep its force error under about half of "
                  "that; 10 % also keeps the 1.5 N damage threshold within 0.15 N (docs/task_accuracy.md)")

#: THE task registry: id -> spec (in registration order)
TASKS: dict[str, TaskSpec] = {spec.id: spec for spec in (
    TaskSpec("SurgSim/Palpation-v0", "surgsim_envs.envs.palpation:PalpationEnv",
             "surgsim_envs.envs.palpation:PalpationConfig", scene="palpation", tool="probe", model="fem_static",
             force_tolerance=ForceTolerance(0.1, why=_PALPATION_WHY), max_episode_steps=600,
             policy="palpation_v0.npz", quick={"spacing": 0.02},
             expert="surgsim_envs.envs.palpation:palpation_expert",
             batched="surgsim_envs.batch.palpation_env:BatchedPalpationEnv"),
    TaskSpec("SurgSim/Grasp-v0", "surgsim_envs.envs.grasp:GraspEnv", "surgsim_envs.envs.grasp:GraspConfig",
             scene="grasp", tool="grasper", model="mass_spring",
             force_tolerance=ForceTolerance(0.1, why=(
                 "the reward switches on the jaw normal force: 'holds' above 0.03 N, damage above 1 N per jaw; "
                 "10 % keeps both onsets within a tenth of where they are set")),
             max_episode_steps=150, policy="grasp_v0.npz", quick={"resolution": 0.015},
             expert="surgsim_envs.envs.grasp:grasp_expert", batched="surgsim_envs.batch.grasp_env:BatchedGraspEnv"),
    TaskSpec("SurgSim/Slippage-v0", "surgsim_envs.envs.slippage:SlippageEnv",
             "surgsim_envs.envs.slippage:SlippageConfig", scene="grasp", tool="grasper", model="mass_spring",
             force_tolerance=ForceTolerance(0.1, why=(
                 "the grasp slips when the pull exceeds mu x the normal force; a 10 % normal-force error moves "
                 "the slip onset by 10 % of the pull, small against the 0.3-1.0 friction randomisation")),
             max_episode_steps=150, policy="slippage_v0.npz", quick={"resolution": 0.015},
             expert="surgsim_envs.envs.slippage:slippage_expert",
             batched="surgsim_envs.batch.slippage_env:BatchedSlippageEnv"),
    TaskSpec("SurgSim/PalpationPress-v0", "surgsim_envs.envs.palpation_press:PalpationPressEnv",
             "surgsim_envs.envs.palpation_press:PalpationPressConfig", scene="palpation", tool="probe",
             model="fem_static", force_tolerance=ForceTolerance(0.1, why=_PALPATION_WHY),
             max_episode_steps=25, policy="palpation_press_v0.npz", quick={"spacing": 0.02},
             expert="surgsim_envs.envs.palpation_press:press_expert"),
    TaskSpec("SurgSim/LayeredPalpation-v0", "surgsim_envs.envs.layered_palpation:LayeredPalpationEnv",
             "surgsim_envs.envs.layered_palpation:LayeredPalpationConfig", scene=None, tool="probe",
             model="fem_hex",
             force_tolerance=ForceTolerance(0.2, why=(
                 "the task is to find the nodule by the force it adds: over the 30x nodule (radius 8 mm, mid-fat) "
                 "the layered FEM reference reads C = 4.2-4.9 x the force at the mirror site (2.5-4.5 mm presses; "
                 "4.2 on its 2 mm lattices, 4.9 on its 0.71 mm ones). A model reading the nodule e low and the mirror "
                 "site e high shrinks C by (1 - e) / (1 + e); keeping at least half of the excess, (C + 1) / 2, "
                 "needs e <= (C - 1) / (3 C + 1) = 23-25 %, so 20 % (docs/task_accuracy.md)")),
             max_episode_steps=30, policy="layered_palpation_v0.npz", quasi_static=True,
             quick={"spacing": 0.01, "size": (0.04, 0.04), "max_presses": 5}),
)}


def task_spec(task_id: str) -> TaskSpec:
    """The spec of ``task_id``; ConfigError listing the known ids."""
    try:
        return TASKS[task_id]
    except (KeyError, TypeError):
        raise ConfigError(f"unknown task {task_id!r}; known tasks: {list(TASKS)}") from None


def register(spec: TaskSpec) -> TaskSpec:
    """Add ``spec`` to :data:`TASKS` and to Gymnasium (ConfigError if another spec has its id)."""
    if not isinstance(spec, TaskSpec):
        raise ConfigError(f"register needs a TaskSpec, got {type(spec).__name__}")
    if spec.id in TASKS and TASKS[spec.id] != spec:
        raise ConfigError(f"task {spec.id!r} is already registered with a different spec; give the new task its "
                          "own id (e.g. a new version suffix -v1)")
    TASKS[spec.id] = spec
    register_with_gymnasium(spec)
    return spec


def register_with_gymnasium(spec: TaskSpec) -> None:
    """``gymnasium.register`` of one spec (idempotent), with its ``max_episode_steps`` (Gymnasium adds
    its TimeLimit wrapper, and the env truncates at the same step itself, paying its end-of-episode
    terms) and the package's shared-memory vector env as its ``vector_entry_point``
    (``gym.make_vec(task, n)``; ``vectorization_mode="sync"``/``"async"`` give Gymnasium's).

    Gymnasium's passive env checker is off: after a first ``reset`` that raises (e.g. a bad option)
    it keeps no reset data and every later ``step`` failed with a TypeError. The envs check their
    own actions, options and outputs; ``gymnasium.utils.env_checker.check_env`` passes on every
    task (tests/test_envs.py)."""
    import gymnasium as gym

    if spec.id in gym.registry:
        return
    # the vector entry is a string (JSON-serialisable spec) that surgsim_envs.envs.__getattr__ resolves
    gym.register(id=spec.id, entry_point=spec.entry_point, disable_env_checker=True,
                 max_episode_steps=spec.max_episode_steps,
                 vector_entry_point=f"surgsim_envs.envs:make_vector|{spec.id}")


def shipped_tasks() -> list[str]:
    """Task ids with a shipped policy whose file is present."""
    return [s.id for s in TASKS.values() if s.policy_path is not None and s.policy_path.is_file()]


def shipped_policy_path(task_id: str) -> Path:
    """The shipped policy file of ``task_id`` (ConfigError naming the tasks that have one)."""
    spec = TASKS.get(task_id) if isinstance(task_id, str) else None
    if spec is None or spec.policy_path is None or not spec.policy_path.is_file():
        raise ConfigError(f"no shipped policy for task {task_id!r}; shipped: {shipped_tasks()}")
    return spec.policy_path


def load_shipped(task_id: str, mode: str | None = None, seed: int | None = 0):
    """The shipped :class:`~surgsim_envs.policies.npz_policy.NpzPolicy` of ``task_id``, acting in the
    file's recorded ``mode`` (PalpationPress-v0: stochastic) unless ``mode`` is given; ``seed``
    seeds its action sampler (``policy.reset(seed)`` reseeds it per episode)."""
    from surgsim_envs.policies.npz_policy import NpzPolicy

    return NpzPolicy.load(shipped_policy_path(task_id), mode=mode, seed=seed)


def expert(task_id: str):
    """The scripted expert factory of ``task_id`` (ConfigError naming the tasks that have one)."""
    spec = task_spec(task_id)
    if spec.expert is None:
        raise ConfigError(f"task {task_id!r} has no scripted expert; tasks with one: "
                          f"{[s.id for s in TASKS.values() if s.expert]}")
    return spec.load(spec.expert)


__all__ = ["ForceTolerance", "TaskSpec", "TASKS", "task_spec", "register", "register_with_gymnasium",
           "shipped_tasks", "shipped_policy_path", "load_shipped", "expert"]

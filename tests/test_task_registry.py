"""The task registry (surgsim_envs/envs/registry.py): one TaskSpec per task, and everything that
lists tasks (Gymnasium registration, the derived id tables, shipped policies, experts, scenes,
tissue models) agrees with it."""

import dataclasses

import gymnasium as gym
import pytest

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs import envs
from surgsim_envs.envs.checks import apply_overrides
from surgsim_envs.envs.registry import (TASKS, ForceTolerance, TaskSpec, expert, register, shipped_policy_path,
                                        task_spec)
from surgsim_envs.errors import ConfigError

IDS = list(TASKS)


def test_the_five_shipped_tasks_are_in_the_registry():
    assert {"SurgSim/Palpation-v0", "SurgSim/Grasp-v0", "SurgSim/Slippage-v0", "SurgSim/PalpationPress-v0",
            "SurgSim/LayeredPalpation-v0"} <= set(TASKS)


def test_the_old_id_tables_are_derived_from_the_registry():
    assert envs.TASKS == {t: s.entry_point for t, s in TASKS.items() if not s.quasi_static}
    assert envs.QUASI_STATIC_TASKS == {t: s.entry_point for t, s in TASKS.items() if s.quasi_static}
    assert envs.MAX_EPISODE_STEPS == {t: s.max_episode_steps for t, s in TASKS.items()}


@pytest.mark.parametrize("task", IDS)
def test_spec_matches_gymnasium_and_the_task_classes(task):
    spec = task_spec(task)
    assert gym.spec(task).entry_point == spec.entry_point
    assert gym.spec(task).max_episode_steps == spec.max_episode_steps
    env_cls, cfg_cls = spec.env_class, spec.config_class
    assert env_cls.config_cls is cfg_cls
    assert getattr(env_cls, "TASK_ID", task) == task


@pytest.mark.parametrize("task", IDS)
def test_spec_names_what_exists(task):
    from surgsim_envs.scene import SCENES
    from surgsim_envs.tissue.registry import names as model_names

    spec = task_spec(task)
    assert spec.scene is None or spec.scene in SCENES
    assert spec.model in model_names()
    cfg = spec.config_class()
    if hasattr(cfg, "model"):
        assert cfg.model == spec.model                      # the default model is the config's default
    quick = apply_overrides(cfg, dict(spec.quick))          # quick overrides are config fields ...
    quick.validate()                                        # ... giving a valid config
    assert shipped_policy_path(task).is_file() if spec.policy else True
    if spec.expert:
        assert callable(expert(task))


@pytest.mark.parametrize("task", IDS)
def test_relative_force_tolerance_is_the_configs_error_tolerance(task):
    """``resolution="auto"`` chooses the lattice within the config's ``error_tolerance``: it is the
    task's declared relative force tolerance, not a second number."""
    spec = task_spec(task)
    cfg = spec.config_class()
    assert spec.force_tolerance.why
    if hasattr(cfg, "error_tolerance"):
        assert spec.force_tolerance.relative and cfg.error_tolerance == spec.force_tolerance.value


def test_dm_control_names_are_unique_snake_case():
    names = [s.dm_control for s in TASKS.values()]
    assert len(set(names)) == len(names)
    assert task_spec("SurgSim/PalpationPress-v0").dm_control == "palpation_press"


def test_unknown_task_lists_the_known_ones():
    with pytest.raises(ConfigError, match=r"unknown task 'SurgSim/Nope-v0'; known tasks: \['SurgSim/Palpation-v0'"):
        task_spec("SurgSim/Nope-v0")


def test_expert_of_a_task_without_one_names_those_with_one():
    with pytest.raises(ConfigError, match="has no scripted expert; tasks with one: .*Grasp-v0"):
        expert("SurgSim/LayeredPalpation-v0")


def test_force_tolerance_bounds():
    t = ForceTolerance(0.1, why="x")
    assert t.allows(1.09, 1.0) and not t.allows(1.11, 1.0)
    a = ForceTolerance(0.05, relative=False)
    assert a.allows(2.04, 2.0) and not a.allows(2.06, 2.0)
    with pytest.raises(ConfigError, match="relative tolerance of 100 % or more"):
        ForceTolerance(1.5)
    with pytest.raises(ConfigError, match="positive finite"):
        ForceTolerance(float("nan"), relative=False)


def test_spec_fields_are_checked():
    spec = task_spec("SurgSim/Grasp-v0")
    with pytest.raises(ConfigError, match="must look like 'Namespace/Name-v0'"):
        dataclasses.replace(spec, id="Grasp")
    with pytest.raises(ConfigError, match=r"entry_point='nomodule' must be 'module:attribute'"):
        dataclasses.replace(spec, entry_point="nomodule")
    with pytest.raises(ConfigError, match="max_episode_steps=0 must be a positive integer"):
        dataclasses.replace(spec, max_episode_steps=0)
    with pytest.raises(TypeError):
        spec.quick["spacing"] = 1.0                         # frozen: a test cannot change another's overrides


def test_register_refuses_a_different_spec_under_a_taken_id():
    spec = task_spec("SurgSim/Grasp-v0")
    with pytest.raises(ConfigError, match="already registered with a different spec"):
        register(dataclasses.replace(spec, max_episode_steps=151))
    assert register(spec) is spec                            # the same spec again is a no-op
    with pytest.raises(ConfigError, match="register needs a TaskSpec"):
        register("SurgSim/Grasp-v0")
    assert isinstance(spec, TaskSpec)


def test_tasks_sharing_a_scene_drive_the_same_tool():
    """Scenarios drive a ready-made scene's tool (scenarios/phases.py SCENE_TOOL, read from the
    registry): two tasks on one scene must not name different tools."""
    from surgsim_envs.scenarios.phases import SCENE_TOOL

    for spec in TASKS.values():
        if spec.scene is not None:
            assert SCENE_TOOL[spec.scene] == spec.tool, spec.id
    assert SCENE_TOOL == {"palpation": "probe", "grasp": "grasper"}


def test_specs_hash_and_compare_by_value():
    spec = task_spec("SurgSim/Palpation-v0")
    assert hash(spec) == hash(dataclasses.replace(spec)) and spec == dataclasses.replace(spec)
    assert spec != dataclasses.replace(spec, quick={"spacing": 0.01})

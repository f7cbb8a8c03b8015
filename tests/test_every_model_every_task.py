"""Every registered tissue model in every registered task: it steps, or the task refuses it with a
CapabilityError naming model, capability and task (tissue contract v2)."""

import importlib

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401
from surgsim_envs import tissue
from surgsim_envs.envs import TASKS
from surgsim_envs.tissue.capabilities import CapabilityError

#: coarse lattices so each pair builds and steps in a few seconds
COARSE = {"SurgSim/Palpation-v0": {"spacing": 0.02}, "SurgSim/Grasp-v0": {"resolution": 0.015},
          "SurgSim/Slippage-v0": {"resolution": 0.015}}


def _env_class(task):
    module, _, cls = TASKS[task].partition(":")
    return getattr(importlib.import_module(module), cls)


@pytest.mark.parametrize("task", sorted(TASKS))
@pytest.mark.parametrize("model", tissue.names())
def test_model_in_task(model, task):
    missing = [c for c in _env_class(task).REQUIRES if c not in tissue.registry.get(model).capabilities]
    if missing:
        with pytest.raises(CapabilityError) as err:
            gym.make(task, model=model, **COARSE[task])
        msg = str(err.value)
        assert model in msg and missing[0] in msg and task in msg
        return
    env = gym.make(task, model=model, **COARSE[task])
    assert env.unwrapped.sim.tissue().name == model
    obs, _ = env.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(3):
        obs, reward, term, trunc, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        assert np.all(np.isfinite(obs)) and np.isfinite(reward)
        if term or trunc:
            break
    env.close()


def test_stiffness_randomisation_goes_through_scale_material(monkeypatch):
    """Palpation's inclusion and Grasp's young_scale reach the model only via scale_material."""
    calls = []
    cls = tissue.registry.get("mass_spring")
    orig = cls.scale_material

    def spy(self, name="young", factor=1.0, mask=None):
        calls.append((name, np.asarray(factor).copy(), None if mask is None else np.asarray(mask).copy()))
        return orig(self, name, factor, mask)

    monkeypatch.setattr(cls, "scale_material", spy)
    env = gym.make("SurgSim/Palpation-v0", spacing=0.02)
    env.reset(seed=0, options={"young_scale": 0.9, "stiffness_contrast": 3.0})
    (n1, f1, m1), (n2, f2, m2) = calls[-2:]
    assert n1 == n2 == "young" and m1 is None and float(f1) == pytest.approx(0.9)
    assert float(f2) == pytest.approx(2.7) and m2.dtype == bool and 0 < m2.sum() < len(m2)
    young = env.unwrapped.sim.tissue().fields["young"]
    assert np.allclose(young[m2] / young[~m2].mean(), 3.0)    # the inclusion is 3x the slab


@pytest.mark.parametrize("task", sorted(TASKS))
def test_a_model_without_forces_is_refused_by_name(task, monkeypatch):
    """A model lacking a capability the task needs is refused before anything is built."""
    from surgsim_envs.tissue import capabilities as caps_module
    from surgsim_envs.tissue import registry

    class NoForces:
        name = "no_forces_model"
        capabilities = frozenset({"surface_only", "quasi_static"})
        require = classmethod(caps_module.require)

    real = registry.get
    monkeypatch.setattr(registry, "get", lambda name: NoForces if name == NoForces.name else real(name))
    with pytest.raises(CapabilityError, match=rf"tissue model 'no_forces_model' cannot serve {task}: it lacks "
                                              r"the capability 'forces'"):
        gym.make(task, model=NoForces.name, **COARSE[task])

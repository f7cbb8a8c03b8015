"""Every registered tissue model in every registered task: it steps, or the task refuses it with a
CapabilityError naming model, capability and task (tissue contract v2)."""

import importlib

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401
from surgsim_envs import tissue
from surgsim_envs.envs import TASKS
from surgsim_envs.envs.registry import task_spec
from surgsim_envs.tissue.capabilities import CapabilityError

#: coarse lattices (each task's quick overrides) so each pair builds and steps in a few seconds
COARSE = {task: dict(task_spec(task).quick) for task in TASKS}


def _env_class(task):
    module, _, cls = TASKS[task].partition(":")
    return getattr(importlib.import_module(module), cls)


@pytest.mark.parametrize("task", sorted(TASKS))
@pytest.mark.parametrize("model", tissue.names())
def test_model_in_task(model, task):
    caps = tissue.registry.get(model).capabilities
    needed = list(_env_class(task).REQUIRES) + (["implicit_contact"] if "quasi_static" in caps else [])
    missing = [c for c in needed if c not in caps]
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


def test_layered_serves_every_task():
    """The layered model (Lin et al. 2008) has every capability every task asks for, so
    test_model_in_task steps it in each (its NBB comes from the organ lattice, geometry/layered_mesh.py)."""
    caps = tissue.registry.get("layered").capabilities
    for task in sorted(TASKS):
        assert not [c for c in _env_class(task).REQUIRES if c not in caps], task
    assert "implicit_contact" in caps     # quasi-static in a contact scene


def test_stiffness_randomisation_goes_through_scale_material(monkeypatch):
    """Palpation's inclusion and Grasp's young_scale reach the model only via scale_material."""
    calls = []
    cls = tissue.registry.get("mass_spring")
    orig = cls.scale_material

    def spy(self, name="young", factor=1.0, mask=None):
        calls.append((name, np.asarray(factor).copy(), None if mask is None else np.asarray(mask).copy()))
        return orig(self, name, factor, mask)

    monkeypatch.setattr(cls, "scale_material", spy)
    env = gym.make("SurgSim/Palpation-v0", model="mass_spring", spacing=0.02)
    env.reset(seed=0, options={"young_scale": 0.9, "stiffness_contrast": 3.0})
    name, factor, mask = calls[-1]                 # one call: per-tet factors, mixed by volume share
    young = env.unwrapped.sim.tissue().fields["young"]
    assert name == "young" and mask is None and factor.shape == young.shape
    from surgsim_envs.geometry import sphere_volume_fractions

    inc = env.unwrapped.inclusion                  # the lump the env reports is the one it cut
    phi = sphere_volume_fractions(env.unwrapped.sim.tissue().element_vertices(), inc["centre"], inc["radius"])
    assert np.allclose(factor, 0.9 * (1 + 2.0 * phi)) and 0 < np.sum(phi > 0) < len(phi)
    assert factor.min() == pytest.approx(0.9) and 0.9 < factor.max() <= 2.7 * (1 + 1e-12)   # slab, inclusion 3x
    assert np.allclose(young / young.min(), factor / 0.9)


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


class _FakeTissue:
    """A tissue whose explicit limit scales like 1 / sqrt(Young's modulus) (a spring network)."""
    auto_pair = ("symplectic", "implicit")

    def __init__(self, stable_dt_at_1, integrator="symplectic"):
        self.base, self.scale, self.integrator = stable_dt_at_1, 1.0, integrator

    def scale_material(self, name="young", factor=1.0, mask=None):
        assert name == "young" and mask is None
        self.scale = float(factor)

    def stable_dt(self):
        return self.base / np.sqrt(self.scale)


def test_integrator_for_range_keeps_explicit_only_if_stable_over_the_whole_range():
    from surgsim_envs.envs.tissue_setup import integrator_for_range

    t = _FakeTissue(5e-4)
    assert integrator_for_range(t, 4e-4, 1.2) is None          # 5e-4 / sqrt(1.2) = 4.56e-4 >= 4e-4
    assert t.scale == 1.0                                      # the material is restored
    assert integrator_for_range(t, 4e-4, 1.6) == "auto"        # 5e-4 / sqrt(1.6) = 3.95e-4 < 4e-4
    assert t.scale == 1.0
    assert integrator_for_range(_FakeTissue(1e-5, "implicit"), 4e-4, 2.0) is None   # already implicit
    t.auto_pair = None                                         # no pair: nothing to switch to
    assert integrator_for_range(t, 4e-4, 1.6) is None


@pytest.mark.parametrize("model, expected", [("mass_spring", "symplectic"), ("fractional", "auto")])
def test_grasp_keeps_explicit_mass_spring_and_gives_a_stiffer_model_auto(model, expected):
    """Grasp-v0 (dt 0.4 ms, young_scale up to 1.2): mass_spring's explicit limit (stable_dt 0.49 ms
    at 1.2x) keeps its symplectic step; fractional's (0.14 ms) makes the task take its "auto"."""
    env = gym.make("SurgSim/Grasp-v0", model=model, resolution=0.015 if model == "fractional" else None)
    tissue = env.unwrapped.sim.tissue()
    assert tissue.integrator == expected
    env.reset(seed=3, options={"young_scale": 1.2})
    env.close()

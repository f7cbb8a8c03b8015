"""Tissue contract v2 (docs/models.md): capabilities, one safety factor, material
changes through the model, integrated forces, and a new model joining by registration."""

import math
import re
from pathlib import Path

import numpy as np
import pytest

from surgsim_envs import geometry, tissue
from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue import registry
from surgsim_envs.tissue.base import DT_SAFETY
from surgsim_envs.tissue.capabilities import CAPABILITIES, CapabilityError
from surgsim_envs.tissue.example_model import LinearSpringsModel

ELASTIC = {"preset": "liver", "relax_fraction": 0.0, "nonlinear": 0.0, "damping": 0.0}


def _vol():
    return geometry.box_volume((0.02, 0.02, 0.02), spacing=0.005)


@pytest.fixture
def clean_registry():
    saved = dict(registry._registry)
    yield
    registry._registry.clear()
    registry._registry.update(saved)


@pytest.mark.parametrize("name", ["mass_spring", "fem"])
def test_capabilities_are_declared_and_required_by_name(name):
    cls = tissue.get(name)
    assert {"forces", "implicit_contact", "viscoelastic", "static_solve"} <= cls.capabilities <= set(CAPABILITIES)
    assert not cls.has("surface_only") and not cls.has("quasi_static")
    with pytest.raises(CapabilityError, match=rf"'{name}' cannot serve Palpation-v0.*'surface_only'"):
        cls.require("surface_only", task="Palpation-v0")
    with pytest.raises(ConfigError, match="valid capabilities"):
        cls.require("teleportation")


def test_an_unknown_capability_in_a_class_is_refused():
    with pytest.raises(ConfigError, match=r"unknown capability name\(s\) \['flying'\]"):
        type("Bad", (LinearSpringsModel,), {"capabilities": frozenset({"forces", "flying"})})


@pytest.mark.parametrize("name", ["mass_spring", "fem"])
def test_one_safety_factor(name):
    m = tissue.make(name, _vol(), "liver")
    crit = m.critical_dt()
    assert m.stable_dt() == pytest.approx(DT_SAFETY * crit)
    assert m.choose_integrator(0.999 * m.stable_dt()) == "symplectic"
    assert m.choose_integrator(1.001 * m.stable_dt()) == "implicit"


def test_no_other_safety_factors_in_the_tissue_layer():
    root = Path(tissue.__file__).parent
    for path in root.glob("*.py"):
        text = path.read_text()
        assert not re.search(r"0\.[0-9]+ \* (self\.)?_?(critical_dt|geometric_dt|spectral)", text), path
        assert "AUTO_SAFETY" not in text, path


def test_mass_spring_scale_material_rederives_the_springs():
    vol = _vol()
    m = tissue.make("mass_spring", vol, "liver")
    k1, km, tau = m.K1.copy(), m.kM.copy(), m.tau.copy()
    m.scale_material("young", 2.0)
    np.testing.assert_allclose(m.K1, 2 * k1)
    np.testing.assert_allclose(m.kM, 2 * km)
    np.testing.assert_allclose(m.tau, tau)                   # relaxation time unchanged
    m.scale_material("young", 1.0)                            # relative to the build, not cumulative
    np.testing.assert_allclose(m.K1, k1)
    # an inclusion: only springs touching masked tets stiffen
    mask = np.linalg.norm(m.element_centroids() - vol.nodes.mean(axis=0), axis=1) < 0.004
    m.scale_material("young", 5.0, mask=mask)
    assert np.all(m.K1 >= k1 - 1e-12) and np.any(m.K1 > 2 * k1) and np.any(np.isclose(m.K1, k1))
    m.set_field("relax_fraction", 0.0)
    assert np.all(m.kM == 0)


def test_fem_scale_material_scales_forces_and_critical_dt():
    vol = _vol()
    m = tissue.make("fem", vol, ELASTIC)
    rng = np.random.default_rng(1)
    x = m.rest_positions + 2e-4 * rng.standard_normal(m.positions.shape)
    f1, crit1 = m.elastic_forces(x), m.critical_dt()
    m.scale_material("young", 3.0)
    np.testing.assert_allclose(m.elastic_forces(x), 3 * f1, rtol=1e-9, atol=1e-12)
    assert m.critical_dt() == pytest.approx(crit1 / math.sqrt(3), rel=1e-3)
    m.set_field("density", 4 * 1060.0)
    assert m.total_mass == pytest.approx(4 * 1060.0 * 0.02 ** 3)
    assert m.critical_dt() == pytest.approx(2 * crit1 / math.sqrt(3), rel=1e-3)


@pytest.mark.parametrize("name", ["mass_spring", "fem"])
def test_material_input_errors_name_the_fix(name):
    m = tissue.make(name, _vol(), "liver")
    t = len(m.element_centroids())
    with pytest.raises(ConfigError, match="unknown material field 'stiffness'.*fields"):
        m.scale_material("stiffness", 2.0)
    with pytest.raises(ConfigError, match="> 0"):
        m.scale_material("young", -1.0)
    with pytest.raises(ConfigError, match=rf"\({t},\) bool"):
        m.scale_material("young", 2.0, mask=np.ones(3, bool))
    with pytest.raises(ConfigError, match="relax_fraction"):
        m.set_field("relax_fraction", 1.5)
    m.step(1e-4)                                               # the refused change left a working model


@pytest.mark.parametrize("name", ["mass_spring", "fem"])
def test_integrated_forces_of_an_explicit_step_are_the_forces_given(name):
    m = tissue.make(name, _vol(), "liver", integrator="symplectic")
    f = np.zeros_like(m.positions)
    f[0] = (0.0, 0.0, -0.01)
    m.step(1e-5, f, np.full(m.n_nodes, 50.0))
    np.testing.assert_array_equal(m.integrated_external_forces, f)


@pytest.mark.parametrize("name", ["mass_spring", pytest.param("fem", marks=pytest.mark.slow)])   # fem: 18 s
def test_integrated_forces_of_an_implicit_step_include_the_stiffness_increment(name):
    m = tissue.make(name, _vol(), ELASTIC, integrator="implicit", cg_tol=1e-12)
    f = np.zeros_like(m.positions)
    f[:, 2] = -0.001
    kc = np.full(m.n_nodes, 200.0)
    p0 = m.momentum()
    m.step(1e-3, f, kc)
    np.testing.assert_allclose(m.integrated_external_forces, f - 1e-3 * kc[:, None] * m.velocities)
    # the momentum change is exactly the integrated impulse (no supports, no damping)
    np.testing.assert_allclose(m.momentum() - p0, 1e-3 * m.integrated_external_forces.sum(axis=0), rtol=1e-8)


def test_a_new_model_joins_by_registration(clean_registry):
    tissue.register("linear_springs", LinearSpringsModel)
    m = tissue.make("linear_springs", _vol(), ELASTIC)
    m.velocities[:] = np.random.default_rng(0).normal(0.0, 1e-3, m.velocities.shape)
    e0, p0 = m.kinetic_energy() + m.elastic_energy(), m.momentum()
    for _ in range(2000):
        m.step(0.1 * m.critical_dt())
    assert m.kinetic_energy() + m.elastic_energy() == pytest.approx(e0, rel=0.02)   # undamped: energy kept
    np.testing.assert_allclose(m.momentum(), p0, atol=1e-9 * np.linalg.norm(p0))   # internal forces only
    assert m.node_field("stress").max() > 0
    m.scale_material("young", 2.0)
    with pytest.raises(CapabilityError, match="'linear_springs'.*'implicit_contact'"):
        m.require("implicit_contact", task="Grasp-v0")
    with pytest.raises(CapabilityError, match="cannot change material field 'poisson'"):
        m.scale_material("poisson", 0.9)


def test_docs_show_the_example_model_verbatim():
    doc = (Path(__file__).parents[1] / "docs" / "models.md").read_text()
    import inspect

    code = Path(inspect.getfile(LinearSpringsModel)).read_text()
    body = code[code.index("class LinearSpringsModel"):]
    assert body.strip() in doc, "docs/models.md must show surgsim_envs/tissue/example_model.py's class verbatim"


@pytest.mark.slow
def test_bench_accuracy_runs_every_registered_model_by_capability(clean_registry, capsys):
    from surgsim_envs.bench.accuracy import sweep

    class _NoForces(LinearSpringsModel):
        name = "display_only"
        capabilities = frozenset({"history"})

    tissue.register("linear_springs", LinearSpringsModel)
    tissue.register("display_only", _NoForces)
    rows = sweep(models=["linear_springs", "display_only"], spacings=(0.003,), progress=False, time_steps=0)
    assert [(r["model"], r["integrator"]) for r in rows] == [("linear_springs", "symplectic")]
    assert 0.0 < rows[0]["error"] < 1.0                       # a real force curve against Dimitriadis
    err = capsys.readouterr().err
    assert "'display_only' cannot serve surgsim bench accuracy" in err and "'forces'" in err


def test_bench_accuracy_skips_a_model_without_forces_naming_the_capability(clean_registry, capsys):
    from surgsim_envs.bench.accuracy import sweep

    class _NoForces(LinearSpringsModel):
        name = "display_only"
        capabilities = frozenset({"history"})

    tissue.register("display_only", _NoForces)
    assert sweep(models=["display_only"], spacings=(0.003,), progress=False, time_steps=0) == []
    assert "'display_only' cannot serve surgsim bench accuracy" in capsys.readouterr().err

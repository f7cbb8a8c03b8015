"""The tissue plugin interface: materials, registry, bad input."""

import numpy as np
import pytest

from surgsim_envs import tissue
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry import Volume, box_volume


def test_material_rejects_bad_values_with_named_fix():
    with pytest.raises(ConfigError, match="young"):
        tissue.Material(young=-1.0)
    with pytest.raises(ConfigError, match="poisson"):
        tissue.Material(young=1e3, poisson=0.5)
    with pytest.raises(ConfigError, match="density"):
        tissue.Material(young=1e3, density=0.0)
    with pytest.raises(ConfigError, match="unknown material preset"):
        tissue.get_material("jelly")


def test_material_presets_have_sources_and_sane_moduli():
    for name in ("liver", "spleen", "kidney", "fat", "muscle", "skin", "silicone"):
        mat = tissue.PRESETS[name]
        assert mat.source, name
        assert 100.0 < mat.young < 1e6
        assert 0.4 <= mat.poisson < 0.5
    m = tissue.get_material({"preset": "liver", "young": 5000.0})
    assert m.young == 5000.0 and m.poisson == tissue.PRESETS["liver"].poisson
    assert m.bulk_modulus > m.shear_modulus


def test_unknown_model_name_lists_registered_models():
    with pytest.raises(ConfigError, match="mass_spring"):
        tissue.make("no_such_model", box_volume((0.02, 0.02, 0.02), 0.01))


def test_register_rejects_duplicate_names():
    with pytest.raises(ConfigError, match="already registered"):
        tissue.register("fem", object)


def test_volume_rejects_inverted_tets():
    v = box_volume((0.02, 0.02, 0.02), 0.01)
    tets = v.tets.copy()
    tets[0] = tets[0][[1, 0, 2, 3]]
    bad = Volume(v.nodes, tets, surface=v.surface)
    with pytest.raises(ConfigError, match="inverted"):
        bad.check()


def test_box_volume_is_watertight_and_exact():
    v = box_volume((0.08, 0.06, 0.03), 0.01)
    assert np.isclose(v.total_volume(), 0.08 * 0.06 * 0.03)
    assert np.all(v.tet_volumes() > 0)
    # closed surface: every edge shared by exactly two triangles
    e = np.sort(np.concatenate([v.surface[:, [0, 1]], v.surface[:, [1, 2]], v.surface[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    assert np.all(counts == 2)
    with pytest.raises(ConfigError, match="spacing"):
        box_volume((0.1, 0.1, 0.1), 0.0)


def test_auto_integrator_needs_an_explicit_implicit_pair():
    from surgsim_envs.tissue.mass_spring import MassSpringModel

    class ExplicitOnly(MassSpringModel):
        integrators = ("symplectic",)
        auto_pair = None
        default_integrator = None

    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    assert ExplicitOnly(vol, "liver").integrator == "symplectic"
    with pytest.raises(ConfigError, match="auto"):
        ExplicitOnly(vol, "liver", integrator="auto")
    with pytest.raises(ConfigError, match="auto"):        # the error lists "auto" among the choices
        tissue.make("mass_spring", vol, "liver", integrator="rk4")
    for name in ("mass_spring", "fem"):
        m = tissue.make(name, vol, "liver")
        assert m.integrator == "auto" and m.active_integrator in m.integrators
        assert "auto" in repr(m) or m.integrator in repr(m)

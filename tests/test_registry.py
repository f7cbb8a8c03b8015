"""Model registry: built-ins, third-party registration, entry points, the `surgsim models` command."""

from importlib import metadata

import numpy as np
import pytest

from surgsim_envs import tissue
from surgsim_envs.cli import main
from surgsim_envs.geometry import box_volume
from surgsim_envs.tissue import registry


class _StillModel(tissue.TissueModel):
    """A trivial plugin: nothing moves (tests the interface, not physics)."""

    name = "still_test_model"
    summary = "test plugin that never moves"

    def _advance(self, dt, forces, stiffness):
        pass

    def elastic_energy(self):
        return 0.0

    def internal_forces(self):
        return np.zeros_like(self.positions)

    def critical_dt(self):
        return float("inf")


@pytest.fixture
def clean_registry():
    saved = dict(registry._registry)
    loaded = registry._entry_points_loaded
    yield
    registry._registry.clear()
    registry._registry.update(saved)
    registry._entry_points_loaded = loaded


def test_builtin_models_are_listed_and_build():
    assert {"mass_spring", "fem"} <= set(tissue.names())
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    for name in ("mass_spring", "fem"):
        model = tissue.make(name, vol, "liver")
        assert model.n_nodes == vol.n_nodes
        assert np.isclose(model.total_mass, 1060.0 * 0.02 ** 3)


def test_registered_class_is_made_and_described(clean_registry):
    tissue.register("still_test_model", _StillModel)
    model = tissue.make("still_test_model", box_volume((0.02, 0.02, 0.02), 0.01), "fat")
    model.step(1e-3)
    assert model.time == pytest.approx(1e-3)
    assert registry.describe()["still_test_model"] == "test plugin that never moves"


def test_entry_point_group_is_loaded(clean_registry, monkeypatch):
    ep = metadata.EntryPoint(name="ep_still_model", value=f"{__name__}:_StillModel", group=registry.ENTRY_POINT_GROUP)

    def fake_entry_points(group=None):
        return [ep] if group == registry.ENTRY_POINT_GROUP else []

    monkeypatch.setattr(registry.metadata, "entry_points", fake_entry_points)
    registry._entry_points_loaded = False
    assert "ep_still_model" in tissue.names()
    assert tissue.get("ep_still_model") is _StillModel


def test_models_command_prints_one_line_per_model(capsys):
    assert main(["models"]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if line.strip()]
    assert len(lines) == len(tissue.names())
    assert any(line.startswith("mass_spring") for line in lines)
    assert all("failed to load" not in line for line in lines)


def test_step_rejects_bad_dt():
    model = tissue.make("mass_spring", box_volume((0.02, 0.02, 0.02), 0.01), "liver")
    for dt in (0.0, -1e-3, float("nan")):
        with pytest.raises(ValueError, match="dt"):
            model.step(dt)

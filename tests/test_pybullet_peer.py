"""PyBullet's soft body as an accuracy-chart peer (surgsim_envs/bench/pybullet_peer.py).

Behaviour of the scene, not timing: the slab pushes back, more with depth and with stiffness;
the VTK tet file PyBullet reads holds exactly our mesh. Needs the [peers] extra (pybullet)."""

import numpy as np
import pytest

from surgsim_envs.bench import pybullet_peer
from surgsim_envs.bench.indent_mesh import graded_slab
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.vtk_legacy import read_legacy_vtk

# a small slab (10 mm thick, 40 mm wide, 4 mm spacing: 484 nodes)
SMALL = dict(indenter_radius=0.005, depth=0.001, thickness=0.01, width=0.04, spacing=0.004, n_depths=3)


def _needs_pybullet():
    pytest.importorskip("pybullet", reason="PyBullet peers need the [peers] extra: pip install pybullet")


def test_vtk_tet_file_holds_the_mesh_exactly(tmp_path):
    vol = graded_slab(0.04, 0.01, 0.004, 0.006, quarter=False)
    path = tmp_path / "slab.vtk"
    pybullet_peer.write_vtk_tets(str(path), vol.nodes, vol.tets)
    points, (conn, offsets), types = read_legacy_vtk(path)
    np.testing.assert_allclose(points, vol.nodes, rtol=1e-8, atol=1e-12)
    assert np.all(types == 10) and np.all(np.diff(offsets) == 4)
    np.testing.assert_array_equal(conn.reshape(-1, 4), vol.tets)


def test_bad_input_is_rejected_before_pybullet_runs():
    with pytest.raises(ConfigError, match="mode must be one of"):
        pybullet_peer.pybullet_indent("cloth")
    with pytest.raises(ConfigError, match="depth"):
        pybullet_peer.pybullet_indent("fem", depth=0.02)
    with pytest.raises(ConfigError, match="hold_steps"):
        pybullet_peer.pybullet_indent("fem", hold_steps=0)


def test_peers_are_skipped_with_a_message_without_pybullet(monkeypatch, capsys):
    monkeypatch.setattr(pybullet_peer, "available", lambda: False)
    assert pybullet_peer.peer_sweep(progress=False) == []
    assert "pip install 'surgsim_envs[peers]'" in capsys.readouterr().err


def test_fem_peer_pushes_back_more_with_depth():
    _needs_pybullet()
    res = pybullet_peer.pybullet_indent("fem", "liver", **SMALL)
    assert np.all(np.isfinite(res.force)) and np.all(res.force > 0) and np.all(np.diff(res.force) > 0)
    # the sphere follows its target (a stiff constraint): depth within 10 % of 1/3, 2/3, 1 mm
    np.testing.assert_allclose(res.depth, [1e-3 / 3, 2e-3 / 3, 1e-3], rtol=0.1)
    assert np.all(res.penetration >= 0) and np.all(res.penetration < res.depth)
    assert res.nodes == 484 and res.us_per_ms > 0


@pytest.mark.slow  # two more PyBullet runs (~30 s on the loaded 2 cores)
def test_mass_spring_peer_force_grows_with_youngs_modulus():
    _needs_pybullet()
    soft = pybullet_peer.pybullet_indent("mass_spring", {"preset": "liver", "young": 2000.0}, **SMALL)
    hard = pybullet_peer.pybullet_indent("mass_spring", {"preset": "liver", "young": 8000.0}, **SMALL)
    assert hard.force[-1] > 2.5 * soft.force[-1]  # 4x the springs; the contact's own compliance takes a part
    assert soft.info["spring_k_N_per_m"] == pytest.approx(2000.0 * 0.004)

"""Validation procedure of Vandewalle et al. 2003 (section 2.2): signed surface distances, state files, CLI."""

import json
import os

import numpy as np
import pytest
import trimesh

from surgsim_envs.cli import main
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.state_file import load_surface_any, save_state
from surgsim_envs.geometry.surface_error import signed_surface_distance, surface_error


def _plane(n=11, size=0.04):
    g = np.linspace(-size / 2, size / 2, n)
    x, y = np.meshgrid(g, g, indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])   # normals +z
    return v, faces


def test_plane_distances_signed_by_exterior_normal():
    v, f = _plane()
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-0.015, 0.015, (40, 2)), rng.choice([0.002, -0.003], 40)])
    d = signed_surface_distance(pts, v, f)
    # trimesh's closest point is micrometre-accurate (candidate faces from an r-tree)
    np.testing.assert_allclose(d, pts[:, 2], atol=5e-6)
    # the exterior is given by the orientation: flipping the faces flips the signs
    np.testing.assert_allclose(signed_surface_distance(pts, v, f[:, ::-1]), -pts[:, 2], atol=5e-6)


def test_sphere_offsets_match_radius_difference_and_trimesh():
    ref = trimesh.creation.icosphere(subdivisions=4, radius=0.010)
    for radius, expect in ((0.012, 0.002), (0.008, -0.002)):
        pred = trimesh.creation.icosphere(subdivisions=3, radius=radius)
        err = surface_error(pred.vertices, pred.faces, ref.vertices, ref.faces)
        # faceting of the reference: chord sag r (1 - cos(theta/2)) < 0.05 mm at subdivision 4
        np.testing.assert_allclose(err.distances, expect, atol=5e-5)
        assert err.mean == pytest.approx(expect, abs=5e-5) and err.std < 3e-5
        # trimesh's signed distance (positive inside) agrees up to the sign convention
        np.testing.assert_allclose(err.distances, -trimesh.proximity.signed_distance(ref, pred.vertices), atol=1e-12)


def test_state_file_roundtrip_and_cli(tmp_path, capsys):
    v, f = _plane()
    ref_path = save_state(tmp_path / "ref", v, f)
    pred_v = v.copy()
    pred_v[:, 2] = np.where(pred_v[:, 0] > 0, 0.001, -0.001)
    # a state file with extra (non-surface) nodes: only the surface's vertices are compared
    pos = np.vstack([pred_v, [[0.0, 0.0, -0.05]]])
    pred_path = save_state(tmp_path / "pred.npz", pos, f, rest_positions=pos, model="test")
    vv, ff = load_surface_any(pred_path)
    assert len(vv) == len(v) and ff.max() == len(v) - 1
    out = tmp_path / "report"
    assert main(["validate", "--predicted", pred_path, "--reference", ref_path, "--out", str(out)]) == 0
    assert "mu =" in capsys.readouterr().out
    summary = json.loads((out / "validation.json").read_text())
    d = pred_v[:, 2]
    assert summary["mu_m"] == pytest.approx(d.mean(), abs=1e-12)
    assert summary["sigma_m"] == pytest.approx(d.std(), abs=1e-12)
    for name in ("distance_map.png", "histogram.png", "distances.npz"):
        assert os.path.getsize(out / name) > 1000
    # mesh files work too (units mm)
    trimesh.Trimesh(v * 1e3, f, process=False).export(tmp_path / "ref_mm.stl")
    assert main(["validate", "--predicted", pred_path, "--reference", str(tmp_path / "ref_mm.stl"),
                 "--units", "mm", "--out", str(out)]) == 0


def test_validation_bad_input(tmp_path, capsys):
    v, f = _plane()
    with pytest.raises(ConfigError, match="does not exist"):
        load_surface_any(tmp_path / "missing.npz")
    np.savez(tmp_path / "bad.npz", nodes=v)
    with pytest.raises(ConfigError, match="positions"):
        load_surface_any(tmp_path / "bad.npz")
    with pytest.raises(ConfigError, match="faces"):
        signed_surface_distance(v, v, f + len(v))
    ref = save_state(tmp_path / "ref", v, f)
    assert main(["validate", "--predicted", str(tmp_path / "bad.npz"), "--reference", ref]) == 2
    assert "positions" in capsys.readouterr().err

"""Vandewalle et al. 2003 planning case: distraction, basic vs growth against a synthetic reference, Fig. 5 sweep."""

import json

import numpy as np
import pytest

from surgsim_envs.cli import main
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.surface_error import surface_error
from surgsim_envs.planning.maxillofacial import DistractionCase
from surgsim_envs.planning.sweep import grown_skin, sweep


def test_distraction_boundary_conditions():
    case = DistractionCase()
    vol = case.volume(0.006)
    r = case.regions(vol)
    fixed, disp = case.dirichlet(vol)
    assert not (r["skin"] & fixed).any() or (r["skin"] & fixed & ~r["border"]).sum() == 0
    # the segment follows the rigid distraction exactly; the borders and the far bone stay
    seg = r["segment"] & ~r["border"]
    seg &= case.bone_weight(vol.nodes) == 1.0
    np.testing.assert_allclose(disp[seg], case.bone_displacement(vol.nodes[seg]), atol=1e-15)
    assert np.all(disp[r["border"]] == 0.0)
    far = r["bone"] & (case.bone_weight(vol.nodes) == 0.0)
    assert far.any() and np.all(disp[far] == 0.0)
    # rigid motion: distances between segment nodes are kept (rotation + translation)
    p = vol.nodes[seg]
    q = p + disp[seg]
    np.testing.assert_allclose(np.linalg.norm(q[1:] - q[0], axis=1), np.linalg.norm(p[1:] - p[0], axis=1), rtol=1e-12)
    assert np.linalg.norm(disp[seg], axis=1).max() > 0.007
    with pytest.raises(ConfigError, match="thickness"):
        DistractionCase(thickness=0.0)


def test_growth_beats_basic_and_k_slice_recovers_truth():
    """Fast representative: a synthetic reference grown at (nu*, k*) = (0.35, 12) on a 4 mm mesh; on a
    6 mm mesh the growth model is closer than the basic model (the paper's Fig. 7) and the k sweep at
    nu* has its minimum at k*."""
    case = DistractionCase()
    ref = grown_skin(case, 0.004, 0.35, 12.0)
    basic = grown_skin(case, 0.006, 0.35, None)
    eb = surface_error(basic[0], basic[1], *ref)
    res = sweep(case, nus=(0.35,), ks=(6.0, 12.0, 20.0), spacing=0.006, reference_spacing=0.004, reference=ref,
                progress=False)
    assert res.recovered() == (0.35, 12.0)
    j = 1
    assert eb.mean < -2e-3                      # basic: lack of material (the paper's negative mean)
    assert abs(res.mu[0, j]) < 0.3 * abs(eb.mean) and res.sigma[0, j] < 0.5 * eb.std


@pytest.mark.slow
def test_sweep_recovers_nu_and_k_on_a_coarser_mesh():
    """Reference on a 2.5 mm mesh, sweep on 4 mm: the joint (nu, k) minimum is the truth."""
    case = DistractionCase()
    res = sweep(case, nus=(0.25, 0.3, 0.35, 0.4, 0.45), ks=(6.0, 10.0, 12.0, 14.0, 20.0), truth=(0.35, 12.0),
                spacing=0.004, reference_spacing=0.0025, progress=False)
    assert res.recovered() == (0.35, 12.0)
    assert res.rms.min() < 0.5 * np.sort(res.rms.ravel())[len(res.ks)]   # a clear minimum, not a flat landscape


def test_grow_cli(tmp_path, capsys):
    out = tmp_path / "grow"
    assert main(["grow", "--out", str(out), "--spacing", "0.008", "--reference-spacing", "0.006",
                 "--nu", "0.35", "--k", "12"]) == 0
    text = capsys.readouterr().out
    assert "converged" in text and "synthetic reference" in text
    summary = json.loads((out / "summary.json").read_text())
    assert summary["volume_ratio_grown"] > summary["volume_ratio_basic"] > 1.0
    for name in ("basic.npz", "grown.npz", "reference.npz", "comparison.png"):
        assert (out / name).stat().st_size > 1000
    assert main(["validate", "--predicted", str(out / "grown.npz"), "--reference", str(out / "reference.npz"),
                 "--out", str(tmp_path / "v")]) == 0
    assert main(["grow", "--out", str(out), "--alpha", "-1", "--no-reference", "--spacing", "0.008"]) == 2
    assert "alpha" in capsys.readouterr().err


def test_bench_growth_runs(tmp_path, capsys):
    assert main(["bench", "growth", "--nodes", "300", "--repeats", "1", "--out", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "growth_speed.json").read_text())
    assert data["nodes"] >= 300 and data["iterations"] > 0 and "load" in data
    assert main(["bench", "growth", "--nodes", "10", "--out", str(tmp_path)]) == 2

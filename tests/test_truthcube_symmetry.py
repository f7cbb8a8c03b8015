"""Truth-cube error budget: the symmetry floor of the measurement and each model's own part."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from surgsim_envs.bench import truthcube_symmetry as ts
from surgsim_envs.errors import ConfigError

REPO = Path(__file__).resolve().parents[1]
L = 0.08


def _grid(n=7, spacing=0.01):
    a = (np.arange(n) - (n - 1) / 2) * spacing
    return np.stack(np.meshgrid(a, a, a, indexing="ij"), axis=-1).reshape(-1, 3)


def _affine(rest, strain):
    u = np.zeros_like(rest)
    u[:, 2] = -strain * (rest[:, 2] + L / 2)
    return u


def test_uniform_compression_is_invariant_and_a_plate_shift_is_all_floor():
    rest = _grid()
    u = _affine(rest, 0.1)
    assert np.allclose(ts.symmetric_part(u, rest, 0.1 * L), u, atol=1e-15)
    # a lateral shift of the moving plate (simple shear in y) breaks every mirror: all of it is floor
    shear = np.zeros_like(rest)
    shear[:, 1] = 0.002 * (rest[:, 2] + L / 2) / L
    b = ts.error_budget(rest + u, rest + u + shear, rest, 0.1 * L)
    assert b["model"] < 1e-12 and b["model_asymmetry"] < 1e-12
    assert b["floor"] == pytest.approx(ts.rms(shear), rel=1e-12)
    # a wrong bulge is symmetric: all of it is the model's
    bulge = np.zeros_like(rest)
    bulge[:, :2] = 0.05 * rest[:, :2]
    b = ts.error_budget(rest + u + bulge, rest + u, rest, 0.1 * L)
    assert b["floor"] < 1e-12
    assert b["model"] == pytest.approx(ts.rms(bulge), rel=1e-12)


def test_budget_is_pythagorean_for_a_symmetric_prediction():
    rng = np.random.default_rng(3)
    rest = _grid() + rng.normal(0, 5e-4, (343, 3))      # irregular beads as in the cube
    measured = rest + _affine(rest, 0.125) + rng.normal(0, 1e-3, (343, 3))
    pred = rest + ts.symmetric_part(_affine(rest, 0.125) + rng.normal(0, 1e-3, (343, 3)), rest, 0.125 * L)
    b = ts.error_budget(pred, measured, rest, 0.125 * L)
    assert b["model_asymmetry"] < 1e-12
    assert b["total"] ** 2 == pytest.approx(b["floor"] ** 2 + b["model"] ** 2, rel=1e-10)


def test_asymmetric_bead_set_and_bad_input_are_rejected():
    rest = _grid()
    with pytest.raises(ConfigError, match="not symmetric"):
        ts.partner_indices(rest + [0.004, 0.0, 0.0])
    with pytest.raises(ConfigError, match="shaped like rest"):
        ts.symmetric_part(np.zeros((5, 3)), rest, 0.01)
    with pytest.raises(ConfigError, match="travel"):
        ts.symmetric_part(np.zeros_like(rest), rest, float("nan"))


def test_measured_floor_exceeds_the_issue_target_at_large_strain(truthcube):
    """The measured field breaks the experiment's symmetry by more than 1.2 mm RMS at 12.5 and
    18.25 % (mostly a lateral shift of the moving-plate side in y): no model with the stated
    bonded plates can reach the 1.2 mm target there. Mirrors alone already give > 1.2 mm."""
    tc, rest, measured = truthcube
    for strain in (0.125, 0.1825):
        u = measured[strain] - rest
        floor = ts.rms(u - ts.symmetric_part(u, rest, strain * tc.CUBE))
        assert floor > 1.2e-3, (strain, floor)
        # only the x and y mirrors (maps 0..7 with no swap and no z flip): still above 1.2 mm
        idx = ts.partner_indices(rest)
        maps = ts.symmetry_maps()
        mirror = [k for k, g in enumerate(maps) if g[2, 2] > 0 and g[0, 1] == 0]
        sym = sum(u[idx[k]] @ maps[k].T for k in mirror) / len(mirror)
        assert ts.rms(u - sym) > 1.2e-3
    # the floor grows with strain and is smaller than the plate travel by an order of magnitude
    floors = [ts.rms(measured[s] - rest - ts.symmetric_part(measured[s] - rest, rest, s * tc.CUBE)) for s in tc.STRAINS]
    assert floors[0] < floors[1] < floors[2] < 0.02 * tc.CUBE


@pytest.mark.slow  # ~20 s of FEM solves; the default run keeps the floor and invariance tests
def test_bonded_fem_prediction_is_symmetric_and_its_model_part_beats_affine(truthcube):
    """Fast representative: linear ANP FEM (bonded plates) predicts a field with the experiment's
    symmetry (its asymmetric part, from the tet pattern and bead irregularity, is < 0.1 mm) and its
    own error is a fraction of the affine (no bulge) prediction's."""
    tc, rest, measured = truthcube
    model, vol, bottom, top = tc.cube_model("fem", 0.01, corotational=False, formulation="anp")
    for strain in (0.05, 0.125):
        model.reset()
        pred = tc.predict_beads(vol, tc.compress(model, bottom, top, strain), rest)
        b = ts.error_budget(pred, measured[strain], rest, strain * tc.CUBE)
        aff = ts.error_budget(tc.affine_prediction(rest, strain), measured[strain], rest, strain * tc.CUBE)
        assert b["model_asymmetry"] < 1e-4, b
        assert b["model"] < 0.5 * aff["model"], (b, aff)
        assert b["total"] ** 2 == pytest.approx(b["floor"] ** 2 + b["model"] ** 2, rel=0.05)


@pytest.mark.slow
def test_neo_hookean_is_within_a_tenth_of_a_millimetre_of_the_floor(truthcube):
    """neo_hookean (10 mm mesh, the paper's E = 15.3 kPa, nu = 0.499; nothing fitted to the beads):
    its own error is < 0.5 mm at 12.5 and 18.25 %, and its total is within 0.1 mm of the floor."""
    tc, rest, measured = truthcube
    model, vol, bottom, top = tc.cube_model("neo_hookean", 0.01)
    for strain in (0.125, 0.1825):
        model.reset()
        pred = tc.predict_beads(vol, tc.compress(model, bottom, top, strain), rest)
        b = ts.error_budget(pred, measured[strain], rest, strain * tc.CUBE)
        assert b["model"] < 0.5e-3, b
        assert b["total"] < b["floor"] + 0.1e-3, b


@pytest.mark.slow
def test_error_budget_figure_is_written(tmp_path):
    """scripts/truthcube.py --figure: one bar group per strain, floor and target lines, off-scale
    bars clipped with their value (synthetic rows; the real table is in docs/benchmarks.md)."""
    spec = importlib.util.spec_from_file_location("truthcube_figure", REPO / "scripts" / "truthcube_figure.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    strains = (0.05, 0.125)
    rows = [("symmetry floor", {s: (1e-3, 0.0, 0.0) for s in strains}),
            ("model a", {s: (1.2e-3, 1.0, 0.5e-3) for s in strains}),
            ("model b (folded)", {s: (9e-3, 1.0, 9e-3) for s in strains})]
    out = tmp_path / "budget.png"
    mod.plot_rows(rows, strains, out)
    assert out.stat().st_size > 10_000
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_the_floor_is_the_moving_plates_sideways_travel_held_out(truthcube):
    """The plate's sideways travel, estimated from the 49 beads next to it only, explains the
    asymmetric part on the other 294 beads: linear ANP FEM's RMS there drops by > 30 % at 5 and
    12.5 % (measured 0.87 -> 0.44 and 1.20 -> 0.66 mm), and the estimate is mostly along y (~1.5-2 mm)."""
    spec = importlib.util.spec_from_file_location("truthcube_variants", REPO / "scripts" / "truthcube_variants.py")
    tv = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tv)
    tc, rest, measured = truthcube
    shift, layer = tv.plate_shift_from_top_layer(rest, measured)
    assert layer.sum() == 49
    for s in tc.STRAINS:
        assert 1.0e-3 < shift[s][1] < 3.0e-3 and abs(shift[s][0]) < 1.0e-3, shift[s]
    stated, shifted = tv.solve(rest), tv.solve(rest, shift=shift)
    keep = ~layer
    for s in (0.05, 0.125):
        before = tc.rms(stated[s][keep], measured[s][keep])
        after = tc.rms(shifted[s][keep], measured[s][keep])
        assert after < 0.7 * before, (s, before, after)


@pytest.mark.slow
def test_neo_hookean_with_the_estimated_plate_travel_meets_1p2_mm_on_held_out_beads(truthcube):
    """The 1.2 mm target, on beads the boundary condition never saw: the plate's sideways travel is
    estimated from the 49 beads next to it (2 numbers per strain), neo_hookean (E, nu from the data
    README) is scored on the other 294 (measured 0.43 / 0.58 / 0.93 mm; stated plates 0.86 / 1.16 / 1.40)."""
    spec = importlib.util.spec_from_file_location("truthcube_variants", REPO / "scripts" / "truthcube_variants.py")
    tv = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tv)
    tc, rest, measured = truthcube
    shift, layer = tv.plate_shift_from_top_layer(rest, measured)
    model, vol, bottom, top = tc.cube_model("neo_hookean", 0.01)
    for s in (0.125, 0.1825):
        model.reset()
        model.set_fixed(bottom)
        model.set_fixed(top, model.rest_positions[top] + [shift[s][0], shift[s][1], -s * tc.CUBE])
        pred = tc.predict_beads(vol, model.static_solve(), rest)
        assert tc.rms(pred[~layer], measured[s][~layer]) < 1.2e-3

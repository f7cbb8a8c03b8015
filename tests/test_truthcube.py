"""Truth cube (Kerdok et al. 2003): FEM bead displacements against the measured ones."""

import importlib.util

import numpy as np
import pytest

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("truthcube_script", REPO / "scripts" / "truthcube.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def cube(shared_data):
    tc = _script()
    rest, measured = tc.load_truthcube(shared_data / "truthcube" / "uniaxial_positions.csv")
    return tc, rest, measured


def test_data_frame_matches_the_experiment(cube):
    tc, rest, measured = cube
    assert rest.shape == (343, 3)
    assert np.all(np.abs(rest) < tc.CUBE / 2)            # beads inside the cube
    for strain, pos in measured.items():
        dz = pos[:, 2] - rest[:, 2]
        assert dz.mean() < 0                               # the cube is compressed downwards
        top, bottom = rest[:, 2] > 0.02, rest[:, 2] < -0.02
        assert dz[top].mean() < dz[bottom].mean()           # more near the moving plate


def test_fem_beats_affine_prediction_and_error_grows_with_strain(cube):
    tc, rest, measured = cube
    model, vol, bottom, top = tc.cube_model("fem", 0.01, corotational=True, formulation="anp")
    errors = {}
    for strain in (0.05, 0.1825):
        model.reset()
        x = tc.compress(model, bottom, top, strain)
        assert np.allclose(x[top, 2], vol.nodes[top, 2] - strain * tc.CUBE)
        pred = tc.predict_beads(vol, x, rest)
        errors[strain] = tc.rms(pred, measured[strain])
        # lateral bulge: mid-height beads move outwards in the simulation as in the data
        mid = np.abs(rest[:, 2]) < 0.006
        r0 = np.linalg.norm(rest[mid, :2], axis=1)
        assert np.mean(np.linalg.norm(pred[mid, :2], axis=1) - r0) > 0
        assert np.mean(np.linalg.norm(measured[strain][mid, :2], axis=1) - r0) > 0
    affine5 = tc.rms(tc.affine_prediction(rest, 0.05), measured[0.05])
    assert errors[0.05] < 0.8 * affine5, (errors, affine5)
    assert errors[0.1825] < tc.rms(tc.affine_prediction(rest, 0.1825), measured[0.1825])
    assert errors[0.05] < 0.05 * tc.CUBE * 0.3          # well below the plate travel (4 mm)

"""Stable Neo-Hookean tets (tissue/neo_hookean.py): energy and forces at large homogeneous strain
against the closed form, the small-strain limit, and the truth cube (Kerdok et al. 2003)."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from surgsim_envs.geometry import box_volume
from surgsim_envs.tissue import make

MAT = {"young": 15_300.0, "poisson": 0.49, "density": 980.0, "damping": 0.0, "name": "silicone-like"}


def _lame():
    E, nu = MAT["young"], MAT["poisson"]
    return E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))


def test_homogeneous_large_strain_energy_and_interior_forces_match_the_closed_form():
    """F = diag(0.7, 1.15, 1.2) (30 % compression): energy = V Psi(F); interior nodes carry no force."""
    vol = box_volume((0.02, 0.02, 0.02), 0.005)
    m = make("neo_hookean", vol, MAT)
    mu, lam = _lame()
    F = np.diag([1.15, 1.2, 0.7])
    m.positions = vol.nodes @ F.T
    J, ic = np.linalg.det(F), np.sum(F * F)
    psi = mu / 2 * (ic - 3) - mu * (J - 1) + (lam + mu) / 2 * (J - 1) ** 2
    assert m.elastic_energy() == pytest.approx(0.02 ** 3 * psi, rel=1e-9)
    f = m.internal_forces()
    X = vol.nodes
    inner = np.all((X > X.min(0) + 1e-9) & (X < X.max(0) - 1e-9), axis=1)
    assert np.abs(f[inner]).max() < 1e-9 * np.abs(f).max()


@pytest.mark.parametrize("c01_fraction", [0.0, 0.7])
def test_small_strain_limit_is_linear_elasticity(c01_fraction):
    vol = box_volume((0.01, 0.01, 0.01), 0.005)
    m = make("neo_hookean", vol, MAT, c01_fraction=c01_fraction)
    mu, lam = _lame()
    rng = np.random.default_rng(2)
    e = rng.normal(size=(3, 3)) * 1e-5
    e = 0.5 * (e + e.T)
    m.positions = vol.nodes + vol.nodes @ e.T
    assert m.elastic_energy() == pytest.approx(1e-6 * (mu * np.sum(e * e) + 0.5 * lam * np.trace(e) ** 2), rel=1e-3)


@pytest.mark.parametrize("c01_fraction", [0.0, 0.7])
def test_forces_are_minus_the_energy_gradient(c01_fraction):
    vol = box_volume((0.01, 0.01, 0.01), 0.005)
    m = make("neo_hookean", vol, MAT, c01_fraction=c01_fraction)
    rng = np.random.default_rng(0)
    x = vol.nodes + rng.normal(scale=5e-4, size=vol.nodes.shape)
    m.positions = x
    f = m.internal_forces()
    for a, k in ((3, 0), (11, 2), (20, 1)):
        h = 1e-8
        m.positions = x.copy()
        m.positions[a, k] += h
        ep = m.elastic_energy()
        m.positions = x.copy()
        m.positions[a, k] -= h
        em = m.elastic_energy()
        assert f[a, k] == pytest.approx(-(ep - em) / (2 * h), rel=1e-5)


def test_mooney_rivlin_homogeneous_energy():
    """c01_fraction f: Psi = C10 (I1-3) + C01 (I2-3) - (2 C10 + 4 C01)(J-1) + k/2 (J-1)^2, mu = 2 (C10 + C01)."""
    vol = box_volume((0.02, 0.02, 0.02), 0.005)
    m = make("neo_hookean", vol, MAT, c01_fraction=0.7)
    mu, lam = _lame()
    c10, c01 = 0.3 * mu / 2, 0.7 * mu / 2
    F = np.diag([1.1, 1.15, 0.75])
    m.positions = vol.nodes @ F.T
    C = F.T @ F
    i1, J = np.trace(C), np.linalg.det(F)
    i2 = 0.5 * (i1 ** 2 - np.sum(C * C))
    psi = c10 * (i1 - 3) + c01 * (i2 - 3) - (2 * c10 + 4 * c01) * (J - 1) + (lam + 0.3 * mu) / 2 * (J - 1) ** 2
    assert m.elastic_energy() == pytest.approx(0.02 ** 3 * psi, rel=1e-9)


@pytest.mark.slow
def test_truth_cube_rms_below_corotational_fem(shared_data):
    """Kerdok truth cube, 10 mm mesh: measured 0.98 / 1.35 / 1.62 mm RMS (corotational ANP FEM: 0.99 / 1.39 /
    1.80 mm, docs/benchmarks.md); the 1.2 mm target at 12.5 % and 18.25 % is NOT reached."""
    spec = importlib.util.spec_from_file_location("tc", Path(__file__).resolve().parents[1] / "scripts" / "truthcube.py")
    tc = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tc)
    rest, measured = tc.load_truthcube(shared_data / "truthcube" / "uniaxial_positions.csv")
    out = tc.run_model("neo_hookean", rest, measured, 0.01)
    assert out[0.125][0] < 1.39e-3 and out[0.1825][0] < 1.70e-3

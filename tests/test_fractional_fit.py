"""Identification of the variable-order law (the variable-order paper, section III) and the 1-D comparison models."""

from __future__ import annotations

import math

import numpy as np
import pytest

from surgsim_envs.bench import fractional_fit as ff
from surgsim_envs.bench import viscoelastic_1d as v1
from surgsim_envs.cli import main
from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue import fractional_calculus as fc


def _synthetic(eta, orders, *, duration=6.0, ramp=1.0, fine=8000, every=20, noise=0.01, seed=1):
    """Ramp-and-hold (smooth ramp) stress made on a grid `every` times finer than the fit's
    (8,001 samples; the fit resamples 400 points), with Gaussian noise of `noise` x max stress."""
    t = np.linspace(0.0, duration, fine + 1)
    x = np.minimum(t / ramp, 1.0)
    eps = 0.05 * (x - np.sin(2 * np.pi * x) / (2 * np.pi))
    sig = v1.fractional_stress(t, eps, eta, fc.PiecewiseOrder.uniform(orders, duration))
    rng = np.random.default_rng(seed)
    noisy = sig[::every] + noise * sig.max() * rng.standard_normal(len(t[::every]))
    return ff.StressRecord(t[::every], eps[::every], noisy, "synthetic")


@pytest.mark.parametrize("eta,orders", [(2.0e4, (0.3, 0.55, 0.4)),
                                        pytest.param(5.0e3, (0.7, 0.2, 0.15), marks=pytest.mark.slow)])
def test_identification_recovers_eta_and_orders_from_noisy_data(eta, orders):
    rec = _synthetic(eta, orders)
    fit = ff.fit_fractional(rec, pieces=3, grid=400, seed=3)
    assert abs(fit.eta / eta - 1) < 0.05
    for got, want in zip(fit.orders, orders):
        assert abs(got / want - 1) < 0.05, (fit.orders, orders)
    assert fit.relative_residual < 0.05            # noise-level misfit


@pytest.mark.slow
def test_a_single_order_cannot_fit_variable_order_data():
    rec = _synthetic(2.0e4, (0.3, 0.55, 0.4), noise=0.0)
    one = ff.fit_fractional(rec, pieces=1, grid=400)
    three = ff.fit_fractional(rec, pieces=3, grid=400)
    assert one.cost > 20 * three.cost


def test_sls_fit_recovers_an_sls_record():
    t = np.linspace(0, 5, 1001)
    eps = 0.04 * np.minimum(t / 0.5, 1.0)
    sig = v1.sls_stress(t, eps, 3e3, 5e3, 0.8)
    sls = ff.fit_sls(ff.StressRecord(t, eps, sig))
    assert sls.e_inf == pytest.approx(3e3, rel=0.01) and sls.e1 == pytest.approx(5e3, rel=0.01)
    assert sls.tau == pytest.approx(0.8, rel=0.01)


def test_sls_closed_forms_match_the_time_stepped_law():
    t = np.linspace(0, 3, 3001)
    step = np.ones_like(t)
    step[0] = 0.0
    sig = v1.sls_stress(t, step * 0.01, 2e3, 1e3, 0.5)   # step over the first sample, then held
    assert np.allclose(sig[10:] / 0.01, v1.relaxation_modulus("sls", t[10:] - 0.5 * t[1], e_inf=2e3, e1=1e3, tau=0.5),
                       rtol=2e-3)
    j = v1.creep_compliance("sls", np.array([0.0, 1e9]), e_inf=2e3, e1=1e3, tau=0.5)
    assert j == pytest.approx([1 / 3e3, 1 / 2e3])
    assert v1.creep_compliance("kelvin_voigt", np.array([1e9]), k=4e3, b=10.0)[0] == pytest.approx(1 / 4e3)
    sb = v1.creep_compliance("scott_blair", np.array([2.0]), eta=1e3, q=0.5)[0]
    assert sb == pytest.approx(math.sqrt(2.0) / (1e3 * math.gamma(1.5)))


def test_record_reader_generic_and_phantom(tmp_path, shared_data):
    rec = _synthetic(1e4, (0.4,), noise=0.0)
    path = tmp_path / "relax.csv"
    ff.write_record(str(path), rec)
    back = ff.read_record(str(path))
    assert np.allclose(back.stress, rec.stress) and np.allclose(back.time, rec.time)
    ph = ff.read_record(str(shared_data / "tissue_mechanics/ecoflex_phantom_compression/EF10_50T_A1.csv"))
    assert len(ph.time) == 1202 and ph.strain.max() == pytest.approx(0.6667, abs=1e-3)
    # compression positive, kPa -> Pa: secant modulus at 10 % strain ~16 kPa (README)
    k = np.searchsorted(ph.strain, 0.1)
    assert ph.stress[k] / ph.strain[k] == pytest.approx(16.2e3, rel=0.05)
    assert ff.check_test(ph, "ramp") == "" and "no hold" in ff.check_test(ph, "relax")


def test_bad_records_raise(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("time,strain,stress\n0,0,0\n1,0.1,x\n")
    with pytest.raises(ConfigError, match="three numbers"):
        ff.read_record(str(p))
    with pytest.raises(ConfigError, match="increase"):
        ff.StressRecord([0, 1, 1, 2, 3], [0] * 5, [0] * 5)
    with pytest.raises(ConfigError, match="pieces"):
        ff.fit_fractional(_synthetic(1e4, (0.4,)), pieces=0)


def test_cli_fit_fractional_prints_parameters_and_saves_plot(tmp_path, capsys):
    rec = _synthetic(1e4, (0.35, 0.5), noise=0.0)
    data, plot = tmp_path / "relax.csv", tmp_path / "fit.png"
    ff.write_record(str(data), rec)
    assert main(["fit", "--model", "fractional", "--test", "relax", "--data", str(data), "--pieces", "2",
                 "--plot", str(plot)]) == 0
    out = capsys.readouterr().out
    assert "eta" in out and "q2" in out and "residual" in out and "SLS" in out
    assert plot.stat().st_size > 10_000
    assert main(["fit", "--model", "fem", "--test", "ramp", "--data", str(data)]) == 2

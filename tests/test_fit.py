"""surgsim fit: recover E from FEM-generated indentation data; mass-spring fit reports a residual."""

import numpy as np
import pytest

from surgsim_envs.bench import material as mt
from surgsim_envs.bench.fit import fit, read_csv
from surgsim_envs.errors import ConfigError

KW = dict(indenter_radius=0.005, thickness=0.01, spacing=0.002)


@pytest.fixture(scope="module")
def data():
    true = {"young": 7000.0, "poisson": 0.45, "relax_fraction": 0.0}
    res = mt.indent("fem", true, depth=0.0015, n_depths=8, time_steps=0, **KW)
    noise = 1.0 + 0.01 * np.random.default_rng(0).standard_normal(len(res.force))
    return res.depth, res.force * noise


def test_fem_fit_recovers_young(data):
    out = fit("fem", "indent", *data, material={"young": 3000.0, "poisson": 0.45}, **KW)
    assert out.params["young"] == pytest.approx(7000.0, rel=0.02)
    assert out.relative_residual < 0.03


def test_mass_spring_fit_reports_residual(data):
    runs = []
    out = fit("mass_spring", "indent", *data, material={"young": 3000.0, "poisson": 0.45, "relax_fraction": 0.0},
              progress=lambda: runs.append(1), **KW)
    assert len(runs) == out.evaluations >= 1       # the CLI's progress bar ticks once per model run
    assert out.params["young"] > 7000.0        # a spring network is softer than the FEM slab (no volume term)
    assert out.residual > 0 and np.isfinite(out.residual)


def test_relax_fit_recovers_sls_parameters():
    true = {"preset": "liver", "relax_fraction": 0.4, "relax_time": 0.3, "nonlinear": 0.0}
    res = mt.relax("mass_spring", true, strain=0.02, ramp_time=0.1, hold_time=0.9, samples=60)
    start = {"preset": "liver", "young": 3000.0, "relax_fraction": 0.2, "relax_time": 0.8, "nonlinear": 0.0}
    out = fit("mass_spring", "relax", res.time, res.force, start, strain=0.02, ramp_time=0.1, samples=60,
              max_evaluations=25)
    assert out.params["relax_fraction"] == pytest.approx(0.4, abs=0.03)
    assert out.params["relax_time"] == pytest.approx(0.3, rel=0.1)
    assert out.params["young"] == pytest.approx(4000.0, rel=0.05)


def test_csv_and_bad_input(tmp_path):
    p = tmp_path / "d.csv"
    p.write_text("depth_m,force_N\n0.001,0.01\n0.002,0.03\n0.003,0.06\n")
    x, f = read_csv(str(p))
    assert len(x) == 3 and f[-1] == 0.06
    with pytest.raises(ConfigError):
        fit("fem", "bend", x, f)
    (tmp_path / "bad.csv").write_text("a,b\n1,x\n")
    with pytest.raises(ConfigError):
        read_csv(str(tmp_path / "bad.csv"))

"""Calibration of the diffusion model against FEM indentation (surgsim fit), checked on a setup it
was not fitted on."""

from __future__ import annotations

import numpy as np
import pytest

from surgsim_envs.bench import material as mt
from surgsim_envs.bench.accuracy_scene import force_error
from surgsim_envs.bench.fit import fit
from surgsim_envs.bench.references import dimitriadis_force, dimitriadis_valid_depth
from surgsim_envs.tissue.diffusion import INDENT_CALIBRATION, DiffusionModel


def test_indentation_through_the_compliance_matches_stepping():
    """bench/material.indent uses contact_compliance for this model: under the same load the
    stepped model settles to the compliance prediction."""
    from surgsim_envs.bench.diffusion_press import paper_case

    m = paper_case("isotropic", points=300, material={"preset": "liver", "young": 30_000.0, "nonlinear": 0.0})
    top = np.flatnonzero(m.rest_positions[:, 2] > 0.0499)[:5]
    comp = m.contact_compliance(top, axis=2)                # per unit +z force (pressing: -z)
    f = np.zeros_like(m.positions)
    f[top, 2] = -2.0
    u = m.static_solve(f) - m.rest_positions
    np.testing.assert_allclose(u[top, 2], comp @ f[top, 2], rtol=1e-9, atol=1e-12)
    assert np.all(np.diag(comp) > 0) and np.all(comp >= 0)


@pytest.mark.slow
def test_fit_to_fem_then_held_out_setup():
    """Fit omega and E to FEM data (E 10 kPa, 4 mm sphere, 20 mm slab); on the held-out accuracy
    scene (E 4 kPa, 5 mm sphere, 30 mm slab, Dimitriadis) the calibrated model errs far less than
    the uncalibrated one, and the fit reproduces INDENT_CALIBRATION."""
    setup = dict(indenter_radius=0.004, thickness=0.02, spacing=0.0015)
    fem = mt.indent("fem", {"preset": "spleen", "relax_fraction": 0.0, "nonlinear": 0.0}, depth=0.0015, n_depths=10,
                    time_steps=0, **setup)
    out = fit("diffusion", "indent", fem.depth, fem.force, "spleen", length="depth", **setup)
    assert out.relative_residual < 0.03
    assert out.params["omega"] == pytest.approx(INDENT_CALIBRATION["omega"], rel=0.05)
    assert out.params["young"] / 10_000.0 == pytest.approx(INDENT_CALIBRATION["stiffness_factor"], rel=0.05)

    mat = {"preset": "liver", "relax_fraction": 0.0, "nonlinear": 0.0}
    dv = dimitriadis_valid_depth(0.005, 0.03)
    errors = {}
    for name, opts in (("calibrated", DiffusionModel.accuracy_options), ("default", {})):
        res = mt.indent("diffusion", mat, indenter_radius=0.005, depth=dv, thickness=0.03, spacing=0.002, n_depths=8,
                        time_steps=0, **opts)
        ref = dimitriadis_force(res.depth, 0.005, 4000.0, 0.45, 0.03, bonded=True)
        errors[name] = force_error(res.depth, res.force, ref, dv)
    assert errors["calibrated"] < 0.15
    assert errors["default"] > 5.0                              # uncalibrated: many times too stiff


def test_relaxation_fit_is_refused_for_a_model_without_viscoelasticity():
    from surgsim_envs.errors import ConfigError

    t = np.linspace(0.0, 1.0, 10)
    with pytest.raises(ConfigError, match="lacks the capability 'viscoelastic'"):
        fit("diffusion", "relax", t, np.exp(-t))

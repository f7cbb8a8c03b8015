"""The task-level accuracy harness (`surgsim bench task-accuracy`): its metrics on known inputs, its
refusals, and one press set in Palpation-v0's own scene."""

from __future__ import annotations

import pytest

from surgsim_envs.bench import task_accuracy as ta
from surgsim_envs.errors import ConfigError

PROBES = ta.ProbeSet(inclusions=(ta.Inclusion("lump", (0.02, 0.0), 0.011, 0.007, 5.0),), depths=(0.003, 0.006),
                     hold=0.5, spacings=(0.01,), reference_spacings=(0.01,))   # 0.5 s: settled to 0.1 %


def _row(forces, model="m"):
    return {"task": "T", "model": model, "spacing": 0.01, "nodes": 10, "forces_N": forces, "max_tensile_N": 0.0,
            "us_per_env_step": 100.0, "us_per_ms": 10.0}


def test_errors_contrast_and_monotonicity_from_known_forces():
    ref = _row({"0/over/3mm": 1.0, "0/over/6mm": 2.0, "0/mirror/3mm": 0.5, "0/mirror/6mm": 1.0})
    ours = _row({"0/over/3mm": 1.1, "0/over/6mm": 1.0, "0/mirror/3mm": 0.5, "0/mirror/6mm": 1.25})
    row = ta.compare(ours, ref, PROBES)
    assert row["error_median"] == pytest.approx((0.1 + 0.25) / 2)     # errors 0.1, 0.5, 0, 0.25
    assert row["error_p95"] == pytest.approx(0.4625)                 # linear percentile of the four
    assert row["contrast"] == [pytest.approx(0.8)] and row["contrast_reference"] == [pytest.approx(2.0)]
    assert not row["monotone"]                                   # over the lump the force fell with depth
    assert ta.compare(ref, ref, PROBES)["monotone"] and ta.compare(ref, ref, PROBES)["error"] == 0.0


def test_unknown_names_are_refused_before_anything_is_written(tmp_path):
    import argparse

    parser = argparse.ArgumentParser()
    ta.add_arguments(parser)
    out = tmp_path / "out"
    for argv, word in ((["--models", "bogus"], "bogus"), (["--tasks", "SurgSim/Nope-v0"], "Nope"),
                       (["--spacings", "0.0005"], "outside 1-20 mm"), (["--spacings", "2.5mm"], "not a number")):
        with pytest.raises(ConfigError, match=word):
            ta.run(parser.parse_args(argv + ["--out", str(out)]))
    assert not out.exists()


def test_presses_in_the_palpation_scene_are_unilateral_rise_with_depth_and_feel_the_lump():
    row = ta.measure("SurgSim/Palpation-v0", "mass_spring", 0.01, PROBES)
    f = row["forces_N"]
    assert row["max_tensile_N"] <= 1e-9                          # contact never pulls the probe
    assert ta.monotone(f, PROBES.depths)
    assert ta.contrast(f, 1, 0.006)[0] > 1.0                      # a 5x stiffer lump feels stiffer
    assert 0.0 <= row["path_difference"] < 0.02                   # frictionless, elastic: one pose, one force


# ----------------------------------------------------------------------------------------------
# the reference: Richardson extrapolation and the quasi-static presses in the task's scene
from surgsim_envs.bench import task_reference as tr  # noqa: E402


def _trapezoid(n: int) -> float:
    """Trapezoid rule for the integral of exp on [0, 1] with n intervals (error c2 h^2 + c4 h^4 + ...)."""
    import numpy as np

    x = np.linspace(0.0, 1.0, n + 1)
    y = np.exp(x)
    return float((y.sum() - 0.5 * (y[0] + y[-1])) / n)


def test_richardson_finds_the_order_and_the_limit_of_a_known_discretisation():
    """The trapezoid rule converges at order 2 to e - 1: from h = 1/4, 1/5, 1/6 the observed order is 2
    and the extrapolation lands much nearer e - 1 than the finest rule (its h^4 term is what is left)."""
    import math

    exact = math.e - 1.0
    h = [1 / 4, 1 / 5, 1 / 6]
    f = [_trapezoid(n) for n in (4, 5, 6)]
    f0, p = tr.richardson(h, f)
    assert p == pytest.approx(2.0, abs=0.05)
    assert abs(f0 - exact) < 0.02 * abs(f[-1] - exact)


def test_richardson_refuses_a_sequence_that_is_not_converging_monotonically():
    with pytest.raises(ConfigError, match="do not converge monotonically"):
        tr.richardson([0.005, 0.004, 0.0033], [0.80, 0.70, 0.75])
    with pytest.raises(ConfigError, match="descending"):
        tr.richardson([0.004, 0.005, 0.0033], [0.8, 0.7, 0.65])


def test_extrapolate_states_last_change_order_and_convergence_per_press():
    """Converged means the last refinement changed every press by under 1 % (the issue's definition):
    a smooth order-2 sequence whose last change is under 1 % converges, and its Richardson limit is used
    because the coarse and the fine triple agree; a press that wobbles by 20 % is not converged and is
    not extrapolated (the finest force is used)."""
    import math

    ns = (5, 6, 7, 8)
    smooth = [{"task": "T", "spacing": 1 / n, "nodes": n, "seconds": 1.0, "forces_N": {"smooth": _trapezoid(n)}}
              for n in ns]
    ref = tr.extrapolate(smooth[::-1])                     # any order in
    assert ref["spacings"] == [1 / n for n in ns]
    last = abs(_trapezoid(8) - _trapezoid(7)) / _trapezoid(8)
    assert ref["last_change"]["smooth"] == pytest.approx(last) and last < 0.01
    assert ref["reference_converged"] and ref["reference_extrapolated"]
    assert ref["observed_order"]["smooth"] == pytest.approx(2.0, abs=0.05)
    assert ref["forces_N"]["smooth"] == pytest.approx(math.e - 1.0, rel=1e-4)
    wobbly = [{**r, "forces_N": {**r["forces_N"], "wobbly": 1.0 + 0.1 * (-1) ** n}} for r, n in zip(smooth, ns)]
    ref = tr.extrapolate(wobbly)
    assert "wobbly" in ref["not_extrapolated"] and ref["forces_N"]["wobbly"] == wobbly[-1]["forces_N"]["wobbly"]
    assert ref["forces_N"]["smooth"] == smooth[-1]["forces_N"]["smooth"]   # one press unchecked: none extrapolated
    assert not ref["reference_converged"] and ref["last_refinement_change"] == pytest.approx(0.2 / 1.1)
    three = tr.extrapolate(smooth[:3])
    assert math.isinf(three["extrapolation_change"]["smooth"]) and not three["reference_extrapolated"]
    assert tr.extrapolate(smooth[:2])["last_change"]["smooth"] > 0.0
    with pytest.raises(ConfigError, match="2 or more spacings"):
        tr.extrapolate(smooth[:1])


def test_reference_presses_in_the_task_scene_rise_with_depth_and_feel_the_lump():
    """One coarse reference row (the coarsest graded lattice: 5 mm at each site): the quasi-static presses rise with
    depth, and a 5x lump raises the force over it above the mirror site's; each site has its own mesh."""
    row = tr.reference_row("SurgSim/Palpation-v0", PROBES, 0.005, "liver", ta.make_task_env)
    f = row["forces_N"]
    assert set(row["nodes_by_site"]) == {"0/over", "0/mirror"}
    assert ta.monotone(f, PROBES.depths)
    assert f["0/over/6mm"] > f["0/mirror/6mm"] > 0.0


def test_reference_scene_is_graded_about_the_press_site_with_its_contact_per_area():
    """The reference's lattice for a site: the site on a surface node, spacing h_f around it (the fine box
    covers the contact radius of the deepest press), the node penalty 1e8 N/m^3 x h_f^2 and samples at h_f / 2;
    the inclusion's mask follows the new mesh."""
    import numpy as np

    fine, xy = 0.004, (-0.02, 0.0)
    env = ta.make_task_env("SurgSim/Palpation-v0", tr.REFERENCE_MODEL, tr.COARSE_SPACING, material=tr.elastic("liver"))
    try:
        n = tr.graded_scene(env, xy, fine, 0.007)
        x = env.sim.tissue().positions
        assert n == len(x)
        top = x[np.isclose(x[:, 2], env.surface_z)]
        assert np.min(np.linalg.norm(top[:, :2] - xy, axis=1)) < 1e-12          # the site is a node
        row = top[np.isclose(top[:, 1], 0.0)][:, 0]
        near = np.sort(row[np.abs(row - xy[0]) <= tr.fine_half_widths(0.01, 0.007)[0] + 1e-9])
        assert np.allclose(np.diff(near), fine, atol=1e-12)                        # uniform h_f across the box
        assert tr.fine_half_widths(0.01, 0.007)[0] >= np.sqrt(2 * 0.01 * 0.007 - 0.007 ** 2)
        contact = env.sim.scene.config.contact
        assert contact.stiffness == pytest.approx(tr.CONTACT_STIFFNESS_PER_AREA * fine ** 2)
        assert contact.surface_samples == tr.SURFACE_SUBDIVISIONS == 2
        env.reset(seed=0, options={"inclusion_position": xy, "stiffness_contrast": (5.0, 5.0),
                                   "inclusion_depth": (0.011, 0.011), "inclusion_radius": (0.007, 0.007),
                                   "young_scale": (1.0, 1.0)})
        young = env.sim.tissue().fields["young"]
        assert len(young) == len(env.sim.tissue().tets) and young.max() / young.min() == pytest.approx(5.0)
    finally:
        env.close()


def test_rescore_recomputes_every_model_error_from_stored_forces_against_a_new_reference(monkeypatch):
    """--rescore: the reference is recomputed and each model row's errors come from its stored per-press
    forces (no model is rerun); a task without a probe set is refused by name."""
    keys = ["0/over/3mm", "0/mirror/3mm"]
    old_ref = {"forces_N": dict.fromkeys(keys, 1.0)}
    new_ref = {"forces_N": {"0/over/3mm": 2.0, "0/mirror/3mm": 1.0}}
    row = {**_row({"0/over/3mm": 1.0, "0/mirror/3mm": 1.0}), "task": "SurgSim/Palpation-v0"}
    probes = ta.ProbeSet(inclusions=PROBES.inclusions, depths=(0.003,), hold=0.5, spacings=(0.01,),
                         reference_spacings=(0.004, 0.002))
    monkeypatch.setitem(ta.PROBE_SETS, "SurgSim/Palpation-v0", (probes, probes))
    monkeypatch.setattr(ta, "converged_reference", lambda task, p, progress: new_ref)
    table = {"rows": [ta.compare(row, old_ref, probes)], "references": {"SurgSim/Palpation-v0": old_ref},
             "quick": False, "tolerances": {}, "not_covered": []}
    assert table["rows"][0]["error"] == 0.0
    out = ta.rescore(table, progress=lambda s: None)
    assert out["references"]["SurgSim/Palpation-v0"] is new_ref
    assert out["rows"][0]["error_median"] == pytest.approx(0.25)          # errors 0.5 and 0
    assert out["rows"][0]["forces_N"] == row["forces_N"]
    with pytest.raises(ConfigError, match="has no probe set"):
        ta.rescore(table, ["SurgSim/PalpationPress-v0"], progress=lambda s: None)


def test_converged_reference_runs_the_reference_at_each_spacing_and_states_its_change():
    """The CLI's reference path end to end on two coarse levels: every press gets a force at each
    level, and the last change is stated (not asserted small: two coarse levels)."""
    probes = ta.ProbeSet(inclusions=PROBES.inclusions, depths=(0.004,), hold=0.3, spacings=(),
                         reference_spacings=(0.005, 0.004))
    ref = ta.converged_reference("SurgSim/Palpation-v0", probes, progress=lambda text: None)
    keys = {"0/over/4mm", "0/mirror/4mm"}
    assert set(ref["forces_N"]) == keys
    assert [len(f) for f in ref["forces_by_spacing"]] == [2, 2]
    assert ref["forces_N"]["0/over/4mm"] > ref["forces_N"]["0/mirror/4mm"] > 0.0   # the lump is felt
    assert 0.0 <= ref["last_refinement_change"] < 1.0

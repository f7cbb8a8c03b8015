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
    for argv, word in ((["--models", "bogus"], "bogus"), (["--tasks", "SurgSim/Nope-v0"], "Nope")):
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

"""`surgsim demo`: runs headless to completion, writes its files, shows the physics it claims."""

import json

import pytest

from surgsim_envs.cli import main


@pytest.mark.parametrize("duration", ["2", "2.7"])  # 2.7 s: phase lengths that are not whole steps
def test_demo_runs_and_summary_shows_the_physics(tmp_path, duration, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--duration", duration, "--no-video", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert (out / "forces.png").stat().st_size > 10_000
    assert "summary.json" in capsys.readouterr().out
    palp, grasp = summary["palpation"], summary["grasp"]
    # the stiff inclusion pushes back harder than the tissue beside it
    assert palp["peak_force_above_inclusion_N"] > 1.1 * palp["peak_force_beside_inclusion_N"] > 0
    # the tip stays on the surface: penetration below 10 % of the indentation depth
    assert palp["max_penetration_m"] < 0.1 * palp["indentation_depth_m"]
    # the grasping simulation paper: the normal force relaxes while the jaws are held, and the tissue slips at a finite pull
    assert grasp["normal_force_end_of_hold_N"] < 0.9 * grasp["normal_force_end_of_close_N"]
    assert 0 < grasp["slip_onset_pull_force_N"] < grasp["peak_normal_force_N"]


def test_demo_rejects_bad_duration(tmp_path, capsys):
    assert main(["demo", "--duration", "0.5", "--no-video", "--out", str(tmp_path)]) != 0
    assert "duration" in capsys.readouterr().err

"""`surgsim demo`: runs headless to completion, writes its files, shows the physics it claims."""

import json

import pytest

from surgsim_envs.cli import main


# 2.7 s: phase lengths that are not whole steps; "cold": caches reported cold, so the demo compiles
# ahead (its warm-up runs on the demo's own simulations, which then go back to their initial state)
@pytest.mark.parametrize("duration, cold", [("2", True), ("2.7", False)])
def test_demo_runs_and_summary_shows_the_physics(tmp_path, duration, cold, capsys, monkeypatch):
    from surgsim_envs import numba_cache

    if cold:
        from surgsim_envs.scene import demo

        monkeypatch.setattr(numba_cache, "is_warm", lambda stage, package=None: False)
        monkeypatch.setattr(demo, "WARMUP_DURATION", 0.5)      # the path, not the compile (caches are warm here)
    out = tmp_path / "demo"
    assert main(["demo", "--duration", duration, "--no-video", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert (out / "forces.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert "summary.json" in printed
    assert ("compiling the physics kernels once" in printed) == cold
    assert (summary["compile_seconds"] > 0) == cold
    for part in ("palpation", "grasp"):
        assert summary[part]["first_step_seconds"] > 0          # timed apart from the rate
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


def test_warmup_lists_its_stages_and_names_an_unknown_one(capsys):
    assert main(["warmup", "--list"]) == 0
    out = capsys.readouterr().out
    for stage in ("demo: palpation scene", "demo: grasp scene", "task: SurgSim/Grasp-v0", "task: SurgSim/PalpationPress-v0"):
        assert stage in out
    assert main(["warmup", "--only", "nosuch"]) == 2
    assert "--only 'nosuch': no stage starts with ['nosuch']; stages: ['demo: palpation scene'" in capsys.readouterr().err


def test_warmup_of_a_warm_task_compiles_nothing(capsys):
    assert main(["warmup", "--only", "task: SurgSim/PalpationPress-v0", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["warmup", "--only", "task: SurgSim/PalpationPress-v0", "--quiet", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in rows] == ["task: SurgSim/PalpationPress-v0"] and rows[0]["kernels_compiled"] == 0


def test_warmup_json_stays_json_when_the_caches_live_outside_the_package(capsys, monkeypatch):
    from surgsim_envs import numba_cache

    monkeypatch.setattr(numba_cache, "caches_here", lambda: False)    # as with NUMBA_CACHE_DIR or a read-only install
    assert main(["warmup", "--only", "task: SurgSim/PalpationPress-v0", "--quiet", "--json"]) == 0
    out = capsys.readouterr()
    assert json.loads(out.out)[0]["name"] == "task: SurgSim/PalpationPress-v0"
    assert "caches outside the package" in out.err

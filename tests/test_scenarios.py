"""Scenarios: schema validation, scoring, the runner and reports, and the grasping simulation paper's grasp protocol.

The mu sweep (close, hold, pull; mu = 0.6, 0.8, 1.0) runs once at a quarter of the paper's
durations and is shared by the paper-002 tests.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.scenarios import load_scenario, loads_scenario
from surgsim_envs.scenarios.scoring import safety_violations, score_criteria
from surgsim_envs.scenarios.schema import CriterionSpec

ROOT = Path(__file__).resolve().parents[1]
TASKS = sorted((ROOT / "tasks").glob("*.toml"))
SCENARIO_TASKS = [p for p in TASKS if p.stem in {"palpation_find_inclusion", "spleen_grasp_and_retract",
                                                   "grasp_slippage_mu_sweep", "palpation_policy",
                                                   "palpation_press_policy"}]
GOOD = """
[scenario]
name = "ok"
scene = "grasp"

[[phases]]
type = "close_jaws"
duration = 1.0

[[phases]]
type = "pull"
duration = 1.0
distance = 0.02
"""


# ----------------------------------------------------------------------------------------------
# schema
def test_shipped_scenarios_are_present_and_validate():
    names = {p.stem for p in SCENARIO_TASKS}
    assert {"palpation_find_inclusion", "spleen_grasp_and_retract", "grasp_slippage_mu_sweep",
            "palpation_policy"} <= names
    for path in SCENARIO_TASKS:
        sc = load_scenario(path)
        assert sc.name == path.stem
        assert sc.phases or sc.policy is not None


def test_mu_sweep_file_follows_paper_002():
    sc = load_scenario(ROOT / "tasks" / "grasp_slippage_mu_sweep.toml")
    assert [p.type for p in sc.phases] == ["close_jaws", "hold", "pull"]
    assert [p.duration for p in sc.phases[:2]] == [4.0, 7.0]
    assert sc.sweep == {"mu": [0.6, 0.8, 1.0]}
    assert [v["mu"] for v, _ in sc.runs()] == [0.6, 0.8, 1.0]
    assert [r.scene.mu for _, r in sc.runs()] == [0.6, 0.8, 1.0]


def test_unknown_key_names_key_value_and_line():
    text = GOOD.replace('distance = 0.02', 'distance = 0.02\nspeeed = 3')
    with pytest.raises(ConfigError) as exc:
        loads_scenario(text, "bad.toml")
    msg = str(exc.value)
    line = text.splitlines().index("speeed = 3") + 1
    assert "speeed" in msg and "3" in msg and f"line {line}" in msg and "phases[1]" in msg


def test_wrong_type_names_key_and_value():
    text = GOOD.replace("duration = 1.0\n\n[[phases]]", 'duration = "four"\n\n[[phases]]')
    with pytest.raises(ConfigError) as exc:
        loads_scenario(text, "bad.toml")
    msg = str(exc.value)
    assert "phases[0].duration" in msg and "'four'" in msg and "line 8" in msg


def test_impossible_phase_order_is_rejected():
    text = GOOD.replace('type = "close_jaws"', 'type = "hold"')
    with pytest.raises(ConfigError, match=r"phases\[1\]\.type.*before the jaws have closed"):
        loads_scenario(text, "bad.toml")
    with pytest.raises(ConfigError, match="needs a probe"):
        loads_scenario(GOOD.replace('type = "pull"\nduration = 1.0\ndistance = 0.02', 'type = "press"'), "bad.toml")
    twice = GOOD + '\n[[phases]]\ntype = "close_jaws"\n'
    with pytest.raises(ConfigError, match="closes the jaws again"):
        loads_scenario(twice, "bad.toml")


@pytest.mark.parametrize("edit, expect", [
    (('scene = "grasp"', 'scene = "kitchen"'), "scenario.scene"),
    (('name = "ok"', 'name = "ok"\ncolour = 1'), "unknown key 'colour'"),
    (('distance = 0.02', 'distance = 0.02\nforce = 1.0'), "either distance"),
    (('duration = 1.0\n\n[[phases]]', 'duration = -1.0\n\n[[phases]]'), "must be > 0 s"),
    (('[[phases]]\ntype = "close_jaws"', '[sweep]\nmu = [0.6, "x"]\n\n[[phases]]\ntype = "close_jaws"'), "sweep.mu[1]"),
    (('[[phases]]\ntype = "close_jaws"', '[scoring.criteria.luck]\ntarget = 1\n\n[[phases]]\ntype = "close_jaws"'),
     "unknown criterion 'luck'"),
    (('scene = "grasp"', 'scene = "grasp"\n[trainee]\ndriver = "robot"'), "unknown driver 'robot'"),
])
def test_malformed_scenarios_fail_with_a_message_naming_the_key(edit, expect):
    with pytest.raises(ConfigError) as exc:
        loads_scenario(GOOD.replace(*edit), "bad.toml")
    assert expect in str(exc.value)


def test_toml_syntax_error_names_the_line():
    with pytest.raises(ConfigError, match="line 3"):
        loads_scenario('[scenario]\nname = "x"\nscene = grasp\n', "bad.toml")


def test_cli_rejects_bad_file_before_simulating(tmp_path, capsys, monkeypatch):
    from surgsim_envs import cli
    from surgsim_envs.scenarios import runner

    def boom(*a, **k):  # pragma: no cover - must not be reached
        raise AssertionError("simulation was built for an invalid scenario")

    monkeypatch.setattr(runner, "build_simulation", boom)
    bad = tmp_path / "bad.toml"
    bad.write_text(GOOD.replace('type = "close_jaws"', 'type = "hold"'))
    assert cli.main(["run", str(bad), "--out", str(tmp_path / "out"), "--no-video", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "bad.toml, line" in err and "pull" in err
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------------------------
# scoring
def test_safety_violations_intervals():
    t = np.arange(10) * 0.1
    f = np.array([0, 1, 3, 4, 1, 0, 5, 5, 0, 0], dtype=float)
    v = safety_violations(t, f, 2.0)
    assert [(round(x["start"], 6), round(x["end"], 6), x["peak"]) for x in v] == [(0.2, 0.4, 4.0), (0.6, 0.8, 5.0)]


def test_criterion_scores_are_linear_between_target_and_limit():
    crit = {"peak_force": CriterionSpec(target=1.0, limit=3.0, weight=1.0),
            "time": CriterionSpec(target=10.0, limit=20.0, weight=3.0)}
    score, res = score_criteria({"peak_force": 2.0, "time": 25.0}, crit)
    by = {r.name: r for r in res}
    assert by["peak_force"].score == pytest.approx(0.5) and by["peak_force"].passed
    assert by["time"].score == 0.0 and not by["time"].passed
    assert score == pytest.approx(100 * 0.5 / 4)


# ----------------------------------------------------------------------------------------------
# runs
@pytest.fixture(scope="module")
def mu_sweep(tmp_path_factory):
    from surgsim_envs.scenarios import run_scenario, write_report

    sc = load_scenario(ROOT / "tasks" / "grasp_slippage_mu_sweep.toml")
    results = run_scenario(sc, duration_scale=0.25, progress=False)
    out = tmp_path_factory.mktemp("mu")
    report = write_report(results, out)
    return results, report, out


def test_mu_sweep_runs_and_writes_report(mu_sweep):
    results, report, out = mu_sweep
    assert all(r.completed for r in results)
    for name in ("report.json", "forces.png", "report.md"):
        assert (out / name).stat().st_size > 0
    data = json.loads((out / "report.json").read_text())
    assert [r["mu"] for r in data["runs"]] == [0.6, 0.8, 1.0]
    for r in data["runs"]:
        assert r["slip_onset_pull"] is not None and r["peak_normal"] > 0
    assert 0 <= data["score"] <= 100 and set(data["criteria"]) >= {"completion", "peak_force"}
    assert "violations" in data["safety"]


def test_slip_onset_pull_force_increases_with_mu(mu_sweep):
    """The grasping simulation paper Fig. 5: slippage occurs at higher pulling forces as friction rises; the normal
    force (set by the closing) is not affected by mu."""
    _, report, _ = mu_sweep
    onset = [r["slip_onset_pull"] for r in report["runs"]]
    assert onset[0] < onset[1] < onset[2]
    assert onset[2] > 1.3 * onset[0]
    peaks = [r["peak_normal"] for r in report["runs"]]
    assert max(peaks) - min(peaks) < 0.15 * np.mean(peaks)
    # Coulomb: the friction force at slip cannot exceed mu times the normal force there
    for r in report["runs"]:
        assert r["metrics"]["slip_onset"]["tangential_force"] <= 1.1 * r["mu"] * r["metrics"]["slip_onset"]["normal_force"]


def test_hold_phase_shows_stress_relaxation(mu_sweep):
    """The grasping simulation paper Fig. 4: the normal force rises while the jaws close and falls (relaxation) while
    they are held still."""
    results, _, _ = mu_sweep
    for res in results:
        rec = res.recording
        close, hold = rec.phase == 0, rec.phase == 1
        f_close = rec.normal[close]
        assert f_close[-1] > 0.5 and f_close[-1] >= 0.9 * f_close.max()       # rises to the end of closing
        f_hold = rec.normal[hold]
        assert f_hold[-1] < 0.8 * f_close[-1]                                 # relaxes while held
        quarters = [q.mean() for q in np.array_split(f_hold, 4)]
        assert all(a > b for a, b in zip(quarters, quarters[1:]))            # monotone decay
        assert res.metrics["relaxed_fraction"] > 0.2


@pytest.mark.parametrize("name", ["palpation_find_inclusion", "spleen_grasp_and_retract"])
def test_scenario_runs_to_completion(name, tmp_path):
    from surgsim_envs.scenarios import run_scenario, write_report

    sc = load_scenario(ROOT / "tasks" / f"{name}.toml")
    results = run_scenario(sc, duration_scale=0.25, progress=False)
    report = write_report(results, tmp_path)
    (res,) = results
    assert res.completed and res.error is None
    assert [s["type"] for s in res.recording.phase_spans] == [p.type for p in sc.phases]
    assert res.recording.t[-1] == pytest.approx(0.25 * sum(p.duration for p in sc.phases), abs=0.02)
    assert (tmp_path / "forces.png").exists() and report["runs"][0]["completed"]
    if name == "palpation_find_inclusion":
        # the stiffest presses lie over the hidden inclusion (grid spacing 10 mm)
        assert res.metrics["inclusion_error"] < 0.008
    else:
        # the force ramp pulls without a gross slip and the jaws open at the end
        assert res.metrics["slip_events"] == 0
        assert res.metrics["peak_pull_force"] > 0.2
        assert res.recording.normal[-1] < 0.05


def test_device_driver_runs_the_scenario(tmp_path):
    """--device scripted: the default simulated hand follows the phase plan through the
    HapticDevice interface and receives the tool force."""
    from surgsim_envs.scenarios import run_scenario

    sc = load_scenario(ROOT / "tasks" / "palpation_find_inclusion.toml")
    (res,) = run_scenario(sc, duration_scale=0.1, device="scripted", progress=False)
    assert res.completed
    assert all(s["driver"] == "device" for s in res.recording.phase_spans)
    assert res.metrics["peak_force"] > 0.02


def test_policy_rollout_scenario(tmp_path):
    pytest.importorskip("gymnasium")
    from surgsim_envs.scenarios import run_scenario, write_report

    sc = load_scenario(ROOT / "tasks" / "palpation_policy.toml")
    (res,) = run_scenario(sc, progress=False)
    report = write_report([res], tmp_path)
    assert res.completed, res.error
    assert res.metrics["inclusion_error"] is not None and res.metrics["inclusion_error"] < 0.02
    assert report["criteria"]["inclusion_error"]["value"] == pytest.approx(res.metrics["inclusion_error"])


def test_bad_policy_reference_is_a_config_error():
    from surgsim_envs.scenarios.policies import load_policy

    with pytest.raises(ConfigError, match="no 'nope'"):
        load_policy("surgsim_envs.scenarios.policies:nope")
    with pytest.raises(ConfigError, match="module:function"):
        load_policy("not-a-reference")

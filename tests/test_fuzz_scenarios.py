"""Hostile scenario files: ``surgsim run --check`` validates everything a run will use
(env_kwargs against the task's own config, criteria, devices, trajectory scripts), so a file
that passes the check cannot fail on its inputs at run time; and a run writes what it has."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

pytest.importorskip("hypothesis", reason="hypothesis is in the [test] extra")
from hypothesis import HealthCheck, given, settings  # noqa: E402

import fuzz_surfaces as fs  # noqa: E402
from fuzz_harness import check  # noqa: E402
from surgsim_envs.cli import main  # noqa: E402
from surgsim_envs.errors import ConfigError  # noqa: E402
from surgsim_envs.scenarios import loads_scenario  # noqa: E402

FAST = settings(max_examples=60, deadline=None, database=None, suppress_health_check=list(HealthCheck))
MORE = settings(max_examples=1000, deadline=None, database=None, suppress_health_check=list(HealthCheck))


@FAST
@given(fs.scenario_case())
def test_fuzz_scenario_values(case):
    check(fs.run_scenario_check, case, timeout_s=20, names=(case[1],))


@pytest.mark.slow
@MORE
@given(fs.scenario_case())
def test_fuzz_scenario_values_more(case):
    check(fs.run_scenario_check, case, timeout_s=20, names=(case[1],))


def _rollout(key, value):
    return fs.ROLLOUT.format(key=key, value=value)


@pytest.mark.parametrize("key, value, message", [
    ("hold_steps", "1000000000000", r"hold_steps=1000000000000 steps is outside \[1, 100,000\]"),
    ("force_weight", "1.0", r"\['force_weight'\] are not fields of SurgSim/PalpationPress-v0's PalpationPressConfig"),
    ("press_cost", "nan", "press_cost=nan must be finite"),
    ("press_cost", "1e308", r"press_cost=1e\+308 is outside \[0, 1e\+06\]"),
    ("integrator", '""', "integrator='' must be a non-empty string"),
    ("render_mode", '"human"', "a scenario runs headless"),
    ("slab_size", '"ab"', "slab_size='ab' must be three positive lengths"),
])
def test_env_kwargs_are_checked_against_the_tasks_own_config(key, value, message):
    with pytest.raises(ConfigError, match=message) as err:
        loads_scenario(_rollout(key, value), "<s>")
    assert "line 9: policy.env_kwargs" in str(err.value)      # the key's line in the file


def test_valid_env_kwargs_pass_the_check():
    sc = loads_scenario(_rollout("press_cost", "0.5"), "<s>")
    assert sc.policy.env_kwargs == {"press_cost": 0.5}


@pytest.mark.parametrize("value, message", [("1e308", r"1e\+308 is out of range: must be >= 0 and <= 1e\+06"),
                                            ("-1.0", "must be >= 0")])
def test_criterion_weights_that_overflow_the_score_are_refused(value, message):
    with pytest.raises(ConfigError, match=message):
        loads_scenario(fs.phases_text("weight", value), "<s>")


def _scenario_with_device(device: str) -> str:
    return fs.phases_text("weight", "1.0").replace(
        '[[phases]]', f'[trainee]\ndriver = "device"\ndevice = "{device}"\n[[phases]]')


def test_a_scenario_file_may_not_open_a_network_port():
    with pytest.raises(ConfigError, match="opens a network port, which a scenario file may not do"):
        loads_scenario(_scenario_with_device("udp:9870"), "<s>")


def test_keyboard_device_without_viewer_fails_the_check(tmp_path, capsys):
    f = tmp_path / "kb.toml"
    f.write_text(_scenario_with_device("keyboard"))
    assert main(["run", str(f), "--check"]) == 2
    assert "reads its input from the viewer window: run with --viewer" in capsys.readouterr().err


def test_malformed_or_endless_trainee_script_fails_the_check(tmp_path):
    (tmp_path / "bad.json").write_text("{")
    (tmp_path / "long.json").write_text(json.dumps({"waypoints": [[0, 0, 0], [0.01, 0, 0]], "speeds": [1e-9]}))
    def with_script(name):
        return _scenario_with_device("scripted").replace('device = "scripted"', f'device = "scripted"\nscript = "{name}"')

    with pytest.raises(ConfigError, match="not valid JSON"):
        loads_scenario(with_script("bad.json"), "<s>", folder=tmp_path)
    with pytest.raises(ConfigError, match="the trajectory lasts 1e\\+07 s, more than the 3600 s"):
        loads_scenario(with_script("long.json"), "<s>", folder=tmp_path)


def test_report_is_written_even_when_a_plot_fails_and_scores_are_not_finite(tmp_path, monkeypatch):
    from surgsim_envs.scenarios import report as rep

    def broken_plot(results, path):
        raise RuntimeError("no plotting backend")

    fake = {"scenario": "s", "description": "", "score": math.nan, "passed": False, "duration_scale": 1.0,
            "criteria": {"peak_force": {"value": math.inf, "unit": "N", "target": 1.0, "limit": 2.0, "weight": 1.0,
                                        "score": math.nan, "passed": False}},
            "safety": {"limit": 3.0, "violations": []}, "runs": [{"score": math.nan, "slip_onset_pull": None}],
            "phases": []}
    monkeypatch.setattr(rep, "build_report", lambda results: dict(fake))
    monkeypatch.setattr(rep, "plot_forces", broken_plot)
    out = rep.write_report([], tmp_path, timeseries=False)
    saved = json.loads((tmp_path / "report.json").read_text())     # valid JSON: NaN written as null
    assert saved["score"] is None and saved["criteria"]["peak_force"]["value"] is None
    assert "forces.png not written (RuntimeError: no plotting backend)" in out["write_errors"][0]
    md = (tmp_path / "report.md").read_text()
    assert "**Score: - / 100**" in md and "Not written: forces.png" in md
    assert np.isnan(fake["score"])      # the caller's report is not modified in place

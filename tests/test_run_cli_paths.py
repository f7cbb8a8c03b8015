"""``surgsim run``: command-line paths resolve from the working directory, several scenario files
run in one call with a summary."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from surgsim_envs import cli
from surgsim_envs.cli.run import command_line_path

ROOT = Path(__file__).resolve().parents[1]
PRESS = ROOT / "tasks" / "palpation_press_policy.toml"
POLICY = "surgsim_envs/policies/palpation_press_v0.npz"


def test_command_line_path_makes_files_absolute_from_the_working_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert command_line_path("p.npz") == str(tmp_path / "p.npz")
    assert command_line_path("sub/m.zip") == str(tmp_path / "sub" / "m.zip")
    assert command_line_path("mine.py:act") == f"{tmp_path / 'mine.py'}:act"
    assert command_line_path("replay:hand.csv") == f"replay:{tmp_path / 'hand.csv'}"
    for unchanged in ("/abs/p.npz", "builtin:scan", "shipped:SurgSim/PalpationPress-v0", "my_pkg.pol:act",
                      "scripted", "udp:5005", "replay:/abs/hand.csv", None):
        assert command_line_path(unchanged) == unchanged


@pytest.mark.slow
def test_relative_policy_from_the_repository_root_runs(tmp_path, monkeypatch, capsys):
    """The README's command: a --policy relative to the working directory, not to tasks/."""
    monkeypatch.chdir(ROOT)
    out = tmp_path / "out"
    assert cli.main(["run", "tasks/palpation_press_policy.toml", "--policy", POLICY, "--no-video", "--quiet",
                     "--out", str(out), "--duration-scale", "0.5"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["runs"][0]["error"] is None
    assert "score" in capsys.readouterr().out


def test_policy_next_to_the_scenario_but_not_in_the_working_directory_is_not_found(tmp_path, monkeypatch, capsys):
    folder = tmp_path / "scen"
    folder.mkdir()
    shutil.copy(PRESS, folder / "press.toml")
    shutil.copy(ROOT / POLICY, folder / "mine.npz")
    elsewhere = tmp_path / "cwd"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert cli.main(["run", str(folder / "press.toml"), "--policy", "mine.npz", "--no-video", "--quiet",
                     "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "policy file 'mine.npz' not found" in err


@pytest.mark.slow
def test_several_scenario_files_run_each_and_print_a_summary(tmp_path, capsys):
    bad = tmp_path / "broken.toml"
    bad.write_text('[scenario]\nname = "x"\nscene = grasp\n')
    out = tmp_path / "out"
    rc = cli.main(["run", str(PRESS), str(bad), str(PRESS), "--no-video", "--quiet", "--out", str(out),
                   "--duration-scale", "0.5"])
    assert rc == 2                      # one file failed
    text = capsys.readouterr()
    assert "broken.toml: not valid TOML" in text.err and "line 3" in text.err
    assert "surgsim run: 3 scenarios, 2 ran, 1 failed" in text.out
    summary = text.out[text.out.index("surgsim run: 3 scenarios"):].splitlines()
    assert "passed" in summary[1] and "error:" in summary[2] and "passed" in summary[3]
    assert (out / "palpation_press_policy" / "report.json").is_file()


def test_several_scenario_files_with_check_all_valid(capsys):
    files = sorted(str(p) for p in (ROOT / "tasks").glob("*.toml"))
    assert len(files) >= 2
    assert cli.main(["run", *files, "--check"]) == 0
    out = capsys.readouterr().out
    assert f"surgsim run: {len(files)} scenarios, {len(files)} ran, 0 failed" in out
    assert out.count(" valid\n") + out.rstrip().endswith(" valid") >= len(files)

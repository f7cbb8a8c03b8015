"""``surgsim choose TASK``: the table's choice for a task, the gym.make call that builds it, or the refusal."""

import json

import gymnasium as gym

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs.bench.choose import choose_task_model
from surgsim_envs.cli import main


def test_the_choice_and_a_gym_make_call_that_builds_it(capsys):
    assert main(["choose", "SurgSim/Palpation-v0", "--tolerance", "0.5", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    pick = choose_task_model("SurgSim/Palpation-v0", 0.5)
    assert (out["model"], out["spacing_m"], out["error_p95"]) == (pick.model, pick.spacing, pick.error)
    assert out["error_p95"] <= 0.5 and out["tolerance"] == 0.5
    env = eval(out["gym_make"], {"gym": gym})          # the printed call builds the chosen tissue
    assert env.unwrapped.sim.tissue().name == pick.model
    env.close()


def test_a_task_without_a_qualifying_row_is_refused_with_the_closest(capsys):
    assert main(["choose", "SurgSim/Grasp-v0"]) == 2
    err = capsys.readouterr().err
    assert "no model meets SurgSim/Grasp-v0's force tolerance 10 %" in err and "closest" in err
    assert main(["choose", "SurgSim/Nope-v0"]) == 2
    assert "known tasks" in capsys.readouterr().err

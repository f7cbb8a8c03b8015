"""Palpation-v0's default on presses nothing was chosen on (surgsim_envs/bench/palpation_heldout.py):
two lumps and two depths outside the task-accuracy probe set, against the shipped graded-FEM
reference, friction on, elastic material."""

import pytest

from surgsim_envs.bench import palpation_heldout as ho
from surgsim_envs.envs.palpation import PalpationConfig
from surgsim_envs.envs.registry import task_spec


@pytest.fixture(scope="module")
def forces():
    return ho.press_forces(PalpationConfig.model)       # the task's default model on its default lattice


def test_the_default_reads_every_held_out_press_within_the_task_tolerance(forces):
    ref = ho.reference()
    finest = ref["levels"][ref["finest"]]
    tol = task_spec(ho.TASK).force_tolerance.value
    assert set(forces) == set(finest)
    for press, f in forces.items():
        assert f == pytest.approx(finest[press], rel=tol), f"{press}: {f:.4f} N, the reference {finest[press]:.4f} N"


def test_the_default_feels_each_held_out_lump_as_the_reference_does(forces):
    """Over each lump / at its mirror site, at both depths: within the tolerance of the reference's
    ratio (1.76-2.58 here), so the lump's signal is kept, not only the force level."""
    ref = ho.reference()
    finest = ref["levels"][ref["finest"]]
    tol = task_spec(ho.TASK).force_tolerance.value
    for i in range(len(ho.HELDOUT.inclusions)):
        for depth in ("4mm", "6mm"):
            ours = forces[f"{i}/over/{depth}"] / forces[f"{i}/mirror/{depth}"]
            theirs = finest[f"{i}/over/{depth}"] / finest[f"{i}/mirror/{depth}"]
            assert theirs > 1.5
            assert ours == pytest.approx(theirs, rel=tol), f"lump {i} at {depth}: {ours:.3f} against {theirs:.3f}"

"""Contact stiffness per unit surface area (``ContactConfig.stiffness_per_area``): the per-node penalty
follows the lattice, "auto" gives it to quasi-static models only, bad values are refused by name,
and in Palpation-v0's own scene the quasi-static FEM at 5 mm reads the converged reference's
forces within the task's declared tolerance, over the lump and at its mirror site."""

import json
from importlib import resources
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401
from surgsim_envs.bench import task_accuracy as ta
from surgsim_envs.bench import task_reference as tr
from surgsim_envs.envs.registry import task_spec
from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.contact_options import (QUASI_STATIC_STIFFNESS_PER_AREA, contact_params_for,
                                                stiffness_per_area_for)
from surgsim_envs.contact import ContactParams

TASK = "SurgSim/Palpation-v0"


def _lattice_tissue(h, caps):
    """A 3 x 3 node square lattice of spacing ``h`` m as a stand-in tissue surface."""
    xy = np.array([(i * h, j * h, 0.0) for j in range(3) for i in range(3)])
    tri = []
    for j in range(2):
        for i in range(2):
            a, b, c, d = 3 * j + i, 3 * j + i + 1, 3 * (j + 1) + i, 3 * (j + 1) + i + 1
            tri += [(a, b, d), (a, d, c)]
    return SimpleNamespace(rest_positions=xy, positions=xy, surface=np.array(tri), capabilities=frozenset(caps))


@pytest.mark.parametrize("h", [0.01, 0.005, 0.0025])
def test_the_per_node_penalty_is_the_area_stiffness_times_the_spacing_squared(h):
    tissue = _lattice_tissue(h, {"quasi_static", "implicit_contact"})
    cfg = SimpleNamespace(stiffness_per_area=2e7, implicit_damping=False)
    p = contact_params_for(ContactParams(stiffness=200.0), cfg, tissue)
    assert p.stiffness == pytest.approx(2e7 * h * h, rel=1e-12)     # axis edges are the median edge
    assert p.tangential_stiffness is None                           # = the normal one


def test_auto_is_per_area_for_quasi_static_models_and_per_node_for_the_others():
    cfg = SimpleNamespace(stiffness_per_area="auto")
    assert stiffness_per_area_for(cfg, _lattice_tissue(0.01, {"quasi_static", "implicit_contact"})) \
        == QUASI_STATIC_STIFFNESS_PER_AREA
    # an explicit step keeps a stiff penalty stable only below dt ~ sqrt(m / k): the per-node one stays
    assert stiffness_per_area_for(cfg, _lattice_tissue(0.01, {"implicit_contact"})) is None
    assert stiffness_per_area_for(SimpleNamespace(stiffness_per_area=None), _lattice_tissue(0.01, set())) is None


@pytest.mark.parametrize("bad", [-1.0, 0.0, float("nan"), float("inf"), "stiff"])
def test_a_bad_stiffness_per_area_is_refused_by_name(bad):
    with pytest.raises(ConfigError, match="stiffness_per_area"):
        stiffness_per_area_for(SimpleNamespace(stiffness_per_area=bad), _lattice_tissue(0.01, set()))
    with pytest.raises(ConfigError, match="contact_stiffness_per_area"):
        gym.make(TASK, contact_stiffness_per_area=bad, disable_env_checker=True)


def test_the_task_builds_the_quasi_static_model_with_the_area_stiffness():
    env = gym.make(TASK, model="fem_static", spacing=0.005, disable_env_checker=True).unwrapped
    try:
        k = env.sim.contacts[next(iter(env.sim.contacts))].params.stiffness
        assert k == pytest.approx(QUASI_STATIC_STIFFNESS_PER_AREA * 0.005 ** 2, rel=1e-9)
    finally:
        env.close()


def _reference_forces():
    table = json.loads(resources.files("surgsim_envs.tissue.data").joinpath("task_accuracy_table.json").read_text())
    return table["references"][TASK]["forces_N"]


def test_quasi_static_fem_at_5mm_reads_the_reference_within_the_task_tolerance_with_friction():
    """The probe set's first lump (5x, r 7 mm, 11 mm deep), pressed 5 mm over it and at its mirror
    site in the task's scene, friction on (liver, mu 0.5), elastic: each force within the task's
    declared tolerance of the converged FEM reference on graded lattices (docs/task_accuracy.md),
    and the lump's contrast (over / mirror) with it."""
    tol = task_spec(TASK).force_tolerance.value
    ref = _reference_forces()
    probes = ta.PROBE_SETS[TASK][0]
    inc = probes.inclusions[0]
    env = ta.make_task_env(TASK, "fem_static", 0.005, material=tr.elastic(ta.task_material(TASK)))
    try:
        presser = ta.Presser(env, probes.hold)
        over = presser.press(inc, inc.position, 0.005)
        mirror = presser.press(inc, ta.mirror(inc.position), 0.005)
    finally:
        env.close()
    assert over == pytest.approx(ref["0/over/5mm"], rel=tol)
    assert mirror == pytest.approx(ref["0/mirror/5mm"], rel=tol)
    assert over / mirror == pytest.approx(ref["0/over/5mm"] / ref["0/mirror/5mm"], rel=tol)

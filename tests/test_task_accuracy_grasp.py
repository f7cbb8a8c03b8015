"""Grasp-v0's and Slippage-v0's probe sets for `surgsim bench task-accuracy`: closures and pulls in the
tasks' own scenes, the slip-onset rule, the scoring and the reference's contact."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs.envs  # noqa: F401
from surgsim_envs.bench import grasp_reference as gr
from surgsim_envs.bench import task_accuracy as ta
from surgsim_envs.bench.probe_sets import grasp_closure as gc
from surgsim_envs.bench.probe_sets import slippage_pull as sp
from surgsim_envs.errors import ConfigError

#: the tasks' quick lattice (their registry's ``quick`` resolution)
COARSE = 0.015


@pytest.mark.parametrize("module", [gc, sp])
def test_the_probe_sets_are_registered_with_the_task_tolerance(module):
    from surgsim_envs.envs.registry import task_spec

    assert ta.PROBE_SETS[module.TASK] == (module.FULL, module.QUICK)
    declared = task_spec(module.TASK).force_tolerance
    assert ta.FORCE_TOLERANCES[module.TASK] == {"tolerance": declared.value, "reason": declared.why}


def test_grasp_tasks_take_the_organ_material_and_name_a_bad_one():
    env = gym.make(gc.TASK, resolution=COARSE, material={"preset": "spleen", "relax_fraction": 0.0},
                   disable_env_checker=True).unwrapped
    fields = env.sim.tissue().fields
    assert np.all(fields["relax_fraction"] == 0.0) and np.all(fields["young"] == 10_000.0)
    env.close()
    with pytest.raises(ConfigError, match=r"SlippageConfig\.material='granite'.*unknown material preset"):
        gym.make(sp.TASK, material="granite", disable_env_checker=True)


def test_grasp_closures_press_harder_as_the_jaws_close_and_never_pull():
    row = ta.measure(gc.TASK, "mass_spring", COARSE, gc.QUICK)
    f = row["forces_N"]
    assert set(f) == {f"{c:+g}/{w}" for c in gc.QUICK.closures for w in ("jaw1", "jaw2", "jaw3", "sum")}
    assert row["max_tensile_N"] == 0.0                       # unilateral: no jaw ever reads a pull
    for c in gc.QUICK.closures:
        assert f[f"{c:+g}/sum"] == pytest.approx(sum(f[f"{c:+g}/jaw{j}"] for j in (1, 2, 3)), rel=1e-12)
    assert f["+0.2/sum"] > f["+0/sum"]                         # a tighter closure presses harder
    assert f["+0.2/sum"] > 2 * row["hold_force_N"]            # and holds
    assert row["settle_change"]["+0.2/sum"] < 0.01            # held to quasi-static: the last 0.5 s moved < 1 %
    scored = ta.compare(row, {"forces_N": dict(f)}, gc.QUICK)
    assert scored["error"] == 0.0 and scored["monotone"]


def test_grasp_errors_are_scored_on_the_holding_threshold_below_it():
    ref = {"a": 0.5, "b": 0.01}
    err = gc.errors({"a": 0.55, "b": 0.04}, ref, threshold=0.03)
    assert err == pytest.approx({"a": 0.1, "b": 1.0})


def test_the_onset_is_the_largest_pull_before_the_slip_passes_its_distance():
    pull = sp.Pull(normal_at_hold=2.0, mu=0.5)
    steps = [(0.10, 0.0001, 2.0, 0.08), (0.30, 0.0010, 2.1, 0.20), (0.25, 0.0015, 2.2, 0.22),
             (0.35, sp.SLIP_ONSET * 1.5, 0.5, 0.30)]
    slid = [pull.add(*s) for s in steps]
    assert slid == [False, False, False, True]
    forces, ratios = {}, {}
    pull.store(forces, ratios)
    assert forces == {"mu0.5/normal": 2.0, "mu0.5/held": 0.30, "mu0.5/held_contact": 0.22}
    assert ratios["mu0.5"] == pytest.approx({"held_ratio": 0.30 / (0.5 * 2.0), "held_ratio_at_onset": 0.30 / (0.5 * 2.2),
                                             "contact_ratio": 0.22 / (0.5 * 2.0), "coulomb_ratio": 0.22 / (0.5 * 2.2)})
    never, forces = sp.Pull(1.0, mu=0.5), {}
    never.add(0.2, 0.0, 1.0, 0.1)
    never.store(forces, {})
    assert forces == {"mu0.5/normal": 1.0}                   # no onset: no held reading


def test_a_pull_in_the_slippage_scene_slides_before_the_motor_limit():
    row = ta.measure(sp.TASK, "mass_spring", COARSE, sp.QUICK)
    f = row["forces_N"]
    assert row["never_slid_mu"] == [] and set(f) == {"mu0.6/normal", "mu0.6/held", "mu0.6/held_contact"}
    assert row["max_tensile_N"] == 0.0
    assert f["mu0.6/normal"] > 0.03 and 0.0 < f["mu0.6/held_contact"] <= f["mu0.6/held"] < 3.0
    ratios = row["held_ratio"]["mu0.6"]
    assert ratios["held_ratio"] == pytest.approx(f["mu0.6/held"] / (0.6 * f["mu0.6/normal"]), rel=1e-12)
    # Coulomb: the tissue's pull on the jaws never exceeds mu x their normal force (the jaws' normals lie
    # across the pull), up to the penalty contact's stick-spring lag of one step
    assert 0.5 < ratios["coulomb_ratio"] <= 1.02
    missing = ta.compare({**row, "forces_N": {"mu0.6/normal": f["mu0.6/normal"]}}, {"forces_N": f}, sp.QUICK)
    assert missing["missing_readings"] == ["mu0.6/held", "mu0.6/held_contact"] and math.isinf(missing["error"])


def test_the_reference_refines_the_organ_under_the_task_grasper_with_a_contact_stiffness_per_area():
    env = gc.make_env(gr.REFERENCE_MODEL, None)                  # the task's default lattice places the grasper
    sim = gr.reference_simulation(env, COARSE)
    params = next(iter(sim.contacts.values())).params
    assert params.stiffness == pytest.approx(gr.CONTACT_STIFFNESS_PER_AREA * COARSE ** 2)
    assert params.tangential_stiffness is None
    coarse = gc.make_env("mass_spring", COARSE)                  # the task at 15 mm: its own lattice and placement
    assert len(sim.tissue().positions) == len(coarse.sim.tissue().positions) != len(env.sim.tissue().positions)
    sim.reset(seed=0)
    assert np.array_equal(sim.tool_position(env.tool_name), env.home)     # one grasper for every refinement
    assert not np.allclose(coarse.home, env.home, atol=1e-3)
    env.close()
    coarse.close()


def test_the_reference_closures_rise_and_never_pull():
    row = gc.reference_row(gc.TASK, gc.QUICK, COARSE)
    f = row["forces_N"]
    assert row["max_tensile_N"] == 0.0 and f["+0.2/sum"] > f["+0/sum"] > 0.03


def test_the_reference_pull_slides_and_holds_a_positive_pull():
    row = sp.reference_row(sp.TASK, sp.QUICK, COARSE)
    f = row["forces_N"]
    assert 0.0 < f["mu0.6/held"] < 3.0 and f["mu0.6/normal"] > 0.03
    assert row["held_ratio"]["mu0.6"]["coulomb_ratio"] <= 1.02


def test_an_instability_at_one_spacing_does_not_skip_the_model_s_other_spacings(monkeypatch):
    from types import SimpleNamespace

    from surgsim_envs.bench import probe_sets

    probes = gc.ClosureSet(closures=(0.0,), hold=1.0, spacings=(0.015, 0.011), reference_spacings=(0.011, 0.008))

    def measure(task, model, spacing, _):
        if model == "not_built":                       # the task does not build it: said once
            return {"task": task, "model": model, "spacing": spacing, "refused": "not built"}
        if spacing == 0.015:                           # unstable at this lattice only
            return {"task": task, "model": model, "spacing": spacing, "refused": "unstable", "spacing_specific": True}
        return {"task": task, "model": model, "spacing": spacing, "forces_N": {"+0/sum": 1.0}}

    def reference_row(task, _, fine):
        return {"task": task, "spacing": fine, "nodes": 1, "seconds": 0.0, "forces_N": {"+0/sum": 1.0}}

    fake = SimpleNamespace(TASK=gc.TASK, REFERENCE_DESCRIPTION="fake", measure=measure, reference_row=reference_row,
                           compare=lambda row, ref, _: row)
    monkeypatch.setitem(probe_sets.DRIVERS, gc.TASK, fake)
    monkeypatch.setitem(ta.PROBE_SETS, gc.TASK, (probes, probes))
    table = ta.build_table([gc.TASK], ["unstable_coarse", "not_built"], progress=lambda s: None)
    got = [(r["model"], r["spacing"], "refused" in r) for r in table["rows"]]
    assert got == [("unstable_coarse", 0.015, True), ("unstable_coarse", 0.011, False), ("not_built", 0.015, True)]

"""LayeredPalpation-v0's probe set for `surgsim bench task-accuracy`: presses in the task's own scene,
the layered FEM reference's lattice and presses, and the refusal of the models the task does not build."""

from __future__ import annotations

import math

import numpy as np
import pytest

from surgsim_envs.bench import layered_reference as lr
from surgsim_envs.bench import task_accuracy as ta
from surgsim_envs.bench.probe_set import ProbeSet
from surgsim_envs.bench.probe_sets import layered_palpation as lp
from surgsim_envs.geometry.anatomy import ABDOMINAL_WALL_THICKNESS

TASK = lp.TASK
ONE_DEPTH = ProbeSet(inclusions=lp.FULL.inclusions, depths=(0.0045,), hold=0.0, spacings=(0.01,),
                     reference_spacings=(0.005,))


def test_the_probe_set_is_registered_with_the_task_tolerance():
    assert ta.PROBE_SETS[TASK] == (lp.FULL, lp.QUICK)
    from surgsim_envs.envs.registry import task_spec

    declared = task_spec(TASK).force_tolerance
    assert ta.FORCE_TOLERANCES[TASK] == {"tolerance": declared.value, "reason": declared.why}
    nodule = lp.NODULE                                    # the task's nodule: radius, factor, mid-fat depth
    assert (nodule.radius, nodule.contrast) == (0.008, 30.0)
    assert nodule.depth == pytest.approx(0.002 + 0.015 / 2)


def test_presses_in_the_task_scene_are_unilateral_rise_with_depth_feel_the_nodule_and_depend_on_the_pose_only():
    row = ta.measure(TASK, "layered", 0.005, lp.QUICK)   # at 10 mm a press between the nodes meets none
    f = row["forces_N"]
    assert set(f) == {"0/over/2.5mm", "0/over/4.5mm", "0/mirror/2.5mm", "0/mirror/4.5mm",
                      "0/over-offnode/2.5mm", "0/over-offnode/4.5mm"}       # the nodule moved by half a cell
    assert row["max_tensile_N"] <= 1e-12                  # the unilateral probe never pulls
    assert ta.monotone(f, lp.QUICK.depths)
    assert ta.contrast(f, 1, 0.0045)[0] > 1.0              # a 30x nodule feels stiffer than its mirror site
    assert row["path_difference"] <= 1e-9                  # the same pose after another press: the same force
    assert row["nodule_centre"][:2] == pytest.approx(lp.NODULE_XY)


def test_presses_between_the_nodes_are_scored_against_the_references_press_over_the_nodule():
    """The reference solves the presses over the nodule and at its mirror site; a row's presses with
    the nodule moved by half a cell count against the press over the nodule at the same depth."""
    ref = {"forces_N": {"0/over/2.5mm": 1.0, "0/over/4.5mm": 2.0, "0/mirror/2.5mm": 0.2, "0/mirror/4.5mm": 0.4}}
    f = {**ref["forces_N"], "0/over-offnode/2.5mm": 0.5, "0/over-offnode/4.5mm": 2.0}
    row = ta.compare({"task": TASK, "forces_N": f}, ref, lp.QUICK)
    assert row["error_median"] == 0.0 and row["error_p95"] == pytest.approx(np.percentile([0.0] * 5 + [0.5], 95))
    assert lp.reference_key("0/over-offnode/2.5mm") == "0/over/2.5mm"
    assert lp.reference_key("0/mirror/2.5mm") == "0/mirror/2.5mm"


def test_models_the_task_does_not_build_are_refused_by_name():
    row = ta.measure(TASK, "fem", 0.005, lp.QUICK)
    assert "forces_N" not in row and "layered model (the paper's springs), fem_static or fem_hex" in row["refused"]


def test_reference_lattice_conforms_to_the_layers_and_labels_the_nodule_by_the_task_rule():
    planes = lr.layer_planes(ABDOMINAL_WALL_THICKNESS)
    assert [p[0] for p in planes] == ["peritoneum", "muscle", "fat", "skin"]
    assert planes[-1][2] == pytest.approx(0.029)
    centre = (0.02, 0.01, lr.nodule_centre_z(planes, "fat", 0.008))
    assert centre[2] == pytest.approx(0.0195)
    fine = 0.002
    vol = lr.wall_volume((0.08, 0.06), planes, (0.02, 0.01), fine, centre, 0.008)
    z = np.unique(np.round(vol.nodes[:, 2], 12))
    for _, lo, hi in planes:                               # a node plane on every interface
        assert np.min(np.abs(z - lo)) < 1e-12 and np.min(np.abs(z - hi)) < 1e-12
    skin = z[z >= 0.027 - 1e-12]
    assert np.max(np.diff(skin)) <= fine * lr.SKIN_CELL_FRACTION + 1e-12
    c = vol.nodes[vol.tets].mean(axis=1)
    inside = np.linalg.norm(c - centre, axis=1) < 0.008
    assert np.array_equal(vol.labels >= len(planes), inside)
    layer = vol.labels % len(planes)
    for k, (_, lo, hi) in enumerate(planes):
        assert np.all((c[layer == k, 2] > lo) & (c[layer == k, 2] < hi))
    top = vol.nodes[np.isclose(vol.nodes[:, 2], 0.029)]
    assert np.min(np.linalg.norm(top[:, :2] - (0.02, 0.01), axis=1)) < 1e-12    # the site is a node


def test_reference_feels_the_nodule_and_pushes_the_probe_at_both_sites():
    """The coarsest reference (5 mm lattices): the 30x nodule raises the force over it above its mirror
    site's, and both presses push the probe up."""
    row = lp.reference_row(TASK, ONE_DEPTH, 0.005)
    f = row["forces_N"]
    assert set(row["nodes_by_site"]) == {"over", "mirror"}
    assert f["0/over/4.5mm"] > f["0/mirror/4.5mm"] > 0.0


@pytest.mark.slow
def test_every_task_spacing_rises_with_depth_feels_the_nodule_and_never_pulls():
    for spacing in lp.FULL.spacings:
        row = ta.measure(TASK, "layered", spacing, lp.FULL)
        f = row["forces_N"]
        assert row["max_tensile_N"] <= 1e-12, spacing
        off = [k for k in f if lp.OFF_NODE in k]
        if spacing / math.sqrt(2) >= 0.005:   # a cell's centre farther from its nodes than the probe's radius:
            assert all(f[k] == 0.0 for k in off), spacing     # the probe passes between them and feels nothing
            f = {k: v for k, v in f.items() if k not in off}
        assert ta.monotone(f, lp.FULL.depths), spacing
        assert ta.contrast(f, 1, 0.0045)[0] > 1.0, spacing
        assert row["path_difference"] <= 1e-9, spacing


@pytest.mark.slow
def test_reference_rises_with_depth_and_its_coarse_lattice_is_not_what_it_measures():
    """At fine spacing 2 mm: every site's force rises with depth, and halving the coarse spacing away from
    the press (5 -> 2.5 mm) moves no press by 1.5 % or more: the error the refinement removes is under the probe."""
    row = lp.reference_row(TASK, lp.FULL, 0.002)
    assert ta.monotone(row["forces_N"], lp.FULL.depths)
    inc = lp.NODULE
    from surgsim_envs.envs.layered_palpation import LayeredPalpationConfig
    from surgsim_envs.geometry.anatomy import ANATOMY_MATERIALS
    from surgsim_envs.materials import PRESETS

    finer = lr.reference_row(TASK, {"over": inc.position, "mirror": (-inc.position[0], -inc.position[1])},
                             lp.FULL.depths, 0.002, size=LayeredPalpationConfig().size,
                             thickness=ABDOMINAL_WALL_THICKNESS, materials={**PRESETS, **ANATOMY_MATERIALS},
                             nodule_xy=inc.position, nodule_radius=inc.radius, nodule_factor=inc.contrast,
                             nodule_layer="fat", tip_radius=0.005, coarse=0.0025)
    for key, value in row["forces_N"].items():
        assert abs(finer["forces_N"][key] - value) < 0.015 * value, key

"""Graded box lattices (``box_volume(grading=...)``, geometry/graded_axis.py): fine around a point,
growing to the coarse spacing, conforming Kuhn cells, the point on a node, bad input refused."""

from __future__ import annotations

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.box import box_volume, graded_axes
from surgsim_envs.geometry.graded_axis import graded_axis, neighbour_ratio
from surgsim_envs.geometry.volume import tet_signed_volumes

SIZE = (0.1, 0.1, 0.02)
GRADING = {"fine": 0.001, "around": (-0.02, 0.0, 0.01), "half_widths": (0.012, 0.012, 0.005)}


def test_graded_axis_is_fine_around_the_point_coarse_away_and_grows_by_at_most_the_ratio():
    x = graded_axis(-0.05, 0.05, -0.02, 0.012, 0.001, 0.005, ratio=1.3)
    d = np.diff(x)
    assert x[0] == -0.05 and x[-1] == 0.05 and np.all(d > 0)
    assert np.min(np.abs(x - (-0.02))) < 1e-15                        # the point is a node
    inside = (x >= -0.032 - 1e-12) & (x <= -0.008 + 1e-12)
    assert np.allclose(np.diff(x[inside]), 0.001, rtol=0, atol=1e-12)  # uniform fine spacing there
    assert len(x[inside]) == 25
    assert d.max() <= 0.005 + 1e-12 and d.max() > 0.004               # grows to the coarse spacing
    assert neighbour_ratio(x) <= 1.3 + 1e-9


def test_graded_axis_with_the_point_on_a_face_keeps_the_face_a_node():
    z = graded_axis(-0.01, 0.01, 0.01, 0.005, 0.001, 0.005, ratio=1.3)
    assert z[-1] == 0.01 and np.allclose(np.diff(z[-6:]), 0.001, atol=1e-12)
    assert neighbour_ratio(z) <= 1.3 + 1e-9


def test_graded_box_is_conforming_with_positive_volumes_and_the_site_on_a_node():
    vol = box_volume(SIZE, 0.005, grading=GRADING)
    axes = graded_axes(SIZE, 0.005, (0.0, 0.0, 0.0), GRADING)
    counts = [len(a) for a in axes]
    assert len(vol.nodes) == np.prod(counts)
    assert len(vol.tets) == 6 * np.prod([c - 1 for c in counts])
    v = tet_signed_volumes(vol.nodes, vol.tets)
    assert np.all(v > 0)
    assert v.sum() == pytest.approx(np.prod(SIZE), rel=1e-12)         # the cells tile the box exactly
    # conforming: every interior triangle is shared by exactly two tets, every boundary one by one
    faces = np.sort(np.concatenate([vol.tets[:, [0, 1, 2]], vol.tets[:, [0, 1, 3]], vol.tets[:, [0, 2, 3]],
                                    vol.tets[:, [1, 2, 3]]]), axis=1)
    _, count = np.unique(faces, axis=0, return_counts=True)
    assert set(count.tolist()) == {1, 2}
    boundary_area = 2 * (SIZE[0] * SIZE[1] + SIZE[0] * SIZE[2] + SIZE[1] * SIZE[2])
    f = np.unique(faces, axis=0)[count == 1]
    x = vol.nodes
    area = 0.5 * np.linalg.norm(np.cross(x[f[:, 1]] - x[f[:, 0]], x[f[:, 2]] - x[f[:, 0]]), axis=1).sum()
    assert area == pytest.approx(boundary_area, rel=1e-12)
    assert np.min(np.linalg.norm(x - np.array([-0.02, 0.0, 0.01]), axis=1)) < 1e-15


def _min_dihedral_deg(vol) -> float:
    x = vol.nodes[vol.tets]
    worst = np.inf
    for a, b, c, d in ((0, 1, 2, 3), (0, 2, 1, 3), (0, 3, 1, 2), (1, 2, 0, 3), (1, 3, 0, 2), (2, 3, 0, 1)):
        e = x[:, b] - x[:, a]
        n1 = np.cross(e, x[:, c] - x[:, a])        # the angle between the two faces at edge (a, b)
        n2 = np.cross(e, x[:, d] - x[:, a])
        cos = np.einsum("ij,ij->i", n1, n2) / (np.linalg.norm(n1, axis=1) * np.linalg.norm(n2, axis=1))
        worst = min(worst, float(np.degrees(np.arccos(np.clip(cos, -1, 1))).min()))
    return worst


def test_graded_box_tets_stay_well_shaped():
    """The graded lattice's worst tet is no worse than the worst Kuhn tet of its most elongated cells
    (edges the finest or the coarsest spacing: the fine strips crossing coarse cells), and a unit cube's
    Kuhn tets have 45 deg (the check itself)."""
    assert _min_dihedral_deg(box_volume((0.001, 0.001, 0.001), 0.001)) == pytest.approx(45.0)
    vol = box_volume(SIZE, 0.005, grading=GRADING)
    d = np.concatenate([np.diff(a) for a in graded_axes(SIZE, 0.005, (0.0, 0.0, 0.0), GRADING)])
    lo, hi = d.min(), d.max()
    extreme = min(_min_dihedral_deg(box_volume(tuple(c), float(max(c)) * 0.999))
                  for c in np.array(np.meshgrid([lo, hi], [lo, hi], [lo, hi])).reshape(3, -1).T)
    assert _min_dihedral_deg(vol) >= extreme - 1e-9


def test_graded_box_refuses_bad_input_by_name():
    with pytest.raises(ConfigError, match="coarse spacing .* finer than the fine"):
        box_volume(SIZE, 0.0005, grading=GRADING)
    with pytest.raises(ConfigError, match="growth ratio"):
        box_volume(SIZE, 0.005, grading={**GRADING, "ratio": 1.0})
    with pytest.raises(ConfigError, match="fine-region centre"):
        box_volume(SIZE, 0.005, grading={**GRADING, "around": (0.2, 0.0, 0.0)})
    with pytest.raises(ConfigError, match="missing \\['half_widths'\\]"):
        box_volume(SIZE, 0.005, grading={"fine": 0.001, "around": (0, 0, 0)})
    with pytest.raises(ConfigError, match="three finite lengths"):
        box_volume(SIZE, 0.005, grading={**GRADING, "half_widths": (0.01, 0.01)})
    with pytest.raises(ConfigError, match="fine spacing"):
        box_volume(SIZE, 0.005, grading={**GRADING, "fine": -0.001})


def test_graded_box_is_reachable_from_the_scene_config():
    """volume_options={"grading": ...} on a slab tissue builds the graded lattice."""
    from surgsim_envs.geometry.organ_source import organ_volume

    vol = organ_volume("slab", spacing=0.005, size=SIZE, grading=GRADING)
    assert len(vol.nodes) == len(box_volume(SIZE, 0.005, grading=GRADING).nodes)

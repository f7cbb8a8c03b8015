"""Volume fractions of a sphere in tetrahedra, and the mixed inclusion they give a task."""

import math

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.box import box_volume
from surgsim_envs.geometry.sphere_fraction import mixed_young_factors, sphere_volume_fractions

UNIT_TET = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]])
FAR = 1e4   # m: a sphere this large is a plane across a unit tet (sag < 1e-4)


def _tet_volumes(v):
    return np.abs(np.linalg.det(v[:, 1:] - v[:, :1])) / 6.0


@pytest.mark.parametrize("t", [0.1, 0.37, 0.5, 0.82, 0.95])
def test_a_plane_cut_matches_the_exact_fraction(t):
    """A huge sphere cuts the unit tet along a plane: x + y + z < t keeps t^3 of it (parallel to a face),
    x < t keeps 1 - (1 - t)^3 (through three edges)."""
    n = np.ones(3) / math.sqrt(3)
    diagonal = sphere_volume_fractions(UNIT_TET, n * (t / math.sqrt(3)) - n * FAR, FAR)[0]
    assert diagonal == pytest.approx(t ** 3, abs=0.015)
    along_x = sphere_volume_fractions(UNIT_TET, [t - FAR, 0.25, 0.25], FAR)[0]
    assert along_x == pytest.approx(1 - (1 - t) ** 3, abs=0.015)


def test_whole_elements_are_exact_and_the_sphere_keeps_its_volume_on_coarse_lattices():
    """Tets with every corner inside read 1 and tets beyond the sphere 0, exactly; the fraction-weighted
    volume is the sphere's within 2 % on 10, 5 and 2 mm lattices, where the centroid rule is 39 % off at
    10 mm (a 7 mm sphere 11 mm deep, as Palpation-v0's probe set)."""
    centre, r = np.array([0.02, 0.0, -0.001]), 0.007
    sphere = 4.0 / 3.0 * math.pi * r ** 3
    for h in (0.01, 0.005, 0.002):
        vol = box_volume((0.1, 0.1, 0.02), h)
        v = vol.nodes[vol.tets]
        frac = sphere_volume_fractions(v, centre, r)
        corners = np.linalg.norm(v - centre, axis=2)
        assert np.all(frac[np.all(corners <= r, axis=1)] == 1.0)
        assert np.all(frac[np.all(corners > r + h * 2, axis=1)] == 0.0)
        assert np.all((frac >= 0) & (frac <= 1))
        assert np.sum(frac * _tet_volumes(v)) == pytest.approx(sphere, rel=0.02)
    vol = box_volume((0.1, 0.1, 0.02), 0.01)
    v = vol.nodes[vol.tets]
    centroid_rule = np.linalg.norm(v.mean(axis=1) - centre, axis=1) < r
    assert abs(np.sum(centroid_rule * _tet_volumes(v)) / sphere - 1) > 0.3


def test_point_elements_and_mixing():
    pts = np.array([[[0, 0, 0.0]], [[0.02, 0, 0]]])
    assert sphere_volume_fractions(pts, [0.001, 0, 0], 0.005).tolist() == [1.0, 0.0]
    assert mixed_young_factors([0.0, 0.5, 1.0], 5.0, 2.0).tolist() == [2.0, 6.0, 10.0]


@pytest.mark.parametrize("bad, match", [
    ({"vertices": np.zeros((3, 3))}, "vertices must be"),
    ({"centre": [0, np.nan, 0]}, "centre must be three finite"),
    ({"radius": -1.0}, "radius must be > 0"),
    ({"radius": float("nan")}, "radius must be > 0"),
])
def test_bad_input_is_refused_by_name(bad, match):
    args = {"vertices": UNIT_TET, "centre": [0, 0, 0], "radius": 0.5, **bad}
    with pytest.raises(ConfigError, match=match):
        sphere_volume_fractions(**args)


def test_a_sphere_too_small_to_sample_puts_its_volume_into_the_nearest_tet():
    """A 0.1 mm lump in a 10 mm lattice misses every sample point; the task still gets it, as its
    volume share of the nearest tet (and a larger lump gets no such patch)."""
    from surgsim_envs.envs.tissue_setup import inclusion_young_factors

    vol = box_volume((0.05, 0.05, 0.02), 0.01)

    class Wall:
        def element_vertices(self):
            return vol.nodes[vol.tets]

    v = vol.nodes[vol.tets]
    centre, r = v[7].mean(axis=0), 1e-4
    f = inclusion_young_factors(Wall(), centre, r, contrast=5.0, scale=0.5)
    share = (4.0 / 3.0 * math.pi * r ** 3) / _tet_volumes(v[7:8])[0]
    assert np.flatnonzero(f != 0.5).tolist() == [7]
    assert f[7] == pytest.approx(0.5 * (1 + 4.0 * share))
    big = inclusion_young_factors(Wall(), centre, 0.012, contrast=5.0, scale=0.5)
    phi = sphere_volume_fractions(v, centre, 0.012)
    assert np.allclose(big, 0.5 * (1 + 4.0 * phi))

"""Graded node coordinates along one axis: uniform and fine around a point, growing geometrically
to a coarse spacing towards both ends.

A box lattice built on three such axes (:func:`surgsim_envs.geometry.box.box_volume` with
``grading=``) keeps the Kuhn split of every cell, so it stays conforming, but puts its nodes where a
local load needs them: a press resolved at spacing ``fine`` costs about as many nodes as a uniform
lattice ``fine / coarse`` times coarser. The point itself is always a node (a sphere pressing on a
node and one pressing between nodes read different forces), and neighbouring cells differ by at
most the growth ``ratio`` (up to the small stretch that makes the cells end on the box's faces).
"""

from __future__ import annotations

import math

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: the largest growth ratio accepted between neighbouring cells: beyond it the cells next to the
#: fine region are badly shaped and the change of spacing itself becomes an error source
MAX_RATIO = 2.0


def _side(length: float, start: float, coarse: float, ratio: float) -> np.ndarray:
    """Cell sizes (m) covering ``length`` m next to a cell of size ``start``: start x q^i capped at
    ``coarse``, with as many cells as growth ``ratio`` needs and the growth q <= ratio that makes
    them sum to ``length`` exactly."""
    if length <= 1e-12:
        return np.zeros(0)
    count, total, size = 0, 0.0, start
    while total < length:
        size = min(size * ratio, coarse)
        total += size
        count += 1
    i = np.arange(1, count + 1)

    def cells(q: float) -> np.ndarray:
        return np.minimum(start * q ** i, coarse)

    if cells(1.0).sum() >= length:          # even uniform cells overfill: equal cells
        return np.full(count, length / count)
    lo, hi = 1.0, float(ratio)
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cells(mid).sum() < length else (lo, mid)
    out = cells(hi)
    return out * (length / out.sum())


def graded_axis(lo: float, hi: float, anchor: float, half_width: float, fine: float, coarse: float,
                ratio: float = 1.3, what: str = "axis") -> np.ndarray:
    """Node coordinates (m, ascending, ``lo`` and ``hi`` included) on [lo, hi]: spacing ``fine`` on
    ``anchor +- half_width`` (``anchor`` a node), growing by ``ratio`` per cell to at most
    ``coarse`` outside it. ConfigError names a bad value, its bound and the fix."""
    lo, hi = float(lo), float(hi)
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ConfigError(f"{what}: graded axis needs lo < hi (m), got [{lo}, {hi}]")
    fine = validate.positive(fine, f"{what}: fine spacing", unit="m", fix="e.g. 0.001 (1 mm)")
    coarse = validate.positive(coarse, f"{what}: coarse spacing", unit="m", fix="e.g. 0.005 (5 mm)")
    if coarse < fine:
        raise ConfigError(f"{what}: coarse spacing {coarse} m is finer than the fine spacing {fine} m; "
                          "give coarse >= fine")
    ratio = validate.real(ratio, f"{what}: growth ratio", lo=1.0, hi=MAX_RATIO, lo_open=True,
                          fix="a growth per cell in (1, 2], e.g. 1.3")
    anchor = validate.real(anchor, f"{what}: fine-region centre", lo=lo, hi=hi, unit="m",
                           fix="a point inside the box")
    half_width = validate.real(half_width, f"{what}: fine-region half width", lo=0.0, unit="m",
                               fix="e.g. 0.012 (12 mm around the point)")
    if (hi - lo) / fine > 4000:
        raise ConfigError(f"{what}: fine spacing {fine} m gives {int((hi - lo) / fine)} cells across "
                          f"{hi - lo} m; raise it")
    # the fine nodes: anchor + k fine inside [anchor - half_width, anchor + half_width] and the box;
    # a fine node closer than half a cell to a face of the box is dropped (the face is the node)
    k_lo = -math.floor(min(half_width, anchor - lo) / fine + 1e-9)
    k_hi = math.floor(min(half_width, hi - anchor) / fine + 1e-9)
    nodes = anchor + fine * np.arange(k_lo, k_hi + 1)
    left, right = nodes[0] - lo, hi - nodes[-1]
    if 0.0 < left < 0.5 * fine and len(nodes) > 1 and nodes[0] != anchor:
        nodes, left = nodes[1:], nodes[1] - lo
    if 0.0 < right < 0.5 * fine and len(nodes) > 1 and nodes[-1] != anchor:
        nodes, right = nodes[:-1], hi - nodes[-2]
    below = nodes[0] - np.cumsum(_side(left, fine, coarse, ratio))
    above = nodes[-1] + np.cumsum(_side(right, fine, coarse, ratio))
    out = np.concatenate([below[::-1], nodes, above])
    out[0], out[-1] = lo, hi                    # exactly on the faces (no round-off gap)
    return out


def neighbour_ratio(coords: np.ndarray) -> float:
    """The largest size ratio between neighbouring cells of an axis (1 = uniform)."""
    d = np.diff(np.asarray(coords, dtype=float))
    if len(d) < 2:
        return 1.0
    return float(np.max(np.maximum(d[1:] / d[:-1], d[:-1] / d[1:])))

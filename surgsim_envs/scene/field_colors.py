"""Colour a tissue surface by a per-node scalar field (``render_field="displacement"`` ...).

Measured in MuJoCo 4.0 (docs/models.md "Scalar fields on screen"): a flex whose material carries a
2-D texture and which has one texture coordinate per vertex (``flex.texcoord``) is drawn with the
texture colour at that coordinate, and ``MjModel.flex_texcoord`` may be rewritten between frames
(``mjv_updateScene`` copies it into ``mjvScene.flextexcoord`` each time). So the colour map is a
256 x 1 texture and a field is shown by writing ``u = (value - lo) / (hi - lo)`` into each
vertex's first texture coordinate: no recompilation, ~13 us per 2,562 vertices for the write.
"""

from __future__ import annotations

import math

import numpy as np

from surgsim_envs.errors import ConfigError

#: viridis anchor colours (matplotlib's viridis at 0, 0.25, 0.5, 0.75, 1), linearly interpolated
_VIRIDIS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], dtype=np.float64)
#: texels of the colour map
COLORMAP_SIZE = 256


def colormap_rgb(size: int = COLORMAP_SIZE) -> np.ndarray:
    """(1, size, 3) uint8 viridis-like colour map, low values dark blue, high values yellow."""
    t = np.linspace(0.0, 1.0, size)
    knots = np.linspace(0.0, 1.0, len(_VIRIDIS))
    rgb = np.stack([np.interp(t, knots, _VIRIDIS[:, c]) for c in range(3)], axis=1)
    return np.round(rgb).astype(np.uint8)[None]


class FieldColors:
    """Maps a tissue's node field to flex texture coordinates.

    tissue: a TissueModel (``node_field(name)``, ``field_names()``); field: the field name;
    value_range: (lo, hi) in the field's unit, or None: lo = 0 and hi = the largest value seen
    since the last :meth:`reset` (so the colours do not flicker from frame to frame).
    """

    def __init__(self, tissue, field: str, value_range=None):
        names = tissue.field_names()
        if field not in names:
            raise ConfigError(f"render_field={field!r}: tissue model '{tissue.name}' has node fields {names}")
        if value_range is not None:
            lo, hi = (float(v) for v in value_range)
            if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
                raise ConfigError(f"render_range must be (lo, hi) with hi > lo, got {value_range!r}")
            value_range = (lo, hi)
        self.tissue = tissue
        self.field = field
        self.value_range = value_range
        self.seen_max = 0.0

    def reset(self) -> None:
        self.seen_max = 0.0

    def coordinates(self, vertex_values: np.ndarray, out: np.ndarray) -> None:
        """Write u in [0.01, 0.99] per vertex into ``out[:, 0]`` (``out[:, 1] = 0.5``)."""
        v = np.asarray(vertex_values, dtype=np.float64)
        top = float(v.max(initial=0.0))
        if not math.isfinite(top):
            v = np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0)
            top = float(v.max(initial=0.0))
        if self.value_range is None:
            self.seen_max = max(self.seen_max, top)
            lo, hi = 0.0, self.seen_max if self.seen_max > 0 else 1.0
        else:
            lo, hi = self.value_range
        u = out[:, 0]
        np.subtract(v, lo, out=u)
        u *= 0.98 / (hi - lo)
        np.clip(u, 0.0, 0.98, out=u)
        u += 0.01
        out[:, 1] = 0.5

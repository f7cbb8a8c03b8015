"""Demo video annotations: caption, force lines and the colour legend of a coloured field."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from surgsim_envs.scene.field_colors import colormap_rgb
from surgsim_envs.scene.video_overlay import ColorLegend, annotate, legend_for


def test_the_legend_shows_the_colour_map_high_at_the_top_and_the_text_is_drawn():
    frame = np.full((480, 640, 3), 120, np.uint8)
    out = annotate(frame, "pressing", ("probe force 0.042 N",), ColorLegend("displacement", "mm", 0.0, 4.0))
    assert out is frame and out.shape == (480, 640, 3) and out.dtype == np.uint8
    cmap = colormap_rgb()[0]
    column = out[:, 640 - 14 - 46 + 7]          # the bar: 45 % of the height, centred, 46 px from the edge
    bar_h = int(480 * 0.45)
    y0 = (480 - bar_h) // 2
    top, bottom = column[y0 + 1], column[y0 + bar_h - 2]
    assert np.abs(top.astype(int) - cmap[-1]).max() <= 12      # yellow: the high end on top
    assert np.abs(bottom.astype(int) - cmap[0]).max() <= 12    # dark blue: the low end at the bottom
    assert np.any(out[:28, :200] != 120) and np.any(out[-30:, :200] != 120)   # caption and force line
    assert np.all(out[200:280, 200:400] == 120)                # the scene itself is left alone


def test_legend_comes_from_a_field_coloured_over_a_fixed_range_only():
    fixed = SimpleNamespace(colors=SimpleNamespace(field="displacement", value_range=(0.0, 0.004)))
    following = SimpleNamespace(colors=SimpleNamespace(field="displacement", value_range=None))
    plain = SimpleNamespace(colors=None)
    assert legend_for(SimpleNamespace(bindings={"a": plain, "b": fixed})) == ColorLegend("displacement", "mm", 0.0, 4.0)
    assert legend_for(SimpleNamespace(bindings={"a": plain, "b": following})) is None

"""Captions, a live force readout and a colour legend drawn onto rendered video frames.

A frame of a tissue coloured by a node field (``render_field``, e.g. displacement) means nothing
without its scale, and a grasp that slips looks like a failed pinch unless the video says what
is happening. :func:`annotate` draws, in place on an RGB frame (H, W, 3) uint8:

* a caption bar at the top (what the tools are doing: "pressing above the inclusion", ...);
* force lines at the bottom left (newtons, the values the summary reports);
* a vertical colour bar at the right with the field's name, unit and range, when a tissue is
  coloured by a field.

OpenCV (a base dependency) draws the text; nothing here touches the physics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from surgsim_envs.scene.field_colors import colormap_rgb

#: field name -> (unit shown, scale from SI to that unit)
FIELD_UNITS = {"displacement": ("mm", 1e3)}


@dataclass(frozen=True)
class ColorLegend:
    """A field's colour scale: name, unit, low and high ends (in that unit)."""

    field: str
    unit: str
    lo: float
    hi: float


def legend_for(sim) -> ColorLegend | None:
    """The colour legend of the first tissue of ``sim`` coloured by a field over a fixed range,
    or None (plain colours, or a range that follows the largest value seen)."""
    for binding in sim.bindings.values():
        colors = getattr(binding, "colors", None)
        if colors is None or colors.value_range is None:
            continue
        unit, scale = FIELD_UNITS.get(colors.field, ("", 1.0))
        lo, hi = colors.value_range
        return ColorLegend(colors.field, unit, lo * scale, hi * scale)
    return None


def _text(img, text, org, scale=0.5, color=(255, 255, 255)):
    """White text on a darkened box just large enough for it (readable on any background)."""
    import cv2

    (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    x, y = org
    y0, y1 = max(0, y - th - 4), min(img.shape[0], y + base + 2)
    x0, x1 = max(0, x - 3), min(img.shape[1], x + tw + 3)
    box = img[y0:y1, x0:x1]
    box[:] = (0.35 * box).astype(img.dtype)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, color, 1, cv2.LINE_AA)


def annotate(frame: np.ndarray, caption: str = "", lines=(), legend: ColorLegend | None = None) -> np.ndarray:
    """Draw the caption, the text ``lines`` and the colour ``legend`` onto ``frame`` (in place;
    returned). Text that does not fit is cut at the frame's edge."""
    h, w = frame.shape[:2]
    if caption:
        _text(frame, caption, (10, 19), 0.55)
    for k, line in enumerate(lines):
        _text(frame, line, (10, h - 12 - 20 * (len(lines) - 1 - k)), 0.5)
    if legend is not None:
        bar_h, bar_w = int(h * 0.45), 14
        x0, y0 = w - bar_w - 46, (h - bar_h) // 2
        ramp = colormap_rgb(bar_h)[0][::-1]                   # top = high
        frame[y0:y0 + bar_h, x0:x0 + bar_w] = ramp[:, None, :]
        frame[y0 - 1, x0 - 1:x0 + bar_w + 1] = 255
        frame[y0 + bar_h, x0 - 1:x0 + bar_w + 1] = 255
        _text(frame, f"{legend.hi:g}", (x0 + bar_w + 4, y0 + 6), 0.4)
        _text(frame, f"{legend.lo:g}", (x0 + bar_w + 4, y0 + bar_h), 0.4)
        title = f"{legend.field} ({legend.unit})" if legend.unit else legend.field
        _text(frame, title, (max(0, x0 - 8 * len(title) + bar_w + 40), y0 - 10), 0.4)
    return frame

"""Action terms: one per tool. Each maps its slice of a task's action (entries in [-1, 1]) to the
tool's command in SI units, as plain functions of Python floats (testable alone; tests check them
against the numpy formulas they stand for).

* probe (:func:`probe_target`): move the target in x, y by up to a step per control step inside
  a square, and set the depth from hover above the rest surface to a maximum depth below it;
* grasper wrist (:func:`wrist_target`): a displacement of up to a step per axis, kept inside a box
  of half-width ``workspace`` around home in the tool's frame;
* grasper jaws (:func:`jaw_opening`, :func:`jaw_closure`): the opening from fully open (-1) to the
  smallest (+1), as an opening (m) or as the closing travel (m) of the jaw actuator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ActionTerm:
    """A task's use of one tool: ``tool`` (the scene's tool name), ``size`` action entries and what
    they command (``doc``: names and units)."""

    tool: str
    size: int
    doc: str = ""


def clip(value: float, low: float, high: float) -> float:
    """``value`` clipped to [low, high] (``np.clip`` of one float, in Python floats)."""
    return high if value > high else (low if value < low else value)


def probe_target(target_xy, a, step: float, limit: float, top: float, hover: float, max_depth: float) -> np.ndarray:
    """(3,) m, the new probe tip target from the old target's (x, y) ``target_xy`` m and action
    ``a`` = (vx, vy, press) in [-1, 1]: x, y move by ``a * step`` m, clipped to +-``limit`` m; the
    tip-centre height runs from ``top + hover`` (press -1; ``top`` = rest surface + tip radius) down
    to ``top - max_depth`` (press +1)."""
    tx, ty = target_xy[0], target_xy[1]
    a0, a1, a2 = a[0], a[1], a[2]
    x = clip(tx + a0 * step, -limit, limit)
    y = clip(ty + a1 * step, -limit, limit)
    press = (a2 + 1.0) / 2.0
    return np.array([x, y, top + hover - press * (hover + max_depth)])


def wrist_target(target: np.ndarray, a: np.ndarray, step: float, home: np.ndarray, frame: np.ndarray,
                 workspace: float) -> np.ndarray:
    """(3,) m, the grasper wrist's new target: ``target + a * step`` m kept inside the box of
    half-width ``workspace`` m around ``home`` in the tool frame ``frame`` (3, 3; columns the tool
    axes in world coordinates)."""
    pos = target + a * step
    local = np.array([clip(v, -workspace, workspace) for v in (frame.T @ (pos - home)).tolist()])
    return home + frame @ local


def jaw_opening(a: float, open_radius: float, min_radius: float) -> float:
    """m, the jaw opening (axis to jaw) for action ``a`` in [-1, 1]: ``open_radius`` at -1,
    ``min_radius`` at +1, clipped to that range."""
    radius = open_radius - (a + 1.0) / 2.0 * (open_radius - min_radius)
    return min(max(radius, min_radius), open_radius)


def jaw_closure(a: float, open_radius: float, min_radius: float) -> float:
    """m, the jaw actuator's closing travel for action ``a`` in [-1, 1]: 0 at -1 (open),
    ``open_radius - min_radius`` at +1."""
    return (a + 1.0) / 2.0 * (open_radius - min_radius)


__all__ = ["ActionTerm", "clip", "probe_target", "wrist_target", "jaw_opening", "jaw_closure"]

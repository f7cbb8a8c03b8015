"""Overflow-safe unit quaternions for untrusted input (network poses, device readings)."""

from __future__ import annotations

import math

#: a quaternion whose largest |component| is below this has no direction
MIN_COMPONENT = 1e-6


def unit_quaternion(quat) -> tuple | None:
    """``quat`` ``(w, x, y, z)`` scaled to unit length without overflow or underflow (components
    up to 1e308 work: it divides by the largest component before squaring), or None when it has
    no meaningful direction (wrong length, non-finite, or every component below
    :data:`MIN_COMPONENT`, 1e-6: such a reading is noise, not a rotation)."""
    try:
        q = [float(v) for v in quat]
    except (TypeError, ValueError):
        return None
    if len(q) != 4 or not all(math.isfinite(v) for v in q):
        return None
    m = max(abs(v) for v in q)
    if not m >= MIN_COMPONENT:
        return None
    q = [v / m for v in q]  # largest component is +-1: squaring cannot overflow
    n = math.sqrt(sum(v * v for v in q))
    return tuple(v / n for v in q)

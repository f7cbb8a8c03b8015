"""Force terms shared by the tasks: the magnitude of a contact force and the tissue-damage penalty
above a force threshold (newtons)."""

from __future__ import annotations

import math

import numpy as np


def vector_norm(v) -> float:
    """Euclidean norm of a small vector: ``np.linalg.norm``'s own formula, sqrt(v . v), without its
    wrapper (same result bit for bit)."""
    v = np.asarray(v, dtype=float).ravel()
    return math.sqrt(v.dot(v))


def damage_penalty(force: np.ndarray, threshold: float, weight: float) -> float:
    """-weight * (|force| - threshold) above the tissue-damage threshold (N), else 0."""
    return -weight * max(0.0, vector_norm(force) - threshold)


__all__ = ["vector_norm", "damage_penalty"]

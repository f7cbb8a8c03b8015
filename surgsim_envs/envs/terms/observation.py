"""Observation terms: each entry of a task's observation is declared once with its name, unit and
physical bounds; the observation space and ``observation_names`` are built from the declarations."""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np


@dataclass(frozen=True)
class ObsTerm:
    """One named observation term: ``size`` entries in ``unit``, physical bounds [low, high]
    (+-inf where none exists, e.g. a contact force)."""

    name: str
    unit: str
    size: int = 1
    low: float = -math.inf
    high: float = math.inf


def observation_space_of(terms) -> tuple[gym.spaces.Box, list[str]]:
    """``(Box, names)`` of a list of :class:`ObsTerm`: float32 bounds per entry and one
    "name [unit]" string per index (``name[i] [unit]`` for multi-entry terms)."""
    lows, highs, names = [], [], []
    for t in terms:
        lows += [t.low] * t.size
        highs += [t.high] * t.size
        names += [f"{t.name} [{t.unit}]"] if t.size == 1 else [f"{t.name}[{i}] [{t.unit}]" for i in range(t.size)]
    box = gym.spaces.Box(np.array(lows, dtype=np.float32), np.array(highs, dtype=np.float32), dtype=np.float32)
    return box, names


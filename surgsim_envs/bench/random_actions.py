"""The actions a timing run steps a task with: uniform in [-1, 1], drawn ahead so drawing them is
not timed. A palpation task's last action component is "report" (ends the episode when > 0): it is
held at -1 so that the episode goes on."""

from __future__ import annotations

import numpy as np


def random_actions(space, n: int, rng: np.random.Generator, palpation: bool) -> np.ndarray:
    """``n`` float32 actions of Box ``space`` drawn from ``rng``, shape ``(n, *space.shape)``."""
    a = rng.uniform(-1, 1, (n, *space.shape)).astype(np.float32)
    if palpation:
        a[..., -1] = -1.0                  # the last component is "report": keep the episode going
    return a

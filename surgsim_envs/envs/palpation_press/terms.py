"""PalpationPress-v0's term functions: the raster order of the map cells and their centres."""

from __future__ import annotations

import numpy as np

from surgsim_envs.envs.palpation.terms import REWARD_TERMS as PALPATION_REWARD_TERMS
from surgsim_envs.envs.terms.force import damage_penalty
from surgsim_envs.envs.terms.reward import RewardTerm
from surgsim_envs.envs.terms.termination import TerminationTerm


def raster_order(cells: int) -> np.ndarray:
    """Row-major cell indices in boustrophedon order (row 0 left to right, row 1 right to left, ...)."""
    rows = [list(range(r * cells, (r + 1) * cells)) for r in range(cells)]
    return np.array([i for r, row in enumerate(rows) for i in (row if r % 2 == 0 else row[::-1])], dtype=int)


def cell_centre(index: int, cells: int, half_width: float) -> np.ndarray:
    """(x, y) m of the centre of row-major map cell ``index`` (inverse of ``map_cell``)."""
    w = 2 * half_width / cells
    return np.array([-half_width + (index % cells + 0.5) * w, -half_width + (index // cells + 0.5) * w])


# ----------------------------------------------------------------------------------------------
# declarations: PalpationPress-v0's reward and termination terms, in summation order (coverage,
# shaping and localisation are Palpation-v0's; a report step pays only the localisation)
def _press_damage(env, weight: float) -> float:
    if env.reported:
        return 0.0
    return damage_penalty(np.array([0.0, 0.0, env.press_peak]), env.config.damage_force, weight)


def _press_cost(env, weight: float) -> float:
    return 0.0 if env.reported else -weight


def _reported(env) -> bool:
    return env.reported


_SHARED = {t.name: t for t in PALPATION_REWARD_TERMS}
REWARD_TERMS = (
    RewardTerm("damage", _press_damage, "damage_weight", "-w (peak press force - damage_force)+ per press; w per N"),
    _SHARED["coverage"],
    _SHARED["shaping"],
    RewardTerm("press_cost", _press_cost, "press_cost", "-w per press"),
    _SHARED["localisation"],
)
TERMINATION_TERMS = (
    TerminationTerm("reported", _reported, "report > 0 after min_presses presses"),
)

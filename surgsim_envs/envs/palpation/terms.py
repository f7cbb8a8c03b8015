"""Palpation-v0's term functions (each testable alone): indentation, stiffness samples, the running
estimate of the inclusion centre, the coverage map and the localisation reward."""

from __future__ import annotations

import math

import numpy as np

from surgsim_envs.envs.terms.force import damage_penalty
from surgsim_envs.envs.terms.reward import RewardTerm
from surgsim_envs.envs.terms.termination import TerminationTerm
from surgsim_envs.errors import ConfigError


def indentation_depth(probe_z: float, surface_z: float, tip_radius: float) -> float:
    """m the probe tip's lowest point lies below the rest surface (0 above it)."""
    return max(0.0, surface_z + tip_radius - probe_z)


def stiffness_estimate(force_z: float, depth: float, min_depth: float) -> float:
    """Apparent stiffness F_z / depth (N/m) of a press deeper than ``min_depth`` m, else 0; always a
    Python float (the same IEEE quotient as with numpy scalars: one type in every step's info keeps
    the vector env's info write plan, ``vector/info.py``, from being rebuilt)."""
    return float(force_z) / float(depth) if depth >= min_depth else 0.0


def is_new_site(xy: np.ndarray, sites: list, spacing: float) -> bool:
    """True if ``xy`` (2,) m is at least ``spacing`` m from every earlier press site."""
    return all(float(np.hypot(*(xy - s))) >= spacing for s in sites)


def stiffness_weighted_estimate(xy: np.ndarray, k: np.ndarray, power: float = 3.0) -> np.ndarray:
    """(2,) m: centroid of sample positions ``xy`` (n, 2) m weighted by ``(k - median(k))+ ** power``
    (k: (n,) N/m stiffness samples); the stiffest sample's position if no sample is above the median."""
    xy, k = np.asarray(xy, dtype=float).reshape(-1, 2), np.asarray(k, dtype=float).reshape(-1)
    if len(k) == 0 or len(k) != len(xy):
        raise ConfigError(f"stiffness_weighted_estimate needs n >= 1 samples with matching xy (n, 2) and k (n,), "
                          f"got xy {xy.shape} and k {k.shape}")
    return weighted_estimate(xy, k, np.median(k), power)


def weighted_estimate(xy: np.ndarray, k: np.ndarray, median, power: float = 3.0) -> np.ndarray:
    """:func:`stiffness_weighted_estimate` of checked (n, 2) / (n,) float arrays with ``median`` =
    ``np.median(k)`` given (the env computes it once per sample for the estimate and the contrast)."""
    w = np.clip(k - median, 0.0, None) ** power
    total = float(w.sum())
    if total <= 0.0:
        return xy[int(np.argmax(k))].copy()
    return (w[:, None] * xy).sum(axis=0) / total


def map_cell(xy: np.ndarray, cells: int, half_width: float) -> int:
    """Row-major index (row = y, column = x) of the ``cells`` x ``cells`` map cell over the square
    +-``half_width`` m that contains ``xy`` (2,) m; points outside fall into the nearest edge cell."""
    if not (isinstance(cells, (int, np.integer)) and cells >= 1) or not half_width > 0:
        raise ConfigError(f"map_cell needs cells >= 1 and half_width > 0 m, got {cells!r}, {half_width!r}")
    xy = np.asarray(xy, dtype=float).reshape(-1)
    if xy.shape != (2,) or not np.all(np.isfinite(xy)):
        raise ConfigError(f"map_cell needs a finite (x, y) in m, got {xy!r}")
    return cell_of(float(xy[0]), float(xy[1]), int(cells), float(half_width))


def cell_of(x: float, y: float, cells: int, half_width: float) -> int:
    """:func:`map_cell` of checked finite floats (the same arithmetic, in Python floats)."""
    i = min(max(math.floor((x + half_width) / (2 * half_width) * cells), 0), cells - 1)
    j = min(max(math.floor((y + half_width) / (2 * half_width) * cells), 0), cells - 1)
    return int(j * cells + i)


def stiffness_map(cell_max_k: np.ndarray) -> np.ndarray:
    """Dimensionless map: per-cell max stiffness sample ``cell_max_k`` (N/m, 0 = never sampled)
    divided by the largest one (all zeros before any sample)."""
    k = np.asarray(cell_max_k, dtype=float)
    if np.any(~np.isfinite(k)) or np.any(k < 0):
        raise ConfigError("stiffness_map needs finite per-cell stiffness values >= 0 N/m")
    top = float(k.max()) if k.size else 0.0
    return k / top if top > 0 else np.zeros_like(k)


def normalised_map(k: np.ndarray) -> np.ndarray:
    """:func:`stiffness_map` of the env's own per-cell array (finite, >= 0 by construction): no checks."""
    top = k.max() if k.size else 0.0
    return k / top if top > 0 else np.zeros_like(k)


def localisation_error(guess_xy: np.ndarray, true_xy: np.ndarray) -> float:
    """m, planar distance from the guess to the inclusion centre."""
    return float(np.hypot(*(np.asarray(guess_xy, dtype=float) - np.asarray(true_xy, dtype=float))))


def localisation_reward(error: float, scale: float, tolerance: float, weight: float, bonus: float) -> float:
    """weight * (1 - min(error / scale, 1)) + bonus if error <= tolerance (all in m)."""
    return weight * (1.0 - min(error / scale, 1.0)) + (bonus if error <= tolerance else 0.0)


def localisation_potential(error: float, scale: float) -> float:
    """phi = 1 - min(error / scale, 1) in [0, 1] of an estimate ``error`` m off (``scale`` m)."""
    return 1.0 - min(error / scale, 1.0)


def potential_shaping(phi: float, phi_before: float, weight: float) -> float:
    """weight * (phi - phi_before): potential-based shaping (summed over an episode it telescopes
    to weight * (phi_final - phi_initial), so it cannot be farmed)."""
    return weight * (phi - phi_before)


# ----------------------------------------------------------------------------------------------
# declarations: the reward and termination terms of Palpation-v0, in summation order. Each reads
# the state the env's step update left (``env.readings()``, the step's events ``new_cell``,
# ``new_site``, ``finished_now``, the potential ``phi`` / ``phi_before``).
def _damage(env, weight: float) -> float:
    return damage_penalty(env.readings()[1], env.config.damage_force, weight)


def _coverage(env, weight: float) -> float:
    return weight if env.new_cell else 0.0


def _shaping(env, weight: float) -> float:
    return potential_shaping(env.phi, env.phi_before, weight)


def _time(env, weight: float) -> float:
    return -weight


def _press_site(env, weight: float) -> float:
    return weight if env.new_site else 0.0


def _localisation(env, weight: float) -> float:
    if not env.finished_now:
        return 0.0
    c = env.config
    return localisation_reward(env.error, c.localisation_scale, c.tolerance_mm * 1e-3, weight, c.success_bonus)


def _reported(env) -> bool:
    c = env.config
    return env.report_held >= c.report_hold_steps and env.steps * env.control_dt >= c.min_report_seconds


REWARD_TERMS = (
    RewardTerm("damage", _damage, "damage_weight", "-w (|F| - damage_force)+ per step; w per N"),
    RewardTerm("coverage", _coverage, "cell_reward", "w for the first stiffness sample in a map cell"),
    RewardTerm("shaping", _shaping, "shaping_weight", "w (phi - phi_before) of the running estimate"),
    RewardTerm("time", _time, "time_cost", "-w per control step"),
    RewardTerm("press_site", _press_site, "press_reward", "w per new press site (up to max_rewarded_sites)"),
    RewardTerm("localisation", _localisation, "localisation_weight",
               "on the report: w (1 - min(err / localisation_scale, 1)) + success_bonus if within tolerance_mm"),
)
TERMINATION_TERMS = (
    TerminationTerm("reported", _reported, "report > 0 held report_hold_steps steps after min_report_seconds"),
)

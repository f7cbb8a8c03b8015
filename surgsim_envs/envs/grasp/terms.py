"""Grasp-state term functions shared by the grasp tasks (Grasp-v0, Slippage-v0): jaws in contact,
grasp, contact reward, progress record, excess force, slip (each testable alone)."""

from __future__ import annotations

import numpy as np

from surgsim_envs.envs.terms.reward import RewardTerm
from surgsim_envs.envs.terms.termination import TerminationTerm
from surgsim_envs.errors import ConfigError


def _values(x) -> list:
    """The entries of a small array-like as a flat list of Python numbers (per-step terms work on
    three jaws: plain Python is several times faster than numpy calls on such tiny arrays)."""
    if type(x) is list:
        return x
    return x.tolist() if type(x) is np.ndarray and x.ndim == 1 else np.asarray(x).ravel().tolist()


def jaws_in_contact(normal: np.ndarray, threshold: float) -> int:
    """Number of jaws whose normal force (N) exceeds ``threshold`` N."""
    return sum(1 for f in _values(normal) if f > threshold)


def is_grasped(normal: np.ndarray, threshold: float, min_jaws: int = 2) -> bool:
    """A grasp holds when at least ``min_jaws`` jaws press with more than ``threshold`` N."""
    return jaws_in_contact(normal, threshold) >= min_jaws


def contact_reward(normal: np.ndarray, threshold: float, weight: float) -> float:
    """weight * fraction of the three jaws pressing with more than ``threshold`` N (dense shaping:
    closing on the tissue pays before the grasp is complete)."""
    values = _values(normal)
    return weight * jaws_in_contact(values, threshold) / max(len(values), 1)


def record_progress(best: float, dist: float) -> tuple[float, float]:
    """``(gain, new best)``: how far (m) ``dist`` beats the best (smallest) distance so far, never
    negative. Summed over an episode the gains are at most the initial distance minus the final
    best, whatever the path (no reward for backing off and approaching again)."""
    gain = max(0.0, float(best) - float(dist))
    return gain, min(float(best), float(dist))


def total_normal_force(normal: np.ndarray) -> float:
    """N, the jaws' normal forces summed in order (``np.sum`` of the entries)."""
    values = _values(normal)
    total = values[0] if values else 0.0
    for f in values[1:]:
        total += f
    return total


def progress_reward(gain: float, initial_distance: float, weight: float) -> float:
    """weight * gain / initial distance: the record gain (m, :func:`record_progress`) as a fraction
    of the initial distance to the target (m); at most ``weight`` over an episode."""
    return weight * gain / initial_distance


def excess_force_penalty(normal: np.ndarray, threshold: float, weight: float) -> float:
    """-weight * sum over jaws of the normal force above the damage threshold (N)."""
    total = 0.0
    for f in _values(normal):
        d = f - threshold
        if d > 0.0:
            total += d
    return -weight * total


def slip_fraction(slipping: int, contacts: int) -> float:
    """Fraction of contact nodes sliding (0 without contact)."""
    return float(slipping) / contacts if contacts > 0 else 0.0


class SlipTracker:
    """Relative displacement (m) between a grasper and the tissue nodes it grasped.

    ``start(tool_pos, node_positions, nodes)`` remembers the grasped nodes; ``distance`` is then
    ``|(tool - tool0) - (centroid - centroid0)|`` — how far the tissue slid along the jaws.
    """

    def __init__(self):
        self.nodes = None
        self.tool0 = None
        self.centroid0 = None

    @property
    def active(self) -> bool:
        return self.nodes is not None

    def start(self, tool_pos: np.ndarray, positions: np.ndarray, nodes: np.ndarray) -> None:
        nodes = np.asarray(nodes, dtype=np.int64)
        if len(nodes) == 0:
            raise ConfigError("SlipTracker.start needs at least one grasped node")
        self.nodes = nodes
        self.tool0 = np.asarray(tool_pos, dtype=float).copy()
        self.centroid0 = positions[nodes].mean(axis=0)

    def reset(self) -> None:
        self.nodes = self.tool0 = self.centroid0 = None

    def distance(self, tool_pos: np.ndarray, positions: np.ndarray) -> float:
        if self.nodes is None:
            return 0.0
        rel = (np.asarray(tool_pos) - self.tool0) - (positions[self.nodes].mean(axis=0) - self.centroid0)
        return float(np.linalg.norm(rel))


def contact_nodes(sim, tissue_name: str | None = None) -> np.ndarray:
    """Indices of tissue nodes that felt a contact force in the last physics step."""
    name = tissue_name or next(iter(sim.contacts))
    f = sim.contacts[name].result.forces
    return np.flatnonzero(np.einsum("ij,ij->i", f, f) > 0.0)


# ----------------------------------------------------------------------------------------------
# declarations: Grasp-v0's reward and termination terms, in summation order. Each reads the state
# the env's step update left (``env.readings()``, ``grasped``, ``progress_gain``, ``succeeded``,
# ``dropped``).
def _excess_force(env, weight: float) -> float:
    return excess_force_penalty(env.readings()[1], env.config.damage_force, weight)


def _contact(env, weight: float) -> float:
    return contact_reward(env.readings()[1], env.config.hold_force, weight)


def _progress(env, weight: float) -> float:
    return progress_reward(env.progress_gain, env.goal_dist0, weight) if env.grasped else 0.0


def _slip(env, weight: float) -> float:
    if not env.grasped:
        return 0.0
    rep = env.readings()[3]
    return -weight * slip_fraction(rep["slipping"], rep["contacts"])


def _drop(env, weight: float) -> float:
    return -weight if env.dropped else 0.0


def _success(env, weight: float) -> float:
    return weight if env.succeeded else 0.0


GRASP_REWARD_TERMS = (
    RewardTerm("excess_force", _excess_force, "force_weight", "-w sum over jaws (normal - damage_force)+; w per N"),
    RewardTerm("contact", _contact, "contact_weight", "w x fraction of jaws pressing above hold_force"),
    RewardTerm("progress", _progress, "progress_weight", "w x record approach to the target / initial distance"),
    RewardTerm("slip", _slip, "slip_weight", "-w x fraction of contact nodes sliding, while grasped"),
    RewardTerm("drop", _drop, "drop_penalty", "-w when a grasp is lost"),
    RewardTerm("success", _success, "success_bonus", "w when the organ is at the target, grasped"),
)
GRASP_TERMINATION_TERMS = (
    TerminationTerm("success", lambda env: env.succeeded, "grasped with the wrist within tolerance of the target"),
    TerminationTerm("dropped", lambda env: env.dropped, "a grasp lost: no contact node left"),
)

"""Slippage-v0's term functions: the pull, the least squeeze that holds it, the squeeze and slip
penalties, and the compiled control schedule of a control step (each testable alone)."""

from __future__ import annotations

import math

from numba import njit

from surgsim_envs.envs.terms.reward import RewardTerm
from surgsim_envs.envs.terms.termination import TerminationTerm


@njit(cache=True)
def pull_force(t: float, rate: float, amplitude: float, frequency: float, phase: float) -> float:
    """N, the pull at ``t`` s after the grasp: a ramp plus a sinusoid, never negative (compiled:
    the control schedule :func:`control_schedule` calls it per MuJoCo step)."""
    return max(0.0, rate * t + amplitude * math.sin(2.0 * math.pi * frequency * t + phase))


def least_squeeze(pull: float, mu: float) -> float:
    """N, the smallest total normal force whose friction (mu * N) balances ``pull`` N."""
    return abs(pull) / mu if mu > 0 else math.inf


def excess_squeeze_penalty(normal_total: float, pull: float, mu: float, weight: float) -> float:
    """-weight * (normal_total - least_squeeze)+ (N)."""
    return -weight * max(0.0, normal_total - least_squeeze(pull, mu))


def slip_penalty(slip_now: float, slip_before: float, weight_per_mm: float) -> float:
    """-weight * increase of the slip distance in mm (no reward for slipping back)."""
    return -weight_per_mm * max(0.0, slip_now - slip_before) * 1e3


def no_pull(t: float) -> float:
    """The settle's pull: none (N)."""
    return 0.0


@njit(cache=True)
def control_schedule(values, jaw, jaw_goal, lim, t, dt, pulling, rate, amplitude, frequency, phase, t0, top):
    """Fill ``values`` (K, 2) with the control schedule of :meth:`SlippageEnv._run`: column 0 the jaw
    control moving from ``jaw`` towards ``jaw_goal`` by at most ``lim`` per MuJoCo step, column 1
    (if ``pulling``) the pull ``min(top, pull_force(t - t0, rate, amplitude, frequency, phase))``, t
    advancing by ``dt`` from ``t`` (as mj_step2 advances d.time). The same operations in the same
    order as the Python loop it replaces (no fastmath), so the schedule is bit for bit the same."""
    for k in range(values.shape[0]):
        d = jaw_goal - jaw
        if d < -lim:
            d = -lim
        if d > lim:
            d = lim
        jaw += d
        values[k, 0] = jaw
        if pulling:
            values[k, 1] = min(top, pull_force(t - t0, rate, amplitude, frequency, phase))
        t += dt


# ----------------------------------------------------------------------------------------------
# declarations: Slippage-v0's reward and termination terms, in summation order. Each reads the
# state the env's step update left (``slip_distance`` / ``slip_before``, ``normal_total``, ``pull``,
# ``mu``, ``lost``).
def _slip(env, weight: float) -> float:
    return slip_penalty(env.slip_distance, env.slip_before, weight)


def _excess_squeeze(env, weight: float) -> float:
    return excess_squeeze_penalty(env.normal_total, env.pull, env.mu, weight)


def _hold(env, weight: float) -> float:
    return 0.0 if env.lost else weight


def _drop(env, weight: float) -> float:
    return -weight if env.lost else 0.0


REWARD_TERMS = (
    RewardTerm("slip", _slip, "slip_weight", "-w per mm of slip increase"),
    RewardTerm("excess_squeeze", _excess_squeeze, "squeeze_weight", "-w (sum normal - pull / mu)+; w per N"),
    RewardTerm("hold", _hold, "hold_reward", "w per control step while the grasp holds"),
    RewardTerm("drop", _drop, "drop_penalty", "-w when the grasp is lost"),
)
TERMINATION_TERMS = (
    TerminationTerm("lost", lambda env: env.lost, "no contact node, or slip beyond max_slip"),
)

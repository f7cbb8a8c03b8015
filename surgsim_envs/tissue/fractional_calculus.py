"""Variable-order fractional derivatives on a uniform time grid (the variable-order paper, eqs. 3-4).

Definitions (paper eqs. 3 and 4), order ``0 <= q(t) <= 1`` evaluated at the *current* time t
(the kernel is ``(t - tau)^(-q(t))``, not ``(t - tau)^(-q(tau))``)::

    Caputo:            D^q f(t) = 1/Gamma(1-q(t)) int_0^t (t-tau)^(-q(t)) f'(tau) dtau
    Riemann-Liouville: D^q f(t) = 1/Gamma(1-q(t)) d/dt int_0^t (t-tau)^(-q(t)) f(tau) dtau

With q piecewise constant in time (paper section III) dq/dt = 0 inside every piece, so at every
grid point the variable-order derivative is the constant-order derivative of order q(t_n) over
the whole past [0, t_n], and ``RL = Caputo + f(0) t^(-q) / Gamma(1-q)``. (At a switching instant
the d/dt of eq. 4 would also differentiate the order; we take the right-hand value, i.e. the new
piece's order, as the definition there.)

Two discretisations, step h, samples f_n = f(n h), order q_n = q(t_n):

* ``"l1"`` (Caputo; the RL value adds the f(0) term): ``D f_n = h^-q/Gamma(2-q) sum_{k=0}^{n-1}
  b_k (f_{n-k} - f_{n-k-1})``, ``b_k = (k+1)^(1-q) - k^(1-q)`` (piecewise-linear interpolation of
  f). Error O(h^(2-q)) for f in C^2 (tests/test_fractional_calculus.py measures 2 - q).
* ``"gl"`` (Grunwald-Letnikov, converges to RL): ``D f_n = h^-q sum_{k=0}^{n} w_k f_{n-k}``,
  ``w_0 = 1, w_k = w_{k-1} (1 - (1 + q)/k)``. Error O(h) (measured order 1).

Limits: q = 0 gives ``f`` (RL/GL) or ``f - f(0)`` (Caputo) exactly, q = 1 gives the backward
difference ``(f_n - f_{n-1})/h`` (both schemes): elastic and viscous (paper section I).

Short-memory principle (Podlubny): ``memory=L`` keeps only the last L steps of the sums
(``k <= L``); the error of the truncation for |f| <= M is bounded by ``M (L h)^(-q) / |Gamma(1-q)|``
(see docs/models/fractional.md for the measured error and cost against L).

Pure numpy/scipy (the 1-D sums are convolutions; scipy picks direct or FFT); the 3-D model keeps
its own numba ring buffer (:mod:`surgsim_envs.tissue.fractional_kernels`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import convolve

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

KINDS = ("caputo", "rl")
SCHEMES = ("l1", "gl")


# --------------------------------------------------------------------------------------------
# weights
def gl_weights(q: float, n: int) -> np.ndarray:
    """Grunwald-Letnikov weights ``w_k = (-1)^k binom(q, k)``, k = 0..n ((n+1,) array)."""
    q = check_order(q)
    k = np.arange(1, n + 1, dtype=np.float64)
    w = np.empty(n + 1)
    w[0] = 1.0
    if n:
        w[1:] = np.cumprod(1.0 - (1.0 + q) / k)
    return w


def l1_weights(q: float, n: int) -> np.ndarray:
    """L1 weights ``b_k = (k+1)^(1-q) - k^(1-q)``, k = 0..n-1 ((n,) array)."""
    q = check_order(q)
    k = np.arange(n, dtype=np.float64)
    b = (k + 1.0) ** (1.0 - q) - k ** (1.0 - q)
    if n:
        b[0] = 1.0          # 0^(1-q) = 0, also in the limit q -> 1 (numpy's 0^0 = 1 would give 0)
    return b


def check_order(q) -> float:
    return validate.real(q, "fractional order q", lo=0.0, hi=1.0, fix="0 elastic, 1 viscous")


# --------------------------------------------------------------------------------------------
# piecewise-constant order
@dataclass(frozen=True)
class PiecewiseOrder:
    """q(t) constant on each of the subintervals [t_{i-1}, t_i) (the last one closed and extended
    beyond its end): ``breaks`` = (t_1, ..., t_{N-1}) interior switching times (s, increasing),
    ``values`` = (q_1, ..., q_N) in [0, 1]. This is the paper's
    ``q = q_0 + sum_i q_i (Theta(t - t_i) - Theta(t - t_{i-1}))`` parametrised by the value in each
    piece."""

    breaks: tuple
    values: tuple

    def __post_init__(self):
        b = np.asarray(self.breaks, dtype=float).ravel()
        v = np.asarray(self.values, dtype=float).ravel()
        if len(v) != len(b) + 1:
            raise ConfigError(f"PiecewiseOrder needs one more value than breaks, got {len(v)} values and "
                              f"{len(b)} breaks")
        if len(b) and (np.any(np.diff(b) <= 0) or not np.all(np.isfinite(b))):
            raise ConfigError(f"PiecewiseOrder breaks must be finite and increasing, got {b.tolist()}")
        for q in v:
            check_order(q)
        object.__setattr__(self, "breaks", tuple(b.tolist()))
        object.__setattr__(self, "values", tuple(v.tolist()))

    @classmethod
    def uniform(cls, values, duration: float) -> "PiecewiseOrder":
        """N equal pieces over [0, duration] with orders ``values``."""
        values = np.atleast_1d(np.asarray(values, dtype=float))
        validate.positive(duration, "duration", unit="s", fix="the time the pieces span")
        n = len(values)
        return cls(tuple(duration * np.arange(1, n) / n), tuple(values))

    def piece_index(self, t) -> np.ndarray:
        """Index of the piece holding each time in ``t``."""
        return np.searchsorted(np.asarray(self.breaks), np.asarray(t, dtype=float), side="right")

    def __call__(self, t) -> np.ndarray:
        return np.asarray(self.values)[self.piece_index(t)]


def _orders(q, n_samples: int, h: float):
    """(piece index per sample, orders per piece) for q a number, a (M,) array or a PiecewiseOrder."""
    if isinstance(q, PiecewiseOrder):
        idx = q.piece_index(h * np.arange(n_samples))
        return idx, np.asarray(q.values)
    arr = np.asarray(q, dtype=float)
    if arr.ndim == 0:
        return np.zeros(n_samples, dtype=np.int64), np.array([check_order(arr)])
    if arr.shape != (n_samples,):
        raise ConfigError(f"q must be a number, a PiecewiseOrder or an array with one order per sample "
                          f"({n_samples},), got shape {arr.shape}")
    values, idx = np.unique(arr, return_inverse=True)
    for v in values:
        check_order(v)
    return idx.reshape(-1), values


def _check_signal(f, h):
    f = np.asarray(f, dtype=float).ravel()
    if len(f) < 2 or not np.all(np.isfinite(f)):
        raise ConfigError(f"f must be a finite 1-D array of at least 2 samples, got shape {np.shape(f)}")
    validate.positive(h, "time step h", unit="s", fix="the sampling interval of the signal")
    return f, float(h)


def _memory(memory, n: int) -> int:
    if memory is None:
        return n
    validate.integer(memory, "memory (short-memory length L in steps)", lo=1, fix="or None for the full history")
    return min(int(memory), n)


# --------------------------------------------------------------------------------------------
# derivatives
def derivative(f, h: float, q, *, kind: str = "caputo", scheme: str = "l1", memory: int | None = None) -> np.ndarray:
    """Variable-order fractional derivative of samples ``f`` (f_n = f(n h), h in s) at every sample.

    q: a number, a :class:`PiecewiseOrder` or an (M,) array of orders per sample, in [0, 1].
    kind: "caputo" (eq. 3) or "rl" (Riemann-Liouville, eq. 4). scheme: "l1" (order 2 - q) or
    "gl" (Grunwald-Letnikov, order 1; "gl" with kind "caputo" differentiates f - f(0)).
    memory: short-memory length L in steps (None: the whole history).
    Returns (M,) in units of f per s^q. The value at t = 0 is 0 for Caputo; for RL with
    f(0) != 0 the true value is infinite and the GL value ``h^-q f(0)`` is returned.
    """
    f, h = _check_signal(f, h)
    if kind not in KINDS:
        raise ConfigError(f"kind must be one of {KINDS}, got {kind!r}")
    if scheme not in SCHEMES:
        raise ConfigError(f"scheme must be one of {SCHEMES}, got {scheme!r}")
    m = len(f)
    idx, values = _orders(q, m, h)
    mem = _memory(memory, m - 1)
    out = np.zeros(m)
    if scheme == "gl":
        g = f - f[0] if kind == "caputo" else f
        for p, qp in enumerate(values):
            sel = idx == p
            if sel.any():
                conv = convolve(g, gl_weights(qp, mem))[:m]
                out[sel] = h ** -qp * conv[sel]
        return out
    df = np.diff(f)
    n = np.arange(m)
    for p, qp in enumerate(values):
        sel = idx == p
        if not sel.any():
            continue
        conv = np.zeros(m)
        conv[1:] = convolve(df, l1_weights(qp, mem))[: m - 1]
        val = h ** -qp / math.gamma(2.0 - qp) * conv
        if kind == "rl" and f[0] != 0.0 and qp < 1.0:
            t = np.maximum(n, 1) * h
            val = val + f[0] * t ** -qp / math.gamma(1.0 - qp)
            val[0] = h ** -qp * f[0]
        out[sel] = val[sel]
    return out


def solve_for_input(g, h: float, q, *, memory: int | None = None) -> np.ndarray:
    """Inverse of the GL derivative: f with ``D^q f = g`` (RL/GL, f_n from g_n step by step:
    ``f_n = (h^q g_n - sum_{k=1}^{min(n,L)} w_k f_{n-k}) / w_0``). Used for creep: the strain of a
    Scott-Blair element under a given stress is ``solve_for_input(stress / eta, h, q)``."""
    g, h = _check_signal(g, h)
    m = len(g)
    idx, values = _orders(q, m, h)
    mem = _memory(memory, m - 1)
    weights = [gl_weights(v, mem) for v in values]
    f = np.zeros(m)
    for n in range(m):
        p = idx[n]
        w = weights[p]
        k = min(n, mem)
        past = float(np.dot(w[1:k + 1], f[n - 1::-1][:k])) if k else 0.0
        f[n] = (h ** values[p] * g[n] - past) / w[0]
    return f


def power_derivative(t, p: float, q: float) -> np.ndarray:
    """Exact ``D^q t^p = Gamma(p+1)/Gamma(p+1-q) t^(p-q)`` (Caputo = RL for p > 0)."""
    t = np.asarray(t, dtype=float)
    return math.gamma(p + 1.0) / math.gamma(p + 1.0 - q) * t ** (p - q)


def short_memory_bound(f_max: float, h: float, q: float, memory: int) -> float:
    """Podlubny's bound ``M (L h)^-q / |Gamma(1 - q)|`` on the truncation error of the GL sum."""
    q = check_order(q)
    if q in (0.0, 1.0):
        return 0.0
    return abs(f_max) * (memory * h) ** -q / abs(math.gamma(1.0 - q))

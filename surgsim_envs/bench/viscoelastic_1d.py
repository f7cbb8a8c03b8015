"""One-dimensional viscoelastic stress-strain laws on a uniform time grid (the variable-order paper, sections I-III).

* variable-order fractional element (eq. 2): ``sigma = eta D^q(t) eps`` (Caputo, L1 scheme;
  equal to Riemann-Liouville for a strain history starting from rest, eps(0) = 0);
* Scott-Blair element: the same with a constant q;
* Kelvin-Voigt (eq. 1): ``sigma = k eps + b deps/dt``;
* standard linear solid (Zener, one Prony term): ``E(t) = E_inf + E1 exp(-t/tau)``, evaluated
  exactly for a piecewise-linear strain history (exponential integrator).

Closed forms of relaxation (unit strain step) and creep (unit stress step) for the comparison
figures live here too. Units: stress Pa, time s, strain dimensionless, eta Pa s^q, b Pa s.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue import fractional_calculus as fc


def uniform_step(time) -> float:
    """The step h (s) of a uniform grid ``time`` starting at 0 (ConfigError otherwise)."""
    t = np.asarray(time, dtype=float)
    if len(t) < 3 or abs(t[0]) > 1e-12 * max(1.0, abs(t[-1])):
        raise ConfigError(f"the time grid must start at 0 s and have >= 3 samples, got {len(t)} samples from {t[0]!r} s")
    h = np.diff(t)
    if np.any(h <= 0) or np.ptp(h) > 1e-6 * h.mean():
        raise ConfigError("the time grid must be uniform (resample the record first, see fractional_fit.resample)")
    return float(h.mean())


def fractional_stress(time, strain, eta: float, order, *, memory: int | None = None) -> np.ndarray:
    """``eta D^q(t) eps`` (Pa) on the uniform grid ``time`` (s); ``order`` a number or a PiecewiseOrder."""
    if not (math.isfinite(eta) and eta > 0):
        raise ConfigError(f"eta must be > 0 Pa s^q, got {eta!r}")
    h = uniform_step(time)
    return eta * fc.derivative(strain, h, order, kind="caputo", scheme="l1", memory=memory)


def kelvin_voigt_stress(time, strain, k: float, b: float) -> np.ndarray:
    """``k eps + b deps/dt`` (Pa); the rate is the backward difference on the grid (0 at t = 0)."""
    h = uniform_step(time)
    eps = np.asarray(strain, dtype=float)
    rate = np.concatenate([[0.0], np.diff(eps) / h])
    return k * eps + b * rate


def sls_stress(time, strain, e_inf: float, e1: float, tau: float) -> np.ndarray:
    """Standard linear solid ``sigma = E_inf eps + h``, ``dh/dt = E1 deps/dt - h/tau``, exact for a
    strain linear between the samples."""
    if not (math.isfinite(tau) and tau > 0):
        raise ConfigError(f"relaxation time tau must be > 0 s, got {tau!r}")
    h = uniform_step(time)
    eps = np.asarray(strain, dtype=float)
    a = math.exp(-h / tau)
    inc = np.concatenate([[0.0], e1 * tau * (1.0 - a) * np.diff(eps) / h])
    return e_inf * eps + lfilter([1.0], [1.0, -a], inc)


# ----------------------------------------------------------------------------------------------
# closed forms: relaxation modulus (stress per unit strain step) and creep compliance (strain per unit stress step)
def relaxation_modulus(model: str, t, **p) -> np.ndarray:
    """G(t) in Pa for t > 0: "scott_blair" (eta, q): eta t^-q / Gamma(1-q); "kelvin_voigt" (k):
    k (plus b delta(t), not shown); "sls" (e_inf, e1, tau): E_inf + E1 exp(-t/tau)."""
    t = np.asarray(t, dtype=float)
    if model == "scott_blair":
        return p["eta"] * t ** -p["q"] / math.gamma(1.0 - p["q"])
    if model == "kelvin_voigt":
        return np.full_like(t, p["k"])
    if model == "sls":
        return p["e_inf"] + p["e1"] * np.exp(-t / p["tau"])
    raise ConfigError(f"unknown 1-D model {model!r}; choose scott_blair, kelvin_voigt or sls")


def creep_compliance(model: str, t, **p) -> np.ndarray:
    """J(t) in 1/Pa: "scott_blair": t^q / (eta Gamma(1+q)); "kelvin_voigt": (1 - exp(-k t/b))/k;
    "sls": 1/E_inf - (1/E_inf - 1/E0) exp(-t/tau_c), E0 = E_inf + E1, tau_c = tau E0/E_inf."""
    t = np.asarray(t, dtype=float)
    if model == "scott_blair":
        return t ** p["q"] / (p["eta"] * math.gamma(1.0 + p["q"]))
    if model == "kelvin_voigt":
        return (1.0 - np.exp(-p["k"] * t / p["b"])) / p["k"]
    if model == "sls":
        e0 = p["e_inf"] + p["e1"]
        tau_c = p["tau"] * e0 / p["e_inf"]
        return 1.0 / p["e_inf"] - (1.0 / p["e_inf"] - 1.0 / e0) * np.exp(-t / tau_c)
    raise ConfigError(f"unknown 1-D model {model!r}; choose scott_blair, kelvin_voigt or sls")

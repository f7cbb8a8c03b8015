"""Analytic references for virtual material tests, each with its source and validity range.

All inputs and outputs are SI (m, N, Pa, s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError


@dataclass(frozen=True)
class Reference:
    """A closed-form reference: ``name``, ``source`` and a sentence on where it is valid."""

    name: str
    source: str
    validity: str


HERTZ = Reference(
    "hertz_sphere_halfspace",
    "Hertz (1882); Johnson, Contact Mechanics (1985) eq. 4.22: F = 4/3 E* sqrt(R) d^1.5, E* = E / (1 - nu^2)",
    "frictionless rigid sphere on a linear elastic half-space; d << R and contact radius a = sqrt(R d) << layer thickness",
)
DIMITRIADIS = Reference(
    "dimitriadis_bonded_layer",
    "Dimitriadis, Horkay, Maresca, Kachar, Chadwick, Biophys. J. 82:2798 (2002), eqs. 12-13 (bonded) and 14-15 (not bonded)",
    "rigid sphere on a linear elastic layer of thickness h on a rigid base; chi = sqrt(R d)/h <= 1, d <= 0.1 R..0.3 R, "
    "small strain",
)
SLS = Reference(
    "standard_linear_solid_ramp_hold",
    "Zener standard linear solid; Boltzmann superposition of E(t) = E_inf + (E0 - E_inf) exp(-t/tau) over a strain ramp "
    "(Findley, Lai, Onaran, Creep and Relaxation of Nonlinear Viscoelastic Materials, 1976, ch. 5)",
    "linear viscoelasticity, small strain, uniaxial stress in a block free to expand laterally",
)
GROSS_SLIP = Reference(
    "coulomb_gross_slip",
    "Coulomb friction: gross slip of a grasped body starts when the pull reaches mu * sum(N) (Amontons-Coulomb law)",
    "rigid jaws, quasi-static pull along the jaw faces, uniform mu; partial slip before gross slip is ignored",
)


def hertz_force(depth, radius: float, young: float, poisson: float) -> np.ndarray:
    """Hertz force (N) of a rigid sphere of ``radius`` (m) pressed ``depth`` (m) into a half-space."""
    validate.positives(fix="give a positive number (SI units)", radius=radius, young=young)
    d = np.clip(np.asarray(depth, dtype=float), 0.0, None)
    return 4.0 / 3.0 * young / (1.0 - poisson ** 2) * math.sqrt(radius) * d ** 1.5


def dimitriadis_force(depth, radius: float, young: float, poisson: float, thickness: float,
                      bonded: bool = True) -> np.ndarray:
    """Force (N) of a rigid sphere (``radius`` m) indenting a layer of ``thickness`` (m) on a rigid base.

    Hertz times the finite-thickness polynomial in chi = sqrt(R d) / h of Dimitriadis et al. (2002),
    with the nu-dependent coefficients alpha0, beta0 for a bonded (or non-bonded) layer.
    """
    validate.positives(fix="give a positive number (SI units)", radius=radius, young=young, thickness=thickness)
    nu = poisson
    if bonded:
        a0 = -(1.2876 - 1.4678 * nu + 1.3442 * nu ** 2) / (1.0 - nu)
        b0 = (0.6387 - 1.0277 * nu + 1.5164 * nu ** 2) / (1.0 - nu)
    else:
        a0 = -0.347 * (3.0 - 2.0 * nu) / (1.0 - nu)
        b0 = 0.056 * (5.0 - 2.0 * nu) / (1.0 - nu)
    d = np.clip(np.asarray(depth, dtype=float), 0.0, None)
    chi = np.sqrt(radius * d) / thickness
    pi = math.pi
    poly = (1.0 - 2.0 * a0 / pi * chi + 4.0 * a0 ** 2 / pi ** 2 * chi ** 2
            - 8.0 / pi ** 3 * (a0 ** 3 + 4.0 * pi ** 2 * b0 / 15.0) * chi ** 3
            + 16.0 * a0 / pi ** 4 * (a0 ** 3 + 3.0 * pi ** 2 * b0 / 5.0) * chi ** 4)
    return hertz_force(d, radius, young, poisson) * poly


def dimitriadis_valid_depth(radius: float, thickness: float, max_chi: float = 1.0, max_depth_ratio: float = 0.3) -> float:
    """Largest depth (m) inside the reference's validity: chi <= max_chi and d <= max_depth_ratio * R."""
    validate.positives(fix="give a positive number (SI units)", radius=radius, thickness=thickness)
    return min(max_chi ** 2 * thickness ** 2 / radius, max_depth_ratio * radius)


def sls_ramp_hold_stress(t, strain: float, ramp_time: float, young: float, relax_fraction: float,
                         relax_time: float) -> np.ndarray:
    """Uniaxial stress (Pa) of a standard linear solid under a strain ramp to ``strain`` over ``ramp_time`` (s), then held.

    E(t) = E_inf + E1 exp(-t / tau), E0 = ``young`` = E_inf + E1, E1 = ``relax_fraction`` * E0.
    Ramp (t <= t_r): sigma = r [E_inf t + E1 tau (1 - exp(-t/tau))], r = strain / t_r.
    Hold (t > t_r): sigma = r [E_inf t_r + E1 tau (exp(-(t - t_r)/tau) - exp(-t/tau))].
    """
    validate.positives(fix="give a positive number (SI units)", ramp_time=ramp_time, young=young, relax_time=relax_time)
    if not 0.0 <= relax_fraction < 1.0:
        raise ConfigError(f"relax_fraction must lie in [0, 1), got {relax_fraction}")
    t = np.asarray(t, dtype=float)
    e1 = relax_fraction * young
    einf = young - e1
    rate = strain / ramp_time
    tau = relax_time
    ramp = rate * (einf * t + e1 * tau * (1.0 - np.exp(-t / tau)))
    th = np.maximum(t - ramp_time, 0.0)
    hold = rate * (einf * ramp_time + e1 * tau * (np.exp(-th / tau) - np.exp(-t / tau)))
    return np.where(t <= ramp_time, ramp, hold)


def gross_slip_pull(mu: float, normal_sum: float) -> float:
    """Pull force (N) at which a grasp with summed jaw normal force ``normal_sum`` (N) slips: mu * sum(N)."""
    if mu < 0 or normal_sum < 0:
        raise ConfigError(f"mu and normal_sum must be >= 0, got mu={mu}, normal_sum={normal_sum}")
    return mu * normal_sum

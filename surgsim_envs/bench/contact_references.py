"""Analytic references for frictional contact of a rigid sphere on a linear elastic half-space.

The frictionless indentation force is Hertz's (:func:`surgsim_envs.bench.references.hertz_force`)
and gross sliding is Coulomb's mu N (:func:`surgsim_envs.bench.references.gross_slip_pull`); this
module adds what friction changes:

* how much a no-slip (fully adhesive, "rough") contact raises the normal stiffness of a punch of
  given contact radius (:func:`no_slip_stiffness_factor`; for a sphere, whose contact grows, the
  converged FEM of docs/contact.md gives less: +5 % at nu = 0, under +0.1 % at nu = 0.45);
* the partial-slip tangential force-displacement curve of a pressed sphere under a growing
  tangential load, up to gross sliding (Cattaneo 1938; Mindlin 1949):
  :func:`cattaneo_mindlin_displacement`, :func:`cattaneo_mindlin_force`.

All inputs and outputs are SI (m, N, Pa). The rigid sphere is the tool, the half-space the tissue
(Young's modulus E, Poisson's ratio nu, shear modulus G = E / (2 (1 + nu))).
"""

from __future__ import annotations

import math

import numpy as np

from surgsim_envs import validate
from surgsim_envs.bench.references import Reference, gross_slip_pull, hertz_force
from surgsim_envs.errors import ConfigError

NO_SLIP_SPHERE = Reference(
    "no_slip_sphere_halfspace",
    "Mossakovskii (1963) and Spence (1968, 1975): a punch in complete adhesion (no slip) with an elastic "
    "half-space has the incremental stiffness dP/dd = 2 E* a kappa(nu), kappa = (1 - nu) ln(3 - 4 nu) / (1 - 2 nu), "
    "whatever the punch profile (Borodich and Keer, Proc. R. Soc. A 460:507, 2004)",
    "rigid axisymmetric punch at a given contact radius a (exact for a flat punch), linear elastic half-space, "
    "small strain; for a sphere the no-slip contact radius at a given depth differs from Hertz's, so the "
    "factor is not the sphere's load ratio; the coupling between normal and shear tractions is Dundurs' "
    "beta = (1 - 2 nu) / (2 (1 - nu)) (Goodman 1962), which vanishes for nu = 0.5",
)
CATTANEO_MINDLIN = Reference(
    "cattaneo_mindlin_partial_slip",
    "Cattaneo (1938); Mindlin (1949); Johnson, Contact Mechanics (1985) eq. 7.42: "
    "delta = 3 mu P (2 - nu) / (16 G a) [1 - (1 - Q / (mu P))^(2/3)]",
    "rigid sphere pressed with a constant normal load P on a linear elastic half-space, then a monotonically "
    "growing tangential load Q <= mu P; Hertz contact radius a; the normal-tangential coupling neglected "
    "(exact for nu = 0.5, Dundurs' beta small for tissue)",
)
COULOMB_SLIDING = Reference(
    "coulomb_gross_sliding",
    "Amontons-Coulomb: a body sliding on a surface carries the tangential force mu N",
    "uniform kinetic coefficient mu, any contact geometry and normal load N",
)


def _poisson(nu: float) -> float:
    if not (isinstance(nu, (int, float, np.floating)) and math.isfinite(nu) and 0.0 <= nu <= 0.5):
        raise ConfigError(f"poisson must lie in [0, 0.5] for these half-space references, got {nu!r}")
    return float(nu)


def shear_modulus(young: float, poisson: float) -> float:
    """G = E / (2 (1 + nu)), Pa."""
    validate.positives(fix="give a positive number (SI units)", young=young)
    return float(young) / (2.0 * (1.0 + _poisson(poisson)))


def dundurs_beta(poisson: float) -> float:
    """Dundurs' second constant for a rigid body on an elastic one, beta = (1 - 2 nu) / (2 (1 - nu)):
    how strongly shear tractions move the surface normally (and normal ones tangentially). 0 for an
    incompressible solid (nu = 0.5), 0.091 at nu = 0.45, 0.5 at nu = 0 (Goodman 1962's coupling)."""
    nu = _poisson(poisson)
    return (1.0 - 2.0 * nu) / (2.0 * (1.0 - nu))


def no_slip_stiffness_factor(poisson: float) -> float:
    """kappa(nu) = (1 - nu) ln(3 - 4 nu) / (1 - 2 nu): the incremental normal stiffness of a punch in
    complete adhesion over that of a frictionless one with the same contact radius (Mossakovskii;
    Spence; :data:`NO_SLIP_SPHERE`). 1 at nu = 0.5 (the limit, taken by its series below 1e-6 of
    1 - 2 nu), 1.0028 at nu = 0.45, 1.029 at nu = 0.3, ln 3 = 1.099 at nu = 0."""
    nu = _poisson(poisson)
    e = 1.0 - 2.0 * nu                      # 3 - 4 nu = 1 + 2 e
    if e < 1e-6:
        series = 1.0 - e + 4.0 * e * e / 3.0  # ln(1 + 2e) / (2e)
        return 2.0 * (1.0 - nu) * series
    return (1.0 - nu) * math.log(1.0 + 2.0 * e) / e


def hertz_contact_radius(normal_force, radius: float, young: float, poisson: float) -> np.ndarray:
    """Hertz contact radius a = (3 P R / (4 E*))^(1/3), m, of a rigid sphere under normal load P (N)."""
    validate.positives(fix="give a positive number (SI units)", radius=radius, young=young)
    nu = _poisson(poisson)
    p = np.asarray(normal_force, dtype=float)
    if np.any(~np.isfinite(p)) or np.any(p < 0):
        raise ConfigError(f"normal_force must be finite and >= 0 N, got {normal_force!r}")
    return np.cbrt(3.0 * p * radius * (1.0 - nu * nu) / (4.0 * young))


def mindlin_slip_displacement(mu: float, normal_force: float, contact_radius: float, young: float,
                              poisson: float) -> float:
    """delta_s = 3 mu P (2 - nu) / (16 G a), m: the tangential displacement at which the pressed sphere
    reaches gross sliding (Q = mu P) in the Cattaneo-Mindlin solution."""
    validate.positives(fix="give a positive number (SI units)", mu=mu, normal_force=normal_force, contact_radius=contact_radius)
    g = shear_modulus(young, poisson)
    return 3.0 * mu * normal_force * (2.0 - float(poisson)) / (16.0 * g * contact_radius)


def cattaneo_mindlin_displacement(tangential_force, mu: float, normal_force: float, contact_radius: float,
                                  young: float, poisson: float) -> np.ndarray:
    """Tangential displacement (m) of a sphere pressed with ``normal_force`` P (N) over a contact of
    radius ``contact_radius`` a (m) under a growing tangential force Q (N), 0 <= Q <= mu P:
    delta = delta_s [1 - (1 - Q / (mu P))^(2/3)] (:data:`CATTANEO_MINDLIN`). Its initial slope is the
    tangential stiffness of a bonded circle, dQ/d delta = 8 G a / (2 - nu)."""
    ds = mindlin_slip_displacement(mu, normal_force, contact_radius, young, poisson)
    q = np.asarray(tangential_force, dtype=float)
    cap = mu * normal_force
    if np.any(~np.isfinite(q)) or np.any(q < 0) or np.any(q > cap * (1.0 + 1e-12)):
        raise ConfigError(f"tangential_force must lie in [0, mu P] = [0, {cap:.6g}] N (beyond it the sphere slides), "
                          f"got {tangential_force!r}")
    return ds * (1.0 - np.cbrt(np.clip(1.0 - q / cap, 0.0, 1.0)) ** 2)


def cattaneo_mindlin_force(displacement, mu: float, normal_force: float, contact_radius: float, young: float,
                           poisson: float) -> np.ndarray:
    """Tangential force Q (N) against the tangential displacement delta >= 0 (m) of the pressed sphere:
    Q = mu P [1 - (1 - delta / delta_s)^(3/2)] up to delta_s, then mu P (gross sliding,
    :func:`coulomb_sliding_force`)."""
    ds = mindlin_slip_displacement(mu, normal_force, contact_radius, young, poisson)
    d = np.asarray(displacement, dtype=float)
    if np.any(~np.isfinite(d)) or np.any(d < 0):
        raise ConfigError(f"displacement must be finite and >= 0 m (the direction of the tangential load), "
                          f"got {displacement!r}")
    s = np.clip(1.0 - d / ds, 0.0, 1.0)
    return mu * normal_force * (1.0 - s * np.sqrt(s))


def coulomb_sliding_force(mu: float, normal_force: float) -> float:
    """Tangential force (N) of gross sliding under the normal load ``normal_force`` (N): mu N."""
    return gross_slip_pull(mu, normal_force)

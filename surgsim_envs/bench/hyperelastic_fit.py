"""Fit constitutive laws to measured uniaxial compression curves (silicone phantoms, brain cortex).

Every law is written for homogeneous uniaxial stress of an incompressible (or, for the linear
laws, small-strain) solid, stretch lambda = 1 + engineering strain (< 1 in compression), nominal
(first Piola-Kirchhoff) stress P in Pa:

* ``linear`` (Hooke; also ``fem``'s corotational law, which in a rotation-free uniaxial stretch
  is the same): P = E (lambda - 1)
* ``mass_spring`` (the network's relaxed tangent modulus E (1 + c eps^2), ``Material.nonlinear``):
  P = E (eps + c eps^3 / 3), eps = lambda - 1
* ``neo_hookean``: P = mu (lambda - lambda^-2)                (W = mu/2 (I1 - 3))
* ``mooney_rivlin``: P = 2 (C10 + C01 / lambda)(lambda - lambda^-2)
* ``ogden``: P = 2 mu / alpha (lambda^(alpha-1) - lambda^(-alpha/2-1))   (one term; mu = shear modulus)

:func:`fit` finds the parameters by least squares on P (scipy ``least_squares``, positive
parameters) over the samples with strain in [0, ``max_strain``]; :func:`evaluate` gives the RMS
error over any strain range, relative to the largest measured stress there. Fitting on small
strains and evaluating on the rest is the non-circular check (extrapolation to data the fit never
saw). Data loaders read ``../shared/data/tissue_mechanics`` (not shipped with the package).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from surgsim_envs.errors import ConfigError


def _linear(lam, p):
    return p[0] * (lam - 1.0)


def _mass_spring(lam, p):
    e = lam - 1.0
    return p[0] * (e + p[1] * e ** 3 / 3.0)


def _neo_hookean(lam, p):
    return p[0] * (lam - lam ** -2)


def _mooney_rivlin(lam, p):
    return 2.0 * (p[0] + p[1] / lam) * (lam - lam ** -2)


def _ogden(lam, p):
    mu, alpha = p
    return 2.0 * mu / alpha * (lam ** (alpha - 1.0) - lam ** (-alpha / 2.0 - 1.0))


#: name -> (stress function, parameter names, initial guess in units of the small-strain modulus E0, lower bounds)
LAWS = {
    "linear": (_linear, ("E",), lambda e0: [e0], [0.0]),
    "mass_spring": (_mass_spring, ("E", "nonlinear"), lambda e0: [e0, 1.0], [0.0, 0.0]),
    "neo_hookean": (_neo_hookean, ("mu",), lambda e0: [e0 / 3.0], [0.0]),
    "mooney_rivlin": (_mooney_rivlin, ("C10", "C01"), lambda e0: [e0 / 12.0, e0 / 12.0], [0.0, 0.0]),
    "ogden": (_ogden, ("mu", "alpha"), lambda e0: [e0 / 3.0, 4.0], [0.0, -30.0]),
}


@dataclass(frozen=True)
class Curve:
    """A measured uniaxial curve: ``stretch`` (-), nominal ``stress`` (Pa, negative in compression)."""

    name: str
    stretch: np.ndarray
    stress: np.ndarray
    source: str = ""


@dataclass(frozen=True)
class Fit:
    law: str
    params: dict
    rms_fit: float          # relative RMS error over the fitted range
    max_strain: float

    def stress(self, stretch) -> np.ndarray:
        fn = LAWS[self.law][0]
        return fn(np.asarray(stretch, dtype=float), list(self.params.values()))


def load_phantom(path) -> Curve:
    """An Ecoflex phantom CSV (Dawood et al., CC BY 4.0): 7 metadata lines, header, then rows
    (time s, compression mm, load N, eng. strain, eng. stress kPa, true strain, true stress kPa)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"phantom compression file not found: {path}")
    data = np.loadtxt(path, delimiter=",", skiprows=8)
    strain, stress = data[:, 3], data[:, 4] * 1e3
    return Curve(path.stem, 1.0 + strain, stress, "Dawood et al., tissue-phantom-material-database (CC BY 4.0)")


def load_budday(path) -> Curve:
    """Budday et al. (2017) cortex compression (stretch, nominal stress kPa; two columns)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"brain compression file not found: {path}")
    data = np.loadtxt(path, delimiter=",")
    return Curve("brain_cortex_" + path.stem, data[:, 0], data[:, 1] * 1e3, "Budday et al. 2017 via Chongran-Zhao/Hyperelastic-fitting (MIT)")


def _select(curve: Curve, lo: float, hi: float) -> np.ndarray:
    strain = 1.0 - curve.stretch
    return (strain >= lo) & (strain <= hi) & np.isfinite(curve.stress)


def evaluate(fit: Fit, curve: Curve, lo: float = 0.0, hi: float = 1.0) -> float:
    """RMS stress error over compressive strains in [lo, hi], relative to the largest |stress| there."""
    sel = _select(curve, lo, hi)
    if sel.sum() < 2:
        raise ConfigError(f"curve {curve.name} has fewer than 2 samples with strain in [{lo}, {hi}]")
    err = fit.stress(curve.stretch[sel]) - curve.stress[sel]
    return float(np.sqrt(np.mean(err ** 2)) / np.max(np.abs(curve.stress[sel])))


def fit(curve: Curve, law: str, max_strain: float = 1.0, min_strain: float = 0.0) -> Fit:
    """Least-squares fit of ``law`` to ``curve`` over compressive strains in [min_strain, max_strain]."""
    import scipy.optimize as so

    if law not in LAWS:
        raise ConfigError(f"unknown law {law!r}; choose one of {sorted(LAWS)}")
    if not (0.0 < max_strain <= 1.0):
        raise ConfigError(f"max_strain must lie in (0, 1], got {max_strain}")
    fn, names, guess, lower = LAWS[law]
    sel = _select(curve, min_strain, max_strain)
    if sel.sum() < len(names) + 2:
        raise ConfigError(f"curve {curve.name}: too few samples in strain [{min_strain}, {max_strain}]")
    lam, p_meas = curve.stretch[sel], curve.stress[sel]
    small = sel & (1.0 - curve.stretch <= min(0.1, max_strain))
    e0 = float(np.polyfit(curve.stretch[small] - 1.0, curve.stress[small], 1)[0]) if small.sum() > 3 else 1e4
    e0 = max(e0, 1.0)
    scale = float(np.max(np.abs(p_meas)))
    best = None
    starts = [guess(e0)] + ([[e0 / 3.0, a] for a in (-4.0, 2.0, 8.0, 15.0)] if law == "ogden" else [])
    for x0 in starts:
        res = so.least_squares(lambda p: (fn(lam, p) - p_meas) / scale, x0, bounds=(lower, np.inf),
                               x_scale=np.abs(x0) + 1e-9)
        if best is None or res.cost < best.cost:
            best = res
    params = dict(zip(names, (float(v) for v in best.x)))
    rms = float(math.sqrt(2.0 * best.cost / len(lam)) * scale / np.max(np.abs(p_meas)))
    return Fit(law, params, rms, float(max_strain))


def small_strain_modulus(f: Fit) -> float:
    """Young's modulus (Pa) of a fitted law at zero strain (3 x shear modulus for incompressible laws)."""
    p = f.params
    return {"linear": lambda: p["E"], "mass_spring": lambda: p["E"], "neo_hookean": lambda: 3.0 * p["mu"],
            "mooney_rivlin": lambda: 6.0 * (p["C10"] + p["C01"]), "ogden": lambda: 3.0 * p["mu"]}[f.law]()

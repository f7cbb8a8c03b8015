"""Uniaxial compression of a phantom-sized block *in the simulator*: nominal stress per strain.

The closed-form laws of :mod:`surgsim_envs.bench.hyperelastic_fit` assume homogeneous uniaxial
stress. Here a tissue model (any registered model with ``static_solve``) is built on a block with
the phantom's height and cross-section area (Dawood et al.: 50 mm diameter x 30 mm cylinders; a
square of equal area), its top face is moved down by ``strain x height`` and the nominal stress is
the support reaction on the top face divided by the rest area. Two plate conditions:

* ``"frictionless"``: the top and bottom faces follow the homogeneous incompressible deformation
  (lateral stretch lambda^-1/2, lambda = 1 - strain; the models hold whole nodes, not single dofs,
  so sliding is prescribed, not free); the rest of the block is free. For an incompressible
  finite-strain solid this *is* the frictionless-plate solution and what the closed-form laws
  describe, so it checks a model's implementation of its law. Two limits: a nearly incompressible
  model settles at J slightly below 1 where the plates hold J = 1 (a one-element pressure layer:
  neo_hookean 0.3-0.7 % at 7.5 mm, 1.5-2.2 % at 15 mm); a geometrically linear model (``fem``
  linear, and corotational, which in a rotation-free stretch is the same) reads the finite lateral
  stretch as a volume change, so its "frictionless" curve is not its own free response.
* ``"bonded"``: the faces cannot move laterally (platens that grip), the truth cube's condition;
  barrelling makes the block stiffer than the closed form.

Units: m, Pa, N.
"""

from __future__ import annotations

import math

import numpy as np

from surgsim_envs.errors import ConfigError, SurgSimError

#: the Ecoflex phantoms of ../shared/data/tissue_mechanics: 50 mm diameter, 30 mm high
PHANTOM_HEIGHT = 0.030
PHANTOM_SIDE = math.sqrt(math.pi * 0.025 ** 2)
PLATES = ("frictionless", "bonded")


def compression_block(model_name: str, material, *, spacing: float = 0.0075, side: float = PHANTOM_SIDE,
                      height: float = PHANTOM_HEIGHT, **options):
    """(model, bottom node indices, top node indices) for a side x side x height block (m)."""
    from surgsim_envs import tissue
    from surgsim_envs.geometry import box_volume

    vol = box_volume((side, side, height), spacing, name="compression_block")
    model = tissue.make(model_name, vol, material, **options)
    z = vol.nodes[:, 2]
    return model, np.flatnonzero(z < z.min() + 1e-9), np.flatnonzero(z > z.max() - 1e-9)


def nominal_stress(model, bottom, top, strain: float, plates: str = "frictionless") -> float:
    """Nominal stress (Pa, negative in compression) at engineering ``strain`` (0 <= strain < 1)."""
    if plates not in PLATES:
        raise ConfigError(f"plates={plates!r}: choose one of {PLATES}")
    if not (0.0 <= strain < 1.0):
        raise ConfigError(f"strain={strain!r} must lie in [0, 1) (engineering compressive strain)")
    X = model.rest_positions
    z0 = float(X[:, 2].min())
    lam = 1.0 - strain
    lateral = lam ** -0.5 if plates == "frictionless" else 1.0
    centre = X[:, :2].mean(axis=0)

    def target(idx):
        t = X[idx].copy()
        t[:, :2] = centre + (t[:, :2] - centre) * lateral
        t[:, 2] = z0 + (t[:, 2] - z0) * lam
        return t

    model.reset()
    model.set_fixed(bottom, target(bottom))
    model.set_fixed(top, target(top))
    model.static_solve()
    area = float(np.ptp(X[:, 0]) * np.ptp(X[:, 1]))
    force_z = -float(model.internal_forces()[top, 2].sum())    # the plate's push on the block
    return force_z / area


def compression_curve(model_name: str, material, strains, plates: str = "frictionless",
                      **block_options) -> tuple[np.ndarray, dict[float, str]]:
    """(nominal stress (Pa) at each engineering strain, {strain: why the model found no equilibrium}).

    One static solve from rest per strain. Where the model's solver fails (a mass-spring network
    that folds, a Newton solve that stalls) the stress is NaN and the failure message is returned:
    the table shows where a model stops, instead of hiding it."""
    model, bottom, top = compression_block(model_name, material, **block_options)
    out, failures = [], {}
    for s in strains:
        try:
            out.append(nominal_stress(model, bottom, top, float(s), plates))
        except SurgSimError as exc:
            if isinstance(exc, ConfigError):
                raise
            out.append(math.nan)
            failures[float(s)] = f"{type(exc).__name__}: {exc}"
    return np.array(out), failures


def material_from_fit(fit, poisson: float = 0.499) -> dict:
    """A material dict (Pa) for the simulator from a :class:`~surgsim_envs.bench.hyperelastic_fit.Fit`:
    Young's modulus at small strain (linear E, 2 mu (1 + nu) for Neo-Hookean, the mass-spring law's E
    and its ``nonlinear`` coefficient), near-incompressible ``poisson``, no damping or relaxation."""
    from surgsim_envs.bench.hyperelastic_fit import small_strain_modulus

    p = fit.params
    young = 2.0 * p["mu"] * (1.0 + poisson) if fit.law == "neo_hookean" else small_strain_modulus(fit)
    mat = {"name": f"fit_{fit.law}", "young": young, "poisson": poisson, "density": 1000.0, "damping": 0.0,
           "relax_fraction": 0.0, "nonlinear": float(p.get("nonlinear", 0.0))}
    return mat

"""Material description shared by every tissue model, and presets with their sources.

Every model accepts the same physical description (:class:`Material`) and maps it to its own
parameters (documented in each model and in ``docs/models.md``). Model-specific overrides go in
``Material.extra`` or as keyword options to :func:`surgsim_envs.tissue.make`.

Units: ``young`` Pa, ``density`` kg/m^3, ``damping`` 1/s (mass-proportional), ``relax_time`` s.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Mapping

from surgsim_envs.errors import ConfigError


@dataclass(frozen=True)
class Material:
    """Isotropic (visco)elastic material.

    young: Young's modulus E (Pa), > 0.
    poisson: Poisson ratio nu, in (-1, 0.5). Soft tissue is nearly incompressible (0.45-0.499).
    density: mass density rho (kg/m^3), > 0.
    damping: mass-proportional (nodal) damping coefficient (1/s): f_damp = -damping * m * v.
    relax_fraction: g1 in [0, 1): fraction of the instantaneous stiffness that relaxes away
        (standard linear solid / one-term Prony series: E(t) = E_inf + (E0 - E_inf) exp(-t/tau),
        with E0 = young and E_inf = (1 - g1) * young).
    relax_time: relaxation time tau (s) of the viscoelastic branch, > 0.
    nonlinear: strain-stiffening coefficient (dimensionless): stiffness grows as
        k(strain) = k0 * (1 + nonlinear * strain^2) in models that support it.
    friction: default tool-tissue Coulomb coefficient mu.
    name, source: label and literature source of the values.
    extra: model-specific overrides (e.g. {"K1": ..., "K2": ...} for the mass-spring model).
    """

    young: float
    poisson: float = 0.45
    density: float = 1000.0
    damping: float = 5.0
    relax_fraction: float = 0.0
    relax_time: float = 1.0
    nonlinear: float = 0.0
    friction: float = 0.6
    name: str = "custom"
    source: str = ""
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        def bad(what: str, value: Any, fix: str) -> ConfigError:
            return ConfigError(f"material '{self.name}': {what}={value!r} is invalid; {fix}")

        for key in ("young", "poisson", "density", "damping", "relax_fraction", "relax_time", "nonlinear", "friction"):
            value = getattr(self, key)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise bad(key, value, "give a finite number")
        if self.young <= 0:
            raise bad("young", self.young, "Young's modulus must be > 0 Pa (soft tissue: 1e3-1e5 Pa)")
        if not (-1.0 < self.poisson < 0.5):
            raise bad("poisson", self.poisson, "Poisson ratio must lie in (-1, 0.5); use 0.45-0.499 for tissue")
        if self.density <= 0:
            raise bad("density", self.density, "density must be > 0 kg/m^3 (tissue ~1000-1100)")
        if self.damping < 0:
            raise bad("damping", self.damping, "damping must be >= 0 1/s")
        if not (0.0 <= self.relax_fraction < 1.0):
            raise bad("relax_fraction", self.relax_fraction, "must lie in [0, 1)")
        if self.relax_time <= 0:
            raise bad("relax_time", self.relax_time, "relaxation time must be > 0 s")
        if self.nonlinear < 0:
            raise bad("nonlinear", self.nonlinear, "strain-stiffening coefficient must be >= 0")
        if self.friction < 0:
            raise bad("friction", self.friction, "friction coefficient must be >= 0")

    # Derived elastic constants -------------------------------------------------------------
    @property
    def shear_modulus(self) -> float:
        """mu = E / (2 (1 + nu)) in Pa."""
        return self.young / (2.0 * (1.0 + self.poisson))

    @property
    def lame_lambda(self) -> float:
        """lambda = E nu / ((1 + nu)(1 - 2 nu)) in Pa."""
        return self.young * self.poisson / ((1.0 + self.poisson) * (1.0 - 2.0 * self.poisson))

    @property
    def bulk_modulus(self) -> float:
        """K = E / (3 (1 - 2 nu)) in Pa."""
        return self.young / (3.0 * (1.0 - 2.0 * self.poisson))

    @property
    def relaxed_young(self) -> float:
        """Long-time modulus E_inf = (1 - g1) E in Pa."""
        return (1.0 - self.relax_fraction) * self.young

    def wave_speed(self) -> float:
        """Dilatational (P-wave) speed sqrt((lambda + 2 mu) / rho) in m/s: sets explicit dt limits."""
        return math.sqrt((self.lame_lambda + 2.0 * self.shear_modulus) / self.density)

    def replace(self, **changes: Any) -> "Material":
        """Copy with fields changed; unknown keys raise a ConfigError naming them."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise ConfigError(f"unknown material field(s) {unknown}; known fields: {sorted(names)}")
        return dataclasses.replace(self, **changes)


# Presets -----------------------------------------------------------------------------------
# Values are small-strain moduli from indentation/compression tests of fresh or in-vivo tissue,
# rounded; nu and viscoelastic terms are typical for soft tissue modelled as nearly incompressible.
PRESETS: dict[str, Material] = {
    "liver": Material(
        young=4_000.0, poisson=0.45, density=1060.0, damping=5.0, relax_fraction=0.5, relax_time=1.5,
        nonlinear=2.0, friction=0.5, name="liver",
        source="E ~ 2-7 kPa: Carter et al. 2001 (in-vivo human liver indentation); "
        "Kerdok 2006 (porcine, viscoelastic relaxation ~1-2 s); rho: ICRP 89",
    ),
    "spleen": Material(
        young=10_000.0, poisson=0.45, density=1054.0, damping=5.0, relax_fraction=0.6, relax_time=1.0,
        nonlinear=3.0, friction=0.6, name="spleen",
        source="E ~ 5-15 kPa: Rosen et al. 2008 (in-vivo porcine spleen compression); "
        "friction mu 0.6 as the grasping simulation paper; rho: ICRP 89",
    ),
    "kidney": Material(
        young=8_000.0, poisson=0.45, density=1050.0, damping=5.0, relax_fraction=0.4, relax_time=1.0,
        nonlinear=2.0, friction=0.5, name="kidney",
        source="E ~ 5-10 kPa: Farshad et al. 1999 (porcine kidney); Rosen et al. 2008",
    ),
    "fat": Material(
        young=1_000.0, poisson=0.49, density=920.0, damping=5.0, relax_fraction=0.5, relax_time=2.0,
        nonlinear=1.0, friction=0.4, name="fat",
        source="E ~ 0.5-2 kPa: Samani et al. 2007 (breast fat, indentation); rho: ICRP 89",
    ),
    "muscle": Material(
        young=25_000.0, poisson=0.45, density=1060.0, damping=5.0, relax_fraction=0.4, relax_time=0.5,
        nonlinear=3.0, friction=0.6, name="muscle",
        source="E ~ 10-50 kPa passive skeletal muscle: Gennisson et al. 2010 (elastography)",
    ),
    "skin": Material(
        young=100_000.0, poisson=0.45, density=1100.0, damping=5.0, relax_fraction=0.3, relax_time=0.5,
        nonlinear=5.0, friction=0.5, name="skin",
        source="E ~ 50-150 kPa in-vivo indentation: Pailler-Mattei et al. 2008; rho: ICRP 89",
    ),
    "silicone": Material(
        young=15_300.0, poisson=0.499, density=980.0, damping=5.0, relax_fraction=0.0, relax_time=1.0,
        nonlinear=0.0, friction=0.8, name="silicone",
        source="RTV6166 truth cube: Kerdok et al. 2003 (E = 15.3 kPa, nu = 0.499, rho = 980 kg/m^3)",
    ),
}


def get_material(material: "Material | str | Mapping[str, Any]") -> Material:
    """Resolve a preset name, a dict of fields (optionally with ``preset``), or a Material."""
    if isinstance(material, Material):
        return material
    if isinstance(material, str):
        try:
            return PRESETS[material]
        except KeyError:
            raise ConfigError(
                f"unknown material preset {material!r}; choose one of {sorted(PRESETS)} "
                "or pass a Material(young=..., poisson=..., density=...)"
            ) from None
    if isinstance(material, Mapping):
        fields = dict(material)
        base = fields.pop("preset", None)
        if base is not None:
            return get_material(base).replace(**fields)
        if "young" not in fields:
            raise ConfigError(f"material dict {material!r} needs 'young' (Pa) or a 'preset' name")
        try:
            return Material(**fields)
        except TypeError as exc:
            raise ConfigError(f"bad material fields {sorted(fields)}: {exc}") from None
    raise ConfigError(f"material must be a preset name, a dict or a Material, got {type(material).__name__}")

"""Tissue contract v2 methods for trees whose base class predates it (CONTRACT_V2.md).

The diffusion model was written against the contract names while the contract itself landed in
``tissue/base.py`` on another branch. :data:`CONTRACT_BASES` is ``(TissueModel,)`` when the base
class already provides ``scale_material`` (the merged tree), else ``(ContractV2Fallback,
TissueModel)``; the fallback implements the same semantics on the hooks the contract uses
(``material_fields``, ``node_field_names``, ``_node_field``, ``node_stress``,
``_on_material_changed``). Delete this module once every branch has the contract.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue import base as _base
from surgsim_envs.tissue.base import TissueModel

#: ``stable_dt() = DT_SAFETY * critical_dt()`` (the base class's value once it defines one)
DT_SAFETY = float(getattr(_base, "DT_SAFETY", 0.8))


class ContractV2Fallback:
    """scale_material / set_field / node_fields / element_centroids / stable_dt (contract v2)."""

    def element_centroids(self) -> np.ndarray:
        return self.rest_positions.copy()

    def stable_dt(self) -> float:
        return DT_SAFETY * float(self.critical_dt())

    @classmethod
    def field_names(cls) -> list[str]:
        return list(cls.node_field_names)

    def node_fields(self, names=None) -> dict:
        names = self.field_names() if names is None else [names] if isinstance(names, str) else list(names)
        return {n: self.node_field(n) for n in names}

    def node_field(self, name: str) -> np.ndarray:
        if name not in self.node_field_names:
            raise ConfigError(f"model '{self.name}' has no node field {name!r}; fields: {self.field_names()}")
        if name == "displacement":
            return np.linalg.norm(self.positions - self.rest_positions, axis=1)
        if name == "stress":
            return self.node_stress()
        return np.asarray(self._node_field(name), dtype=np.float64)

    def _check_field_name(self, name: str) -> None:
        if name not in self.fields:
            raise ConfigError(f"unknown material field {name!r}; fields: {sorted(self.fields)}")
        if name not in self.material_fields:
            raise ConfigError(f"tissue model '{self.name}' cannot change material field {name!r} after build; "
                              f"it re-derives only {sorted(self.material_fields)}")

    def scale_material(self, name: str = "young", factor=1.0, mask=None) -> None:
        self._check_field_name(name)
        t = len(self.fields[name])
        f = np.asarray(factor, dtype=np.float64)
        if f.ndim not in (0, 1) or (f.ndim == 1 and f.shape != (t,)):
            raise ConfigError(f"scale_material: factor must be a number or a ({t},) array, got shape {f.shape}")
        if not np.all(np.isfinite(f)) or np.any(f <= 0):
            raise ConfigError(f"scale_material: factor must be finite and > 0, got min {float(np.min(f)):.3g}")
        values = self.fields[name].copy()
        new = self._fields0[name] * np.broadcast_to(f, (t,))
        if mask is None:
            values[:] = new
        else:
            m = np.asarray(mask)
            if m.dtype != bool or m.shape != (t,):
                raise ConfigError(f"scale_material: mask must be a ({t},) bool array, got dtype {m.dtype} shape {m.shape}")
            values[m] = new[m]
        self._apply_field(name, values)

    def set_field(self, name: str, values) -> None:
        self._check_field_name(name)
        t = len(self.fields[name])
        v = np.asarray(values, dtype=np.float64)
        if v.ndim not in (0, 1) or (v.ndim == 1 and v.shape != (t,)) or not np.all(np.isfinite(v)):
            raise ConfigError(f"set_field({name!r}): values must be a finite number or ({t},) array, got shape {v.shape}")
        self._apply_field(name, np.broadcast_to(v, (t,)).copy())

    def _apply_field(self, name: str, values: np.ndarray) -> None:
        old = self.fields[name]
        self.fields[name] = values
        try:
            if name == "density":
                if np.any(values <= 0):
                    raise ConfigError("density must be > 0 kg/m^3 at every node")
                self.masses = self._lumped_masses()
            self._on_material_changed(name)
        except Exception:
            self.fields[name] = old
            if name == "density":
                self.masses = self._lumped_masses()
            self._on_material_changed(name)
            raise


CONTRACT_BASES = (TissueModel,) if hasattr(TissueModel, "scale_material") else (ContractV2Fallback, TissueModel)

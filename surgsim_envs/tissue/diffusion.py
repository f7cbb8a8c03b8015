"""Chemical diffusion of mechanical load on a surface (Zhong et al. 2016, chapter 9).

A surface-only model: a scalar concentration C per surface node (Pa: a load density, the
strain-energy density of eq. 9.7) is injected where tools press, diffuses over the surface with a
per-node, direction-dependent coefficient omega (eqs. 9.5-9.18) and pushes the surface in; its
gradient adds the tangential internal force of eqs. 9.19-9.21; nodes move by eq. 9.22 (mass,
damping, explicit). docs/models/diffusion.md gives the equations and every choice made where the
paper is silent; in short, per surface node i with control area S_i (Fig. 9.1), outward rest
normal n_i, displacement u_i, layer depth h::

    dC_i/dt = sum_j a_ij (C_j - C_i) + (p_i - C_i) / tau           (9.9 / 9.16 + load and bulk exchange)
    p_i     = max(0, -G_i . n_i) / S_i                              (the contact pressure, eq. 9.7)
    m_i a_i = -S_i C_i n_i + G~_i - S_i h W_i grad C_i              (diffused load, eqs. 9.19-9.21)
              - S_i (E_i / h) (1 + beta_i |u_i|^2 / h^2) u_i - c_i m_i v_i   (the bulk below, eq. 9.22)

with ``a_ij`` from omega (dimensionless; diffusivity ``omega L^2 / tau``, L the body's size, so a
load spreads over about ``sqrt(omega) L``), ``G~`` the external force without its compressive
normal part (tangential friction and pulls act directly), ``m_i = rho S_i h``, ``c = damping``.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Mapping

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, TissueUnstableError
from surgsim_envs.geometry.volume import Volume
from surgsim_envs.tissue import diffusion_operator as op
from surgsim_envs.tissue.diffusion_kernels import (AREA, BETA, COEF_COLUMNS, DAMPING, INV_MASS, K_AREA, NX, NZ,
                                                   diffusion_step)
from surgsim_envs.tissue.diffusion_static import (contact_compliance, node_gradients, static_positions,
                                                  steady_concentration)
from surgsim_envs.tissue.base import TissueModel
from surgsim_envs.materials import Material

SCHEMES = ("auto", "triangles", "grid")
#: most diffusion sub-steps per step (substeps="auto" uses up to this many)
MAX_SUBSTEPS = 64
#: calibration against FEM indentation on another setup (docs/models/diffusion.md "Calibration"):
#: ``surgsim fit --model diffusion --test indent --data fem_indent_spleen.csv --material spleen
#: --radius 0.004 --thickness 0.02 --spacing 0.0015 --option length=depth`` on the tet FEM's force
#: curve (E 10 kPa, nu 0.45, 4 mm sphere, 20 mm slab) gave young 13,573.5 Pa (x 1.357) and omega
#: 0.0438 (1.5 % RMS misfit). The accuracy chart (liver 4 kPa, 5 mm sphere, 30 mm slab) uses it.
INDENT_CALIBRATION = {"omega": 0.043827, "length": "depth", "stiffness_factor": 13573.5 / 10000.0}


def surface_view(volume: Volume) -> Volume:
    """The volume without its tets (same nodes, same surface): what a surface-only model sees.
    Interior nodes stay in place (their indices are kept for anchors) but carry nothing."""
    if len(volume.tets) == 0:
        return volume
    out = Volume(volume.nodes.copy(), np.zeros((0, 4), dtype=np.int32), volume.surface.copy(),
                 name=volume.name, node_labels=volume.node_labels.copy())
    for attr in ("quads",):
        if hasattr(volume, attr):
            setattr(out, attr, getattr(volume, attr))
    return out


class DiffusionModel(TissueModel):
    """Surface tissue driven by the diffusion of the contact load (Zhong et al. 2016).

    volume: a Volume; only its surface is used (tets, if any, are dropped; interior nodes stay
        still). material: young (Pa, the bulk under the surface: foundation modulus E/h), density,
        damping (1/s), nonlinear (strain stiffening: E (1 + nonlinear (|u|/h)^2)).
    omega: diffusion coefficient, dimensionless, > 0: a number or one per node (N,)
        (inhomogeneous). The diffusivity is ``omega L^2 / load_time``.
    omega_long: with a scalar omega, the longitudinal coefficient (along meridians about ``axis``);
        ``omega`` is then the latitudinal one (anisotropy, Fig. 9.3).
    omega_tensor: (N,3,3) per-node dimensionless tensor (overrides omega/omega_long); only its
        tangent-plane part matters.
    axis: polar axis of the latitude/longitude directions (default z); the directions follow the
        surface normal (latitude = axis x normal), so no centre is needed.
    load_time: tau (s), the time over which the load spreads and relaxes into the bulk.
    depth: h (m), depth of tissue under the surface (default half the smallest bounding-box side).
    length: L (m), the size that makes omega dimensionless (default the largest bounding-box side;
        "depth": L = depth, so that omega transfers between bodies of one thickness and any width).
    stiffness_factor: the bulk modulus is ``stiffness_factor x young / depth`` (Pa/m); calibrated
        against indentation (INDENT_CALIBRATION), 1 otherwise.
    gradient_scale: factor on the gradient force of eqs. 9.19-9.21 (1 = as derived, 0 = off).
    damping_ratio: extra damping of each node on the bulk, as a fraction of critical (1 = critical;
        0 leaves only the material's mass-proportional ``damping``, the paper's "damping").
    scheme: "triangles" (eqs. 9.16-9.18), "grid" (eq. 9.9 where the volume carries ``quads`` and a
        node has a full 4-neighbour stencil, triangles elsewhere) or "auto" (grid if quads exist).
    substeps: diffusion sub-steps per step: an integer (1 = the paper's single explicit update; a
        dt above the diffusion bound is then a ConfigError) or "auto" (the fewest sub-steps that
        keep each below the bound, at most MAX_SUBSTEPS; each costs one sparse product).
    """

    name: ClassVar[str] = "diffusion"
    summary: ClassVar[str] = ("surface-only: contact load diffuses over the surface (omega per node and direction) "
                              "and dents it; Zhong et al. 2016, explicit")
    integrators: ClassVar[tuple[str, ...]] = ("symplectic",)
    capabilities: ClassVar[frozenset[str]] = frozenset({"forces", "unstructured_mesh", "surface_only", "static_solve"})
    material_fields: ClassVar[tuple[str, ...]] = ("young", "density", "damping", "nonlinear", "omega")
    node_field_names: ClassVar[tuple[str, ...]] = ("displacement", "stress", "concentration", "omega")
    #: parameters ``surgsim fit --test indent`` searches besides young (bounds), see bench/fit.py
    fit_shape_parameters: ClassVar[dict] = {"omega": (1e-4, 2.0)}
    #: options of the calibrated model on the accuracy chart (bench/accuracy.py), see INDENT_CALIBRATION
    accuracy_options: ClassVar[dict] = INDENT_CALIBRATION

    def __init__(self, volume: Volume, material: Material | str | Mapping[str, Any] = "liver", *,
                 omega=0.08, omega_long: float | None = None, omega_tensor=None, axis=(0.0, 0.0, 1.0),
                 load_time: float = 0.05, depth: float | None = None, length: float | None = None,
                 gradient_scale: float = 1.0, damping_ratio: float = 1.0, stiffness_factor: float = 1.0,
                 scheme: str = "auto", substeps: int | str = "auto", **base_kwargs):
        if not isinstance(volume, Volume):
            raise ConfigError(f"volume must be a surgsim_envs.geometry.Volume, got {type(volume).__name__}")
        surf = surface_view(volume)
        op.check_surface(surf.nodes, surf.surface, what=f"diffusion model on '{volume.name}'")
        used = np.unique(surf.surface)
        lo, hi = surf.nodes[used].min(axis=0), surf.nodes[used].max(axis=0)
        ext = hi - lo
        self.load_time = validate.positive(load_time, "diffusion model: load_time", unit="s", fix="try 0.05")
        self.depth = validate.positive(depth if depth is not None else 0.5 * float(ext.min() if ext.min() > 0 else ext.max()),
                                       "diffusion model: depth", unit="m",
                                       fix="give the tissue depth under the surface, e.g. 0.02")
        if isinstance(length, str) and length == "depth":
            length = self.depth
        self.length = validate.positive(length if length is not None else float(ext.max()), "diffusion model: length",
                                        unit="m", fix="give the body's size in m (or 'depth'), e.g. 0.1")
        self.stiffness_factor = validate.positive(
            stiffness_factor, "diffusion model: stiffness_factor",
            fix="the bulk modulus is stiffness_factor x young / depth; 1 = uncalibrated")
        if scheme not in SCHEMES:
            raise ConfigError(f"diffusion model: scheme={scheme!r}; choose one of {SCHEMES}")
        has_quads = getattr(surf, "quads", None) is not None
        if scheme == "grid" and not has_quads:
            raise ConfigError(f"diffusion model: scheme='grid' needs a volume with a structured quad grid "
                              f"(volume.quads, e.g. make_volume('rounded_cube')); '{volume.name}' has none; "
                              "use scheme='triangles'")
        self.scheme = "grid" if (scheme == "grid" or (scheme == "auto" and has_quads)) else "triangles"
        if not (substeps == "auto" or (isinstance(substeps, (int, np.integer)) and 1 <= substeps <= MAX_SUBSTEPS)):
            raise ConfigError(f"diffusion model: substeps must be 'auto' or an integer in 1..{MAX_SUBSTEPS}, "
                              f"got {substeps!r}")
        self.auto_substeps = substeps == "auto"
        self.substeps = 1 if self.auto_substeps else int(substeps)
        self.damping_ratio = validate.non_negative(damping_ratio, "diffusion model: damping_ratio", fix="1 = critical")
        self.gradient_scale = validate.non_negative(gradient_scale, "diffusion model: gradient_scale",
                                                    fix="1 = as derived (eqs. 9.19-9.21), 0 = off")
        n = surf.n_nodes
        self._areas = op.control_areas(surf.nodes, surf.surface)
        self._normals = op.vertex_normals(surf.nodes, surf.surface)
        self._omega_in = omega
        self._rel = self._relative_tensors(surf, omega, omega_long, omega_tensor, axis)
        super().__init__(surf, material, **base_kwargs)
        if not hasattr(self, "_fields0"):       # base class before contract v2
            self._fields0 = {k: v.copy() for k, v in self.fields.items()}
        if not hasattr(self, "integrated_external_forces"):
            self.integrated_external_forces = np.zeros_like(self.positions)
        self._active_nodes = used.astype(np.int64)
        self.concentration = np.zeros(n)
        self._c_bound: float | None = None   # largest |C| loaded so far (Pa), for the divergence check
        self._tmp = np.zeros(n)
        self._source = np.zeros(n)
        self._pairs, self._full = (op.grid_pairs(surf.quads, n) if self.scheme == "grid"
                                   else (None, None))
        self._grad = op.gradient_operator(surf.nodes, surf.surface, self._pairs, self._full)
        self._derive()
        self._update_free()

    # ---------------------------------------------------------------------------------------
    # Build
    def _relative_tensors(self, surf, omega, omega_long, omega_tensor, axis) -> np.ndarray:
        n = surf.n_nodes
        if omega_tensor is not None:
            t = np.asarray(omega_tensor, dtype=np.float64)
            if t.shape != (n, 3, 3) or not np.all(np.isfinite(t)):
                raise ConfigError(f"diffusion model: omega_tensor must be a finite ({n}, 3, 3) array, got shape {t.shape}")
            proj = np.eye(3)[None] - self._normals[:, :, None] * self._normals[:, None, :]
            tang = proj @ (0.5 * (t + t.transpose(0, 2, 1))) @ proj
            used = np.unique(surf.surface)
            scalar = 0.5 * np.trace(tang, axis1=1, axis2=2)
            eig = np.linalg.eigvalsh(tang[used])
            if np.any(eig[:, 1:] <= 0):        # the smallest eigenvalue is the normal direction (0)
                bad = used[np.flatnonzero(np.any(eig[:, 1:] <= 0, axis=1))[0]]
                raise ConfigError(f"diffusion model: omega_tensor at node {bad} is not positive definite in the "
                                  "tangent plane; every direction needs omega > 0")
            self._omega_in = np.where(scalar > 0, scalar, 1.0)
            return tang / self._omega_in[:, None, None]
        om = np.asarray(omega, dtype=np.float64)
        if om.ndim == 0:
            validate.positive(om.item(), "diffusion model: omega",
                              fix="the paper uses 0.08-0.24; very low values give local deformation")
        elif om.shape != (n,) or not np.all(np.isfinite(om)) or np.any(om <= 0):
            raise ConfigError(f"diffusion model: omega must be a number > 0 or ({n},) array of numbers > 0 "
                              f"(one per node), got shape {om.shape}"
                              + (f", min {float(np.min(om)):.3g}" if om.size else ""))
        if omega_long is None:
            return op.relative_tensors(self._normals)
        if om.ndim != 0:
            raise ConfigError("diffusion model: omega_long needs a scalar omega (the latitudinal value); for "
                              "per-node anisotropy give omega_tensor")
        w_long = validate.positive(omega_long, "diffusion model: omega_long", fix="e.g. 0.24 with omega=0.08 (Fig. 9.3)")
        lat, lon, s = op.lat_long_frames(self._normals, axis)
        return op.relative_tensors(self._normals, lat, lon, s, 1.0, w_long / float(om))

    def _build_fields(self) -> dict[str, np.ndarray]:
        out = super()._build_fields()
        out["omega"] = np.broadcast_to(np.asarray(self._omega_in, dtype=np.float64), (self.volume.n_nodes,)).copy()
        return out

    def _lumped_masses(self) -> np.ndarray:
        """m_i = rho_i S_i h (kg): the control area times the depth; zero off the surface."""
        return self.fields["density"] * self._areas * self.depth

    def _derive(self) -> None:
        """Operators and per-node coefficients from the current material fields."""
        f = self.fields
        omega = f["omega"]
        scale = self.length ** 2 / self.load_time
        nodes, tris = self.rest_positions, self.surface
        if self.scheme == "grid":
            r1, c1, v1 = op.triangle_rates(nodes, tris, omega, self._rel, scale, self._areas)
            tri_row = ~self._full[r1]
            r2, c2, v2 = op.grid_rates(nodes, self._pairs, self._full, omega, self._rel, scale)
            rows, cols, vals = (np.concatenate([r1[tri_row], r2]), np.concatenate([c1[tri_row], c2]),
                                np.concatenate([v1[tri_row], v2]))
        else:
            rows, cols, vals = op.triangle_rates(nodes, tris, omega, self._rel, scale, self._areas)
        self._rates = op.to_csr(self.n_nodes_total, rows, cols, vals)
        self._bound_cache = None
        self._kappa = self.stiffness_factor * f["young"] / self.depth
        self._beta = f["nonlinear"] / self.depth ** 2
        # damping (1/s): the material's mass-proportional part plus damping_ratio x critical of each
        # node on the bulk (2 zeta omega_n, omega_n^2 = E / (rho h^2)): the bulk below is viscous
        omega_n = np.sqrt(self.stiffness_factor * f["young"] / (f["density"] * self.depth ** 2))
        self._damping = f["damping"] + 2.0 * self.damping_ratio * omega_n
        # gradient force coefficient: gradient_scale * S_i h omega_i R_i (N per Pa/m)
        self._wgrad = np.ascontiguousarray(
            (self.gradient_scale * self._areas * self.depth * omega)[:, None, None] * self._rel)
        # the gradient force as one operator: F_i = -sum_k gf[k] C[idx[k]] with gf = Wg_i grad_val[k]
        ptr, idx, val = self._grad
        rows = np.repeat(np.arange(len(ptr) - 1), np.diff(ptr))
        self._gforce = (ptr, idx, np.ascontiguousarray(np.einsum("kij,kj->ki", self._wgrad[rows], val)))
        self._update_coef()

    def _update_coef(self) -> None:
        """The per-node coefficient table of the step kernel (diffusion_kernels.COEF_COLUMNS)."""
        coef = np.zeros((self.n_nodes_total, COEF_COLUMNS))
        coef[:, NX:NZ + 1] = self._normals
        coef[:, AREA] = self._areas
        coef[:, INV_MASS] = np.where(self.masses > 0, 1.0 / np.where(self.masses > 0, self.masses, 1.0), 0.0)
        coef[:, DAMPING] = self._damping
        coef[:, K_AREA] = self._areas * self._kappa
        coef[:, BETA] = self._beta
        self._coef = coef

    @property
    def n_nodes_total(self) -> int:
        return len(self.rest_positions)

    def _on_material_changed(self, name: str) -> None:
        if name == "omega" and np.any(self.fields["omega"][self._active_nodes] <= 0):
            raise ConfigError("omega must be > 0 at every surface node")
        if name in ("young", "damping", "nonlinear", "density") and np.any(self.fields[name] < (0 if name != "young" else 1e-300)):
            raise ConfigError(f"{name} must be {'> 0' if name == 'young' else '>= 0'} at every node")
        self._derive()

    def _on_fixed_changed(self) -> None:
        if hasattr(self, "_active_nodes"):
            self._update_free()

    def _update_free(self) -> None:
        self._free = self._active_nodes[~self.fixed[self._active_nodes]]

    # ---------------------------------------------------------------------------------------
    # Stepping
    def _advance(self, dt: float, forces: np.ndarray, stiffness: np.ndarray | None) -> None:
        if self.auto_substeps:
            one = self._diffusion_bound()
            self.substeps = max(1, min(MAX_SUBSTEPS, int(math.ceil(dt / one))))
        crit = self.diffusion_critical_dt()
        if dt > crit:
            raise ConfigError(
                f"diffusion model: dt={dt:.3g} s is above the explicit diffusion stability bound {crit:.3g} s "
                f"({self.substeps} substep(s), load_time {self.load_time:g} s, max omega "
                f"{float(self.fields['omega'].max()):.3g}); lower dt, raise substeps to "
                f"{int(math.ceil(self.substeps * dt / crit))} or more, or raise load_time")
        forces = np.ascontiguousarray(forces, dtype=np.float64)
        if self._c_bound is None:             # first step after a build/reset/manual change: initial state
            self._c_bound = float(np.abs(self.concentration).max())
        bound = diffusion_step(self.positions, self.velocities, self.rest_positions, self.concentration, self._tmp,
                               self._source, forces, self._coef, self._normals, self._areas, *self._rates,
                               *self._gforce, self._active_nodes, self._free, self.gravity, 1.0 / self.load_time, dt,
                               self.substeps, self._c_bound)
        np.copyto(self.integrated_external_forces, forces)   # the caller may reuse its buffer
        if bound < 0:
            raise TissueUnstableError(self.name, dt, self.critical_dt(),
                                      f"the concentration diverged (max |C| {float(np.abs(self.concentration).max()):.3g} Pa "
                                      f"against at most {self._c_bound:.3g} Pa loaded) at t={self.time:.4g} s")
        self._c_bound = bound

    def _reset_state(self) -> None:
        self.concentration[:] = 0.0
        self._c_bound = None
        self.integrated_external_forces = np.zeros_like(self.positions)

    # ---------------------------------------------------------------------------------------
    # Stability
    def diffusion_critical_dt(self) -> float:
        """Explicit Euler bound of the concentration update (s): one sub-step's bound (Gershgorin,
        ``2 / max_i (|sum_j a_ij + 1/tau| + sum_j |a_ij|)``) times ``substeps`` (MAX_SUBSTEPS
        with substeps="auto")."""
        return (MAX_SUBSTEPS if self.auto_substeps else self.substeps) * self._diffusion_bound()

    def _diffusion_bound(self) -> float:
        if self._bound_cache is not None:
            return self._bound_cache
        ptr, idx, val = self._rates
        rows = np.repeat(np.arange(len(ptr) - 1), np.diff(ptr))
        s = np.zeros(len(ptr) - 1)
        a = np.zeros(len(ptr) - 1)
        np.add.at(s, rows, val)
        np.add.at(a, rows, np.abs(val))
        bound = np.abs(s + 1.0 / self.load_time) + a
        self._bound_cache = 2.0 / float(bound[self._active_nodes].max())
        return self._bound_cache

    def mechanical_critical_dt(self) -> float:
        """Symplectic Euler bound of eq. 9.22 at the current displacement (s): ``2 / omega_n`` with
        ``omega_n^2 = S k(u) / m``, k(u) the tangent foundation stiffness; and ``2 / damping``."""
        act = self._active_nodes
        u2 = np.sum((self.positions[act] - self.rest_positions[act]) ** 2, axis=1)
        k = self._areas[act] * self._kappa[act] * (1.0 + 3.0 * self._beta[act] * u2)
        w2 = float(np.max(k / self.masses[act]))
        c = float(np.max(self._damping[act]))
        out = 2.0 / math.sqrt(w2)
        return min(out, 2.0 / c) if c > 0 else out

    def critical_dt(self) -> float:
        """min(diffusion bound, mechanical bound) in s, no safety factor (contract v2)."""
        return min(self.diffusion_critical_dt(), self.mechanical_critical_dt())

    # ---------------------------------------------------------------------------------------
    # Energies, forces, fields
    def _displacements(self) -> np.ndarray:
        return self.positions - self.rest_positions

    def elastic_energy(self) -> float:
        """Energy stored in the bulk under the surface (J): sum S k (|u|^2/2 + beta |u|^4/4)."""
        u2 = np.sum(self._displacements() ** 2, axis=1)
        act = self._active_nodes
        e = self._areas * self._kappa * (0.5 * u2 + 0.25 * self._beta * u2 * u2)
        return float(e[act].sum())

    def internal_forces(self) -> np.ndarray:
        """(N,3) N: the forces of eq. 9.22 other than the external ones (diffused load, gradient,
        bulk, damping) at the current state."""
        n = self.n_nodes_total
        g = node_gradients(self, self.concentration)
        u = self._displacements()
        u2 = np.sum(u * u, axis=1)
        k = self._areas * self._kappa * (1.0 + self._beta * u2)
        out = (-(self._areas * self.concentration)[:, None] * self._normals - np.einsum("nij,nj->ni", self._wgrad, g)
               - k[:, None] * u - (self._damping * self.masses)[:, None] * self.velocities)
        mask = np.zeros(n, dtype=bool)
        mask[self._active_nodes] = True
        out[~mask] = 0.0
        return out

    def node_stress(self) -> np.ndarray:
        """(N,) Pa: the bulk stress under each node, ``E/h (1 + beta |u|^2) |u|``."""
        u = np.linalg.norm(self._displacements(), axis=1)
        return self._kappa * (1.0 + self._beta * u * u) * u

    def _node_field(self, name: str) -> np.ndarray:
        if name == "concentration":
            return self.concentration.copy()
        if name == "omega":
            return self.fields["omega"].copy()
        return super()._node_field(name)

    # ---------------------------------------------------------------------------------------
    # Equilibrium (tissue/diffusion_static.py)
    def steady_concentration(self, forces: np.ndarray | None = None) -> np.ndarray:
        """(N,) Pa, the concentration a constant ``forces`` (N,3) N settles to."""
        return steady_concentration(self, self._check_forces(forces))

    def static_solve(self, forces: np.ndarray | None = None, **kwargs) -> np.ndarray:
        """(N,3) m equilibrium positions under constant ``forces`` (contract ``static_solve``);
        the state is not changed."""
        return static_positions(self, self._check_forces(forces))

    def contact_compliance(self, nodes, axis: int = 2) -> np.ndarray:
        """(k,k) m/N: displacement of ``nodes`` along ``axis`` per unit force along ``axis`` at each
        of them, pressing into the surface (used by bench/material.indent)."""
        return contact_compliance(self, nodes, axis)

    def _check_forces(self, forces) -> np.ndarray:
        f = self.external_forces if forces is None else np.asarray(forces, dtype=np.float64)
        if f.shape != self.positions.shape or not np.all(np.isfinite(f)):
            raise ConfigError(f"forces must be a finite {self.positions.shape} array in N, got shape {f.shape}")
        return f

    def total_load(self) -> float:
        """sum_i S_i C_i (N): the load the concentration currently carries (in steady state under
        a constant compressive load, the load applied)."""
        return float(self._areas @ self.concentration)

    def describe(self) -> dict[str, Any]:
        out = super().describe()
        out.update(scheme=self.scheme, load_time=self.load_time, depth=self.depth, length=self.length,
                   substeps=self.substeps, omega=[float(self.fields["omega"].min()), float(self.fields["omega"].max())])
        return out

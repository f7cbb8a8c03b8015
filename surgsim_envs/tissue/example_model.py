"""A minimal tissue model: linear springs on the tet edges, symplectic Euler (docs/models.md).

It is the worked example of how a new model joins the contract (it is not registered by
default): declare ``capabilities`` and ``material_fields``, implement ``_advance``,
``critical_dt``, ``elastic_energy``, ``internal_forces``, ``node_stress`` and
``_on_material_changed``; then ``tissue.register("linear_springs", LinearSpringsModel)``.
Spring constant ``k_e = sum_t E_t V_t / L0^2`` over the tets around edge e (as mass_spring).
"""

from __future__ import annotations

import math

import numpy as np

from surgsim_envs.tissue.base import TissueModel, von_mises


class LinearSpringsModel(TissueModel):
    name = "linear_springs"
    summary = "example: linear springs on tet edges, symplectic Euler (docs/models.md)"
    integrators = ("symplectic",)
    capabilities = frozenset({"forces", "subsurface_stiffness"})
    material_fields = ("young", "density")

    def __init__(self, volume, material="liver", **kwargs):
        super().__init__(volume, material, **kwargs)
        edges = volume.edges().astype(np.int64)
        self.i, self.j = edges[:, 0], edges[:, 1]
        self.rest_lengths = np.linalg.norm(self.rest_positions[self.j] - self.rest_positions[self.i], axis=1)
        tets = volume.tets.astype(np.int64)
        pairs = np.sort(tets[:, [0, 0, 0, 1, 1, 2, 1, 2, 3, 2, 3, 3]].reshape(-1, 2, 6).transpose(0, 2, 1)
                        .reshape(-1, 2), axis=1)
        n = self.n_nodes
        self.edge_of = np.searchsorted(self.i * n + self.j, pairs[:, 0] * n + pairs[:, 1])
        self._on_material_changed("young")

    def _on_material_changed(self, name):
        w = np.repeat(self.fields["young"] * self.volume.tet_volumes(), 6)
        self.k = np.bincount(self.edge_of, weights=w, minlength=len(self.i)) / self.rest_lengths ** 2

    def _spring_tension(self, x):
        d = x[self.j] - x[self.i]
        length = np.linalg.norm(d, axis=1)
        return d / length[:, None], self.k * (length - self.rest_lengths), d

    def internal_forces(self):
        u, t, _ = self._spring_tension(self.positions)
        f = np.zeros_like(self.positions)
        np.add.at(f, self.i, t[:, None] * u)
        np.add.at(f, self.j, -t[:, None] * u)
        return f

    def _advance(self, dt, forces, stiffness):
        free = ~self.fixed[:, None]
        acc = (self.internal_forces() + forces) / self.masses[:, None] + self.gravity
        self.velocities += dt * acc * free
        self.positions += dt * self.velocities

    def critical_dt(self):
        rate = np.zeros(self.n_nodes)   # Gershgorin bound of max eig(M^-1 K): sum of 2 k / m per node
        np.add.at(rate, self.i, 2 * self.k)
        np.add.at(rate, self.j, 2 * self.k)
        return 2.0 / math.sqrt(float(np.max(rate / self.masses)))

    def elastic_energy(self):
        _, t, _ = self._spring_tension(self.positions)
        return float(np.sum(0.5 * t * t / self.k))

    def node_stress(self):
        u, t, d = self._spring_tension(self.positions)   # virial: sum_e t_e d_e u_e^T / (2 V_i)
        outer = (t[:, None, None] * d[:, :, None] * u[:, None, :])
        sig = np.zeros((self.n_nodes, 3, 3))
        np.add.at(sig, self.i, outer)
        np.add.at(sig, self.j, outer)
        vnode = np.zeros(self.n_nodes)
        np.add.at(vnode, self.volume.tets.reshape(-1), np.repeat(self.volume.tet_volumes() / 4, 4))
        return von_mises(sig / (2 * vnode)[:, None, None])

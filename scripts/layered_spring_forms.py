"""Spring forms tried for the layered abdominal wall against FEM (how close to FEM each form gets).

The comparison of ``surgsim_envs.bench.layers_accuracy`` (8 x 8 cm abdominal wall patch, bottom
bonded, rigid flat punch of radius 10 mm pressed 1 mm, linear models on the same lattice tets and
per-layer materials) for several stiffness forms of the layered lattice:

* ``paper``: eq. 2.8 springs, K = G_L A / L, one scalar Laplacian for x, y and z;
* ``navier``: springs at the shear modulus mu plus an averaged-nodal volume term (lambda + mu),
  whose continuum is Navier's equation inside every layer;
* ``calibrated``: the per-material identified network of ``tissue/spring_calibration.py`` (tet
  edges + cross-face springs + nodal volume term, fitted to every tet's elasticity);
* ``membrane``: the skin's in-plane springs as a bending-free membrane (in-plane components
  E / (1 - nu^2) A / L, the normal component 0), the rest as the paper;
* ``membrane+navier``: that skin with the ``navier`` form everywhere else.

Usage: ``PYTHONPATH=. python scripts/layered_spring_forms.py 0.004 [--fem]`` (prints N per form
and, with --fem, the FEM force and the ratios). Units: m, N.
"""

from __future__ import annotations

import sys

import numpy as np
import scipy.sparse as sp

from surgsim_envs.bench.layers_accuracy import RADIUS, PATCH, press_linear
from surgsim_envs.geometry.anatomy import abdominal_wall_volume
from surgsim_envs.tissue import fem_assembly as asm
from surgsim_envs.tissue.layered import LayeredModel


def per_component(nbr: np.ndarray, kcomp: np.ndarray) -> sp.csr_matrix:
    """3N x 3N (node-major) stiffness of NBB springs with a stiffness per displacement component (N,6,3)."""
    n = len(nbr)
    i_idx, d_idx = np.nonzero(nbr >= 0)
    j = nbr[i_idx, d_idx]
    rows, cols, vals = [], [], []
    for c in range(3):
        k = kcomp[i_idx, d_idx, c]
        rows += [3 * i_idx + c, 3 * np.arange(n) + c]
        cols += [3 * j + c, 3 * np.arange(n) + c]
        vals += [-k, kcomp[:, :, c].sum(axis=1)]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n, 3 * n))


def forms(spacing: float, with_fem: bool = False) -> dict:
    vol = abdominal_wall_volume(spacing, size=PATCH)
    bottom = vol.face_nodes(4)
    top = np.flatnonzero(vol.neighbours[:, 5] < 0)
    top_z = float(vol.nodes[top, 2].max())
    lay = LayeredModel(vol, fixed=bottom)
    n, nbr = vol.n_nodes, lay.nbr
    E, nu = lay.fields["young"], lay.fields["poisson"]
    mu, lam = E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))
    grads, vols, _ = asm.shape_gradients(vol.nodes, vol.tets)

    def volume_term(beta):
        return asm.anp_volumetric_matrix(vol.tets, grads, vols, asm.nodal_average(vol.tets, vols, beta, n), n)

    base = np.repeat(lay.kk[:, :, None], 3, axis=2)
    # springs at mu: each spring scaled by the mean (1 - nu) = mu / G_L of the tets around it
    i_idx, d_idx, rows, tets_per, counts = lay._spring_tets
    s = np.bincount(rows, weights=(1 - nu)[tets_per], minlength=len(i_idx))
    at_mu = base.copy()
    at_mu[i_idx, d_idx, :] *= np.where(counts > 0, s / np.maximum(counts, 1), 1.0)[:, None]
    skin = vol.spring_material == list(vol.material_names).index("skin")
    skin[:, 4:] = False                                    # the skin's in-plane (x, y) springs

    def membrane(k):
        out = k.copy()
        for d in range(4):
            sel = skin[:, d]
            out[sel, d, :2] = 2.0 * base[sel, d, :2]      # E / (1 - nu^2) = 2 G_L
            out[sel, d, 2] = 0.0                          # bending-free
        return out

    Ks = {"paper": per_component(nbr, base),
          "navier": per_component(nbr, at_mu) + volume_term(lam + mu),
          "membrane": per_component(nbr, membrane(base)),
          "membrane+navier": per_component(nbr, membrane(at_mu)) + volume_term(lam + mu)}
    from surgsim_envs.tissue.calibrated_mass_spring import CalibratedMassSpringModel

    regions = {k: vol.material_table[m] for k, m in enumerate(vol.layer_names)}
    cms = CalibratedMassSpringModel(vol, regions[0], region_materials=regions, fixed=bottom)
    Ks["calibrated"] = cms.stiffness_matrix()
    out = {"spacing": spacing, "nodes": n, "calibration_residual": float(cms.calibration.residual)}
    for name, K in Ks.items():
        out[name] = float(press_linear(K, vol.nodes, bottom, top, (0.0, 0.0), RADIUS, (0.001,), top_z)[0])
    if with_fem:
        from surgsim_envs.tissue.fem import TetFEMModel

        fem = TetFEMModel(vol, regions[0], region_materials=regions, fixed=bottom, corotational=False)
        out["fem"] = float(press_linear(fem.stiffness_matrix(), vol.nodes, bottom, top, (0.0, 0.0), RADIUS,
                                        (0.001,), top_z)[0])
    return out


if __name__ == "__main__":
    res = forms(float(sys.argv[1]) if len(sys.argv) > 1 else 0.004, "--fem" in sys.argv)
    ref = res.get("fem")
    for k, v in res.items():
        extra = f"  ({v / ref:.2f} x FEM)" if ref and isinstance(v, float) and k not in ("spacing", "fem",
                                                                                       "calibration_residual") else ""
        print(f"{k:>22}: {v:.4g}{extra}" if isinstance(v, float) else f"{k:>22}: {v}")

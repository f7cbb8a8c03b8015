"""What no model can explain in a plate-compression measurement: its symmetry-violating part.

A homogeneous isotropic cube between two bonded plates (bottom face at z = -L/2 fixed, top face
at z = +L/2 moved by (0, 0, -d)) has the symmetries of the square about z (mirrors x -> -x,
y -> -y, the swap x <-> y: 8 maps G) and the mid-plane reflection z -> -z, under which the
displacement field maps as

    u'(X) = G u(G^T X) + c_G,      c_G = (0, 0, -d) if G flips z else 0

(for any isotropic hyperelastic law, W(G F G^T) = W(F), so u' is a solution whenever u is; at
equilibrium without gravity it is the same solution). Averaging over the 16 maps is an affine
projection P whose linear part is orthogonal, so for every model prediction p with P p = p

    |p - m|^2 = |p - P m|^2 + |m - P m|^2

over the beads: ``m - P m`` (the measurement's asymmetric part: a lateral shift of the moving plate,
a bead grid off the cube centre, gravity, inhomogeneity, noise) is a floor no model with the stated
boundary conditions can go under, and ``p - P m`` is what the model itself gets wrong.

Positions and displacements in m; the cube centre is the origin.
"""

from __future__ import annotations

import itertools

import numpy as np

from surgsim_envs.errors import ConfigError


def symmetry_maps() -> list[np.ndarray]:
    """The 16 orthogonal 3x3 maps: the square's 8 (x/y mirrors and swap) times the z reflection."""
    maps = []
    for swap, sx, sy, sz in itertools.product((False, True), (1, -1), (1, -1), (1, -1)):
        lateral = np.array([[0.0, 1.0], [1.0, 0.0]]) if swap else np.eye(2)
        g = np.zeros((3, 3))
        g[:2, :2] = np.diag([sx, sy]) @ lateral
        g[2, 2] = sz
        maps.append(g)
    return maps


def partner_indices(rest: np.ndarray, tol: float = 4.5e-3) -> np.ndarray:
    """(16, B) index of the bead nearest to G^T X for each map G and bead X (rest positions, m).

    Raises ConfigError when the bead set is not symmetric to within ``tol`` (m; keep it below half
    the bead spacing) or a map does not permute the beads one to one."""
    rest = np.asarray(rest, dtype=np.float64)
    if rest.ndim != 2 or rest.shape[1] != 3 or len(rest) == 0 or not np.all(np.isfinite(rest)):
        raise ConfigError(f"rest positions must be a finite (B, 3) array in m, got shape {rest.shape}")
    out = np.empty((16, len(rest)), dtype=np.int64)
    for k, g in enumerate(symmetry_maps()):
        image = rest @ g                         # rows: (G^T X)^T = X^T G
        dist = np.linalg.norm(image[:, None, :] - rest[None, :, :], axis=2)
        out[k] = np.argmin(dist, axis=1)
        worst = float(dist[np.arange(len(rest)), out[k]].max())
        if worst > tol:
            raise ConfigError(f"bead set is not symmetric about the cube centre: a mirrored bead is {worst * 1e3:.2f} mm "
                              f"from the nearest bead (tol {tol * 1e3:.2f} mm); centre the positions or raise tol")
        if len(np.unique(out[k])) != len(rest):
            raise ConfigError("bead set is not symmetric about the cube centre: a mirror map sends two beads to one; "
                              "centre the positions or lower tol")
    return out


def symmetric_part(displacement: np.ndarray, rest: np.ndarray, travel: float, tol: float = 4.5e-3) -> np.ndarray:
    """P u: the displacement field (B, 3) m averaged over the 16 symmetries of the compressed cube.

    travel: downward travel d (m) of the top plate (> 0 compresses)."""
    u = np.asarray(displacement, dtype=np.float64)
    if u.shape != np.shape(rest) or not np.all(np.isfinite(u)):
        raise ConfigError(f"displacement must be a finite array shaped like rest {np.shape(rest)}, got {u.shape}")
    if not np.isfinite(travel):
        raise ConfigError(f"travel must be a finite length in m, got {travel!r}")
    idx = partner_indices(rest, tol)
    acc = np.zeros_like(u)
    for k, g in enumerate(symmetry_maps()):
        acc += u[idx[k]] @ g.T
        if g[2, 2] < 0:
            acc[:, 2] -= travel
    return acc / 16.0


def rms(a: np.ndarray) -> float:
    """Root mean square length (m) of the rows of ``a``."""
    return float(np.sqrt(np.mean(np.sum(np.asarray(a) ** 2, axis=1))))


def error_budget(predicted: np.ndarray, measured: np.ndarray, rest: np.ndarray, travel: float) -> dict[str, float]:
    """RMS errors (m) of a prediction against a measurement (bead positions (B, 3) m):

    total: |p - m|;  floor: |m - P m| (no symmetric model goes under it);
    model: |p - P m| (what the model gets wrong);  model_asymmetry: |p - P p| (should be ~0:
    mesh and bead-grid irregularity);  offset_z: mean over beads of (P m - p)_z, the uniform
    vertical shift, which every symmetric model shares (it is fixed by the plate travel)."""
    rest = np.asarray(rest, dtype=np.float64)
    up = np.asarray(predicted, dtype=np.float64) - rest
    um = np.asarray(measured, dtype=np.float64) - rest
    pm = symmetric_part(um, rest, travel)
    pp = symmetric_part(up, rest, travel)
    return {"total": rms(up - um), "floor": rms(um - pm), "model": rms(up - pm),
            "model_asymmetry": rms(up - pp), "offset_z": float(np.mean(pm[:, 2] - up[:, 2]))}

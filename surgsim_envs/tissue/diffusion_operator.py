"""Discrete operators of the chemical-diffusion surface model (Zhong et al. 2016, sections 9.4-9.5).

Everything here is built once from the rest surface (numpy); the numba step kernel
(:mod:`surgsim_envs.tissue.diffusion_kernels`) only applies them. All operators are stored as
compressed rows (``ptr``, ``idx``, values) over the node indices of the surface.

* **Control volumes (Fig. 9.1).** The control volume of node i joins the centroids of its
  triangles and the midpoints of its edges, so every triangle gives a third of its area to each of
  its nodes: ``S_i = sum_t A_t / 3`` (:func:`control_areas`).
* **Triangle scheme (eqs. 9.14-9.18).** The flux of ``omega grad C`` through the two segments
  ``M_ij G_ijk`` and ``G_ijk M_ik`` of triangle t (gradient eq. 9.15 constant on t) is
  ``-sum_b K_t[i, b] C_b`` with ``K_t[a, b] = A_t grad(phi_a) . W_t grad(phi_b)`` (the linear-element
  stiffness): the path from midpoint to midpoint turns the outward normal into a multiple of
  ``A_t grad(phi_i)`` whatever the centroid. With a scalar omega this is the paper's
  ``omega / 6 (lambda (C_j - C_i) + mu (C_k - C_i))`` term; ``tests/test_diffusion.py`` checks it
  against eqs. 9.17-9.18 written out. ``W_t`` is a tangent-plane tensor (anisotropy).
* **Grid scheme (eq. 9.9).** At a node with four grid neighbours (two opposite pairs a-i-b on the
  two grid lines) the second differences on a non-uniform grid:
  ``2 omega / (h- (h- + h+))`` towards a, ``2 omega / (h+ (h- + h+))`` towards b. Nodes without a
  full stencil (cube corners, borders) use the triangle scheme.
* **Gradient (eqs. 9.15, 9.20, 9.21).** Per node, the area-weighted mean of the triangle
  gradients of its ring (triangles) or half the signed sum of eq. 9.20 (grid); see
  :func:`gradient_operator`.

Rates are stored as ``a_ij`` in ``dC_i/dt = sum_j a_ij (C_j - C_i)`` (1/s).
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError


def check_surface(nodes: np.ndarray, tris: np.ndarray, what: str = "surface") -> None:
    """ConfigError unless ``tris`` is a consistently oriented 2-manifold (with or without border)
    of non-degenerate triangles."""
    tris = np.asarray(tris, dtype=np.int64)
    if tris.ndim != 2 or tris.shape[1] != 3 or len(tris) == 0:
        raise ConfigError(f"{what}: needs (F, 3) triangles, got shape {tris.shape}")
    if np.any(tris[:, 0] == tris[:, 1]) or np.any(tris[:, 1] == tris[:, 2]) or np.any(tris[:, 0] == tris[:, 2]):
        raise ConfigError(f"{what}: a triangle repeats a node; remove collapsed triangles")
    p = nodes[tris]
    area2 = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    scale = float(np.ptp(nodes[np.unique(tris)], axis=0).max()) ** 2
    bad = np.flatnonzero(area2 <= 1e-12 * scale)
    if len(bad):
        raise ConfigError(f"{what}: {len(bad)} degenerate (zero-area) triangle(s), first #{bad[0]}; clean the mesh")
    directed = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    key = np.sort(directed, axis=1)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    if np.any(counts > 2):
        e = key[np.flatnonzero(counts[inv] > 2)[0]]
        raise ConfigError(f"{what}: non-manifold edge ({e[0]}, {e[1]}) is shared by {int(counts.max())} triangles; "
                          "a surface model needs every edge in at most two triangles (split the mesh or "
                          "repair it, e.g. trimesh's process/repair)")
    _, dcounts = np.unique(directed, axis=0, return_counts=True)
    if np.any(dcounts > 1):
        raise ConfigError(f"{what}: triangles are not consistently oriented (an edge is traversed twice in the "
                          "same direction); fix the winding (trimesh.repair.fix_winding)")


def control_areas(nodes: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(N,) m^2 area of each node's control volume (Fig. 9.1): a third of each adjacent triangle."""
    p = nodes[tris]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    out = np.zeros(len(nodes))
    np.add.at(out, tris.reshape(-1), np.repeat(area / 3.0, 3))
    return out


def vertex_normals(nodes: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(N,3) unit outward normals (area-weighted triangle normals; zero for unused nodes)."""
    p = nodes[tris]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    out = np.zeros((len(nodes), 3))
    for k in range(3):
        np.add.at(out, tris[:, k], n)
    length = np.linalg.norm(out, axis=1)
    return out / np.where(length > 0, length, 1.0)[:, None]


def shape_gradients(nodes: np.ndarray, tris: np.ndarray):
    """``(grad (F,3,3), area (F,))``: gradient (1/m) of each linear shape function phi_a of each
    triangle (row a), lying in the triangle's plane, and the triangle area (m^2)."""
    p = nodes[tris]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    a2 = np.linalg.norm(n, axis=1)
    nh = n / a2[:, None]
    grad = np.empty((len(tris), 3, 3))
    for a in range(3):
        opp = p[:, (a + 2) % 3] - p[:, (a + 1) % 3]          # edge opposite vertex a
        grad[:, a] = np.cross(nh, opp) / a2[:, None]
    return grad, 0.5 * a2


def lat_long_frames(normals: np.ndarray, axis):
    """``(t_lat, t_long, s)``: per node the unit latitudinal direction (along parallels, around
    ``axis``), the longitudinal one (along meridians, in the tangent plane) and ``s`` in [0, 1],
    the sine of the angle between the normal and the axis (0 at the poles, where the parametric
    directions are undefined and the material is taken as isotropic)."""
    ax = np.asarray(axis, dtype=np.float64).reshape(3)
    norm = np.linalg.norm(ax)
    if not (np.isfinite(norm) and norm > 0):
        raise ConfigError(f"anisotropy axis must be a non-zero 3-vector, got {axis!r}")
    ax = ax / norm
    lat = np.cross(ax, normals)
    s = np.linalg.norm(lat, axis=1)
    lat = lat / np.where(s > 1e-12, s, 1.0)[:, None]
    lon = np.cross(normals, lat)
    return lat, lon, np.clip(s, 0.0, 1.0)


def relative_tensors(normals: np.ndarray, lat=None, lon=None, s=None, ratio_lat: float = 1.0,
                     ratio_long: float = 1.0) -> np.ndarray:
    """(N,3,3) dimensionless tangent-plane tensors R_i: ``ratio_lat t_lat t_lat^T + ratio_long
    t_long t_long^T`` blended towards the isotropic mean ``(ratio_lat + ratio_long)/2 (I - n n^T)``
    near the poles (weight ``s^2``). Without frames: the isotropic projector ``I - n n^T``."""
    proj = np.eye(3)[None] - normals[:, :, None] * normals[:, None, :]
    if lat is None:
        return proj
    aniso = ratio_lat * lat[:, :, None] * lat[:, None, :] + ratio_long * lon[:, :, None] * lon[:, None, :]
    w = (s * s)[:, None, None]
    return w * aniso + (1.0 - w) * 0.5 * (ratio_lat + ratio_long) * proj


def triangle_rates(nodes, tris, omega, rel, scale: float, areas):
    """``(rows (M,), cols (M,), a (M,))`` 1/s, the triangle scheme (eqs. 9.16-9.18) with a
    tensor coefficient: per triangle ``W_t = harmonic mean of omega over its nodes x mean of R``
    (a very low omega at any node blocks the flux through that triangle: local deformation),
    times ``scale`` (m^2/s, the diffusivity unit). Duplicates are summed by the caller."""
    grad, area = shape_gradients(nodes, tris)
    om = omega[tris]
    w_h = 3.0 / np.sum(1.0 / om, axis=1)
    W = rel[tris].mean(axis=1) * (w_h * scale)[:, None, None]
    # K_t[a, b] = A grad_a . W grad_b
    Wg = np.einsum("fij,fbj->fbi", W, grad)
    K = np.einsum("f,fai,fbi->fab", area, grad, Wg)
    rows, cols, vals = [], [], []
    for a in range(3):
        for b in range(3):
            if a == b:
                continue
            rows.append(tris[:, a])
            cols.append(tris[:, b])
            vals.append(-K[:, a, b] / areas[tris[:, a]])
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)


def grid_pairs(quads: np.ndarray, n_nodes: int):
    """Per node the two opposite neighbour pairs of a structured quad grid: ``pairs (N,2,2)``
    (node indices, -1 where the node has no full 4-neighbour stencil) and ``full (N,)`` bool."""
    quads = np.asarray(quads, dtype=np.int64)
    nbrs = [set() for _ in range(n_nodes)]
    shares = [set() for _ in range(n_nodes)]        # pairs of neighbours in one quad with the node
    for q in quads:
        for c in range(4):
            i, a, b = q[c], q[(c + 1) % 4], q[(c + 3) % 4]
            nbrs[i].update((a, b))
            shares[i].add((min(a, b), max(a, b)))
    pairs = -np.ones((n_nodes, 2, 2), dtype=np.int64)
    full = np.zeros(n_nodes, dtype=bool)
    for i in range(n_nodes):
        nb = sorted(nbrs[i])
        if len(nb) != 4 or len(shares[i]) != 4:
            continue
        first = nb[0]
        opp = [x for x in nb[1:] if (min(first, x), max(first, x)) not in shares[i]]
        if len(opp) != 1:
            continue
        rest = [x for x in nb if x not in (first, opp[0])]
        pairs[i] = [[first, opp[0]], rest]
        full[i] = True
    return pairs, full


def grid_rates(nodes, pairs, full, omega, rel, scale: float):
    """``(rows, cols, a)`` 1/s, eq. 9.9 at the nodes with a full stencil. The coefficient along
    each grid line is ``e^T W e`` (W at the edge: harmonic mean of the two nodes' omega times the
    mean of their R), so anisotropy and inhomogeneity enter as in the triangle scheme."""
    rows, cols, vals = [], [], []
    for i in np.flatnonzero(full):
        for a, b in pairs[i]:
            hm = np.linalg.norm(nodes[i] - nodes[a])
            hp = np.linalg.norm(nodes[b] - nodes[i])
            for j, h_own, sign in ((a, hm, -1.0), (b, hp, 1.0)):
                e = (nodes[j] - nodes[i]) / h_own
                om = 2.0 * omega[i] * omega[j] / (omega[i] + omega[j])
                d = om * float(e @ (0.5 * (rel[i] + rel[j])) @ e) * scale
                rows.append(i)
                cols.append(j)
                vals.append(2.0 * d / (h_own * (hm + hp)))
    return np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64), np.asarray(vals, dtype=np.float64)


def to_csr(n: int, rows, cols, vals, width: int = 1):
    """Sum duplicates and compress: ``(ptr (n+1,), idx (M,), val (M,) or (M, width))``."""
    rows = np.asarray(rows, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    vals = np.asarray(vals, dtype=np.float64).reshape(len(rows), width)
    key = rows * n + cols
    uniq, inv = np.unique(key, return_inverse=True)
    summed = np.zeros((len(uniq), width))
    np.add.at(summed, inv.reshape(-1), vals)
    r = uniq // n
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.add.at(ptr, r + 1, 1)
    ptr = np.cumsum(ptr)
    val = summed[:, 0].copy() if width == 1 else summed
    return ptr, (uniq % n).astype(np.int64), np.ascontiguousarray(val)


def gradient_operator(nodes, tris, pairs=None, full=None):
    """CSR ``(ptr, idx, val (M,3))`` with ``grad C_i = sum val[k] C[idx[k]]`` (1/m).

    Triangles (eqs. 9.15, 9.21): area-weighted mean over the ring of the constant triangle
    gradients. Grid (eq. 9.20, at full-stencil nodes if ``pairs`` is given): half the signed sum
    ``sum_j (C_j - C_i) / |P_i P_j| U_ij`` over the four neighbours, which is the central-difference
    gradient on a uniform grid (the absolute value printed in eq. 9.20 would cancel any linear
    profile, so the signed difference is used)."""
    n = len(nodes)
    grad, area = shape_gradients(nodes, tris)
    ring = np.zeros(n)
    np.add.at(ring, tris.reshape(-1), np.repeat(area, 3))
    rows, cols, vals = [], [], []
    use_tri = np.ones(n, dtype=bool) if full is None else ~full
    for a in range(3):
        for b in range(3):
            i = tris[:, a]
            keep = use_tri[i]
            rows.append(i[keep])
            cols.append(tris[keep, b])
            vals.append(area[keep, None] * grad[keep, b] / ring[i[keep], None])
    if full is not None:
        for i in np.flatnonzero(full):
            for j in pairs[i].reshape(-1):
                d = nodes[j] - nodes[i]
                h = np.linalg.norm(d)
                u = d / h
                rows += [np.array([i]), np.array([i])]
                cols += [np.array([j]), np.array([i])]
                vals += [0.5 * u[None] / h, -0.5 * u[None] / h]
    return to_csr(n, np.concatenate(rows), np.concatenate(cols), np.concatenate(vals), width=3)

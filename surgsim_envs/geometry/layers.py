"""Heterogeneous volumes from interface surfaces: tri-ray node snapping (Lin et al. 2008, section 2.3).

Input: a closed outer ``boundary`` surface, a base material (the region just inside the boundary)
and an ordered list of :class:`Interface` s, outer to inner. Each interface encloses the region of
its own material: a closed triangle mesh (the region inside it, e.g. muscle or bone in a thigh) or
a height sheet ``z = f(x, y)`` spanning the boundary (the region below it, e.g. the layers of the
abdominal wall). A point belongs to the material of the LAST region that contains it.

Algorithm (:func:`layered_volume`):

1. ``dd = max(d_min, d_threshold)`` (eq. 2.2): ``d_min`` is the smallest distance between two
   crossings of DIFFERENT surfaces along the Z rays, ``d_threshold`` the requested spacing.
2. Z rays: a lattice of spacing ``dd`` fills the boundary (cells whose centre is inside are kept,
   eq. 2.1: ``P[i, j, k+1] = P[i, j, k] + dd r``). Along every Z ray the node closest to each
   surface crossing snaps onto it when it lies within ``dd / 2`` (eq. 2.3); boundary crossings
   first, then interfaces, each node at most once.
3. X and Y rays move EXISTING nodes that are not yet snapped onto interface crossings (and the
   boundary), again within ``dd / 2``, without adding nodes (Fig. 2.6).
4. Snaps that would flatten a lattice tet below ``min_quality`` are halved, then undone (the NBB
   order of every node along every axis is kept).
5. Flags: every node gets its material; a node snapped onto an interface (also one that lay on the
   crossing already, a snap of length zero; not one whose snap was undone) gets that interface's
   own material (``interface_material``, e.g. fascia), forming the interface's spring layer.
   Springs join the six direct lattice neighbours (the NBB, Fig. 2.11); a homogeneous spring gets
   the material of its ends, a heterogeneous spring (one end on an interface) the material of
   the other end (the paper's rule); a spring joining two different materials with no interface
   point between them (an interface thinner than the lattice could resolve) gets the two in
   series.

The result is a :class:`LayeredVolume`: a :class:`Volume` (Kuhn tets of the kept cells, for masses,
rendering and FEM comparison) whose tet labels are layer indices, plus the lattice structure the
``layered`` tissue model needs (neighbour table, per-spring materials, node flags).
Bad input (open surfaces, interfaces crossing each other or the boundary, zero-thickness layers,
unknown material names) raises :class:`ConfigError` naming the surface. Lengths in m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.axis_rays import RAY_JITTER, axis_line_hits, points_inside_along_lines
from surgsim_envs.geometry.box import _KUHN
from surgsim_envs.geometry.lattice import MAX_LATTICE_NODES, as_trimesh, make_manifold
from surgsim_envs.geometry.snapping import guard_snaps
from surgsim_envs.geometry.volume import Volume, boundary_triangles, tet_signed_volumes

#: neighbour directions of the NBB (Fig. 2.11): -x, +x, -y, +y, -z, +z
DIRECTIONS = np.array([[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]], dtype=np.int64)
#: a layer thinner than this fraction of d_threshold counts as zero-thickness
MIN_THICKNESS_FRACTION = 1e-3
#: height sheets are sampled this many times finer than d_threshold for checks and meshing
SHEET_SAMPLES_PER_SPACING = 2


@dataclass(frozen=True)
class Interface:
    """One interface surface and the material region it encloses.

    name: the surface's name (used in every error message).
    material: material name of the region inside (closed mesh) or below (height sheet) it.
    surface: a closed triangle mesh (``trimesh.Trimesh`` or ``(vertices, faces)``, m), or a callable
        ``f(x, y) -> z`` (vectorised, m) describing a sheet across the whole boundary.
    interface_material: material of the points snapped onto this surface (its own spring layer,
        e.g. "fascia"); None = ``material``.
    """

    name: str
    material: str
    surface: Any
    interface_material: str | None = None

    @property
    def is_sheet(self) -> bool:
        return callable(self.surface)


@dataclass
class LayerSet:
    """A boundary, its base material and interfaces (outer to inner); see the module docstring.

    materials: optional {name: Material} for names that are not presets of
    :mod:`surgsim_envs.materials` (the anatomy modules give fascia, peritoneum, bone...).
    rigid: material names that do not deform (bone): their nodes are held fixed by the model.
    """

    boundary: Any
    base_material: str
    interfaces: Sequence[Interface] = ()
    name: str = "layered"
    materials: dict = field(default_factory=dict)
    rigid: Sequence[str] = ()


@dataclass
class LayeredVolume(Volume):
    """A :class:`Volume` of a structured lattice with material layers (built by :func:`layered_volume`).

    Extra fields (N nodes, T tets): ``lattice_index`` (N,3) int lattice coordinates;
    ``neighbours`` (N,6) int32 node index in each NBB direction (:data:`DIRECTIONS`, -1 none);
    ``spring_area`` (N,6) m^2 cross-section each spring represents; ``spring_material`` (N,6) int
    index into ``material_names`` (-1 none; -2 - m: two materials m and the other end's in series);
    ``node_material`` (N,) int material index; ``node_interface`` (N,) int interface index or -1;
    ``material_names`` list; ``material_table`` {name: Material}; ``layer_names`` region names per
    tet label (0 = base); ``rigid_materials`` names; ``spacing`` dd (m).
    """

    lattice_index: np.ndarray | None = None
    neighbours: np.ndarray | None = None
    spring_area: np.ndarray | None = None
    spring_material: np.ndarray | None = None
    node_material: np.ndarray | None = None
    node_interface: np.ndarray | None = None
    material_names: list = field(default_factory=list)
    material_table: dict = field(default_factory=dict)
    layer_names: list = field(default_factory=list)
    interface_names: list = field(default_factory=list)
    rigid_materials: tuple = ()
    spacing: float = 0.0

    def with_nodes(self, nodes: np.ndarray) -> "LayeredVolume":
        """Copy with new node positions (m), e.g. translated into a scene; the lattice is kept."""
        import dataclasses

        out = dataclasses.replace(self, nodes=np.asarray(nodes, dtype=np.float64).copy())
        return out

    def translated(self, offset) -> "LayeredVolume":
        return self.with_nodes(self.nodes + np.asarray(offset, dtype=float))

    def face_nodes(self, direction: int) -> np.ndarray:
        """(N,) bool: nodes with no neighbour in NBB ``direction`` (0..5 = -x, +x, -y, +y, -z, +z),
        i.e. on that face of the lattice (``face_nodes(4)``: the bottom, to bond; ``face_nodes(5)``: the top)."""
        if direction not in range(6):
            raise ConfigError(f"face_nodes: direction must be 0..5 (-x, +x, -y, +y, -z, +z), got {direction!r}")
        return self.neighbours[:, direction] < 0

    @property
    def rigid_nodes(self) -> np.ndarray:
        """Indices of nodes of a rigid material (bone)."""
        rigid = [self.material_names.index(m) for m in self.rigid_materials if m in self.material_names]
        return np.flatnonzero(np.isin(self.node_material, rigid))

    def node_material_name(self, i: int) -> str:
        return self.material_names[int(self.node_material[i])]


# ----------------------------------------------------------------------------------------------
# validation
def resolve_material(name: str, table: dict, what: str):
    """Material of ``name`` from ``table`` or the presets; ConfigError naming ``what`` otherwise."""
    from surgsim_envs.materials import PRESETS, Material, get_material

    if isinstance(name, Material):
        return name
    if not isinstance(name, str):
        raise ConfigError(f"{what}: material must be a name, got {name!r}")
    if name in table:
        return get_material(table[name])
    if name in PRESETS:
        return PRESETS[name]
    raise ConfigError(f"{what}: unknown material {name!r}; known: {sorted(set(table) | set(PRESETS))} "
                      "(add it to LayerSet.materials as a Material)")


def _sheet_heights(iface: Interface, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    try:
        z = np.asarray(iface.surface(x, y), dtype=np.float64)
        z = np.broadcast_to(z, np.broadcast(x, y).shape)
    except Exception as exc:  # noqa: BLE001 - any failure of user code is bad input
        raise ConfigError(f"interface '{iface.name}': its height function failed: {exc}") from None
    if not np.all(np.isfinite(z)):
        raise ConfigError(f"interface '{iface.name}': its height function returned NaN/inf")
    return z


def _boundary_span(boundary, u0: float, v0: float, step: float, nx: int, ny: int):
    """Lowest and highest boundary crossing (m) of each vertical sample ray (NaN where none)."""
    line, t, _ = axis_line_hits(boundary.triangles, 2, u0, v0, step, nx, ny)
    bot = np.full(nx * ny, np.nan)
    top = np.full(nx * ny, np.nan)
    if len(t):
        np.fmin.at(bot, line, t)
        np.fmax.at(top, line, t)
    return bot, top


def _check_interfaces(ls: LayerSet, boundary, h: float) -> list:
    """Validate the interfaces; return per interface a trimesh (sheets meshed over the boundary)."""
    lo, hi = boundary.bounds
    names = set()
    meshes = []
    step = h / SHEET_SAMPLES_PER_SPACING
    nx = max(int((hi[0] - lo[0]) / step), 1)
    ny = max(int((hi[1] - lo[1]) / step), 1)
    u0 = lo[0] + (0.5 + RAY_JITTER[0]) * step
    v0 = lo[1] + (0.5 + RAY_JITTER[1]) * step
    GX, GY = np.meshgrid(u0 + step * np.arange(nx), v0 + step * np.arange(ny), indexing="ij")
    px, py = GX.ravel(), GY.ravel()
    # boundary bottom/top along sample columns (sheets must stay strictly inside)
    b_bot, b_top = _boundary_span(boundary, u0, v0, step, nx, ny)
    inside_col = np.isfinite(b_bot) & (b_top > b_bot)
    tol = MIN_THICKNESS_FRACTION * h
    prev_sheet = None
    for k, iface in enumerate(ls.interfaces):
        if not isinstance(iface, Interface):
            raise ConfigError(f"interfaces[{k}] must be a surgsim_envs.geometry.layers.Interface, got "
                              f"{type(iface).__name__}")
        if not iface.name or iface.name in names:
            raise ConfigError(f"interface name {iface.name!r} is empty or used twice; give every surface a unique name")
        names.add(iface.name)
        resolve_material(iface.material, ls.materials, f"interface '{iface.name}'")
        if iface.interface_material is not None:
            resolve_material(iface.interface_material, ls.materials, f"interface '{iface.name}' interface_material")
        if iface.is_sheet:
            z = _sheet_heights(iface, px, py)
            sel = inside_col
            below = z[sel] - b_bot[sel]
            above = b_top[sel] - z[sel]
            if np.any(below <= tol) or np.any(above <= tol):
                bad = np.flatnonzero(sel)[np.argmin(np.minimum(below, above))]
                raise ConfigError(f"interface '{iface.name}' intersects the boundary at (x, y) = "
                                  f"({px[bad]:.4g}, {py[bad]:.4g}) m (z = {z[bad]:.4g} m, boundary from "
                                  f"{b_bot[bad]:.4g} to {b_top[bad]:.4g} m); keep the sheet strictly inside")
            if prev_sheet is not None:
                zp = _sheet_heights(prev_sheet, px, py)
                gap = (zp - z)[sel]
                if np.any(gap <= tol):
                    bad = np.flatnonzero(sel)[np.argmin(gap)]
                    what = "intersects" if gap.min() < -tol else "touches (zero-thickness layer)"
                    raise ConfigError(f"interface '{iface.name}' {what} interface '{prev_sheet.name}' at (x, y) = "
                                      f"({px[bad]:.4g}, {py[bad]:.4g}) m (gap {gap.min():.3g} m): the layer "
                                      f"'{prev_sheet.material}' between them needs a positive thickness")
            prev_sheet = iface
            meshes.append(_sheet_mesh(iface, lo, hi, step))
        else:
            mesh = as_trimesh(iface.surface, what=f"interface '{iface.name}'")
            if abs(mesh.volume) <= (tol ** 1) * max(mesh.area, 1e-300):
                raise ConfigError(f"interface '{iface.name}' encloses zero volume (zero-thickness layer); give "
                                  "its region a positive thickness")
            inside_b = boundary.contains(mesh.vertices)
            if not inside_b.all():
                raise ConfigError(f"interface '{iface.name}' intersects the boundary ({int((~inside_b).sum())} of its "
                                  f"{len(mesh.vertices)} vertices lie outside it); keep it strictly inside")
            meshes.append(mesh)
    # pairwise: closed meshes must nest or be disjoint; closed vs sheet on one side
    for a in range(len(ls.interfaces)):
        for b in range(a + 1, len(ls.interfaces)):
            A, B = ls.interfaces[a], ls.interfaces[b]
            if A.is_sheet and B.is_sheet:
                continue
            if B.is_sheet:
                A, B = B, A
                ma, mb = meshes[b], meshes[a]
            else:
                ma, mb = meshes[a], meshes[b]
            if A.is_sheet:
                v = mb.vertices
                side = v[:, 2] - _sheet_heights(A, v[:, 0], v[:, 1])
                if side.min() < 0 < side.max():
                    raise ConfigError(f"interface '{B.name}' intersects interface '{A.name}' (it lies on both sides "
                                      "of the sheet); move one of them")
                continue
            inb = mb.contains(ma.vertices)
            ina = ma.contains(mb.vertices)
            if (0 < inb.sum() < len(inb)) or (0 < ina.sum() < len(ina)):
                raise ConfigError(f"interface '{A.name}' intersects interface '{B.name}' (each has vertices on both "
                                  "sides of the other); nest them or keep them apart")
    return meshes


def _sheet_mesh(iface: Interface, lo: np.ndarray, hi: np.ndarray, step: float):
    """Triangulated height sheet over the boundary's xy box (slightly enlarged), for ray casting."""
    import trimesh

    pad = 2.0 * step
    xs = np.arange(lo[0] - pad, hi[0] + pad + step, step)
    ys = np.arange(lo[1] - pad, hi[1] + pad + step, step)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    Z = _sheet_heights(iface, X.ravel(), Y.ravel())
    v = np.stack([X.ravel(), Y.ravel(), Z], axis=1)
    nx, ny = len(xs), len(ys)
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return trimesh.Trimesh(v, faces, process=False)


# ----------------------------------------------------------------------------------------------
#: m, how far above a height sheet a point still counts as on it: far above the round-off of
#: lattice and sheet heights (~1e-17 m at the lattice's scale), far below any layer's thickness
ON_SHEET = 1e-12


def _region_of(ls: LayerSet, meshes: list, points: np.ndarray, on_sheet_below: bool = False) -> np.ndarray:
    """(P,) region index of points: 0 = base, k = interface k-1 (the last containing region wins).

    on_sheet_below: a point on a height sheet (to :data:`ON_SHEET`) lies below it, as the points
    snapped onto the sheet do (for lattice nodes); else only points strictly below it (cell centres)."""
    region = np.zeros(len(points), dtype=np.int64)
    tol = ON_SHEET if on_sheet_below else 0.0
    for k, (iface, mesh) in enumerate(zip(ls.interfaces, meshes)):
        if iface.is_sheet:
            heights = _sheet_heights(iface, points[:, 0], points[:, 1])
            inside = points[:, 2] <= heights + tol if on_sheet_below else points[:, 2] < heights
        else:
            inside = mesh.contains(points) if len(points) else np.zeros(0, bool)
        region[inside] = k + 1
    return region


def _d_min(surfaces: list, lo, hi, h: float) -> float:
    """Smallest distance between crossings of different surfaces along Z rays at spacing h (eq. 2.2)."""
    nx = max(int(math.ceil((hi[0] - lo[0]) / h)), 1)
    ny = max(int(math.ceil((hi[1] - lo[1]) / h)), 1)
    u0 = lo[0] + (0.5 + RAY_JITTER[0]) * h
    v0 = lo[1] + (0.5 + RAY_JITTER[1]) * h
    lines, ts, owners = [], [], []
    for s, mesh in enumerate(surfaces):
        line, t, _ = axis_line_hits(mesh.triangles, 2, u0, v0, h, nx, ny)
        lines.append(line)
        ts.append(t)
        owners.append(np.full(len(t), s))
    line, t, owner = np.concatenate(lines), np.concatenate(ts), np.concatenate(owners)
    order = np.lexsort((t, line))
    line, t, owner = line[order], t[order], owner[order]
    ok = (line[1:] == line[:-1]) & (owner[1:] != owner[:-1])
    if not ok.any():
        return 0.0
    return float(np.min(np.diff(t)[ok]))


def layered_volume(layer_set: LayerSet, spacing: float, *, min_quality: float = 0.1,
                   use_d_min: bool = False) -> LayeredVolume:
    """Build the heterogeneous lattice of ``layer_set`` (module docstring).

    spacing: d_threshold (m). use_d_min: True applies eq. 2.2 literally, ``dd = max(d_min, spacing)``
        (d_min, the closest approach of two different surfaces, then sets the spacing if larger);
        False (default) uses ``dd = spacing`` and relies on snapping each node at most once.
    min_quality: tet quality below which snaps are shrunk (see :func:`guard_snaps`).
    """
    ls = layer_set
    if not isinstance(ls, LayerSet):
        raise ConfigError(f"layered_volume needs a LayerSet, got {type(ls).__name__}")
    boundary = as_trimesh(ls.boundary, what=f"boundary of '{ls.name}'")
    resolve_material(ls.base_material, ls.materials, f"boundary of '{ls.name}' (base_material)")
    for m in ls.rigid:
        resolve_material(m, ls.materials, f"rigid material of '{ls.name}'")
    try:
        h = float(spacing)
    except (TypeError, ValueError):
        raise ConfigError(f"spacing must be a length in m, got {spacing!r}") from None
    lo, hi = boundary.bounds
    extent = hi - lo
    if not (math.isfinite(h) and h > 0):
        raise ConfigError(f"spacing must be > 0 m, got {spacing!r}; try {float(extent.min()) / 8:.3g}")
    if np.prod(np.ceil(extent / h) + 3) > MAX_LATTICE_NODES:
        raise ConfigError(f"spacing {h:g} m gives more than {MAX_LATTICE_NODES:,} lattice nodes for '{ls.name}'; "
                          "increase it")
    meshes = _check_interfaces(ls, boundary, h)
    if use_d_min:
        h = max(_d_min([boundary, *meshes], lo, hi, h), h)

    # lattice (eq. 2.1): cells whose centre is inside the boundary
    ncell = np.ceil(extent / h - 1e-9).astype(np.int64)
    ncell = np.maximum(ncell, 1)
    origin = (lo + hi) / 2.0 - ncell * h / 2.0
    counts = ncell + 1
    cx, cy, cz = (int(c) for c in ncell)
    line, t, _ = axis_line_hits(boundary.triangles, 2, origin[0] + (0.5 + RAY_JITTER[0]) * h,
                                origin[1] + (0.5 + RAY_JITTER[1]) * h, h, cx, cy)
    ci, cj, ck = (a.ravel() for a in np.meshgrid(np.arange(cx), np.arange(cy), np.arange(cz), indexing="ij"))
    inside = points_inside_along_lines(line, t, ci * cy + cj, origin[2] + (ck + 0.5) * h)
    occ = np.zeros((cx, cy, cz), dtype=bool)
    occ[ci[inside], cj[inside], ck[inside]] = True
    if occ.sum() < 8:
        raise ConfigError(f"spacing {h:g} m is too coarse for '{ls.name}' (extent {np.round(extent, 4).tolist()} m)")
    occ = make_manifold(occ)
    ci, cj, ck = np.nonzero(occ)
    flat_tets = np.concatenate([np.stack([np.ravel_multi_index((ci + a, cj + b, ck + c), counts)
                                          for (a, b, c) in path], axis=1) for path in _KUHN])
    used, tets = np.unique(flat_tets, return_inverse=True)
    tets = tets.reshape(-1, 4).astype(np.int32)
    index = np.stack(np.unravel_index(used, counts), axis=1).astype(np.int64)
    rest = origin + h * index
    neg = tet_signed_volumes(rest, tets) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    surf = boundary_triangles(tets)
    n = len(rest)
    lookup = np.full(int(counts.prod()), -1, dtype=np.int64)
    lookup[used] = np.arange(n)

    # snapping (eq. 2.3): Z rays first (boundary, then interfaces), then X and Y rays
    disp = np.zeros((n, 3))
    snapped = np.zeros(n, dtype=bool)
    on_iface = np.full(n, -1, dtype=np.int64)
    movable_b = np.zeros(n, dtype=bool)
    movable_b[np.unique(surf)] = True
    surfaces = [(boundary, -2)] + [(m, k) for k, m in enumerate(meshes)]
    for axes in ((2,), (0, 1)):
        for mesh, tag in surfaces:
            for axis in axes:
                _snap_axis(mesh.triangles, axis, origin, h, counts, index, lookup, disp, snapped, on_iface,
                           tag, movable_b if tag == -2 else ~movable_b)
    # a ray along the boundary's own face (the lattice's outermost line, shifted outward by the jitter)
    # misses it: keep those nodes inside the boundary's bounding box (else a box's edge rows stick out)
    moved = np.linalg.norm(disp, axis=1) > 0
    disp = np.clip(rest + disp, lo, hi) - rest
    disp, _ = guard_snaps(rest, disp, tets, min_quality=min_quality)
    # a node whose snap was undone is off its interface; a node that already lay on the crossing
    # (a zero-length snap) is on it, so its flag must not depend on the round-off of that length
    undone = moved & ~(np.linalg.norm(disp, axis=1) > 0)
    on_iface[undone] = -1
    nodes = rest + disp

    # flags: region of each node (at its lattice point, or just inside for boundary nodes)
    centre_pull = 1e-3 * h
    region = _region_of(ls, meshes, nodes + 0.0, on_sheet_below=True)
    outside = ~boundary.contains(nodes - centre_pull * np.sign(nodes - (lo + hi) / 2.0))
    if outside.any():  # boundary nodes: take the region of their nearest cell centre
        probe = _nearest_cell_centre(index[outside], occ, origin, h)
        region[outside] = _region_of(ls, meshes, probe)
    layer_names = [ls.base_material] + [i.material for i in ls.interfaces]
    region_material = [ls.base_material] + [i.material for i in ls.interfaces]
    iface_material = [i.interface_material or i.material for i in ls.interfaces]
    material_names = sorted(set(region_material) | set(iface_material))
    mat_index = {m: k for k, m in enumerate(material_names)}
    node_material = np.array([mat_index[region_material[r]] for r in region], dtype=np.int64)
    sel = on_iface >= 0
    node_material[sel] = [mat_index[iface_material[k]] for k in on_iface[sel]]
    node_region = region

    # tet labels: region of each kept cell's centre
    cell_centres = origin + h * (np.stack([ci, cj, ck], axis=1) + 0.5)
    cell_region = _region_of(ls, meshes, cell_centres)
    labels = np.tile(cell_region, len(_KUHN)).astype(np.int32)

    # NBB neighbours, spring areas (kept cells around each lattice edge / 4 x h^2) and materials
    neighbours = np.full((n, 6), -1, dtype=np.int32)
    area = np.zeros((n, 6))
    for d, off in enumerate(DIRECTIONS):
        nb = index + off
        ok = np.all((nb >= 0) & (nb < counts), axis=1)
        j = np.full(n, -1, dtype=np.int64)
        j[ok] = lookup[np.ravel_multi_index(nb[ok].T, counts)]
        neighbours[:, d] = j
        area[:, d] = _edge_cell_count(index, d, occ) * h * h / 4.0
    has = neighbours >= 0
    area[~has] = 0.0
    neighbours[has & (area <= 0)] = -1
    spring_material = _spring_materials(neighbours, node_material, on_iface)

    vol = LayeredVolume(nodes, tets, surf, labels, name=ls.name, node_labels=node_region.astype(np.int32),
                        lattice_index=index, neighbours=neighbours, spring_area=area,
                        spring_material=spring_material, node_material=node_material, node_interface=on_iface,
                        material_names=material_names,
                        material_table={m: resolve_material(m, ls.materials, f"material '{m}'") for m in material_names},
                        layer_names=layer_names, interface_names=[i.name for i in ls.interfaces],
                        rigid_materials=tuple(ls.rigid), spacing=h)
    vol.check()
    return vol


def _nearest_cell_centre(idx: np.ndarray, occ: np.ndarray, origin: np.ndarray, h: float) -> np.ndarray:
    """Centre (m) of a kept cell touching each lattice node ``idx`` (M,3)."""
    out = np.zeros((len(idx), 3))
    found = np.zeros(len(idx), dtype=bool)
    shape = np.array(occ.shape)
    for a in (-1, 0):
        for b in (-1, 0):
            for c in (-1, 0):
                cell = idx + np.array([a, b, c])
                ok = ~found & np.all((cell >= 0) & (cell < shape), axis=1)
                ok[ok] = occ[cell[ok, 0], cell[ok, 1], cell[ok, 2]]
                out[ok] = origin + h * (cell[ok] + 0.5)
                found |= ok
    return out


def _edge_cell_count(index: np.ndarray, d: int, occ: np.ndarray) -> np.ndarray:
    """Number of kept cells (0-4) around the lattice edge from each node in direction d."""
    axis = d // 2
    lo_cell = index.copy()
    if d % 2 == 0:
        lo_cell[:, axis] -= 1
    others = [a for a in range(3) if a != axis]
    shape = np.array(occ.shape)
    count = np.zeros(len(index), dtype=np.int64)
    for s0 in (-1, 0):
        for s1 in (-1, 0):
            cell = lo_cell.copy()
            cell[:, others[0]] += s0
            cell[:, others[1]] += s1
            ok = np.all((cell >= 0) & (cell < shape), axis=1)
            hit = np.zeros(len(index), dtype=bool)
            hit[ok] = occ[cell[ok, 0], cell[ok, 1], cell[ok, 2]]
            count += hit
    return count


def _spring_materials(neighbours: np.ndarray, node_material: np.ndarray, on_iface: np.ndarray) -> np.ndarray:
    """Per spring material index by the paper's rule (module docstring, step 5); -2 - m marks
    a series pair (the spring's own end m and the other end's material)."""
    n = len(neighbours)
    out = np.full((n, 6), -1, dtype=np.int64)
    for d in range(6):
        j = neighbours[:, d].astype(np.int64)
        ok = j >= 0
        i = np.flatnonzero(ok)
        jj = j[ok]
        mi, mj = node_material[i], node_material[jj]
        fi, fj = on_iface[i] >= 0, on_iface[jj] >= 0
        res = np.where(mi == mj, mi, -2 - mi)              # default: series of the two ends
        res = np.where((mi != mj) & fi & ~fj, mj, res)     # heterogeneous: the non-interface end
        res = np.where((mi != mj) & fj & ~fi, mi, res)
        out[i, d] = res
    return out


def _snap_axis(triangles, axis, origin, h, counts, index, lookup, disp, snapped, on_iface, tag, movable):
    """Snap the not-yet-snapped movable node nearest to each crossing along ``axis`` rays within h/2."""
    ua, va = (axis + 1) % 3, (axis + 2) % 3
    nu, nv = int(counts[ua]), int(counts[va])
    line, t, _ = axis_line_hits(triangles, axis, origin[ua] + RAY_JITTER[ua] * h, origin[va] + RAY_JITTER[va] * h,
                                h, nu, nv)
    if len(t) == 0:
        return
    k = np.rint((t - origin[axis]) / h).astype(np.int64)
    ok = (k >= 0) & (k < counts[axis])
    line, t, k = line[ok], t[ok], k[ok]
    idx = np.empty((len(k), 3), dtype=np.int64)
    idx[:, axis] = k
    idx[:, ua] = line // nv
    idx[:, va] = line % nv
    node = lookup[np.ravel_multi_index(idx.T, counts)]
    dd = t - (origin[axis] + k * h)
    ok = node >= 0
    node, dd = node[ok], dd[ok]
    ok = (np.abs(dd) <= 0.5 * h) & movable[node] & ~snapped[node]
    node, dd = node[ok], dd[ok]
    order = np.lexsort((np.abs(dd), node))
    node, dd = node[order], dd[order]
    first = np.ones(len(node), dtype=bool)
    first[1:] = node[1:] != node[:-1]
    node, dd = node[first], dd[first]
    disp[node, axis] = dd
    snapped[node] = True
    if tag >= 0:
        on_iface[node] = tag


def volume_summary(vol: LayeredVolume) -> dict:
    """Counts per material and interface (for docs and reports)."""
    out = {"nodes": int(vol.n_nodes), "tets": int(len(vol.tets)), "spacing_m": float(vol.spacing),
           "surface_triangles": int(len(vol.surface))}
    out["nodes_per_material"] = {m: int(np.count_nonzero(vol.node_material == k))
                                 for k, m in enumerate(vol.material_names)}
    out["interface_points"] = {nm: int(np.count_nonzero(vol.node_interface == k))
                               for k, nm in enumerate(vol.interface_names)}
    return out


def series_modulus(a: float, b: float) -> float:
    """Two equal-length springs of moduli a and b in series (Pa)."""
    return 2.0 * a * b / (a + b)


__all__ = ["Interface", "LayerSet", "LayeredVolume", "layered_volume", "resolve_material", "DIRECTIONS",
           "volume_summary", "series_modulus"]


def layered_from_grid(volume: Volume, materials: dict, name: str | None = None) -> LayeredVolume:
    """A :class:`LayeredVolume` from a plain tet ``volume`` whose nodes lie on a tensor-product grid
    (``box_volume``, graded benchmark slabs): NBB neighbours are the adjacent grid nodes, spring
    areas the dual-cell faces, node materials from ``volume.node_labels`` with ``materials``
    {label: Material}. ConfigError if the nodes are not on such a grid (snapped organ lattices)."""
    X = volume.nodes
    idx = np.zeros((len(X), 3), dtype=np.int64)
    coords = []
    for a in range(3):
        scale = max(float(np.ptp(X[:, a])), 1e-12)
        key = np.round(X[:, a] / scale, 9)
        u, inv = np.unique(key, return_inverse=True)
        idx[:, a] = inv
        coords.append(np.array([X[inv == k, a].mean() for k in range(len(u))]))
    counts = np.array([len(c) for c in coords])
    flat = np.ravel_multi_index(idx.T, counts)
    if len(np.unique(flat)) != len(X) or np.prod(counts) > 20 * len(X):
        raise ConfigError(f"volume '{volume.name}': the layered model needs nodes on a regular (tensor-product) "
                          "lattice; build it with surgsim_envs.geometry.layers.layered_volume or box_volume")
    lookup = np.full(int(np.prod(counts)), -1, dtype=np.int64)
    lookup[flat] = np.arange(len(X))
    n = len(X)
    neighbours = np.full((n, 6), -1, dtype=np.int32)
    for d, off in enumerate(DIRECTIONS):
        nb = idx + off
        ok = np.all((nb >= 0) & (nb < counts), axis=1)
        j = np.full(n, -1, dtype=np.int64)
        j[ok] = lookup[np.ravel_multi_index(nb[ok].T, counts)]
        neighbours[:, d] = j
    half = np.zeros((n, 6))  # half distance to the neighbour in each direction (0 if none)
    for d in range(6):
        j = neighbours[:, d]
        ok = j >= 0
        half[ok, d] = 0.5 * np.abs(X[j[ok], d // 2] - X[ok, d // 2])
    area = np.zeros((n, 6))
    for d in range(6):
        b, c = [a for a in range(3) if a != d // 2]
        area[:, d] = (half[:, 2 * b] + half[:, 2 * b + 1]) * (half[:, 2 * c] + half[:, 2 * c + 1])
    area[neighbours < 0] = 0.0
    labels = sorted(set(np.unique(volume.labels).tolist()))
    names = [f"label{k}" for k in labels]
    table = {f"label{k}": materials[k] for k in labels}
    node_material = np.searchsorted(labels, volume.node_labels).astype(np.int64)
    on_iface = np.full(n, -1, dtype=np.int64)
    out = LayeredVolume(X, volume.tets, volume.surface, volume.labels, name=name or volume.name,
                        node_labels=volume.node_labels, lattice_index=idx, neighbours=neighbours, spring_area=area,
                        spring_material=_spring_materials(neighbours, node_material, on_iface),
                        node_material=node_material, node_interface=on_iface, material_names=names,
                        material_table=table, layer_names=names, interface_names=[], rigid_materials=(),
                        spacing=float(np.median(2 * half[half > 0])))
    src = getattr(volume, "source_surface", None)
    if src is not None:
        out.source_surface = src
    return out

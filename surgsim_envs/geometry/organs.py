"""Procedural organs: smooth closed surfaces with real-organ sizes, and their tet volumes.

Shapes are built from a subdivided icosphere pushed out to a rounded superellipsoid and then
bent / tapered by smooth, orientation-preserving maps (shears and monotone scalings), so each
surface stays watertight, outward-oriented and free of self-intersections. All lengths in m.

========================  =====================================  =======================
name                      shape                                  default size (x, y, z)
========================  =====================================  =======================
``slab``                  box of tissue (as ``geometry.box_volume``)  10 x 10 x 2 cm
``slab_inclusion``        slab with a stiff sphere (label 1) inside    8 x 8 x 2 cm, r 6 mm
``spleen``                curved, kidney-bean shaped, flattened  11.5 x 7 x 3.8 cm
``liver_lobe``            wedge: thick dome tapering to a thin rim   15 x 10 x 6 cm
``rounded_cube``          round-cornered cube, surface grid only      10 x 10 x 10 cm, ~900 points
========================  =====================================  =======================

Organs rest on a bed: lowest point at z = 0, bounding box centred in x and y. The slabs keep the
convention of :func:`surgsim_envs.geometry.make_volume` ("slab"): centred at the origin.
"""

from __future__ import annotations

import inspect

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.box import box_volume
from surgsim_envs.geometry.inclusion import add_spherical_inclusion
from surgsim_envs.geometry.lattice import lattice_volume
from surgsim_envs.geometry.rounded_cube import rounded_cube_volume
from surgsim_envs.geometry.snapping import guard_snaps
from surgsim_envs.geometry.volume import Volume

#: default lattice spacing (m) per organ: about 800-1,500 nodes, fit for a real-time simulation
DEFAULT_SPACING = {"slab": 0.005, "slab_inclusion": 0.005, "spleen": 0.0058, "liver_lobe": 0.0085,
                   "rounded_cube": 0.1 / 12, "abdominal_wall": 0.004, "thigh": 0.005}

SLAB_SIZE = (0.1, 0.1, 0.02)
INCLUSION_SLAB_SIZE = (0.08, 0.08, 0.02)


def _check_dims(**dims) -> dict:
    out = {}
    for key, val in dims.items():
        try:
            v = float(val)
        except (TypeError, ValueError):
            raise ConfigError(f"{key} must be a length in m, got {val!r}") from None
        if not (np.isfinite(v) and 0.0 < v < 2.0):
            raise ConfigError(f"{key} must be a positive length below 2 m (SI units: metres), got {val!r}")
        out[key] = v
    return out


def _rounded_blob(subdivisions: int, exponent: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere mapped radially onto the superellipsoid |x|^n + |y|^n + |z|^n = 1."""
    import trimesh

    if not (isinstance(subdivisions, (int, np.integer)) and 1 <= subdivisions <= 6):
        raise ConfigError(f"subdivisions must be an integer in 1..6, got {subdivisions!r}; 4 gives 5,120 faces")
    sphere = trimesh.creation.icosphere(subdivisions=int(subdivisions))
    d = np.asarray(sphere.vertices, dtype=float)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = np.sum(np.abs(d) ** exponent, axis=1) ** (-1.0 / exponent)
    return d * r[:, None], np.asarray(sphere.faces)


def _finish(vertices: np.ndarray, faces: np.ndarray, size: tuple[float, float, float], name: str):
    """Scale to the bounding-box ``size`` (m), lowest point at z = 0, centred in x, y; check closed."""
    import trimesh

    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    v = (vertices - lo) * (np.asarray(size) / (hi - lo))
    v[:, :2] -= np.asarray(size[:2]) / 2.0
    mesh = trimesh.Trimesh(v, faces, process=True)
    if mesh.volume < 0:
        mesh.invert()
    mesh.metadata["name"] = name
    if not mesh.is_watertight or not mesh.is_winding_consistent:  # pragma: no cover - construction guarantees it
        raise ConfigError(f"procedural {name} surface is not closed; report this bug")
    return mesh


def spleen_surface(length: float = 0.115, width: float = 0.07, thickness: float = 0.038,
                   subdivisions: int = 4):
    """Spleen-like closed surface (``trimesh.Trimesh``, m): a flattened, bean-curved ellipsoid.

    length x width x thickness is the bounding box (defaults 11.5 x 7 x 3.8 cm, an adult spleen;
    enclosed volume about 145 cm^3). The long axis is x, the bean curves in the x-y plane (concave
    hilar side toward -y), the diaphragmatic face (+z) is convex and the organ thins toward its poles.
    """
    dims = _check_dims(length=length, width=width, thickness=thickness)
    p, faces = _rounded_blob(subdivisions, 2.3)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    z = z * (1.0 - 0.35 * x**2)              # thinner toward the poles
    y = y * (1.0 - 0.1 * x**2)               # narrower toward the poles
    y = y + 1.0 * x**2                       # bean curvature (shear: injective)
    z = z - 0.25 * x**2 - 0.1 * y**2          # convex diaphragmatic face, lies curved on its bed
    return _finish(np.stack([x, y, z], axis=1), faces, (dims["length"], dims["width"], dims["thickness"]), "spleen")


def liver_lobe_surface(length: float = 0.15, width: float = 0.10, thickness: float = 0.06,
                       subdivisions: int = 4):
    """Liver-lobe-like closed surface (``trimesh.Trimesh``, m): a domed wedge.

    Bounding box length x width x thickness (defaults 15 x 10 x 6 cm, a right hepatic lobe;
    enclosed volume about 500 cm^3). Thick and dome-shaped at -x, tapering to a thin rounded rim at
    +x; the inferior (visceral) face is flatter than the superior (diaphragmatic) dome.
    """
    dims = _check_dims(length=length, width=width, thickness=thickness)
    p, faces = _rounded_blob(subdivisions, 2.6)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    z = z * (0.8 + 0.2 * np.tanh(3.0 * z))   # flatter underside (monotone in z)
    z = z * (1.0 - 0.6 * (x + 1.0) / 2.0)    # wedge: thickness 1 at -x down to 0.4 at +x
    y = y * (1.0 - 0.15 * (x + 1.0) / 2.0)   # slightly narrower rim
    z = z - 0.12 * (x**2 + y**2)             # dome on top, concave visceral face
    return _finish(np.stack([x, y, z], axis=1), faces, (dims["length"], dims["width"], dims["thickness"]),
                   "liver_lobe")


def _slab(spacing: float, size=SLAB_SIZE, center=(0.0, 0.0, 0.0)) -> Volume:
    return box_volume(size, spacing, center=center, name="slab")


def _slab_inclusion(spacing: float, size=INCLUSION_SLAB_SIZE, center=(0.0, 0.0, 0.0), inclusion_centre=None,
                    inclusion_radius: float = 0.006, label: int = 1) -> Volume:
    """Slab (default 8 x 8 x 2 cm, centred at ``center``) with a hidden stiff sphere (label ``label``):
    default radius 6 mm, centred 2 mm below mid-depth, so its top is 6 mm under the upper face
    (invisible from above, found by palpation)."""
    vol = box_volume(size, spacing, center=center, name="slab_inclusion")
    if inclusion_centre is None:
        inclusion_centre = (center[0], center[1], center[2] - 0.002)
    out = add_spherical_inclusion(vol, inclusion_centre, inclusion_radius, label=label)
    out.name = "slab_inclusion"
    return out


def _onto_bed(vol: Volume, min_quality: float) -> Volume:
    """Lift nodes left below the bed (z < 0, outside the surface) onto z = 0, unless a tet would
    drop below ``min_quality`` (then the lift is shrunk as in snapping)."""
    below = vol.nodes[:, 2] < 0.0
    if not below.any():
        return vol
    disp = np.zeros_like(vol.nodes)
    disp[below, 2] = -vol.nodes[below, 2]
    disp, _ = guard_snaps(vol.nodes, disp, vol.tets, min_quality=min_quality)
    out = Volume(vol.nodes + disp, vol.tets, vol.surface, vol.labels, vol.name)
    if getattr(vol, "lattice_index", None) is not None:   # the lattice is unchanged (layered model's NBB)
        out.lattice_index = vol.lattice_index
    return out


def _organ(surface_fn, name):
    def build(spacing: float, snap: bool = True, max_snap: float = 0.5, min_quality: float = 0.15, **shape) -> Volume:
        # the surface rests on z = 0; snapped nodes follow it (no shift, which would pull them off it)
        surface = surface_fn(**shape)
        vol = lattice_volume(surface, spacing, snap=snap, name=name, max_snap=max_snap,
                             min_quality=min_quality)
        vol = _onto_bed(vol, min_quality) if snap else vol
        # the smooth surface it was meshed from, (vertices m, faces): rendered embedded in the tets
        # (geometry/embedding.py, scene/tissue_binding.py)
        vol.source_surface = (np.asarray(surface.vertices, dtype=np.float64), np.asarray(surface.faces, dtype=np.int64))
        return vol
    build.__signature__ = inspect.Signature(  # for the error message listing options
        [p for p in inspect.signature(build).parameters.values() if p.kind != p.VAR_KEYWORD]
        + list(inspect.signature(surface_fn).parameters.values()))
    return build


def _layered(kind: str):
    """Layered anatomy of Lin et al. 2008 (surgsim_envs.geometry.anatomy), imported on use."""
    def build(spacing: float, **shape) -> Volume:
        from surgsim_envs.geometry import anatomy

        return (anatomy.abdominal_wall_volume if kind == "abdominal_wall" else anatomy.thigh_volume)(spacing, **shape)
    names = {"abdominal_wall": ("size", "skin", "fat", "muscle", "peritoneum", "fat_variation"),
             "thigh": ("radius", "length", "skin", "fat", "bone_radius", "bone_offset", "sections")}[kind]
    build.__signature__ = inspect.Signature(  # option names for make_volume's check (no import of anatomy)
        [inspect.Parameter("spacing", inspect.Parameter.POSITIONAL_OR_KEYWORD)]
        + [inspect.Parameter(n, inspect.Parameter.KEYWORD_ONLY, default=None) for n in names])
    return build


_BUILDERS = {
    "slab": _slab,
    "abdominal_wall": _layered("abdominal_wall"),
    "thigh": _layered("thigh"),
    "slab_inclusion": _slab_inclusion,
    "spleen": _organ(spleen_surface, "spleen"),
    "liver_lobe": _organ(liver_lobe_surface, "liver_lobe"),
    "rounded_cube": rounded_cube_volume,   # surface only (no tets): for surface models (Zhong et al. 2016)
}

#: names :func:`make_volume` knows (``block`` is served by :func:`surgsim_envs.geometry.make_volume`)
ORGANS = tuple(_BUILDERS)


def make_volume(name: str, spacing: float | None = None, **kwargs) -> Volume:
    """Tet volume of a named procedural organ (see the module table); ``spacing`` in m (default
    :data:`DEFAULT_SPACING`, about 800-1,500 nodes). Extra keywords go to the shape (e.g.
    ``length=0.12``, ``inclusion_radius=0.008``) or the discretisation (``snap``, ``min_quality``)."""
    if name not in _BUILDERS:
        raise ConfigError(f"unknown organ/volume {name!r}; known: {['block', *ORGANS]}")
    builder = _BUILDERS[name]
    params = inspect.signature(builder).parameters
    unknown = sorted(set(kwargs) - set(params) - {"spacing"})
    if unknown:
        allowed = [p for p in params if p != "spacing"]
        raise ConfigError(f"make_volume({name!r}) got unknown option(s) {unknown}; allowed: {allowed}")
    h = DEFAULT_SPACING[name] if spacing is None else spacing
    if name in ("slab", "slab_inclusion"):
        try:
            ok = float(h) > 0 and np.isfinite(float(h))
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ConfigError(f"spacing must be > 0 m, got {h!r}; try 0.005 (5 mm)")
        size = np.asarray(kwargs.get("size", SLAB_SIZE if name == "slab" else INCLUSION_SLAB_SIZE), dtype=float)
        if size.shape == (3,) and np.all(size > 0) and float(h) > float(size.min()):
            raise ConfigError(f"spacing {h} m is larger than the thinnest side of the slab {size.tolist()} m "
                              f"(fewer than 2 cells across); use spacing <= {float(size.min()) / 2:.3g} m")
    return builder(h, **kwargs)

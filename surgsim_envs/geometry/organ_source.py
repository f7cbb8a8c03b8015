"""One entry point for "which organ": a registered name, a mesh file or a :class:`Volume`.

``organ_volume(organ, spacing=None, units="m", **options)`` returns the tet :class:`Volume`
every scene, task and scenario builds its tissue from:

* a registered name (``"slab"``, ``"block"``, ``"spleen"``, ... :func:`make_volume`);
* a closed surface file (STL/OBJ/PLY/OFF/glTF): checked (finite vertices, watertight, no
  overlapping shells, no self-intersection), set on its bed (lowest point at z = 0, centred in x
  and y), filled with snapped lattice tets (:func:`lattice_volume`, Lin et al. 2008), and given the
  surface as ``source_surface`` so the scene renders the smooth mesh embedded in the tets;
* a tet mesh file (legacy ``.vtk``, :func:`load_tet_mesh`), set on its bed;
* a :class:`Volume` (used as given, after :meth:`Volume.check`).

Bad input raises ConfigError saying what is wrong with the mesh (never printing whole arrays).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.loaders import SURFACE_SUFFIXES, TET_SUFFIXES, load_tet_mesh, unit_scale
from surgsim_envs.geometry.volume import Volume
from surgsim_envs.geometry.nested_shells import nested_shell
from surgsim_envs.geometry.self_intersection import meeting_pairs

#: options that go to the lattice filling of a surface file
LATTICE_OPTIONS = ("snap", "max_snap", "min_quality")
#: default spacing (m) for a mesh file: about 12 cells across the smallest extent, within 3-8 mm
DEFAULT_CELLS = 12


def registered_organs() -> list[str]:
    from surgsim_envs.geometry.organs import ORGANS

    return ["block", *ORGANS]


def describe_organ(organ) -> str:
    """A short description of an ``organ=`` value for messages (never a whole array)."""
    if isinstance(organ, Volume):
        return repr(organ)
    text = repr(organ)
    return text if len(text) <= 80 else text[:77] + "..."


def organ_volume(organ, spacing: float | None = None, units: str = "m", **options) -> Volume:
    """The tet Volume of ``organ`` (see the module docstring); ``spacing`` in m, ``units`` of a
    mesh file ("m", "cm", "mm"); other options go to the named builder or the lattice filling."""
    if isinstance(organ, Volume):
        if options:
            raise ConfigError(f"organ is a Volume ({organ!r}); volume options {sorted(options)} do not apply to it")
        organ.check()
        return organ
    if isinstance(organ, Path) or (isinstance(organ, str) and Path(organ).suffix.lower() in
                                   SURFACE_SUFFIXES + TET_SUFFIXES):
        path = Path(organ)
        suffix = path.suffix.lower()
        if suffix in TET_SUFFIXES:
            if options:
                raise ConfigError(f"tet mesh {str(path)!r}: volume options {sorted(options)} do not apply to a tet mesh")
            return on_bed(load_tet_mesh(path, units=units))
        if suffix in SURFACE_SUFFIXES:
            return surface_file_volume(path, spacing, units, **options)
        raise ConfigError(f"organ file {str(path)!r}: unsupported format {suffix!r}; use one of "
                          f"{list(SURFACE_SUFFIXES + TET_SUFFIXES)}")
    if isinstance(organ, str):
        if organ not in registered_organs():
            raise ConfigError(f"unknown organ {organ!r}; registered organs: {registered_organs()}, or give a mesh "
                              f"file ({', '.join(SURFACE_SUFFIXES + TET_SUFFIXES)}) or a surgsim_envs.geometry.Volume")
        from surgsim_envs.geometry.named_volume import make_volume

        return make_volume(organ, spacing=spacing, **options)
    raise ConfigError(f"organ must be a registered name {registered_organs()}, a mesh path "
                      f"({', '.join(SURFACE_SUFFIXES + TET_SUFFIXES)}) or a Volume, got {type(organ).__name__} "
                      f"{describe_organ(organ)}")


def on_bed(vol: Volume) -> Volume:
    """Copy with the lowest node at z = 0 and the bounding box centred in x and y."""
    lo, hi = vol.bounds()
    offset = np.array([-(lo[0] + hi[0]) / 2.0, -(lo[1] + hi[1]) / 2.0, -lo[2]])
    out = vol.translated(offset)
    src = getattr(vol, "source_surface", None)
    if src is not None:
        out.source_surface = (src[0] + offset, src[1])
    return out


def surface_file_volume(path, spacing: float | None = None, units: str = "m", **options) -> Volume:
    """Tet Volume filled into the closed surface in ``path`` (checked by :func:`check_surface_mesh`)."""
    import trimesh

    from surgsim_envs.geometry.lattice import lattice_volume
    from surgsim_envs.geometry.organs import _onto_bed

    unknown = sorted(set(options) - set(LATTICE_OPTIONS))
    if unknown:
        raise ConfigError(f"surface file {str(path)!r}: unknown volume option(s) {unknown}; allowed: "
                          f"{list(LATTICE_OPTIONS)} (plus spacing and units)")
    scale = unit_scale(units)
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"organ mesh file {str(p)!r} does not exist")
    try:
        raw = trimesh.load(str(p), force="mesh", process=False)
    except Exception as exc:  # noqa: BLE001 - any parser failure is bad input
        raise ConfigError(f"organ mesh {str(p)!r} could not be read by trimesh: {exc}") from None
    if not isinstance(raw, trimesh.Trimesh) or len(raw.faces) == 0:
        raise ConfigError(f"organ mesh {str(p)!r} holds no triangles")
    mesh = check_surface_mesh(raw, f"organ mesh {str(p)!r}")
    mesh.apply_scale(scale)
    lo, hi = mesh.bounds
    mesh.apply_translation([-(lo[0] + hi[0]) / 2.0, -(lo[1] + hi[1]) / 2.0, -lo[2]])
    extent = hi - lo
    if spacing is None:
        spacing = float(np.clip(float(extent.min()) / DEFAULT_CELLS, 0.003, 0.008))
    lat = {k: options[k] for k in LATTICE_OPTIONS if k in options}
    vol = lattice_volume(mesh, spacing, name=p.stem, **lat)
    vol = _onto_bed(vol, lat.get("min_quality", 0.15)) if lat.get("snap", True) else vol
    vol.source_surface = (np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64))
    return vol


def check_surface_mesh(mesh, what: str = "surface"):
    """Validate a triangle mesh as an organ boundary; returns a processed, outward-wound copy.

    Raises ConfigError if a vertex is NaN/inf, the surface is not closed, it consists of several
    shells that overlap (one inside or through another: the lattice fill would be a hollow or
    doubled lattice), or triangles of one shell cross or touch each other (other than neighbours
    sharing a vertex). Every check runs in about n log n, so large meshes are checked whole."""
    import trimesh

    v = np.asarray(mesh.vertices, dtype=np.float64)
    bad = np.flatnonzero(~np.all(np.isfinite(v), axis=1))
    if len(bad):
        raise ConfigError(f"{what}: {len(bad)} of {len(v)} vertices are NaN/inf (first: vertex {int(bad[0])}); "
                          "clean the mesh (remove those vertices) and save it again")
    m = trimesh.Trimesh(v, np.asarray(mesh.faces), process=True)
    if not m.is_watertight:
        raise ConfigError(f"{what} is not closed ({len(m.faces)} faces with open edges or holes): a closed surface "
                          "is needed to tell inside from outside. Repair it (trimesh.repair.fill_holes, "
                          "trimesh.repair.fix_winding, or MeshLab/Blender) and save a closed mesh")
    labels = trimesh.graph.connected_component_labels(m.face_adjacency, node_count=len(m.faces))
    n_shells = int(labels.max()) + 1
    within, across = meeting_pairs(m, labels)
    overlap = ConfigError(
        f"{what} has {n_shells} shells and two of them overlap or touch (one lies inside, cuts through or "
        "touches another): "
        "filling it would give a hollow or doubled lattice. Merge the shells into one closed surface (a boolean "
        "union) or keep one organ per file")
    if across or nested_shell(m, labels) is not None:
        raise overlap
    if within:
        raise ConfigError(f"{what} intersects or touches itself ({within} pairs of triangles that cross or touch "
                          "without sharing a vertex): inside and outside are ambiguous. Repair the mesh (e.g. "
                          "MeshLab 'Select self-intersecting faces', or a boolean union of its parts) and save it "
                          "again")
    if not m.is_winding_consistent:
        trimesh.repair.fix_winding(m)
    if m.volume < 0:
        m.invert()
    return m

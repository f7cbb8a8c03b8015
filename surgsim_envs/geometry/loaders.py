"""Loading organ meshes: closed surfaces (STL/OBJ/PLY via trimesh) and tet meshes (legacy VTK).

Both loaders convert to metres (``units`` = "m", "cm" or "mm"). Surfaces must be watertight
(a closed surface is needed to fill it with tets); tet meshes are re-oriented (negative tets get
two nodes swapped), unused points are dropped and degenerate tets are rejected.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.volume import Volume, boundary_triangles, tet_signed_volumes
from surgsim_envs.geometry.vtk_legacy import read_legacy_vtk, tets_from_cells

#: metres per unit
UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
SURFACE_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf")
TET_SUFFIXES = (".vtk",)


def unit_scale(units: str) -> float:
    """Metres per ``units`` ("m", "cm", "mm")."""
    if units not in UNITS:
        raise ConfigError(f"units must be one of {list(UNITS)}, got {units!r} (mesh files carry no units; "
                          "say what the coordinates are in)")
    return UNITS[units]


def _existing(path, suffixes, what: str) -> Path:
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{what} file {str(p)!r} does not exist")
    if p.suffix.lower() not in suffixes:
        raise ConfigError(f"{what} file {str(p)!r}: unsupported format {p.suffix!r}; use one of {list(suffixes)}")
    return p


def load_surface(path, units: str = "m"):
    """Closed triangle surface from STL/OBJ/PLY/OFF/glTF as a ``trimesh.Trimesh`` in metres.

    Raises ConfigError if the file is missing, unreadable or not watertight (with a repair hint).
    Inward-wound closed surfaces are inverted so normals point out.
    """
    import trimesh

    scale = unit_scale(units)
    p = _existing(path, SURFACE_SUFFIXES, "surface")
    try:
        mesh = trimesh.load(str(p), force="mesh", process=True)
    except Exception as exc:  # noqa: BLE001 - any parser failure is bad input
        raise ConfigError(f"surface file {str(p)!r} could not be read by trimesh: {exc}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ConfigError(f"surface file {str(p)!r} holds no triangles")
    if not mesh.is_watertight:
        raise ConfigError(
            f"surface {str(p)!r} is not watertight (holes or open edges in {len(mesh.faces)} faces); a closed "
            "surface is needed to tell inside from outside. Repair it, e.g. trimesh.repair.fill_holes(mesh) and "
            "trimesh.repair.fix_winding(mesh), or close it in MeshLab/Blender, and save a closed mesh"
        )
    if not mesh.is_winding_consistent:
        trimesh.repair.fix_winding(mesh)
    if mesh.volume < 0:
        mesh.invert()
    mesh.apply_scale(scale)
    mesh.metadata["name"] = p.stem
    return mesh


def load_tet_mesh(path, units: str = "m", name: str | None = None) -> Volume:
    """Tetrahedral :class:`Volume` (m) from a legacy VTK UNSTRUCTURED_GRID (ASCII or BINARY).

    Only tet cells (VTK type 10) are kept; points not used by a tet are dropped; negatively
    oriented tets are re-ordered. Raises ConfigError for unreadable files, meshes without tets and
    degenerate (zero-volume) tets, which no reordering can fix.
    """
    scale = unit_scale(units)
    p = _existing(path, TET_SUFFIXES, "tet mesh")
    points, (conn, offsets), types = read_legacy_vtk(p)
    tets = tets_from_cells(conn, offsets, types)
    label = name or p.stem
    if len(tets) == 0:
        kinds = sorted(set(np.unique(types).tolist()))
        raise ConfigError(f"tet mesh {str(p)!r} has no tetrahedra (VTK cell type 10); cell types present: {kinds}. "
                          "Fill the surface with lattice_volume(load_surface(...), spacing) instead")
    if tets.min() < 0 or tets.max() >= len(points):
        raise ConfigError(f"tet mesh {str(p)!r}: tet node indices out of range [0, {len(points)}); the file is corrupt")
    if not np.all(np.isfinite(points)):
        raise ConfigError(f"tet mesh {str(p)!r}: points contain NaN/inf; clean the mesh")
    used, compact = np.unique(tets, return_inverse=True)
    nodes = points[used] * scale
    tets = compact.reshape(-1, 4).astype(np.int32)
    vol = tet_signed_volumes(nodes, tets)
    edge_scale = np.ptp(nodes, axis=0).max()
    degenerate = np.flatnonzero(np.abs(vol) <= 1e-9 * edge_scale**3)
    if len(degenerate):
        i = degenerate[0]
        raise ConfigError(
            f"tet mesh {str(p)!r}: {len(degenerate)} degenerate tets with (near) zero volume (first: #{i}, nodes "
            f"{tets[i].tolist()}, volume {vol[i]:.3g} m^3); no reordering can fix them. Remesh the organ (e.g. "
            "lattice_volume(surface, spacing)) or remove those tets"
        )
    neg = vol < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    return Volume(nodes, tets, boundary_triangles(tets), name=label)

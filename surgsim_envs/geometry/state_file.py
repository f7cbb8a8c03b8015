"""Model-state files for validation: a deformed surface saved as ``.npz``.

Format ``surgsim-state-1`` (numpy ``.npz``): ``positions`` (N,3) float m (deformed node
positions), ``surface`` (F,3) int (triangles into ``positions``, outward normals), optional
``rest_positions`` (N,3) m, ``format`` = "surgsim-state-1" and free-form string ``meta`` (JSON).
:func:`load_surface_any` also reads triangle meshes (STL/OBJ/PLY/OFF) through trimesh; open
surfaces are allowed (a skin patch), units given by ``units``.
"""

from __future__ import annotations

import json
import os

import numpy as np

from surgsim_envs.errors import ConfigError

STATE_FORMAT = "surgsim-state-1"
MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf")
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def save_state(path, positions, surface, rest_positions=None, **meta) -> str:
    """Write a state file (``.npz`` added if missing); returns the path written."""
    path = str(path)
    if not path.endswith(".npz"):
        path += ".npz"
    pos = np.asarray(positions, dtype=np.float64)
    surf = np.asarray(surface, dtype=np.int64)
    if pos.ndim != 2 or pos.shape[1] != 3 or surf.ndim != 2 or surf.shape[1] != 3:
        raise ConfigError(f"positions must be (N,3) and surface (F,3); got {pos.shape}, {surf.shape}")
    arrays = {"positions": pos, "surface": surf, "format": np.array(STATE_FORMAT), "meta": np.array(json.dumps(meta))}
    if rest_positions is not None:
        arrays["rest_positions"] = np.asarray(rest_positions, dtype=np.float64)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    np.savez_compressed(path, **arrays)
    return path


def load_surface_any(path, units: str = "m"):
    """``(vertices (V,3) m, faces (F,3))`` from a state file (.npz) or a triangle mesh file."""
    path = str(path)
    if not os.path.isfile(path):
        raise ConfigError(f"surface file {path!r} does not exist; give a state file (.npz, format {STATE_FORMAT}) "
                          f"or a mesh ({', '.join(MESH_SUFFIXES)})")
    if units not in UNITS:
        raise ConfigError(f"units must be one of {list(UNITS)}, got {units!r}")
    ext = os.path.splitext(path)[1].lower()
    if ext == ".npz":
        with np.load(path, allow_pickle=False) as data:
            missing = {"positions", "surface"} - set(data.files)
            if missing:
                raise ConfigError(f"state file {path!r} lacks {sorted(missing)}; a {STATE_FORMAT} file holds "
                                  "'positions' (N,3) m and 'surface' (F,3)")
            pos, surf = np.array(data["positions"], dtype=np.float64), np.array(data["surface"])
        used = np.unique(surf)
        remap = np.full(len(pos), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        return pos[used] * UNITS[units], remap[surf]
    if ext not in MESH_SUFFIXES:
        raise ConfigError(f"unsupported surface file {path!r}: use .npz (state) or one of {MESH_SUFFIXES}")
    import trimesh

    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # noqa: BLE001 - any parser failure is bad input
        raise ConfigError(f"surface file {path!r} could not be read by trimesh: {exc}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ConfigError(f"surface file {path!r} holds no triangles")
    return np.asarray(mesh.vertices, dtype=np.float64) * UNITS[units], np.asarray(mesh.faces, dtype=np.int64)

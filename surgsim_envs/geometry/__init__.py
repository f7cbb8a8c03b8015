"""Geometry: volumes, procedural organs, mesh loading and volumetric discretisation (no MuJoCo).

- :class:`Volume`: tet mesh (m) + outward boundary + per-tet region labels.
- :func:`make_volume`: named volumes ("block", "slab", "slab_inclusion", "spleen", "liver_lobe").
- :func:`organ_volume`: a registered name, a mesh file (STL/OBJ/PLY/VTK) or a Volume -> checked Volume.
- :func:`spleen_surface`, :func:`liver_lobe_surface`: procedural closed organ surfaces (trimesh).
- :func:`load_surface` (STL/OBJ/PLY), :func:`load_tet_mesh` (legacy VTK): meshes from files.
- :func:`lattice_volume`: fill any closed surface with lattice tets, boundary snapped by tri-ray
  node snapping (Lin et al. 2008).
- :mod:`surgsim_envs.geometry.mapped_lattice`: the same fill on a graded tensor grid (fine where
  a load needs it).
- :func:`add_spherical_inclusion`: label the tets of a spherical inclusion.
- :func:`sphere_volume_fractions`: the share of each tet inside a sphere (an inclusion that keeps
  its volume on any lattice).
- :func:`embed_points`, :func:`interpolate`: tie a fine visual surface to the tets (rendering).
"""

from surgsim_envs.geometry.box import box_volume, lattice_tets
from surgsim_envs.geometry.embedding import Embedding, embed_points, embed_surface, interpolate
from surgsim_envs.geometry.inclusion import add_spherical_inclusion
from surgsim_envs.geometry.lattice import lattice_volume, surface_distance
from surgsim_envs.geometry.loaders import load_surface, load_tet_mesh
from surgsim_envs.geometry.named_volume import make_volume
from surgsim_envs.geometry.organ_source import check_surface_mesh, organ_volume
from surgsim_envs.geometry.organs import ORGANS, liver_lobe_surface, spleen_surface
from surgsim_envs.geometry.snapping import tet_quality
from surgsim_envs.geometry.sphere_fraction import mixed_young_factors, sphere_volume_fractions
from surgsim_envs.geometry.volume import Volume, boundary_triangles, tet_signed_volumes

__all__ = ["Volume", "box_volume", "lattice_tets", "boundary_triangles", "tet_signed_volumes", "make_volume",
           "lattice_volume", "surface_distance", "load_surface", "load_tet_mesh", "add_spherical_inclusion",
           "spleen_surface", "liver_lobe_surface", "tet_quality", "ORGANS",
           "Embedding", "embed_points", "embed_surface", "interpolate", "organ_volume", "check_surface_mesh",
           "sphere_volume_fractions", "mixed_young_factors"]

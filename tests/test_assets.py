"""The shipped assets folder (top-level assets/, installed as surgsim_envs/assets/) is found by
the package, and its kidney mesh loads as an organ."""

from pathlib import Path

import numpy as np
import pytest

import surgsim_envs
from surgsim_envs.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]


def test_assets_path_resolves_to_the_top_level_folder():
    kidney = surgsim_envs.assets_path("meshes", "kidney.stl")
    assert kidney.is_file()
    assert surgsim_envs.assets_path("textures", "colormap.png").is_file()
    # the package's assets/ is the repository's assets/ (what `pip install .` copies into the wheel)
    assert kidney.resolve() == (ROOT / "assets" / "meshes" / "kidney.stl").resolve()


def test_missing_asset_names_what_ships():
    with pytest.raises(ConfigError, match=r"no asset 'meshes/liver\.stl'.*kidney\.stl"):
        surgsim_envs.assets_path("meshes", "liver.stl")


def test_colormap_png_is_the_scene_colormap():
    cv2 = pytest.importorskip("cv2")
    from surgsim_envs.scene.field_colors import colormap_rgb

    png = cv2.imread(str(surgsim_envs.assets_path("textures", "colormap.png")))[..., ::-1]
    assert np.array_equal(png, colormap_rgb())


def test_shipped_kidney_loads_as_organ():
    """organ=<kidney.stl> fills the closed surface with tets: the tet volume matches the surface's
    enclosed volume and the bounding box is the kidney's 11 x 6 x 3.5 cm (to a lattice cell)."""
    import trimesh

    from surgsim_envs.geometry import organ_volume
    from surgsim_envs.scene.config import TissueConfig

    path = surgsim_envs.assets_path("meshes", "kidney.stl")
    surface = trimesh.load(str(path), force="mesh")
    assert surface.is_watertight
    spacing = 0.006
    vol = organ_volume(path, spacing=spacing)
    p, t = vol.nodes, vol.tets
    a, b, c, d = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]], p[t[:, 3]]
    tet_volume = np.abs(np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a))).sum() / 6.0
    assert tet_volume == pytest.approx(surface.volume, rel=0.12)
    extent = vol.bounds()[1] - vol.bounds()[0]
    assert np.allclose(extent, surface.extents, atol=spacing)
    assert extent[0] == pytest.approx(0.11, abs=0.01)
    TissueConfig(name="kidney", organ=path, model="mass_spring")   # accepted by the scene config

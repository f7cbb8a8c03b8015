"""organ= accepts a registered name, a mesh path (STL/OBJ/PLY/VTK) or a Volume; bad meshes say
what is wrong with them."""

import numpy as np
import pytest
import trimesh

from surgsim_envs import geometry, tissue
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry import organ_volume
from surgsim_envs.geometry.self_intersection import self_intersections

KIDNEY = dict(radius=0.03)   # an ellipsoidal "kidney", 6 x 4 x 3 cm


def _kidney_mesh():
    m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    m.apply_scale([0.03, 0.02, 0.015])
    m.apply_translation([0.2, -0.1, 0.5])   # far from the bed: organ_volume must place it
    return m


@pytest.fixture(scope="module")
def kidney_stl(tmp_path_factory):
    path = tmp_path_factory.mktemp("mesh") / "kidney.stl"
    _kidney_mesh().export(path)
    return path


def test_surface_file_is_filled_placed_on_its_bed_and_keeps_its_smooth_surface(kidney_stl):
    vol = organ_volume(kidney_stl, spacing=0.005)
    lo, hi = vol.bounds()
    assert lo[2] == pytest.approx(0.0, abs=0.05 * 0.005)   # resting on z = 0 (nodes snapped to the surface)
    assert np.allclose((lo[:2] + hi[:2]) / 2, 0.0, atol=0.003)          # centred in x, y
    assert hi - lo == pytest.approx([0.06, 0.04, 0.03], abs=0.004)      # the mesh's size (m)
    analytic = 4.0 / 3.0 * np.pi * 0.03 * 0.02 * 0.015
    assert vol.total_volume() == pytest.approx(analytic, rel=0.08)      # filled, not hollow
    verts, faces = vol.source_surface
    assert verts[:, 2].min() == pytest.approx(0.0, abs=1e-9) and len(faces) == 1280


def test_units_of_a_mesh_file(tmp_path):
    m = _kidney_mesh()
    m.apply_scale(1000.0)                  # the same organ written in mm
    path = tmp_path / "kidney_mm.obj"
    m.export(path)
    vol = organ_volume(path, spacing=0.005, units="mm")
    lo, hi = vol.bounds()
    assert hi - lo == pytest.approx([0.06, 0.04, 0.03], abs=0.004)


def test_every_model_builds_on_a_mesh_path(kidney_stl):
    """Every model that declares "unstructured_mesh" builds and steps on a user mesh (its bottom on
    a bed); one that does not (a grid-only model) refuses the mesh with a ConfigError."""
    for name in tissue.names():
        if "unstructured_mesh" not in tissue.get(name).capabilities:
            with pytest.raises(ConfigError):
                tissue.make(name, str(kidney_stl), "liver", spacing=0.006)
            continue
        model = tissue.make(name, str(kidney_stl), "liver", spacing=0.006)
        z = model.rest_positions[:, 2]
        model.set_fixed(z < z.min() + 0.003)
        model.step(1e-4)
        assert np.all(np.isfinite(model.positions))


def test_a_tet_mesh_and_a_volume_are_accepted(tmp_path):
    vol = geometry.box_volume((0.02, 0.02, 0.01), spacing=0.005)
    assert organ_volume(vol) is vol
    with pytest.raises(ConfigError, match="do not apply"):
        organ_volume(vol, size=(1, 1, 1))


def test_unknown_organ_lists_the_registered_ones():
    with pytest.raises(ConfigError, match=r"registered organs: \['block'.*'spleen'"):
        organ_volume("kidnee")
    with pytest.raises(ConfigError, match="mesh path"):
        organ_volume(42)


def test_volume_repr_is_short_in_errors():
    vol = geometry.box_volume((0.1, 0.1, 0.02), spacing=0.002)
    assert "array" not in repr(vol) and len(repr(vol)) < 200
    with pytest.raises(ConfigError) as info:
        tissue.make("no_such_model", vol)
    assert "array" not in str(info.value) and len(str(info.value)) < 500


def test_nan_vertices_are_named(tmp_path):
    path = tmp_path / "nan.obj"
    m = _kidney_mesh()
    lines = [f"v {x} {y} {z}" for x, y, z in m.vertices]
    lines[5] = "v nan 0.1 0.2"
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in m.faces]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError, match="NaN"):
        organ_volume(path)


def test_open_surface_is_refused(tmp_path):
    m = _kidney_mesh()
    m.update_faces(np.arange(len(m.faces)) != 3)   # punch a hole
    path = tmp_path / "open.stl"
    m.export(path)
    with pytest.raises(ConfigError, match="not closed"):
        organ_volume(path)


def test_two_overlapping_shells_are_refused(tmp_path):
    a = _kidney_mesh()
    b = a.copy()
    b.apply_translation([0.02, 0.0, 0.0])
    path = tmp_path / "two.stl"
    trimesh.util.concatenate([a, b]).export(path)
    with pytest.raises(ConfigError, match="overlap"):
        organ_volume(path)


def test_two_separate_shells_are_not_an_overlap():
    a = _kidney_mesh()
    b = a.copy()
    b.apply_translation([0.2, 0.0, 0.0])
    from surgsim_envs.geometry import check_surface_mesh
    check_surface_mesh(trimesh.util.concatenate([a, b]))


def test_self_intersecting_surface_is_refused(tmp_path):
    m = trimesh.creation.icosphere(subdivisions=2, radius=0.02)
    clean = self_intersections(m)
    v = m.vertices.copy()
    top = int(np.argmax(v[:, 2]))
    v[top] = [0.003, 0.002, -0.035]         # pull the north pole through the south cap
    bad = trimesh.Trimesh(v, m.faces, process=False)
    assert clean == 0 and self_intersections(bad) > 0
    path = tmp_path / "folded.ply"
    bad.export(path)
    with pytest.raises(ConfigError, match="intersects or touches itself"):
        organ_volume(path)


@pytest.mark.parametrize("kind", ["path", "volume"])
def test_scene_takes_a_mesh_path_or_a_volume(kidney_stl, kind):
    from surgsim_envs.scene import SceneConfig, TissueConfig, build_scene

    organ = str(kidney_stl) if kind == "path" else organ_volume(kidney_stl, spacing=0.006)
    cfg = SceneConfig(name="user_organ", tissues=[TissueConfig(name="kidney", organ=organ, spacing=0.006,
                                                               position=(0.0, 0.0, 0.02))],
                      tools=[], cameras=[])
    scene = build_scene(cfg)
    t = scene.tissues["kidney"]
    lo, hi = t.rest_positions.min(axis=0), t.rest_positions.max(axis=0)
    assert (lo + hi)[2] / 2 == pytest.approx(0.02, abs=1e-9)     # bounding-box centre at position
    assert t.fixed.any()                                           # anchored on its bed ("bottom")
    assert scene.bindings["kidney"].smooth                         # rendered with the mesh's own surface


def test_a_large_self_intersecting_surface_is_checked_whole():
    m = trimesh.creation.icosphere(subdivisions=5, radius=0.02)   # 20,480 faces
    assert len(m.faces) > 20_000 and self_intersections(m) == 0
    v = m.vertices.copy()
    v[int(np.argmax(v[:, 2]))] = [0.001, 0.001, -0.03]           # the north pole through the south cap
    bad = trimesh.Trimesh(v, m.faces, process=False)
    assert self_intersections(bad) > 0
    from surgsim_envs.geometry import check_surface_mesh
    with pytest.raises(ConfigError, match="intersects or touches itself"):
        check_surface_mesh(bad)


def test_a_surface_that_touches_itself_without_crossing_is_refused():
    m = trimesh.creation.icosphere(subdivisions=2, radius=0.02)
    v = m.vertices.copy()
    top = int(np.argmax(v[:, 2]))
    far = [i for i, f in enumerate(m.faces) if top not in f and v[f, 2].max() < -0.015][0]
    v[top] = v[m.faces[far]].mean(axis=0)        # the pole pulled onto a face of the south cap
    touched = trimesh.Trimesh(v, m.faces, process=False)
    assert self_intersections(touched) > 0
    # two shells that only touch (a cube standing on another's face) are refused as well
    from surgsim_envs.geometry import check_surface_mesh
    a = trimesh.creation.box(extents=(0.02, 0.02, 0.02))
    b = trimesh.creation.box(extents=(0.01, 0.01, 0.01)).apply_translation([0.0, 0.0, 0.015])
    with pytest.raises(ConfigError, match="overlap or touch"):
        check_surface_mesh(trimesh.util.concatenate([a, b]))


def test_many_separate_shells_pass_and_a_nested_one_is_found():
    from surgsim_envs.geometry import check_surface_mesh
    s = trimesh.creation.icosphere(subdivisions=1, radius=0.004)
    parts = [s.copy().apply_translation([0.01 * (i % 10), 0.01 * (i // 10 % 10), 0.01 * (i // 100)])
             for i in range(1000)]
    check_surface_mesh(trimesh.util.concatenate(parts))
    inner = trimesh.creation.icosphere(subdivisions=1, radius=0.001).apply_translation([0.05, 0.05, 0.05])
    with pytest.raises(ConfigError, match="overlap"):
        check_surface_mesh(trimesh.util.concatenate(parts + [inner]))

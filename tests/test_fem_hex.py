"""fem_hex: box hexahedra with incompatible modes. The element against beam theory and the patch
test, the model's condensed compliance against its own full solve, and LayeredPalpation-v0's wall
against the shipped converged reference (docs/task_accuracy.md)."""

import json

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry import box_volume
from surgsim_envs.geometry.box_cells import box_cells
from surgsim_envs.tissue import make
from surgsim_envs.tissue.hex_elements import box_stiffness, hex_stiffness


def _cantilever(cells: int, incompatible: bool, poisson: float = 0.0) -> float:
    """Tip deflection of a 10 x 1 x 1 cantilever, one cell through its depth, over PL^3 / 3EI."""
    vol = box_volume(size=(10.0, 1.0, 1.0), spacing=10.0 / cells, center=(5.0, 0.5, 0.5))
    cells_ = box_cells(vol)
    assert len(cells_.hexes) == cells                         # one cell through the width and depth
    young = np.full(cells, 1000.0)
    k = hex_stiffness(len(vol.nodes), cells_.hexes, cells_.sizes, young, np.full(cells, poisson)).toarray()
    if not incompatible:
        k = np.zeros_like(k)
        for h, size in zip(cells_.hexes, cells_.sizes):
            dofs = (3 * h[:, None] + np.arange(3)).ravel()
            k[np.ix_(dofs, dofs)] += box_stiffness(size, 1000.0, poisson, incompatible=False)
    free = ~np.repeat(vol.nodes[:, 0] < 1e-9, 3)
    tip = np.flatnonzero(vol.nodes[:, 0] > 10.0 - 1e-9)
    f = np.zeros(3 * len(vol.nodes))
    f[3 * tip + 2] = -1.0 / len(tip)
    u = np.zeros_like(f)
    u[free] = np.linalg.solve(k[np.ix_(free, free)], f[free])
    return -u[3 * tip + 2].mean() / (10.0 ** 3 / (3 * 1000.0 * (1.0 / 12.0)))


def test_one_cell_through_a_bending_beam_follows_beam_theory_where_trilinear_cells_lock():
    for cells in (5, 10):
        assert _cantilever(cells, True) == pytest.approx(1.0, abs=0.01)     # beam theory: PL^3 / 3EI
        assert _cantilever(cells, False) < 0.7                             # shear locking
    assert _cantilever(5, False) < 0.4


def test_patch_test_a_linear_field_is_reproduced_inside_uneven_cells():
    vol = box_volume(size=(0.03, 0.02, 0.025), spacing=0.005,
                     grading={"fine": 0.002, "around": (0.0, 0.0, 0.0), "half_widths": (0.004, 0.004, 0.004)})
    cells = box_cells(vol)
    assert len(np.unique(np.round(cells.sizes, 9), axis=0)) > 3           # cells of several shapes
    k = hex_stiffness(len(vol.nodes), cells.hexes, cells.sizes, np.full(len(cells.hexes), 3e3),
                      np.full(len(cells.hexes), 0.45)).tocsr()
    grad = np.array([[1e-3, 2e-3, -1e-3], [0.5e-3, -2e-3, 1e-3], [3e-3, 0.0, 1e-3]])
    exact = vol.nodes @ grad.T
    lo, hi = vol.nodes.min(0), vol.nodes.max(0)
    boundary = np.any((vol.nodes <= lo + 1e-9) | (vol.nodes >= hi - 1e-9), axis=1)
    free = ~np.repeat(boundary, 3)
    u = exact.reshape(-1).copy()
    from scipy.sparse.linalg import spsolve
    u[free] = spsolve(k[free][:, free].tocsc(), -(k[free][:, ~free] @ u[~free]))
    assert np.abs(u - exact.reshape(-1)).max() < 1e-9 * np.abs(exact).max()


def test_rigid_motions_cost_no_force_and_the_element_is_symmetric():
    ke = box_stiffness((0.004, 0.003, 0.001), 1e5, 0.49)
    assert np.allclose(ke, ke.T, atol=1e-12 * np.abs(ke).max())
    corners = np.array([[0, 0, 0], [4, 0, 0], [4, 3, 0], [0, 3, 0], [0, 0, 1], [4, 0, 1], [4, 3, 1], [0, 3, 1]]) * 1e-3
    rotation = np.cross(np.array([0.3, -0.2, 1.0]), corners).reshape(-1)       # infinitesimal rotation
    translation = np.tile([1.0, -2.0, 0.5], 8)
    for mode in (rotation, translation):
        assert np.abs(ke @ mode).max() < 1e-9 * np.abs(ke).max() * np.abs(mode).max()
    eig = np.linalg.eigvalsh(ke)
    assert np.sum(eig < 1e-9 * eig.max()) == 6 and eig.min() > -1e-9 * eig.max()


def test_condensed_compliance_equals_the_full_solve():
    vol = box_volume(size=(0.02, 0.02, 0.01), spacing=0.005)
    bottom = np.flatnonzero(vol.nodes[:, 2] < vol.nodes[:, 2].min() + 1e-9)
    model = make("fem_hex", vol, "liver", fixed=bottom)
    top = np.flatnonzero(vol.nodes[:, 2] > vol.nodes[:, 2].max() - 1e-9)[:4]
    w, u0 = model.compliance_block(top)
    f = np.array([[0.0, 0.01, -0.02], [0.003, 0.0, -0.01], [0.0, 0.0, -0.03], [-0.002, 0.0, 0.0]])
    condensed = model.apply_nodal_forces(top, f)
    full = np.zeros_like(model.positions)
    full[top] = f
    solved = model.static_solve(full)
    assert np.abs(condensed - solved).max() < 1e-12 + 1e-9 * np.abs(solved - vol.nodes).max()
    assert np.allclose((w @ f.reshape(-1)).reshape(-1, 3), (solved - vol.nodes)[top], rtol=1e-9, atol=1e-15)
    assert np.allclose(model.internal_forces()[top], -f, rtol=1e-7, atol=1e-12)   # equilibrium at the loaded nodes
    wz, _ = model.compliance_block(top, axis=2)
    assert np.allclose(wz, w[2::3, 2::3], rtol=1e-12, atol=0)


def test_a_volume_that_is_not_a_box_lattice_is_refused_by_name():
    from surgsim_envs.geometry import organ_volume

    with pytest.raises(ConfigError, match="not a box lattice.*fem_static"):
        make("fem_hex", organ_volume("spleen", spacing=0.011), "spleen")


def _default_presses(inclusion_xy=None):
    """The probe set's presses on LayeredPalpation-v0 as gym.make builds it (its default model and
    spacing), with the nodule at ``inclusion_xy`` (default: the probe set's)."""
    import dataclasses

    from surgsim_envs.bench.probe_sets import layered_palpation as lp
    from surgsim_envs.envs.layered_palpation import LayeredPalpationConfig

    cfg = LayeredPalpationConfig()
    assert (cfg.model, cfg.spacing) == ("fem_hex", 0.004)
    probes = lp.FULL if inclusion_xy is None else dataclasses.replace(
        lp.FULL, inclusions=(dataclasses.replace(lp.NODULE, position=tuple(inclusion_xy)),))
    return lp.measure(lp.TASK, cfg.model, cfg.spacing, probes)


def _check(row, ref, contrast_share=0.8):
    from surgsim_envs.bench.choose import task_tolerance

    from surgsim_envs.bench.probe_sets import layered_palpation as lp

    # every press, those between the nodes against the reference's press over the nodule
    errors = {k: f / ref[lp.reference_key(k)] - 1 for k, f in row["forces_N"].items()}
    assert len(errors) == 9
    assert max(abs(e) for e in errors.values()) <= task_tolerance("SurgSim/LayeredPalpation-v0"), errors
    over, mirror = (row["forces_N"][f"0/{s}/3.5mm"] for s in ("over", "mirror"))
    assert over / mirror > contrast_share * ref["0/over/3.5mm"] / ref["0/mirror/3.5mm"]   # the nodule's contrast kept
    assert row["path_difference"] < 1e-9 and row["max_tensile_N"] == 0.0


def test_layered_palpation_default_reads_the_reference_within_the_task_tolerance():
    """gym.make("SurgSim/LayeredPalpation-v0") (fem_hex at 3.33 mm): the probe set of the task-accuracy
    table (nodule at (2, 1) cm, presses over it, at its mirror site and over it moved to the middle of
    a cell, to 2.5, 3.5, 4.5 mm) against the shipped 0.71 mm reference; the task's declared tolerance
    is 20 %. (At 5 mm the presses between the nodes read up to 22 % low.)"""
    from surgsim_envs.bench.probe_sets import layered_palpation as lp
    from surgsim_envs.tissue.task_table import TASK_TABLE_PATH

    with open(TASK_TABLE_PATH) as fh:
        ref = json.load(fh)["references"][lp.TASK]["forces_N"]
    _check(_default_presses(), ref)


def test_layered_palpation_default_reads_a_held_out_nodule_within_the_task_tolerance():
    """The same presses with the nodule at (-1.5, 0.5) cm, a position the table was not built on,
    against the graded reference at 1 mm (scripts/layered_heldout_reference.py)."""
    from importlib import resources

    data = json.loads(resources.files("surgsim_envs.tissue").joinpath(
        "data/layered_palpation_heldout_reference.json").read_text())
    _check(_default_presses(data["position"]), data["forces_N"])


def _one_cell_stretch(split_axis: int, load_axis: int) -> float:
    """The stiffness (N/m) of a 2 x 3 x 4 mm cell stretched along ``load_axis`` (nu 0; its two faces
    across that axis moved apart evenly, on rollers; one corner pinned), its Young's modulus 1 kPa at
    the Gauss points on the low side of ``split_axis`` and 9 kPa on the high side."""
    from surgsim_envs.geometry.box_cells import CORNER_SIGNS
    from surgsim_envs.tissue.hex_elements import GAUSS_POINTS

    size = np.array([0.002, 0.003, 0.004])
    ke = box_stiffness(size, np.where(GAUSS_POINTS[:, split_axis] < 0, 1e3, 9e3), 0.0)
    low = CORNER_SIGNS[:, load_axis] < 0
    held = np.zeros((8, 3), dtype=bool)
    held[:, load_axis] = True                                  # both faces on rollers, moved apart
    held[np.flatnonzero(low)[0]] = True                        # one corner pinned
    u = np.zeros((8, 3))
    u[~low, load_axis] = 1e-5
    free = ~held.reshape(-1)
    u = u.reshape(-1)
    u[free] = np.linalg.solve(ke[np.ix_(free, free)], -ke[np.ix_(free, ~free)] @ u[~free])
    force = (ke @ u).reshape(8, 3)[~low, load_axis].sum()
    return force / 1e-5


def test_a_cell_split_between_its_gauss_points_is_the_series_or_the_parallel_of_its_halves():
    """A region given per Gauss point (an inclusion's boundary through a cell): a cell whose low half
    is 1 kPa and high half 9 kPa, loaded across the split, has the two halves in series (Reuss,
    the incompatible modes let the strain differ between them: 2 / (1/E1 + 1/E2) = 1.8 kPa) and,
    loaded along it, in parallel (Voigt, 5 kPa); one modulus per cell (its centre's) would give
    9 or 1 kPa either way."""
    area_over_length = {0: 0.003 * 0.004 / 0.002, 1: 0.002 * 0.004 / 0.003, 2: 0.002 * 0.003 / 0.004}
    for split in range(3):
        for load in range(3):
            modulus = _one_cell_stretch(split, load) / area_over_length[load]
            expected = 1.8e3 if split == load else 5e3
            assert modulus == pytest.approx(expected, rel=1e-9), (split, load)


def _small_wall():
    vol = box_volume(size=(0.02, 0.02, 0.01), spacing=0.005)
    bottom = np.flatnonzero(vol.nodes[:, 2] < vol.nodes[:, 2].min() + 1e-9)
    return vol, bottom


def test_material_given_per_gauss_point_equals_the_cell_rule_where_cells_are_uniform():
    vol, bottom = _small_wall()
    a = make("fem_hex", vol, "liver", fixed=bottom)
    b = make("fem_hex", vol, "liver", fixed=bottom)
    points = a.material_points()
    assert points.shape == (len(a.cells.hexes), 8, 3)
    assert np.allclose(points.mean(axis=1), a.element_centroids(), atol=1e-15)
    per_cell = 1.0 + np.arange(len(a.cells.hexes)) % 3
    a.scale_material_at_points("young", np.repeat(per_cell[:, None], 8, axis=1))
    b.scale_material("young", per_cell)
    assert np.allclose(a.fields["young"], b.fields["young"], rtol=1e-15)
    diff = (a.stiffness_matrix() - b.stiffness_matrix()).toarray()
    assert np.abs(diff).max() <= 1e-12 * abs(b.stiffness_matrix()).max()


def test_a_stiff_region_through_cells_stiffens_by_its_share_and_scale_material_undoes_it():
    vol, bottom = _small_wall()
    model = make("fem_hex", vol, "liver", fixed=bottom)
    top = np.flatnonzero(vol.nodes[:, 2] > vol.nodes[:, 2].max() - 1e-9)
    press = np.zeros((len(vol.nodes), 3))
    press[top, 2] = -0.01

    def sink(factors=None):
        if factors is not None:
            model.scale_material_at_points("young", factors)
        return -(model.static_solve(press)[top, 2] - vol.nodes[top, 2]).mean()

    soft = sink()
    x = model.material_points()[..., 0]
    half = sink(np.where(x > 0.0025, 10.0, 1.0))   # the region's edge through the middle of a column of cells
    assert 0 < np.sum(model.fields["young"] == 5.5 * model.material.young) < len(model.cells.hexes)
    cells = model.element_centroids()[:, 0]
    whole = sink(np.repeat(np.where(cells > 0.0, 10.0, 1.0)[:, None], 8, axis=1))   # those cells whole
    assert whole < half < soft
    assert model.fields["young"].min() == pytest.approx(model.material.young)
    model.scale_material("young", 1.0)
    assert sink() == pytest.approx(soft, rel=1e-12)


def test_material_per_gauss_point_refuses_bad_factors_by_name():
    vol, bottom = _small_wall()
    model = make("fem_hex", vol, "liver", fixed=bottom)
    n = len(model.cells.hexes)
    with pytest.raises(ConfigError, match=r"factors must be a \(%d, 8\) array" % n):
        model.scale_material_at_points("young", np.ones((n, 1)))
    with pytest.raises(ConfigError, match="finite and > 0"):
        model.scale_material_at_points("young", np.full((n, 8), np.nan))
    mixed = np.ones((n, 8))
    mixed[0, 0] = 2.0
    with pytest.raises(ConfigError, match="only 'young' may vary within a cell"):
        model.scale_material_at_points("poisson", mixed)
    assert np.all(model.fields["poisson"] == model.material.poisson)    # nothing changed


def test_a_model_with_one_point_per_element_takes_them_as_scale_material():
    vol, bottom = _small_wall()
    a = make("fem_static", vol, "liver", fixed=bottom)
    b = make("fem_static", vol, "liver", fixed=bottom)
    points = a.material_points()
    assert points.shape == (len(vol.tets), 1, 3)
    inside = np.linalg.norm(points - np.array([0.0, 0.0, 0.005]), axis=2) < 0.006
    a.scale_material_at_points("young", np.where(inside, 5.0, 1.0))
    b.scale_material("young", 5.0, mask=inside[:, 0])
    assert np.array_equal(a.fields["young"], b.fields["young"])
    with pytest.raises(ConfigError, match=r"factors must be a \(%d, 1\) array" % len(vol.tets)):
        a.scale_material_at_points("young", np.ones(len(vol.tets)))

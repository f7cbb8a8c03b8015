"""The layered model's ``stiffness="elastic"`` option: elasticity of the snapped cells in
the paper's constrained static solve (extreme lengths as rigid links, force accumulation)."""

from __future__ import annotations

import numpy as np
import pytest

from surgsim_envs.bench.layers_accuracy import press_linear, punch_contact
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.anatomy import abdominal_wall_volume
from surgsim_envs.tissue import make
from surgsim_envs.tissue.layered import LayeredModel


@pytest.fixture(scope="module")
def wall():
    return abdominal_wall_volume(0.005, size=(0.05, 0.05))


def _punch(model, vol, radius, depth):
    top = np.flatnonzero(vol.neighbours[:, 5] < 0)
    nodes, targets = punch_contact(vol.nodes, top, (0.0, 0.0), radius, depth)
    model.set_fixed(np.union1d(np.flatnonzero(model.fixed), nodes))
    model.set_fixed(nodes, targets)
    return nodes


def test_elastic_stiffness_option_is_checked(wall):
    with pytest.raises(ConfigError, match="stiffness must be one of"):
        LayeredModel(wall, stiffness="vector")


def test_elastic_block_near_incompressible_matches_fem_without_locking():
    """A homogeneous block at nu 0.49 under a flat punch (dd 5 mm): the cell mean-dilatation volume
    term gives the FEM (averaged nodal pressure) force on the same lattice within 10 % (measured
    0.94 x; 0.98 x at dd 2.5 mm), where plain linear tets with a per-tet volume term lock (measured
    1.70 x; 1.31 x at dd 2.5 mm)."""
    from surgsim_envs.geometry import box_volume
    from surgsim_envs.tissue import fem_assembly as asm

    vol = box_volume((0.05, 0.05, 0.025), 0.005, center=(0, 0, 0.0125))
    bottom = vol.nodes[:, 2] < 1e-9
    top = np.flatnonzero(vol.nodes[:, 2] > 0.025 - 1e-9)
    mat = {"young": 10e3, "poisson": 0.49}
    grads, vols, _ = asm.shape_gradients(vol.nodes, vol.tets)
    e, nu = np.full(len(vol.tets), 10e3), np.full(len(vol.tets), 0.49)
    stiff = {"elastic": make("layered", vol, mat, fixed=bottom, stiffness="elastic").stiffness_matrix(),
             "fem": make("fem", vol, mat, fixed=bottom, corotational=False).stiffness_matrix(),
             "p1": asm.assemble(vol.tets, asm.element_stiffness(asm.b_matrices(grads), asm.d_matrices(e, nu), vols),
                                vol.n_nodes)}
    f = {k: press_linear(K, vol.nodes, bottom, top, (0, 0), 0.01, [0.001], 0.025)[0] for k, K in stiff.items()}
    assert abs(f["elastic"] / f["fem"] - 1) < 0.10
    assert f["p1"] / f["fem"] > 1.25


def test_elastic_static_solve_is_the_linear_solution_and_contact_force_its_reaction(wall):
    """No extreme length reached (1 mm press): the constrained solve equals the linear system of
    ``stiffness_matrix`` with the punch nodes held, and ``contact_force`` is its reaction."""
    bottom = wall.face_nodes(4)
    model = LayeredModel(wall, fixed=bottom, stiffness="elastic")
    nodes = _punch(model, wall, 0.008, 0.001)
    model.static_solve()
    top = np.flatnonzero(wall.neighbours[:, 5] < 0)
    ref = press_linear(model.stiffness_matrix(), wall.nodes, bottom, top, (0, 0), 0.008, [0.001],
                       float(wall.nodes[top, 2].max()))[0]
    assert model.unconverged == 0 and not np.any(model.push > 0)
    np.testing.assert_allclose(model.contact_force(nodes)[2], ref, rtol=1e-8)
    free = ~model.fixed
    assert np.abs(model.internal_forces()[free]).max() < 1e-8 * ref


def test_elastic_deep_press_holds_extreme_lengths_with_rigid_links(wall):
    """A press to 60 % of the wall: springs reach their extreme length and become rigid links whose
    forces are passed on (eq. 2.5): no pair closer than its extreme length beyond 0.1 %, pushes only
    compressive and only on links at that length, every free node in equilibrium, no
    interpenetration; stepping again changes nothing (the state is the equilibrium)."""
    bottom = wall.face_nodes(4)
    model = LayeredModel(wall, fixed=bottom, stiffness="elastic")
    thickness = wall.nodes[:, 2].max()
    nodes = _punch(model, wall, 0.008, 0.6 * thickness)
    model.static_solve()
    assert model.unconverged == 0 and np.count_nonzero(model.push > 0) > 0 and np.all(model.push >= 0)
    for gap, rigid, lmin in model.link_gaps():
        assert gap.min() > -1e-3 * lmin.max()
        assert np.all(np.abs(gap[rigid]) < 1e-3 * lmin.max())
    f = model.contact_force(nodes)[2]
    free = ~model.fixed
    assert f > 0.5 and np.abs(model.internal_forces()[free]).max() < 1e-6 * f
    assert model.interpenetrations() == 0
    model.step(1e-3)
    np.testing.assert_allclose(model.contact_force(nodes)[2], f, rtol=1e-9)


def test_elastic_penalty_contact_and_scale_material(wall):
    """Implicit contact stiffness (the scene's penalty contact): the integrated force is
    g + kc (x_start - x) and balances the node's internal force; doubling E doubles the punch force."""
    bottom = wall.face_nodes(4)
    model = LayeredModel(wall, fixed=bottom, stiffness="elastic")
    top = np.flatnonzero(wall.neighbours[:, 5] < 0)
    centre = top[np.argmin(np.linalg.norm(wall.nodes[top, :2], axis=1))]
    f = np.zeros((model.n_nodes, 3))
    kc = np.zeros(model.n_nodes)
    f[centre, 2], kc[centre] = -0.05, 200.0
    x_start = model.positions[centre].copy()
    model.step(1e-3, f, kc)
    g = model.integrated_external_forces[centre]
    np.testing.assert_allclose(g, f[centre] + kc[centre] * (x_start - model.positions[centre]), rtol=1e-12)
    assert -0.05 < g[2] < 0
    np.testing.assert_allclose(g + model.internal_forces()[centre], 0.0, atol=1e-9)
    fresh = LayeredModel(wall, fixed=bottom, stiffness="elastic")
    nodes = _punch(fresh, wall, 0.008, 0.001)
    fresh.static_solve()
    f1 = fresh.contact_force(nodes)[2]
    fresh.scale_material("young", 2.0)
    fresh.static_solve()
    np.testing.assert_allclose(fresh.contact_force(nodes)[2], 2 * f1, rtol=1e-9)


@pytest.mark.slow
def test_elastic_wall_within_ten_percent_of_fem_on_an_untuned_probe():
    """The accuracy target on a patch and probe not used while developing the option (6 x 6 cm,
    7 mm punch; the option was developed on the 8 x 8 cm patch and 10 mm punch, where FEM has
    converged at dd 3 mm: 0.146 -> 0.145 N at 2 mm): the elastic layered wall within 10 % of FEM
    (ANP tets) on the same layered volume at dd 3 mm (measured 0.994; the paper's springs 1.19).
    Nothing is fitted."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "layered_elastic_accuracy.py"
    spec = importlib.util.spec_from_file_location("layered_elastic_accuracy", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    res = mod.forces(0.06, 0.007, 0.003, fem=True, paper=True)
    assert abs(res["elastic"] / res["fem"] - 1) < 0.10
    assert res["paper"] / res["fem"] > 1.10          # the paper's scalar springs miss the target here

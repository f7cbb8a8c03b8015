"""Lin et al. 2008: heterogeneous layered volumes (tri-ray snapping) and the layered model."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.anatomy import abdominal_wall_layers, abdominal_wall_volume, thigh_layers
from surgsim_envs.geometry.layers import Interface, LayerSet, layered_volume
from surgsim_envs.tissue import make
from surgsim_envs.tissue.layered import LayeredModel, laplace_modulus


@pytest.fixture(scope="module")
def wall():
    return abdominal_wall_volume(0.005, size=(0.05, 0.05))


def _box(z0=0.0, z1=0.03, s=0.05):
    b = trimesh.creation.box(extents=(s, s, z1 - z0))
    b.apply_translation((0, 0, (z0 + z1) / 2))
    return b


# ---------------------------------------------------------------------------------------------
# geometry
def test_interface_points_lie_on_their_sheets(wall):
    """Z-ray snapping (eq. 2.3) puts one node per column exactly on the fat/muscle sheet (10 mm
    from any other surface); every flagged node of every sheet lies on it; flags follow."""
    layers = abdominal_wall_layers(size=(0.05, 0.05))
    ij = wall.lattice_index[:, :2]
    interior = len(np.unique(ij[(ij > ij.min(axis=0)).all(axis=1) & (ij < ij.max(axis=0)).all(axis=1)], axis=0))
    assert np.count_nonzero(wall.node_interface == 1) >= interior  # side-boundary nodes snap to the boundary
    for k, iface in enumerate(layers.interfaces):
        on = wall.node_interface == k
        z = iface.surface(wall.nodes[on, 0], wall.nodes[on, 1])
        np.testing.assert_allclose(wall.nodes[on, 2], z, atol=1e-12)
    fascia = wall.material_names.index("fascia")
    assert np.all(wall.node_material[wall.node_interface == 1] == fascia)


def test_box_wall_stays_inside_its_boundary_and_bottom_face_is_flat():
    """Lattice rows along the box's own faces (rays that miss the boundary) are kept inside it: the
    whole bottom face (nodes without a -z neighbour) lies on z = 0, every node inside the box."""
    vol = abdominal_wall_volume(0.004, size=(0.08, 0.08))
    bottom = vol.face_nodes(4)
    assert bottom.sum() == 21 * 21
    np.testing.assert_allclose(vol.nodes[bottom, 2], 0.0, atol=1e-12)
    lo, hi = vol.nodes.min(axis=0), vol.nodes.max(axis=0)
    np.testing.assert_allclose(lo, [-0.04, -0.04, 0.0], atol=1e-12)
    np.testing.assert_allclose(hi, [0.04, 0.04, 0.029], atol=1e-12)
    with pytest.raises(ConfigError, match="direction"):
        vol.face_nodes(6)


def test_springs_follow_paper_rules(wall):
    """Homogeneous springs take their material; a spring from an interface point to another
    material takes that material (definition 2 and section 2.3)."""
    fascia, muscle = wall.material_names.index("fascia"), wall.material_names.index("muscle")
    on = np.flatnonzero(wall.node_interface == 1)
    down = wall.neighbours[on, 4]
    ok = down >= 0
    assert np.all(wall.node_material[down[ok]] == muscle)
    assert np.all(wall.spring_material[on[ok], 4] == muscle)
    right = wall.neighbours[on, 1]
    both = (right >= 0) & (wall.node_interface[np.maximum(right, 0)] == 1)
    assert both.sum() > 10
    assert np.all(wall.spring_material[on[both], 1] == fascia)   # along the interface: its own material


def test_x_rays_move_existing_points_onto_a_steep_interface():
    """A closed interface with steep sides gets nodes on it from X/Y rays, none added (Fig. 2.6)."""
    sphere = trimesh.creation.icosphere(3, radius=0.011)
    sphere.apply_translation((0, 0, 0.015))
    ls = LayerSet(_box(), "fat", [Interface("tumour", "muscle", sphere)])
    vol = layered_volume(ls, 0.004)
    plain = layered_volume(LayerSet(_box(), "fat", []), 0.004)
    assert vol.n_nodes == plain.n_nodes
    on = vol.node_interface == 0
    r = np.linalg.norm(vol.nodes[on] - (0, 0, 0.015), axis=1)
    assert on.sum() > 20
    np.testing.assert_allclose(r, 0.011, atol=0.011 * 0.02)  # on the faceted sphere
    moved = vol.nodes[on] - plain.nodes[on]
    assert np.count_nonzero(np.abs(moved[:, 0]) + np.abs(moved[:, 1]) > 0) > 0  # some moved along x or y


@pytest.mark.parametrize("case, words", [
    ("open", ["interface 'cap'", "watertight"]),
    ("crossing_boundary", ["interface 'ball'", "intersects the boundary"]),
    ("crossing_each_other", ["intersects interface"]),
    ("zero_thickness", ["touches (zero-thickness layer)", "'lower'"]),
    ("unknown_material", ["interface 'ball'", "unknown material 'unobtainium'"]),
    ("sheet_outside", ["interface 'high'", "intersects the boundary"]),
])
def test_bad_input_names_the_surface(case, words):
    ball = trimesh.creation.icosphere(2, radius=0.008)
    ball.apply_translation((0, 0, 0.015))
    if case == "open":
        cap = ball.copy()
        cap.update_faces(np.arange(len(cap.faces) - 5))
        ifs = [Interface("cap", "muscle", cap)]
    elif case == "crossing_boundary":
        big = trimesh.creation.icosphere(2, radius=0.02)
        big.apply_translation((0, 0, 0.015))
        ifs = [Interface("ball", "muscle", big)]
    elif case == "crossing_each_other":
        b2 = ball.copy()
        b2.apply_translation((0.008, 0, 0))
        ifs = [Interface("ball", "muscle", ball), Interface("ball2", "muscle", b2)]
    elif case == "zero_thickness":
        ifs = [Interface("upper", "muscle", lambda x, y: 0.02 + 0 * x),
               Interface("lower", "fat", lambda x, y: 0.02 + 0 * x)]
    elif case == "unknown_material":
        ifs = [Interface("ball", "unobtainium", ball)]
    else:
        ifs = [Interface("high", "muscle", lambda x, y: 0.04 + 0 * x)]
    with pytest.raises(ConfigError) as err:
        layered_volume(LayerSet(_box(), "fat", ifs), 0.004)
    for w in words:
        assert w in str(err.value)


def test_thigh_bone_is_rigid():
    vol = layered_volume(thigh_layers(radius=0.03, length=0.05, fat=0.006, bone_radius=0.01, bone_offset=0.0), 0.005)
    model = LayeredModel(vol)
    assert len(model.rigid_nodes) > 0
    assert model.fixed[model.rigid_nodes].all()


# ---------------------------------------------------------------------------------------------
# model
def _pressed(vol, depth, radius=0.006):
    from surgsim_envs.contact.kinematic_probe import KinematicProbe

    bottom = vol.face_nodes(4)  # no node below: the whole bottom face
    model = make("layered", vol, fixed=bottom)
    top = np.flatnonzero(vol.neighbours[:, 5] < 0)
    probe = KinematicProbe(model, top, radius)
    z = vol.nodes[top, 2].max()
    probe.move_to((0.0, 0.0, z + radius - depth))
    return model, probe


def test_local_iteration_reaches_the_linear_equilibrium(wall):
    """Eqs. 2.8-2.10 iterated on active nodes converge to the springs' linear solution (no clamp
    active at a shallow press): the local and the direct all-node solves agree."""
    model, probe = _pressed(wall, 0.002)
    model.static_solve(method="direct")
    f_direct = probe.force()[2]
    x_direct = model.positions.copy()
    model.positions[:] = model.rest_positions
    model.positions[model.fixed] = model.fixed_targets[model.fixed]
    model.push[:] = 0.0
    model.static_solve(method="local", max_sweeps=20000)
    assert model.unconverged == 0
    assert f_direct > 0
    assert abs(probe.force()[2] / f_direct - 1) < 0.01
    assert np.abs(model.positions - x_direct).max() < 0.02 * 0.002


def test_upper_layers_deform_more_and_never_interpenetrate(wall):
    """Fig. 2.14: displacement decreases with depth; even a press to 60 % of the wall's thickness
    leaves every node inside its neighbouring bounding box (no layer passes another)."""
    model, probe = _pressed(wall, 0.004)
    model.static_solve()
    col = (np.abs(model.rest_positions[:, 0]) < 0.004) & (np.abs(model.rest_positions[:, 1]) < 0.004)
    disp = -(model.positions[:, 2] - model.rest_positions[:, 2])
    means = [disp[col & (wall.node_labels == k)].mean() for k in range(3)]  # skin, fat, muscle
    assert means[0] > means[1] > means[2] > 0
    thickness = wall.nodes[:, 2].max()
    probe.move_to((0.0, 0.0, thickness + 0.006 - 0.6 * thickness))
    model.static_solve()
    assert model.interpenetrations() == 0
    assert np.count_nonzero(model.push > 0) > 0          # extreme springs carry accumulated force


def test_active_set_static_solve_is_an_equilibrium_with_rigid_extreme_springs(wall):
    """A press to 60 % of the wall's thickness puts springs at their extreme length. The all-node
    active-set solve satisfies the conditions of eqs. 2.5/2.8 with rigid springs: no spring shorter
    than its extreme length, forces passed on only by springs AT that length and only
    compressive, and every free node in equilibrium (springs + accumulated forces = 0)."""
    model, probe = _pressed(wall, 0.004)
    thickness = wall.nodes[:, 2].max()
    probe.move_to((0.0, 0.0, thickness + 0.006 - 0.6 * thickness))
    model.static_solve(method="direct")
    assert model.unconverged == 0
    assert np.count_nonzero(model.push > 0) > 0
    assert np.all(model.push >= 0)
    f = probe.force()[2]
    for gap, rigid, lmin in model.link_gaps():
        assert gap.min() > -1e-3 * lmin.max()            # rigid links: penetration < 0.1 % of lmin
        assert np.all(np.abs(gap[rigid]) < 1e-3 * lmin.max())
    free = ~model.fixed
    residual = np.abs(model.internal_forces()[free]).max()
    assert f > 0.1 and residual < 1e-6 * f


def test_prefactored_solver_tracks_the_all_node_force_while_the_probe_moves(wall):
    """A probe pressed 3 mm and slid 12 mm in 0.4 mm steps (contact nodes join and leave): the per-step
    solver's force equals the all-node static solution at every pose (exact for the linear springs)."""
    import copy

    model, probe = _pressed(wall, 0.003)
    model.solver = "prefactored"
    model.static_solve()
    z = wall.nodes[probe.candidates, 2].max()
    seen = set(probe.nodes.tolist())
    for k in range(30):
        probe.move_to((-0.006 + 0.0004 * (k + 1), 0.0, z + 0.006 - 0.003))
        seen |= set(probe.nodes.tolist())
        model.step(1e-3)
        ref = copy.deepcopy(model)
        ref.static_solve()
        f, f_ref = probe.force()[2], ref.contact_force(probe.nodes)[2]
        assert f_ref > 0
        assert abs(f / f_ref - 1) < 1e-6, (k, f, f_ref)
    assert len(seen - set(probe.nodes.tolist())) >= 2          # the contact set did change


def test_fast_step_touches_the_contact_region_and_recovers_the_rest_lazily():
    """The prefactored step writes only the columns around the contact; the probe force equals the
    all-node static solution (within 2 %; exact for the linear springs) at every pose, and the
    positions recovered afterwards (lazily, row by row or all at once) are the all-node solution."""
    import copy

    vol = abdominal_wall_volume(0.004, size=(0.06, 0.06))
    model, probe = _pressed(vol, 0.003, radius=0.005)
    model.solver = "prefactored"
    model.static_solve()
    z = vol.nodes[probe.candidates, 2].max()
    far = np.flatnonzero(np.hypot(vol.nodes[:, 0], vol.nodes[:, 1]) > 0.02)
    for k in range(6):
        probe.move_to((0.0008 * (k + 1), 0.0, z + 0.005 - 0.003))
        model.step(1e-3)
        assert model._lazy and model.last_active < 0.5 * model.n_nodes   # only the contact region written
        f = probe.force()[2]
        rows = model.node_positions(far)                                  # evaluated, nothing written
        assert model._lazy
        ref = copy.deepcopy(model)                                        # writes the positions out
        assert not model._lazy
        np.testing.assert_allclose(rows, model.positions[far], rtol=0, atol=1e-12)
        expect = ref.static_solve()
        f_ref = ref.contact_force(probe.nodes)[2]
        assert f_ref > 0.05 and abs(f / f_ref - 1) < 0.02, (k, f, f_ref)
        assert abs(f / f_ref - 1) < 1e-6                                  # exact to round-off
        np.testing.assert_allclose(model.positions, expect, rtol=0, atol=1e-9)
    probe.move_to((0.0, 0.0, z + 0.01))          # lifted: the wall returns to rest, still lazily
    model.step(1e-3)
    assert model._lazy and model.last_active < 0.5 * model.n_nodes
    np.testing.assert_allclose(model.positions, vol.nodes, rtol=0, atol=1e-12)


def test_prefactored_step_holds_springs_at_extreme_length_as_rigid_links(wall):
    """Pressed to 50 and 60 % of the thickness (springs at their extreme length), the prefactored
    step's rigid links give the all-node active-set force, with pushes and no interpenetration."""
    import copy

    model, probe = _pressed(wall, 0.002)
    model.solver = "prefactored"
    model.step(1e-3)
    thickness = wall.nodes[:, 2].max()
    for depth in (0.5, 0.6):
        probe.move_to((0.0, 0.0, thickness + 0.006 - depth * thickness))
        model.step(1e-3)
        assert getattr(model, "prefactored_fallbacks", 0) == 0
        assert np.count_nonzero(model.push > 0) > 0
        ref = copy.deepcopy(model)
        ref.static_solve()
        # exact links here, stiff ones (1e4 x the largest spring, chained) in the reference: 0.16 % at 60 %
        assert abs(probe.force()[2] / ref.contact_force(probe.nodes)[2] - 1) < 5e-3
        assert model.interpenetrations() == 0


def test_solver_option_is_checked(wall):
    with pytest.raises(ConfigError, match="solver"):
        LayeredModel(wall, solver="cg")
    with pytest.raises(ConfigError, match="block_radius"):
        LayeredModel(wall, block_radius=0.0)


@pytest.mark.slow
def test_force_accumulation_against_bone_rises_sharply():
    """Fig. 2.16: once the soft layers over the femur reach their extreme length the probe force
    grows far faster than in the soft range, and a press deeper than the fully compressed tissue
    allows (23 mm soft tissue, 20 % of it remains) is refused with a clear error."""
    from surgsim_envs.bench.layers_experiments import bone_press, leg_model

    model, top = leg_model(0.004, length=0.04)
    res = bone_press(model, top, [0.004, 0.008, 0.016, 0.0175])
    f, d = np.asarray(res["force"]), np.asarray(res["depth"])
    soft = (f[1] - f[0]) / (d[1] - d[0])
    hard = (f[3] - f[2]) / (d[3] - d[2])
    assert res["rigid_springs"][-1] > 0
    assert hard > 3 * soft
    with pytest.raises(ConfigError, match="reduce the depth"):
        bone_press(model, top, [0.021])


@pytest.mark.slow
def test_deep_path_force_several_times_shallow():
    """Fig. 2.15: pressing deep (muscle engaged) gives several times the force of a shallow path,
    and along the deep path the force is largest where the fat is thinnest (-x)."""
    from surgsim_envs.bench.layers_experiments import path_forces, wall_model

    model, top = wall_model(0.005, size=(0.1, 0.05))
    xs = [-0.03, 0.0, 0.03]
    shallow = path_forces(model, top, 0.003, xs)["force"]
    deep = path_forces(model, top, 0.012, xs)["force"]
    assert np.mean(deep) > 3 * np.mean(shallow)            # measured 4.1x at this resolution
    assert deep[0] > deep[1] > deep[2]


def test_scene_contact_matches_integrated_force(wall):
    """Implicit contact: the force reported as integrated equals g + kc (x_start - x) and the
    node's spring forces balance it at equilibrium (reaction for the tool)."""
    bottom = wall.nodes[:, 2] <= 1e-9
    model = make("layered", wall, fixed=bottom)
    top = np.flatnonzero(wall.neighbours[:, 5] < 0)
    centre = top[np.argmin(np.linalg.norm(wall.nodes[top, :2], axis=1))]
    f = np.zeros((model.n_nodes, 3))
    kc = np.zeros(model.n_nodes)
    f[centre, 2] = -0.05
    kc[centre] = 200.0
    x_start = model.positions[centre].copy()
    model.step(1e-3, f, kc)
    g = model.integrated_external_forces[centre]
    np.testing.assert_allclose(g, f[centre] + kc[centre] * (x_start - model.positions[centre]), rtol=1e-12)
    assert g[2] < 0 and abs(g[2]) < 0.05                 # the contact spring relaxed part of the load
    spring = model.internal_forces()[centre]
    np.testing.assert_allclose(g + spring, 0.0, atol=1e-3 * 0.05)   # local equilibrium of eq. 2.9
    assert "quasi_static" in model.capabilities and np.isinf(model.stable_dt())


def test_contract_fields_and_scale_material(wall):
    model, probe = _pressed(wall, 0.002)
    model.static_solve()
    fields = model.node_fields()
    for key in ("displacement", "stress", "active", "layer"):
        assert fields[key].shape == (model.n_nodes,)
    assert model.element_centroids().shape == (len(wall.tets), 3)
    f0 = probe.force()[2]
    model.scale_material("young", 2.0)           # every material twice as stiff: linear force doubles
    model.static_solve()
    assert abs(probe.force()[2] / f0 - 2.0) < 1e-6
    muscle = wall.labels == 2
    model.scale_material("young", 1.0)
    model.scale_material("young", 10.0, mask=muscle)  # a stiffer muscle raises the force, less than 2x
    model.static_solve()
    assert 1.0 < probe.force()[2] / f0 < 2.0


def test_laplace_modulus_matches_boussinesq_punch():
    """G_L = E / (2 (1 - nu^2)): Laplace punch 4 a G_L d equals Boussinesq 2 a E d / (1 - nu^2)."""
    E, nu, a, d = 3e4, 0.45, 0.01, 0.001
    assert np.isclose(4 * a * laplace_modulus(E, nu) * d, 2 * a * E * d / (1 - nu ** 2))


def test_layered_palpation_task_feels_the_nodule():
    """SurgSim/LayeredPalpation-v0: pressing over the hidden stiff nodule gives a larger force (N)
    than pressing the same depth away from it; committing there pays more than far away."""
    import gymnasium as gym

    import surgsim_envs  # noqa: F401 - registers the tasks
    from surgsim_envs.envs import register_envs

    register_envs()
    env = gym.make("SurgSim/LayeredPalpation-v0").unwrapped
    env.reset(seed=3)
    cfg = env.config
    ax, ay = env.nodule[0] / (0.5 * cfg.size[0]), env.nodule[1] / (0.5 * cfg.size[1])
    far = (-np.sign(ax) * 0.9, -np.sign(ay) * 0.9)
    obs_on, *_ = env.step([ax, ay, 0.5, -1.0])
    obs_off, *_ = env.step([far[0], far[1], 0.5, -1.0])
    assert obs_on[3] > 1.2 * obs_off[3] > 0
    _, r_on, term, _, _ = env.step([ax, ay, 0.5, 1.0])
    assert term and r_on > 0.9


def test_probe_scene_steps_with_the_layered_model():
    """A MuJoCo probe scene runs the layered model: the probe pushed into the wall feels an upward
    force (N) from the integrated contact, and no layer passes another."""
    from surgsim_envs.scene.builder import build_scene
    from surgsim_envs.scene.config import ProbeConfig, SceneConfig, TissueConfig
    from surgsim_envs.scene.simulation import Simulation

    t = TissueConfig(name="wall", organ="abdominal_wall", model="layered", material=None, spacing=0.005,
                     volume_options={"size": (0.05, 0.05)}, position=(0, 0, 0.0145), anchors=("bottom",))
    sim = Simulation(build_scene(SceneConfig(tissues=[t], tools=[ProbeConfig(position=(0, 0, 0.036))], dt=1e-3)))
    tis = sim.tissue()
    top = tis.positions[:, 2].max()
    sim.set_tool_target("probe", (0, 0, top + 0.005 - 0.003), speed=0.05)
    sim.step(150)
    assert sim.tool_force("probe")[2] > 0.01
    assert tis.interpenetrations() == 0
    assert np.all(np.isfinite(tis.positions))


@pytest.mark.slow
def test_homogeneous_block_matches_fem_and_boussinesq():
    """On a box lattice the layered model builds its NBB from the grid. A 6 cm homogeneous block
    under a rigid flat punch (radius 8 mm, 1 mm): the layered springs (G_L = E / (2 (1 - nu^2)),
    derived from the half-space punch, not fitted) give the FEM force on the same tets within 10 %
    (measured 2 %), and Boussinesq's half-space force within 25 % (finite, bonded block)."""
    from surgsim_envs.bench.layers_accuracy import press_linear
    from surgsim_envs.geometry import box_volume

    E, nu, a = 25e3, 0.45, 0.008
    vol = box_volume((0.12, 0.12, 0.06), 0.004, center=(0, 0, 0.03))
    bottom = vol.nodes[:, 2] < 1e-9
    top = np.flatnonzero(vol.nodes[:, 2] > 0.06 - 1e-9)
    r = np.sort(np.unique(np.round(np.hypot(vol.nodes[top, 0], vol.nodes[top, 1]), 9)))
    a_eff = 0.5 * (r[r < a].max() + r[r >= a].min())       # nodal punch edge
    forces = {}
    for name in ("layered", "fem"):
        model = make(name, vol, {"young": E, "poisson": nu}, fixed=bottom)
        K = model.stiffness_matrix() if callable(model.stiffness_matrix) else model.stiffness_matrix
        forces[name] = press_linear(K, vol.nodes, bottom, top, (0, 0), a, [0.001], 0.06)[0]
    assert abs(forces["layered"] / forces["fem"] - 1) < 0.10
    assert abs(forces["layered"] / (2 * a_eff * E * 0.001 / (1 - nu ** 2)) - 1) < 0.25


@pytest.mark.slow
def test_layered_wall_against_fem_on_the_bonded_wall():
    """The layered abdominal wall against FEM (same lattice tets, same layer materials, whole bottom
    face bonded), flat punch 10 mm pressed 0.5-2 mm at dd 4 mm: linear in depth in both, the layered
    wall stiffer by the documented 22 % (scalar springs: the thin skin acts as a membrane), not the
    2.8x of a wall hanging from two edge rows. The 10 % target is not met (docs/models/layered.md)."""
    from surgsim_envs.bench.layers_accuracy import compare

    res = compare(0.004)
    ratio = np.asarray(res["layered"]) / np.asarray(res["fem"])
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-6)
    assert 1.1 < ratio[0] < 1.35


def test_layered_accuracy_scene_reads_the_linear_reaction():
    """``surgsim bench accuracy --scene layered``: the punch force the harness reads from a model
    (static_solve, then the reaction on the held nodes) is the linear stiffness reaction of the same
    press (an independent path: K u with the held displacements), and is linear in depth."""
    from surgsim_envs.bench.accuracy_layered import RADIUS, _scene, press
    from surgsim_envs.bench.layers_accuracy import press_linear

    row = press("layered", 0.006, time_steps=2, solver="prefactored")
    vol, bottom, top, z_top = _scene(0.006)
    lay = LayeredModel(vol, fixed=bottom)
    f_lin = press_linear(lay.stiffness_matrix(), vol.nodes, bottom, top, (0.0, 0.0), RADIUS, row["depth"], z_top)
    np.testing.assert_allclose(row["force"], f_lin, rtol=1e-6)
    assert row["force"][0] > 0 and abs(row["force"][-1] / row["force"][0] - 4.0) < 1e-6   # 2 mm vs 0.5 mm
    assert row["contact_nodes"] >= 5 and np.isfinite(row["us_per_ms"])


def test_round_robin_sweep_covers_every_node_and_spring(wall, monkeypatch):
    """The prefactored step's sweep pieces (written and checked one per step) together hold every
    free node and both ends of every spring between free nodes, so no extreme length goes unchecked."""
    from surgsim_envs.tissue import layered_prefactored

    monkeypatch.setattr(layered_prefactored, "SWEEP_CHUNK", 64)   # several pieces per slab pair
    model = LayeredModel(wall, fixed=wall.face_nodes(4), solver="prefactored")
    pc = model._prefactored_solver()
    chunks = pc._sweep_chunks()
    n_pairs = len(np.unique(wall.lattice_index[pc.free, 0])) - 1
    assert len(chunks) >= 2 * n_pairs and set(np.concatenate(chunks).tolist()) == set(pc.free.tolist())
    owner = np.zeros((model.n_nodes, len(chunks)), dtype=bool)
    for k, c in enumerate(chunks):
        owner[c, k] = True
    for d in (1, 3, 5):
        i = pc.free[model.nbr[pc.free, d] >= 0]
        j = model.nbr[i, d]
        i, j = i[~pc.anchor[j]], j[~pc.anchor[j]]
        assert np.all((owner[i] & owner[j]).any(axis=1))


def test_prefetched_rows_give_the_same_force(wall):
    """With ``prefetch_rows`` the compliance rows come from a background thread: same force as the
    all-node solution while the probe slides over new nodes."""
    import copy

    model, probe = _pressed(wall, 0.003)
    model.solver, model.prefetch_rows = "prefactored", True
    z = wall.nodes[probe.candidates, 2].max()
    for k in range(8):
        probe.move_to((0.001 * k, 0.0, z + 0.006 - 0.003))
        model.step(1e-3)
    assert model._pc._prefetch is not None
    ref = copy.deepcopy(model)
    ref.static_solve()
    assert abs(probe.force()[2] / ref.contact_force(probe.nodes)[2] - 1) < 1e-6

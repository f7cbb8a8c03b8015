"""3-D fractional tissue model (the variable-order paper extended to tets): limits, history, equilibrium, stability, contract."""

from __future__ import annotations

import math

import numpy as np
import pytest

from surgsim_envs import tissue
from surgsim_envs.errors import ConfigError, TissueUnstableError
from surgsim_envs.geometry import box_volume
from surgsim_envs.tissue import fractional_calculus as fc
from surgsim_envs.tissue.fem import TetFEMModel
from surgsim_envs.tissue.fractional import FractionalTetModel

MAT = {"young": 5000.0, "poisson": 0.4, "density": 1000.0, "damping": 0.0, "relax_fraction": 0.5, "relax_time": 0.5}


@pytest.fixture(scope="module")
def block():
    return box_volume((0.03, 0.03, 0.02), 0.01)


def _faces(vol):
    z = vol.nodes[:, 2]
    return np.isclose(z, z.min()), np.isclose(z, z.max())


def test_registered_with_the_contract_names(block):
    cls = tissue.get("fractional")
    assert cls is FractionalTetModel
    assert {"forces", "history", "viscoelastic", "static_solve"} <= cls.capabilities
    m = tissue.make("fractional", block, MAT)
    fields = m.node_fields()
    assert {"displacement", "stress"} <= set(fields) and set(m.field_names()) == set(fields)
    assert all(v.shape == (m.n_nodes,) for v in fields.values())
    assert m.element_centroids().shape == (len(block.tets), 3)
    assert m.stable_dt() < m.critical_dt()


def test_order_zero_is_linear_elastic_fem(block):
    bottom, top = _faces(block)
    frac = FractionalTetModel(block, MAT, order=0.0, integrator="symplectic", fixed=bottom)
    elastic = dict(MAT, relax_fraction=0.0)        # q = 0: both branches elastic, total stiffness C
    fem = TetFEMModel(block, elastic, integrator="symplectic", corotational=False, formulation="standard", fixed=bottom)
    forces = np.zeros((frac.n_nodes, 3))
    forces[top, 2] = -0.02
    dt = 0.5 * min(frac.critical_dt(), fem.critical_dt())
    for _ in range(200):
        frac.step(dt, forces)
        fem.step(dt, forces)
    u = fem.positions - fem.rest_positions
    assert np.abs(frac.positions - fem.positions).max() < 1e-8 * np.abs(u).max()
    # q = 0: the limit is 2 / omega_max of M^-1 K (fem includes the fixed nodes' rows: 0.7 % lower)
    assert frac.critical_dt() == pytest.approx(fem.critical_dt(), rel=0.02)


def test_element_stress_is_the_fractional_derivative_of_the_elastic_stress_history(block):
    # every node prescribed (affine uniaxial strain history): the tet stress must be
    # (1 - g) C eps + g tau^q D^q[C eps] with the GL derivative of the strain history, memory L
    q, mem, dt = 0.4, 30, 1e-3
    m = FractionalTetModel(block, MAT, order=q, memory=mem, coarse_blocks=0, integrator="implicit")
    allnodes = np.ones(m.n_nodes, dtype=bool)
    z0 = block.nodes[:, 2] - block.nodes[:, 2].min()
    n = 80
    strain = 0.02 * np.sin(np.linspace(0, 3, n + 1)) ** 2
    stresses = []
    for k in range(1, n + 1):
        target = block.nodes.copy()
        target[:, 2] = block.nodes[:, 2].min() + z0 * (1 + strain[k])
        m.set_fixed(allnodes, target)
        m.step(dt)
        stresses.append(m.element_stress()[:, 2, 2])
    e, nu = MAT["young"], MAT["poisson"]
    c33 = e * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    g, tau = MAT["relax_fraction"], MAT["relax_time"]
    frac = fc.derivative(strain, dt, q, kind="rl", scheme="gl", memory=mem)
    expected = c33 * ((1 - g) * strain + g * tau ** q * frac)[1:]
    got = np.array(stresses)
    assert np.allclose(got, expected[:, None], rtol=1e-9, atol=1e-9 * np.abs(expected).max())


@pytest.mark.parametrize("branch,memory", [(1.0, 100), (0.5, 20)])
def test_relaxation_equilibrium_equals_the_elastic_static_solution(block, branch, memory):
    bottom, top = _faces(block)
    m = FractionalTetModel(block, MAT, order=0.4, memory=memory, branch_fraction=branch, integrator="implicit",
                           fixed=bottom)
    target = block.nodes[top] + np.array([0.002, 0.0, -0.003]) * (block.nodes[top, :1] / 0.03 + 0.5)
    m.set_fixed(top, target)
    fem = TetFEMModel(block, dict(MAT, relax_fraction=0.0), corotational=False, formulation="standard", fixed=bottom)
    fem.set_fixed(top, target)
    ref = fem.static_solve()
    u_ref = np.abs(ref - block.nodes).max()
    for _ in range(3000):
        m.step(1e-3)
    assert np.abs(m.positions - ref).max() < 1e-5 * u_ref
    assert np.abs(m.static_solve() - ref).max() < 1e-9 * u_ref


def test_pure_fractional_tissue_creeps_and_has_no_static_solution_under_load(block):
    bottom, top = _faces(block)
    m = FractionalTetModel(block, MAT, order=0.3, branch_fraction=1.0, memory=4000, integrator="implicit", fixed=bottom)
    forces = np.zeros((m.n_nodes, 3))
    forces[top, 2] = -0.01
    with pytest.raises(ConfigError, match="creeps"):
        m.static_solve(forces)
    depth = {}
    for k in range(1, 4001):
        m.step(1e-3, forces)
        if k in (1000, 2000, 4000):
            depth[k] = block.nodes[top, 2].mean() - m.positions[top, 2].mean()
    # Scott-Blair creep: u ~ t^q (no equilibrium)
    assert depth[4000] / depth[2000] == pytest.approx(2 ** 0.3, rel=0.02)
    assert depth[2000] / depth[1000] == pytest.approx(2 ** 0.3, rel=0.03)


def test_implicit_and_symplectic_agree_at_small_dt(block):
    bottom, top = _faces(block)
    out = {}
    for integ in ("symplectic", "implicit"):
        m = FractionalTetModel(block, MAT, order=fc.PiecewiseOrder((0.02,), (0.2, 0.5)), integrator=integ, fixed=bottom)
        forces = np.zeros((m.n_nodes, 3))
        forces[top, 2] = -0.02
        dt = 0.25 * m.critical_dt()
        for _ in range(int(0.05 / dt)):
            m.step(dt, forces)
        out[integ] = m.positions - m.rest_positions
    scale = np.abs(out["implicit"]).max()
    assert np.abs(out["implicit"] - out["symplectic"]).max() < 0.03 * scale


@pytest.mark.parametrize("q", [0.2, 0.6])
def test_critical_dt_separates_stable_from_unstable(block, q):
    bottom, _ = _faces(block)
    for factor, stable in ((0.9, True), (1.3, False)):
        m = FractionalTetModel(block, MAT, order=q, integrator="symplectic", fixed=bottom)
        m.velocities[:] = 1e-3 * np.random.default_rng(0).standard_normal(m.velocities.shape)
        m.velocities[bottom] = 0.0
        dt = factor * m.critical_dt()
        if stable:
            for _ in range(3000):
                m.step(dt)
            assert np.abs(m.positions - m.rest_positions).max() < 1e-3
        else:
            with pytest.raises(TissueUnstableError):
                for _ in range(3000):
                    m.step(dt)


def test_reset_clears_history_and_scale_material_stiffens(block):
    bottom, top = _faces(block)
    m = FractionalTetModel(block, MAT, integrator="implicit", fixed=bottom)
    forces = np.zeros((m.n_nodes, 3))
    forces[top, 2] = -0.02
    for _ in range(50):
        m.step(1e-3, forces)
    first = m.positions.copy()
    m.reset()
    assert m._count == 0 and not m._buf.any()
    for _ in range(50):
        m.step(1e-3, forces)
    assert np.array_equal(m.positions, first)            # same history -> same trajectory
    soft = m.static_solve(forces)
    m.scale_material("young", 2.0)
    stiff = m.static_solve(forces)
    assert np.allclose(stiff - block.nodes, 0.5 * (soft - block.nodes), rtol=1e-9, atol=1e-15)
    m.scale_material("young", 4.0, mask=np.zeros(len(block.tets), dtype=bool))   # masked out: unchanged
    assert np.allclose(m.static_solve(forces), stiff)
    m.scale_material("young", 1.0)                                                  # relative to build: back to 1x
    assert np.allclose(m.static_solve(forces), soft)


def test_bad_input(block):
    with pytest.raises(ConfigError, match="order q"):
        FractionalTetModel(block, MAT, order=1.0)
    with pytest.raises(ConfigError, match="memory"):
        FractionalTetModel(block, MAT, memory=0)
    with pytest.raises(ConfigError, match="GB history"):
        FractionalTetModel(block, MAT, memory=10 ** 8)
    with pytest.raises(ConfigError, match="branch_fraction"):
        FractionalTetModel(block, MAT, branch_fraction=2.0)
    m = FractionalTetModel(block, MAT)
    with pytest.raises(ConfigError, match="unknown material field"):
        m.scale_material("stiffness", 2.0)
    with pytest.raises(ConfigError, match="Dirichlet"):
        m.static_solve()


def test_probe_scene_steps_with_the_fractional_model():
    from surgsim_envs.scene import ProbeConfig, SceneConfig, Simulation, TissueConfig, build_scene

    slab = TissueConfig(name="slab", organ="slab", model="fractional", material="liver", spacing=0.01,
                        anchors=("bottom",), position=(0.0, 0.0, 0.01), volume_options={"size": (0.06, 0.06, 0.02)},
                        options={"integrator": "symplectic"})
    sim = Simulation(build_scene(SceneConfig(name="t", tissues=[slab], cameras=[], dt=2e-4,
                                             tools=[ProbeConfig(name="probe", tip_radius=0.008, position=(0, 0, 0.03))])))
    sim.set_tool_target("probe", [0.0, 0.0, 0.024])         # tip 4 mm into the 20 mm slab
    sim.step(1500)
    model = sim.tissue("slab")
    assert model.name == "fractional" and model.node_fields()["displacement"].max() > 1e-3
    assert sim.tool_force("probe")[2] > 0.01           # N: the tissue pushes the probe back up


def test_palpation_task_runs_on_the_fractional_tissue():
    import gymnasium as gym

    from surgsim_envs.envs import register_envs

    register_envs()
    env = gym.make("SurgSim/Palpation-v0", model="fractional", integrator="auto")   # 1 ms > explicit limit: implicit
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        obs, reward, term, trunc, info = env.step(env.action_space.sample())
    tissue_model = env.unwrapped.sim.tissue()
    assert tissue_model.name == "fractional" and tissue_model.active_integrator == "implicit"
    assert np.all(np.isfinite(obs)) and np.isfinite(reward)
    env.close()


@pytest.mark.parametrize("integrator", ["implicit", "symplectic"])
def test_two_level_memory_recovers_the_whole_history_that_truncation_loses(block, integrator):
    # creep under a constant load for 1,500 steps: the whole history against L = 50 alone and
    # L = 50 plus 30 block averages of 50 steps (the nested-memory tail)
    bottom, top = _faces(block)
    dt = 1e-3 if integrator == "implicit" else 0.5 * FractionalTetModel(block, MAT, order=0.4, integrator="symplectic",
                                                                      fixed=bottom).critical_dt()

    def run(**kw):
        m = FractionalTetModel(block, MAT, order=0.4, integrator=integrator, fixed=bottom, **kw)
        forces = np.zeros((m.n_nodes, 3))
        forces[top, 2] = -0.02
        out = []
        for _ in range(1500):
            m.step(dt, forces)
            out.append(block.nodes[top, 2].mean() - m.positions[top, 2].mean())
        return np.array(out)

    full = run(memory=1500)
    err = {k: np.max(np.abs(run(memory=50, **kw) - full)) / np.max(full)
           for k, kw in (("plain", {"coarse_blocks": 0}), ("nested", {"coarse_blocks": 30, "coarse_step": 50}))}
    assert err["plain"] > 0.3                    # truncation: the creep stalls after 50 steps
    assert err["nested"] < 0.02
    with pytest.raises(ConfigError, match="coarse_step"):
        FractionalTetModel(block, MAT, memory=10, coarse_blocks=3, coarse_step=20)

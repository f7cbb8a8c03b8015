"""Linear / corotational tetrahedral FEM (Vandewalle et al. 2003 basic model): analytic checks and stability."""

import numpy as np
import pytest

from surgsim_envs import tissue
from surgsim_envs.errors import ConfigError, TissueUnstableError
from surgsim_envs.geometry import Volume, box_volume

SOFT = {"young": 1.0e4, "poisson": 0.3, "density": 1000.0, "damping": 0.0}


def rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def single_tet():
    a = 0.01
    nodes = np.array([[0, 0, 0], [a, 0, 0], [0, a, 0], [0, 0, a]], float)
    return Volume(nodes, np.array([[0, 1, 2, 3]])), a


def test_registry_maps_fem_to_model():
    cls = tissue.get("fem")
    assert cls.name == "fem" and cls.integrators == ("implicit", "symplectic") and cls.summary


@pytest.mark.parametrize("formulation", ["standard", "anp"])
def test_single_tet_forces_equal_hand_computed_ke_u(formulation):
    vol, a = single_tet()
    E, nu = SOFT["young"], SOFT["poisson"]
    model = tissue.make("fem", vol, SOFT, corotational=False, formulation=formulation)
    # hand computation: gradients of N0..N3 for the right-angled tet, paper eq. 3 B, eq. 2 D
    grads = np.array([[-1, -1, -1], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) / a
    B = np.zeros((6, 12))
    for m, (gx, gy, gz) in enumerate(grads):
        B[:, 3 * m:3 * m + 3] = [[gx, 0, 0], [0, gy, 0], [0, 0, gz], [gy, gx, 0], [0, gz, gy], [gz, 0, gx]]
    f = E / ((1 + nu) * (1 - 2 * nu))
    D = np.zeros((6, 6))
    D[:3, :3] = f * nu
    D[np.arange(3), np.arange(3)] = f * (1 - nu)
    D[np.arange(3, 6), np.arange(3, 6)] = f * (1 - 2 * nu) / 2
    Ke = B.T @ D @ B * a ** 3 / 6
    u = np.zeros((4, 3))
    u[3] = [2e-4, -1e-4, 5e-4]                       # move the apex
    model.positions = vol.nodes + u
    forces = model.internal_forces()
    np.testing.assert_allclose(forces.ravel(), -Ke @ u.ravel(), rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(forces.sum(axis=0), 0.0, atol=1e-15)
    assert abs(forces[3] @ u[3]) > 0 and forces[3] @ u[3] < 0   # restoring


@pytest.mark.parametrize("formulation", ["standard", "anp"])
@pytest.mark.parametrize("corotational", [False, True])
def test_patch_test_linear_field_reproduced_with_uniform_stress(formulation, corotational):
    vol = box_volume((0.03, 0.03, 0.03), 0.01)
    model = tissue.make("fem", vol, SOFT, corotational=corotational, formulation=formulation)
    grad = np.array([[0.010, 0.004, -0.002], [0.003, -0.006, 0.001], [-0.002, 0.005, 0.008]])
    if corotational:
        grad = 0.5 * (grad + grad.T)   # pure stretch: the corotated strain is then exactly linear
    exact = vol.nodes + vol.nodes @ grad.T + np.array([1e-3, -2e-3, 5e-4])
    boundary = vol.surface_nodes
    interior = np.setdiff1d(np.arange(vol.n_nodes), boundary)
    assert len(interior) == 8
    model.set_fixed(boundary, exact[boundary])
    x = model.static_solve()
    np.testing.assert_allclose(x[interior], exact[interior], atol=1e-12)
    np.testing.assert_allclose(model.positions, x)
    eps = 0.5 * (grad + grad.T)
    if corotational:   # polar: F = I + grad is symmetric positive -> R = I, strain = grad
        eps = grad
    mu, lam = model.mu[0], model.lam[0]
    sigma = 2 * mu * eps + lam * np.trace(eps) * np.eye(3)
    stress = model.element_stress()
    np.testing.assert_allclose(stress, np.broadcast_to(sigma, stress.shape), rtol=1e-8, atol=1e-8 * np.abs(sigma).max())


def cantilever_tip_ratio(spacing, poisson, formulation):
    """FEM tip deflection / Timoshenko (Euler-Bernoulli + shear) for an end-loaded clamped beam."""
    L, h, E, P = 0.1, 0.01, 1.0e4, 1e-3
    vol = box_volume((L, h, h), spacing, center=(L / 2, 0, 0))
    model = tissue.make("fem", vol, {"young": E, "poisson": poisson, "density": 1000.0},
                        corotational=False, formulation=formulation)
    model.set_fixed(np.flatnonzero(vol.nodes[:, 0] < 1e-9))
    end = np.flatnonzero(vol.nodes[:, 0] > L - 1e-9)
    y, z = vol.nodes[end, 1], vol.nodes[end, 2]     # trapezoid weights of a uniform shear traction
    w = np.where(np.isclose(abs(y), h / 2), 0.5, 1.0) * np.where(np.isclose(abs(z), h / 2), 0.5, 1.0)
    forces = np.zeros((vol.n_nodes, 3))
    forces[end, 2] = -P * w / w.sum()
    x = model.static_solve(forces)
    tip = -(x[end, 2] - vol.nodes[end, 2]).mean()
    G, I, A = E / (2 * (1 + poisson)), h ** 4 / 12, h * h
    k_shear = 10 * (1 + poisson) / (12 + 11 * poisson)
    return tip / (P * L ** 3 / (3 * E * I) + P * L / (k_shear * G * A))


def test_cantilever_converges_to_beam_theory():
    coarse = cantilever_tip_ratio(0.005, 0.3, "anp")
    fine = cantilever_tip_ratio(0.002, 0.3, "anp")
    assert abs(fine - 1) < 0.10, fine
    assert abs(fine - 1) < abs(coarse - 1)
    # standard linear tets are stiffer in bending but converge too
    std_fine = cantilever_tip_ratio(0.002, 0.3, "standard")
    assert abs(std_fine - 1) < 0.2 and std_fine < fine


def test_volumetric_locking_at_nu_0499_and_anp_cure():
    standard = cantilever_tip_ratio(0.002, 0.499, "standard")
    anp = cantilever_tip_ratio(0.002, 0.499, "anp")
    assert standard < 0.2, f"standard formulation should lock (tip ratio {standard:.3f})"
    assert abs(anp - 1) < 0.15, f"ANP should not lock (tip ratio {anp:.3f})"


def small_free_block(corotational, damping=0.0, seed=0):
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    model = tissue.make("fem", vol, {**SOFT, "damping": damping}, integrator="symplectic",
                        corotational=corotational)
    rng = np.random.default_rng(seed)
    model.positions = vol.nodes + rng.normal(0, 2e-4, vol.nodes.shape)
    return model


@pytest.mark.parametrize("corotational", [False, True])
def test_undamped_explicit_energy_bounded_and_momentum_conserved(corotational):
    model = small_free_block(corotational)
    dt = 0.5 * model.critical_dt()
    e0 = model.elastic_energy()
    energies = []
    for i in range(10_000):
        model.step(dt)
        if i % 50 == 0:
            energies.append(model.kinetic_energy() + model.elastic_energy())
    energies = np.array(energies)
    assert energies.max() < 1.5 * e0 and energies.min() > 0.5 * e0
    assert abs(energies[-20:].mean() - energies[:20].mean()) < 0.1 * e0   # no drift
    np.testing.assert_allclose(model.momentum(), 0.0, atol=1e-12 * model.total_mass)


def test_damped_explicit_dissipates():
    model = small_free_block(True, damping=20.0)
    dt = 0.5 * model.critical_dt()
    e0 = model.elastic_energy()
    prev = e0
    for _ in range(20):
        for _ in range(50):
            model.step(dt)
        e = model.kinetic_energy() + model.elastic_energy()
        assert e <= prev * 1.05
        prev = e
    assert prev < 0.2 * e0


@pytest.mark.parametrize("formulation", ["standard", "anp"])
@pytest.mark.parametrize("corotational", [False, True])
def test_internal_forces_sum_to_zero(formulation, corotational):
    vol = box_volume((0.03, 0.02, 0.02), 0.01)
    model = tissue.make("fem", vol, SOFT, corotational=corotational, formulation=formulation, stiffness_damping=0.01)
    rng = np.random.default_rng(1)
    model.positions = vol.nodes + rng.normal(0, 1e-3, vol.nodes.shape)
    model.velocities = rng.normal(0, 1e-2, vol.nodes.shape)
    f = model.internal_forces()
    assert np.abs(f).max() > 0
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-12 * np.abs(f).sum())


def test_rigid_rotation_gives_no_force_only_when_corotational():
    vol = box_volume((0.04, 0.03, 0.02), 0.01)
    rot = rotation([1, 2, 3], np.deg2rad(60))
    moved = (vol.nodes - vol.nodes.mean(0)) @ rot.T + vol.nodes.mean(0) + [0.01, 0, 0]
    forces = {}
    for cor in (True, False):
        model = tissue.make("fem", vol, SOFT, corotational=cor)
        stretch = vol.nodes * [1.01, 1, 1]                     # 1 % stretch: a force scale
        scale = np.abs(model.elastic_forces(stretch)).max()
        forces[cor] = np.abs(model.elastic_forces(moved)).max() / scale
        model.positions = moved
        assert model.inverted_elements() == 0
    assert forces[True] < 1e-8
    assert forces[False] > 10


def spinning_block(threads=1, omega=4.0):
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    model = tissue.make("fem", vol, SOFT, integrator="symplectic", threads=threads)
    r = vol.nodes - vol.nodes.mean(0)
    model.velocities = np.cross([0.3 * omega, 0.0, omega], r)   # rigid spin, no strain
    return model


def test_symplectic_spin_is_strain_free_with_one_warm_started_rotation_iteration():
    """A freely spinning block turns ~1.5 revolutions; the per-step Cayley update of the polar
    rotation (rotation_iters=1) must keep the spurious corotated strain at the centrifugal level."""
    model = spinning_block()
    dt = 0.5 * model.critical_dt()
    ke0 = model.kinetic_energy()
    steps = int(2.3 / (4.0 * dt)) + 1   # angle ~ 2.3 * 4 rad
    for _ in range(steps):
        model.step(dt)
    assert model.elastic_energy() < 1e-3 * ke0
    assert abs(model.kinetic_energy() + model.elastic_energy() - ke0) < 1e-3 * ke0
    np.testing.assert_allclose(model.momentum(), 0.0, atol=1e-12 * model.total_mass)
    rot = model._rots
    np.testing.assert_allclose(np.einsum("tji,tjk->tik", rot, rot), np.broadcast_to(np.eye(3), rot.shape), atol=1e-12)


@pytest.mark.parametrize("integrator", ["symplectic", "implicit"])
def test_parallel_kernels_match_single_thread_and_are_deterministic(integrator):
    vol = box_volume((0.03, 0.02, 0.02), 0.005)
    runs = []
    x = vol.nodes[:, 0]
    for threads in (1, 2, 2):
        model = tissue.make("fem", vol, SOFT, integrator=integrator, threads=threads, stiffness_damping=1e-4,
                            fixed=x < x.min() + 1e-9)
        forces = np.zeros((vol.n_nodes, 3))
        forces[x > x.max() - 1e-9, 2] = -1e-3
        dt = 1e-3 if integrator == "implicit" else 4e-4   # critical dt ~ 1e-3 s
        for _ in range(10 if integrator == "implicit" else 40):
            model.step(dt, forces)
        runs.append((model.positions.copy(), model.elastic_energy()))
    scale = np.abs(runs[0][0] - vol.nodes).max()
    assert scale > 1e-4
    # same physics; only the summation order differs
    np.testing.assert_allclose(runs[1][0], runs[0][0], rtol=0, atol=1e-9 * scale)
    assert abs(runs[1][1] - runs[0][1]) < 1e-9 * runs[0][1]
    assert np.array_equal(runs[1][0], runs[2][0]) and runs[1][1] == runs[2][1]        # bitwise repeatable


def test_inverted_elements_are_counted():
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    model = tissue.make("fem", vol, SOFT)
    x = vol.nodes.copy()
    x[:, 2] *= -1.0   # mirror: every tet inverted
    model.positions = x
    assert model.inverted_elements() == len(vol.tets)


def test_explicit_beyond_critical_dt_raises_and_below_is_stable():
    stable = small_free_block(True, damping=0.0)
    crit = stable.critical_dt()            # raw estimate (contract v2: no safety factor inside)
    for _ in range(3000):
        stable.step(stable.stable_dt())
    unstable = small_free_block(True, damping=0.0)
    with pytest.raises(TissueUnstableError, match="critical dt"):
        for _ in range(3000):
            unstable.step(1.45 * crit)
    geo = stable.critical_dt("geometric")
    assert 0.25 * crit < geo < 4 * crit


@pytest.mark.parametrize("corotational", [False, True])
def test_implicit_is_stable_far_beyond_critical_dt_and_settles_on_static_solution(corotational):
    vol = box_volume((0.04, 0.02, 0.02), 0.01)
    mat = {**SOFT, "damping": 30.0}
    model = tissue.make("fem", vol, mat, integrator="implicit", corotational=corotational)
    clamp = np.flatnonzero(vol.nodes[:, 0] < vol.nodes[:, 0].min() + 1e-9)
    model.set_fixed(clamp)
    forces = np.zeros((vol.n_nodes, 3))
    forces[vol.nodes[:, 0] > 0.019, 2] = -2e-3
    dt = 10 * model.critical_dt()
    for _ in range(600):
        model.step(dt, forces)
    dynamic = model.positions.copy()
    static = tissue.make("fem", vol, mat, corotational=corotational)
    static.set_fixed(clamp)
    target = static.static_solve(forces)
    deflection = np.abs(target - vol.nodes).max()
    assert deflection > 1e-3
    assert np.abs(dynamic - target).max() < 0.02 * deflection


def test_implicit_treats_contact_stiffness_implicitly():
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    node = int(np.argmax(vol.nodes[:, 2] + vol.nodes[:, 0] * 1e-3))
    goal = vol.nodes[node] + [0, 0, -2e-3]
    k = 5e3   # penalty spring (N/m), far stiffer than the tissue at this dt

    def run(pass_stiffness, integrator="implicit"):
        model = tissue.make("fem", vol, {**SOFT, "damping": 5.0}, integrator=integrator)
        model.set_fixed(np.flatnonzero(vol.nodes[:, 2] < vol.nodes[:, 2].min() + 1e-9))
        stiff = np.zeros(vol.n_nodes)
        stiff[node] = k
        for _ in range(300):
            f = np.zeros((vol.n_nodes, 3))
            f[node] = k * (goal - model.positions[node])
            model.step(2e-3, f, stiff if pass_stiffness else None)
        return model

    model = run(True)
    assert np.linalg.norm(model.positions[node] - goal) < 1e-3   # pulled close to the spring target
    with pytest.raises(TissueUnstableError):
        run(False, integrator="symplectic")


def test_static_solve_follows_moving_fixed_targets_corotational_large_rotation():
    vol = box_volume((0.04, 0.01, 0.01), 0.005, center=(0.02, 0, 0))
    model = tissue.make("fem", vol, SOFT, corotational=True)
    end = np.flatnonzero(vol.nodes[:, 0] > 0.04 - 1e-9)
    rot = rotation([0, 0, 1], np.deg2rad(90))
    model.set_fixed(np.arange(vol.n_nodes), vol.nodes @ rot.T)   # everything rotated rigidly
    model.release(np.setdiff1d(np.arange(vol.n_nodes), np.r_[end, np.flatnonzero(vol.nodes[:, 0] < 1e-9)]))
    x = model.static_solve()
    np.testing.assert_allclose(x, vol.nodes @ rot.T, atol=1e-9)   # corotational: stays rigid


def test_bad_input_is_rejected_with_clear_messages():
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    with pytest.raises(ConfigError, match="poisson"):
        tissue.make("fem", vol, {"young": 1e4, "poisson": 0.5})
    with pytest.raises(ConfigError, match="young"):
        tissue.make("fem", vol, {"young": 0.0, "poisson": 0.3})
    with pytest.raises(ConfigError, match="formulation"):
        tissue.make("fem", vol, SOFT, formulation="mixed-up")
    with pytest.raises(ConfigError, match="integrator"):
        tissue.make("fem", vol, SOFT, integrator="rk4")
    with pytest.raises(ConfigError, match="stiffness_damping"):
        tissue.make("fem", vol, SOFT, stiffness_damping=-1.0)
    for bad in (0, 1.5, True):
        with pytest.raises(ConfigError, match="threads"):
            tissue.make("fem", vol, SOFT, threads=bad)
    tets = vol.tets.copy()
    tets[0] = tets[0][[1, 0, 2, 3]]
    with pytest.raises(ConfigError, match="inverted"):
        tissue.make("fem", Volume(vol.nodes, tets, surface=vol.surface), SOFT)
    model = tissue.make("fem", vol, SOFT)
    with pytest.raises(ConfigError, match="Dirichlet"):
        model.static_solve()
    with pytest.raises(ConfigError, match="stiffness"):
        model.step(1e-3, None, np.ones(3))


def test_auto_integrator_default_picks_explicit_only_below_its_limit():
    vol = box_volume((0.02, 0.02, 0.02), 0.005)
    z = vol.nodes[:, 2]
    model = tissue.make("fem", vol, {**SOFT, "damping": 5.0}, fixed=np.isclose(z, z.min()))
    assert model.integrator == "auto" and "auto" in model.integrator_names()
    crit = model.critical_dt()
    force = np.zeros_like(model.positions)
    force[np.isclose(z, z.max()), 2] = -0.01
    model.step(0.5 * crit, force)
    assert model.active_integrator == "symplectic"
    for _ in range(200):                       # 10 x the explicit limit: implicit, and stable
        model.step(10.0 * crit, force)
    assert model.active_integrator == "implicit" and model.describe()["active_integrator"] == "implicit"
    assert np.all(np.isfinite(model.positions)) and model.inverted_elements() == 0
    assert model.choose_integrator(0.79 * crit) == "symplectic" and model.choose_integrator(0.81 * crit) == "implicit"
    # explicit names still work and do not switch
    sym = tissue.make("fem", vol, SOFT, integrator="symplectic")
    sym.step(0.5 * crit)
    assert sym.active_integrator == "symplectic" and sym.choose_integrator(1.0) == "implicit"


# --- implicit corotational solve: pressure (Woodbury / pressure Schur complement) preconditioner
RUBBER = {"young": 15_300.0, "poisson": 0.499, "density": 980.0, "damping": 5.0}   # silicone-like, nu -> 0.5


def bending_run(preconditioner, steps=60, contact=False, moving=False, poisson=0.499):
    """Clamped beam of nearly incompressible rubber swinging down under gravity (large rotations),
    optionally with a penalty contact spring (implicit `stiffness`) and a moving clamp."""
    vol = box_volume((0.06, 0.012, 0.012), 0.004, center=(0.03, 0.0, 0.0))
    x = vol.nodes[:, 0]
    model = tissue.make("fem", vol, {**RUBBER, "poisson": poisson}, integrator="implicit",
                        preconditioner=preconditioner, fixed=x < 1e-9, gravity=(0.0, 0.0, -9.81))
    tip = np.flatnonzero(x > x.max() - 1e-9)
    iters = []
    for i in range(steps):
        forces, stiff = np.zeros((vol.n_nodes, 3)), None
        if contact:   # a 200 N/m spring pulls one tip node back up
            stiff = np.zeros(vol.n_nodes)
            stiff[tip[0]] = 200.0
            forces[tip[0]] = 200.0 * (vol.nodes[tip[0]] - model.positions[tip[0]])
        if moving:
            model.fixed_targets[model.fixed] += [0.0, 0.0, 2e-5]
        model.step(2e-3, forces, stiff)
        iters.append(model.last_cg_iterations)
    return model, np.array(iters), tip


def test_auto_preconditioner_choice_and_bad_input():
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    assert tissue.make("fem", vol, "silicone").preconditioner == "pressure"        # kappa/mu = 500
    assert tissue.make("fem", vol, "liver").preconditioner == "jacobi"             # kappa/mu = 9.7
    assert tissue.make("fem", vol, "silicone", formulation="standard").preconditioner == "jacobi"
    assert tissue.make("fem", vol, "silicone").describe()["preconditioner"] == "pressure"
    with pytest.raises(ConfigError, match="preconditioner"):
        tissue.make("fem", vol, "liver", preconditioner="ilu")
    with pytest.raises(ConfigError, match="anp"):
        tissue.make("fem", vol, "liver", formulation="standard", preconditioner="pressure")


@pytest.mark.parametrize("case", ["free", "contact", "moving"])
def test_pressure_preconditioner_solves_the_same_system_in_far_fewer_iterations(case):
    runs = {p: bending_run(p, contact=case == "contact", moving=case == "moving") for p in ("jacobi", "pressure")}
    (mj, ij, tip), (mp, ip, _) = runs["jacobi"], runs["pressure"]
    sag = np.abs(mj.positions[tip] - mj.rest_positions[tip]).max()
    assert sag > 2e-3                                      # large deflection: elements rotate
    assert np.abs(mj._rots[:, 0, 2]).max() > 0.1           # > ~6 deg rotation somewhere
    # both solve (M' + c_k R K R^T) v = b to cg_tol = 1e-6: same trajectory to solver tolerance
    np.testing.assert_allclose(mp.positions, mj.positions, rtol=0, atol=1e-5 * sag)
    assert ip.mean() < 0.3 * ij.mean()                     # Jacobi needs O(sqrt(kappa/mu)) more
    assert mp.inverted_elements() == 0


def test_pressure_preconditioner_is_deterministic_and_rebuilt_when_dt_changes():
    a, ia, _ = bending_run("pressure", steps=20)
    b, ib, _ = bending_run("pressure", steps=20)
    assert np.array_equal(a.positions, b.positions) and np.array_equal(ia, ib)
    c_k = 2e-3 ** 2
    cached = a._pressure_preconditioner(2e-3, c_k)
    assert a._pressure_preconditioner(2e-3, c_k) is cached          # same dt, same clamp: factor reused
    a.step(1e-3)
    assert a._pre[2] is not cached and a._pre[0][0] == 1e-3

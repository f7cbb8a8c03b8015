"""Nonlinear viscoelastic mass-spring-damper model (the grasping simulation paper): physics and bad input."""

import math

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from surgsim_envs import tissue
from surgsim_envs.errors import ConfigError, TissueUnstableError
from surgsim_envs.geometry import Volume, box_volume
from surgsim_envs.tissue.mass_spring import CAPPED_POISSON, MassSpringModel


def _faces(vol):
    z = vol.nodes[:, 2]
    return np.isclose(z, z.max()), np.isclose(z, z.min())


def _elastic(**changes):
    """Liver with the given fields changed."""
    return tissue.get_material("liver").replace(**changes)


def test_registry_builds_the_model_with_both_integrators():
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    for integ in ("symplectic", "implicit"):
        m = tissue.make("mass_spring", vol, "spleen", integrator=integ)
        assert isinstance(m, MassSpringModel) and m.integrator == integ
        assert m.n_springs == len(vol.edges())
    assert np.isclose(m.total_mass, 1054.0 * 0.02 ** 3)


def test_small_strain_modulus_matches_young_on_box_lattice():
    """Uniaxial compression with sliding (roller) ends: effective E within 20 % of the material's."""
    vol = box_volume()  # default block, 5 mm lattice
    E = 4000.0
    m = MassSpringModel(vol, _elastic(young=E, relax_fraction=0.0, nonlinear=0.0))
    K = m.stiffness_matrix()
    top, bot = _faces(vol)
    n, H, eps = vol.n_nodes, np.ptp(vol.nodes[:, 2]), 1e-3
    u, fixed = np.zeros(3 * n), np.zeros(3 * n, bool)
    fixed[3 * np.flatnonzero(top) + 2] = fixed[3 * np.flatnonzero(bot) + 2] = True
    b = np.flatnonzero(bot)
    fixed[3 * b[0]] = fixed[3 * b[0] + 1] = fixed[3 * b[-1] + 1] = True  # no rigid sliding/spin
    u[3 * np.flatnonzero(top) + 2] = -eps * H
    free = ~fixed
    u[free] = spla.spsolve(K[free][:, free].tocsc(), -K[free][:, fixed] @ u[fixed])
    force = -(K @ u)[3 * np.flatnonzero(top) + 2].sum()
    area = np.ptp(vol.nodes[:, 0]) * np.ptp(vol.nodes[:, 1])
    E_eff = force / area / eps
    assert abs(E_eff / E - 1.0) < 0.2, E_eff


def test_inclusion_makes_its_springs_stiffer():
    vol = box_volume((0.04, 0.04, 0.04), 0.005)
    centroids = vol.nodes[vol.tets].mean(axis=1)
    labels = (np.linalg.norm(centroids, axis=1) < 0.01).astype(np.int32)
    vol = Volume(vol.nodes, vol.tets, labels=labels)
    m = MassSpringModel(vol, "liver", region_materials={1: {"preset": "liver", "young": 40_000.0}})
    # edges whose every tet is in the inclusion vs edges with no inclusion tet
    n = vol.n_nodes
    inside_node = vol.node_labels == 1
    bulk_only = np.zeros(n, bool)
    bulk_only[np.unique(vol.tets[labels == 0])] = True
    core = inside_node[m.si] & inside_node[m.sj] & ~bulk_only[m.si] & ~bulk_only[m.sj]
    outside = ~inside_node[m.si] & ~inside_node[m.sj]
    assert core.any() and outside.any()
    ratio = m.K1 / MassSpringModel(vol, "liver").K1  # per spring, against the homogeneous organ
    assert np.allclose(ratio[core], 10.0) and np.allclose(ratio[outside], 1.0)
    mixed = ~core & ~outside
    assert np.all((ratio[mixed] >= 1.0 - 1e-12) & (ratio[mixed] <= 10.0 + 1e-12)) and np.any(ratio[mixed] > 1.5)


def test_undamped_symplectic_energy_is_bounded_over_10000_steps():
    vol = box_volume((0.03, 0.03, 0.03), 0.01)
    m = MassSpringModel(vol, _elastic(damping=0.0, relax_fraction=0.0, nonlinear=2.0))
    rng = np.random.default_rng(1)
    m.positions += rng.normal(0.0, 5e-4, m.positions.shape)
    dt = 0.1 * m.critical_dt()
    e = np.empty(10_000)
    e0 = m.kinetic_energy() + m.elastic_energy()
    for k in range(10_000):
        m.step(dt)
        e[k] = m.kinetic_energy() + m.elastic_energy()
    # symplectic Euler: an O(dt) bounded oscillation of the energy ...
    assert np.max(np.abs(e - e0)) < 0.1 * e0
    # ... and no secular drift: the mean energy early and late agree
    assert abs(e[-1000:].mean() - e[:1000].mean()) < 0.005 * e0


@pytest.mark.parametrize("integrator", ["symplectic", "implicit"])
def test_damped_energy_decays_monotonically(integrator):
    vol = box_volume((0.03, 0.03, 0.03), 0.01)
    m = MassSpringModel(vol, _elastic(damping=20.0), integrator=integrator)
    m.positions += np.random.default_rng(2).normal(0.0, 5e-4, m.positions.shape)
    # small explicit dt: symplectic Euler's energy oscillates by O(dt * omega) about the true value
    dt = 0.05 * m.critical_dt() if integrator == "symplectic" else 1e-3
    energies = [m.kinetic_energy() + m.elastic_energy()]
    steps_per_sample = max(1, int(round(2e-3 / dt)))
    while len(energies) < 150:
        for _ in range(steps_per_sample):
            m.step(dt)
        energies.append(m.kinetic_energy() + m.elastic_energy())
    energies = np.array(energies)
    assert np.all(np.diff(energies) <= 0.02 * energies[0])
    assert energies[-1] < 0.2 * energies[0]


def test_internal_forces_sum_to_zero_and_free_body_keeps_its_momentum():
    vol = box_volume((0.03, 0.02, 0.02), 0.005)
    m = MassSpringModel(vol, _elastic(damping=0.0, relax_fraction=0.5, nonlinear=3.0))
    rng = np.random.default_rng(3)
    m.positions += rng.normal(0.0, 1e-3, m.positions.shape)
    m.velocities[:] = rng.normal(0.0, 0.01, m.velocities.shape)
    f = m.internal_forces()
    assert np.abs(f).sum() > 0
    assert np.allclose(f.sum(axis=0), 0.0, atol=1e-10 * np.abs(f).sum())
    p0 = m.momentum().copy()
    for _ in range(500):
        m.step(0.5 * m.critical_dt())
    assert np.allclose(m.momentum(), p0, atol=1e-9 * np.abs(m.masses[:, None] * m.velocities).sum() + 1e-15)


def test_held_compression_relaxes_to_long_term_fraction_with_time_constant_tau():
    g1, tau = 0.5, 1.0
    vol = box_volume((0.02, 0.02, 0.02), 0.005)
    top, bot = _faces(vol)
    # heavy nodal damping removes the ramp's vibration; it does not change the equilibrium force
    m = MassSpringModel(vol, _elastic(relax_fraction=g1, relax_time=tau, nonlinear=0.0, damping=30.0),
                        integrator="implicit", fixed=top | bot)
    dt, ramp, hold, strain = 1e-3, 0.1, 6 * tau, 0.05
    H = np.ptp(vol.nodes[:, 2])
    rest_top = vol.nodes[top]

    def top_force():
        return m.internal_forces()[top][:, 2].sum()  # upward push of the tissue on the plate (N)

    n_ramp = int(round(ramp / dt))
    for k in range(1, n_ramp + 1):
        x = k / n_ramp
        m.set_fixed(top, rest_top - [0.0, 0.0, strain * H * x * x * (3 - 2 * x)])  # smooth start and stop
        m.step(dt)
    peak = top_force()
    assert peak > 0
    forces = []
    for _ in range(int(round(hold / dt))):
        m.step(dt)
        forces.append(top_force())
    forces = np.array(forces)
    # monotonic decay (sampled every 10 ms; a < 1 % wiggle from the ramp allowed)
    assert np.all(np.diff(forces[::10]) <= 1e-2 * peak)
    assert np.all(np.diff(forces[50:]) < 0)  # strictly once the ramp's vibration has died out
    final = forces[-1]
    assert final / peak == pytest.approx(1.0 - g1, rel=0.1)
    # time constant: one tau into the hold, (F - F_inf) / (F0 - F_inf) ~ exp(-1)
    f_tau = forces[int(round(tau / dt)) - 1]
    assert (f_tau - final) / (peak - final) == pytest.approx(math.exp(-1.0), abs=0.1)


def _secant_stiffness(nonlinear, strains):
    """|F| / strain (N) of a 2 cm cube clamped between plates, relaxed equilibrium at each strain
    (positive strain = compression, negative = tension)."""
    vol = box_volume((0.02, 0.02, 0.02), 0.005)
    top, bot = _faces(vol)
    m = MassSpringModel(vol, _elastic(nonlinear=nonlinear), fixed=top | bot)
    H = np.ptp(vol.nodes[:, 2])
    out = []
    for s in strains:
        m.set_fixed(top, vol.nodes[top] - [0.0, 0.0, s * H])
        m.static_solve()
        out.append(abs(m.internal_forces()[top][:, 2].sum()) / abs(s))
    return np.array(out)


def test_large_strain_stiffens_the_force_strain_curve():
    stretch = -np.array([0.02, 0.05, 0.1, 0.15, 0.2])
    liver = _secant_stiffness(tissue.PRESETS["liver"].nonlinear, stretch)
    assert liver[-1] > liver[0]  # secant stiffness at 20 % > at 2 %
    # the cubic term K2 stiffens beyond the geometric change of the linear network, both ways.
    # Compression stays at <= 10 %: near 15 % this spring network buckles between the plates
    # (its lowest tangent eigenvalue reaches zero) and static_solve returns the folded minimum.
    for strains, nonlinear in ((stretch, 5.0), (np.array([0.02, 0.05, 0.08, 0.1]), 20.0)):
        linear = _secant_stiffness(0.0, strains)
        stiff = _secant_stiffness(nonlinear, strains)
        assert stiff[-1] / stiff[0] > linear[-1] / linear[0] + 0.05
        assert np.all(np.diff(stiff / linear) > 0)


def test_implicit_is_stable_at_1ms_for_skin_where_symplectic_raises():
    vol = box_volume((0.04, 0.04, 0.02), 0.005)
    top, bot = _faces(vol)
    push = np.zeros((vol.n_nodes, 3))
    push[top, 2] = -1.0 / top.sum()  # 1 N spread over the top face
    implicit = MassSpringModel(vol, "skin", integrator="implicit", fixed=bot)
    assert implicit.critical_dt() < 1e-3
    for _ in range(300):
        implicit.step(1e-3, push)
    disp = np.linalg.norm(implicit.positions - implicit.rest_positions, axis=1).max()
    assert np.isfinite(disp) and 0 < disp < 2e-3
    # contact stiffness is accepted and treated implicitly
    implicit.step(1e-3, push, stiffness=np.full(vol.n_nodes, 1e4))
    explicit = MassSpringModel(vol, "skin", integrator="symplectic", fixed=bot)
    with pytest.raises(TissueUnstableError) as info:
        for _ in range(300):
            explicit.step(1e-3, push)
    assert info.value.critical_dt < 1e-3
    assert np.all(np.isfinite(explicit.critical_dt()))


def test_symplectic_is_stable_below_its_critical_dt_estimate():
    vol = box_volume((0.03, 0.03, 0.02), 0.005)
    m = MassSpringModel(vol, "skin", fixed=_faces(vol)[1])
    m.velocities[~m.fixed] = np.random.default_rng(4).normal(0.0, 0.05, (int((~m.fixed).sum()), 3))
    dt = 0.95 * m.critical_dt()
    for _ in range(2000):
        m.step(dt)
    assert np.all(np.isfinite(m.positions))


def test_overrides_set_the_paper_parameters_and_reset_clears_branches():
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    m = MassSpringModel(vol, "liver", K1=50.0, K2=1e6, b0=0.01, b1=2.0)
    assert np.all(m.K1 == 50.0) and np.all(m.K2 == 1e6) and np.all(m.b0 == 0.01) and np.all(m.b1 == 2.0)
    g1 = tissue.PRESETS["liver"].relax_fraction
    assert np.allclose(m.kM, g1 / (1 - g1) * 50.0)
    assert np.allclose(m.tau, 2.0 / m.kM)
    from_extra = MassSpringModel(vol, tissue.PRESETS["liver"].replace(extra={"K1": 20.0}))
    assert np.all(from_extra.K1 == 20.0)
    m.positions[0] += 1e-3
    m.step(1e-4)
    assert np.abs(m.branch_forces()).max() > 0
    m.reset()
    assert np.abs(m.branch_forces()).max() == 0 and m.elastic_energy() == 0


def test_bad_input_raises_config_error_with_the_fix():
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    with pytest.raises(ConfigError, match="K1"):
        MassSpringModel(vol, "liver", K1=-1.0)
    with pytest.raises(ConfigError, match="b0"):
        MassSpringModel(vol, "liver", b0=float("nan"))
    with pytest.raises(ConfigError, match="integrator"):
        MassSpringModel(vol, "liver", integrator="rk4")
    with pytest.raises(ConfigError, match="springs"):
        MassSpringModel(vol, "liver", springs="lattice")
    with pytest.raises(ConfigError, match="relax_fraction"):
        MassSpringModel(vol, _elastic(relax_fraction=0.0), b1=1.0)
    m = MassSpringModel(vol, "liver", integrator="implicit")
    for bad_dt in (0.0, -1e-3, float("nan")):
        with pytest.raises(ConfigError, match="dt"):
            m.step(bad_dt)
    with pytest.raises(ConfigError, match="stiffness"):
        m.step(1e-3, stiffness=np.ones(3))
    with pytest.raises(ConfigError, match="fixed"):
        m.static_solve()


def test_speed_bench_rows_cover_every_integrator_and_reject_bad_sizes():
    from surgsim_envs.bench import speed

    rows = speed.run_bench([30], repeats=1, steps=2, warmup=1, models=["mass_spring"], progress=False)
    assert [r["integrator"] for r in rows] == list(MassSpringModel.integrators)
    for r in rows:
        assert set(r) == {"model", "integrator", "nodes", "dt_s", "us_per_step"}
        assert r["model"] == "mass_spring" and r["us_per_step"] > 0
        assert abs(r["nodes"] - 30) <= 15
    with pytest.raises(ConfigError, match="sizes"):
        speed.parse_sizes("250,abc")


def test_speed_bench_reruns_a_diverged_explicit_case_at_a_stable_dt_and_names_it():
    """Symplectic mass-spring at 245 nodes is stable at rest at 1 ms but its critical dt under the
    0.5 N load is 0.943 ms: the row runs at DT_SAFETY x the reported critical dt and says so."""
    from surgsim_envs.bench import speed
    from surgsim_envs.tissue.base import DT_SAFETY

    row = speed.time_model(MassSpringModel, "symplectic", 250, repeats=5, steps=50, warmup=20)
    assert row["nodes"] == 245
    assert row["us_per_step"] is not None and row["us_per_step"] > 0
    assert "error" not in row
    assert 0.5e-3 < row["dt_s"] < DT_SAFETY * 1.2e-3         # below the loaded critical dt, not a blind halving
    assert "unstable at dt 1 ms" in row["note"] and f"{DT_SAFETY} x critical" in row["note"]


def test_speed_bench_row_names_why_a_case_failed():
    from surgsim_envs.bench import speed
    from surgsim_envs.errors import TissueUnstableError

    class AlwaysUnstable:
        name, integrators = "always_unstable", ("symplectic",)
        default_integrator, auto_pair, capabilities = "symplectic", None, ()

        def __init__(self, vol, material, integrator, fixed):
            self.n_nodes = vol.n_nodes

        def stable_dt(self):
            return 1e-3

        def step(self, dt, forces):
            raise TissueUnstableError(self.name, dt, dt / 2, "node speed too high")

    class Broken(AlwaysUnstable):
        name = "broken"

        def step(self, dt, forces):
            raise ZeroDivisionError("division by zero")

    row = speed.time_model(AlwaysUnstable, "symplectic", 30, repeats=1, steps=1, warmup=1)
    assert row["us_per_step"] is None
    assert row["error"].startswith("unstable: tissue model 'always_unstable' became unstable")
    assert row["dt_s"] == pytest.approx(1e-3 * (0.8 / 2) ** speed.RETRIES)   # retried RETRIES times, then gave up
    row = speed.time_model(Broken, "symplectic", 30, repeats=1, steps=1, warmup=1)
    assert row["us_per_step"] is None and row["error"] == "ZeroDivisionError: division by zero"
    table = speed.format_table([row])
    assert "failed [1]" in table and "[1] broken/symplectic/" in table


# --- integrator="auto" (the default): explicit below 0.8 x critical_dt(), implicit above -----------
def test_auto_integrator_is_the_default_and_switches_with_dt():
    vol = box_volume((0.02, 0.02, 0.02), 0.005)
    m = MassSpringModel(vol, "skin", fixed=_faces(vol)[1])
    assert m.integrator == "auto" and "auto" in MassSpringModel.integrator_names()
    crit = m.critical_dt()
    assert m._cg is None                              # implicit buffers are allocated lazily
    m.step(0.5 * crit)
    assert m.active_integrator == "symplectic" and m._cg is None
    m.step(2.0 * crit)                                # a new dt re-evaluates the choice
    assert m.active_integrator == "implicit" and m._cg is not None
    assert m.describe()["integrator"] == "auto" and m.describe()["active_integrator"] == "implicit"
    m.step(0.5 * crit)
    assert m.active_integrator == "symplectic"
    # the boundary is the documented rule, and the choice is a function of the state only
    from surgsim_envs.tissue.base import DT_SAFETY as AUTO_SAFETY
    assert m.choose_integrator(0.999 * AUTO_SAFETY * m.critical_dt()) == "symplectic"
    assert m.choose_integrator(1.001 * AUTO_SAFETY * m.critical_dt()) == "implicit"


def test_auto_takes_contact_stiffness_into_account():
    vol = box_volume((0.02, 0.02, 0.02), 0.005)
    m = MassSpringModel(vol, "liver", fixed=_faces(vol)[1])
    dt = 0.5 * m.critical_dt()
    assert m.choose_integrator(dt) == "symplectic"
    kc = np.zeros(m.n_nodes)
    kc[_faces(vol)[0]] = 100.0 * float(m.K1.max())     # stiff penalty springs on the top face
    assert m.choose_integrator(dt, kc) == "implicit"
    m.step(dt, np.zeros_like(m.positions), kc)
    assert m.active_integrator == "implicit"


def test_auto_is_deterministic_and_stable_where_the_explicit_integrator_fails():
    vol = box_volume((0.02, 0.02, 0.02), 0.005)

    def run(integ):
        m = MassSpringModel(vol, "skin", integrator=integ, fixed=_faces(vol)[1])
        f = np.zeros_like(m.positions)
        f[_faces(vol)[0], 2] = -0.01
        chosen = []
        for dt in [0.5 * m.critical_dt()] * 5 + [1e-3] * 50:   # skin: critical dt ~ 0.3 ms
            m.step(dt, f)
            chosen.append(m.active_integrator)
        return m.positions.copy(), chosen

    x1, chosen = run("auto")
    x2, chosen2 = run("auto")
    assert np.array_equal(x1, x2) and chosen == chosen2            # same inputs, same choices
    assert chosen[:5] == ["symplectic"] * 5 and set(chosen[5:]) == {"implicit"}
    with pytest.raises(TissueUnstableError):
        run("symplectic")


# --- optional volume term (Teschner et al. 2004) ---------------------------------------------------
def _uniaxial(m, vol):
    """Roller-end uniaxial compression (small strain, linear): (E_eff / E, effective Poisson ratio)."""
    K = m.stiffness_matrix(relaxed=True)
    X = vol.nodes
    top, bot = _faces(vol)
    n, H, eps = vol.n_nodes, np.ptp(X[:, 2]), 1e-3
    u, fixed = np.zeros(3 * n), np.zeros(3 * n, bool)
    fixed[3 * np.flatnonzero(top) + 2] = fixed[3 * np.flatnonzero(bot) + 2] = True
    b = np.flatnonzero(bot)
    fixed[3 * b[0]] = fixed[3 * b[0] + 1] = fixed[3 * b[-1] + 1] = True
    u[3 * np.flatnonzero(top) + 2] = -eps * H
    free = ~fixed
    u[free] = spla.spsolve(K[free][:, free].tocsc(), -K[free][:, fixed] @ u[fixed])
    force = -(K @ u)[3 * np.flatnonzero(top) + 2].sum()
    x = X[:, 0]
    U = u.reshape(-1, 3)
    lateral = (U[np.isclose(x, x.max()), 0].mean() - U[np.isclose(x, x.min()), 0].mean()) / np.ptp(x)
    return force / (np.ptp(x) * np.ptp(X[:, 1])) / eps / m.material.young, lateral / eps


@pytest.mark.parametrize("poisson", [0.3, 0.45, 0.49])
def test_volume_term_auto_gives_the_material_poisson_ratio_and_modulus(poisson):
    vol = box_volume()
    mat = _elastic(poisson=poisson, relax_fraction=0.0, nonlinear=0.0)
    e_plain, nu_plain = _uniaxial(MassSpringModel(vol, mat), vol)
    e_auto, nu_auto = _uniaxial(MassSpringModel(vol, mat, volume_stiffness="auto"), vol)
    e_capped, nu_capped = _uniaxial(MassSpringModel(vol, mat, volume_stiffness="capped"), vol)
    assert nu_plain < 0.1                              # the bare network barely bulges
    assert abs(nu_auto - poisson) < 0.05 and abs(e_auto - 1.0) < 0.1
    # "capped" (the point-load option): the material's E, its Poisson ratio up to the cap (0.123), not more
    assert abs(nu_capped - CAPPED_POISSON) < 0.03 and abs(e_capped - 1.0) < 0.05
    # a fixed k_v leaves the springs alone and only adds bulk stiffness
    e_kv, nu_kv = _uniaxial(MassSpringModel(vol, mat, volume_stiffness=2.0 * mat.young), vol)
    assert nu_kv > nu_plain + 0.2 and e_kv > e_plain


def test_volume_forces_are_the_energy_gradient_and_sum_to_zero():
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    m = MassSpringModel(vol, _elastic(relax_fraction=0.0), volume_stiffness="auto")
    rng = np.random.default_rng(3)
    m.positions = m.positions + rng.normal(0.0, 1e-3, m.positions.shape)
    f = m.volume_forces()
    assert np.abs(f).max() > 0
    scale = np.abs(f).max()
    assert np.abs(f.sum(axis=0)).max() < 1e-10 * scale                       # no net force
    assert np.abs(np.cross(m.positions, f).sum(axis=0)).max() < 1e-10 * scale  # no net torque
    # central differences of the energy
    h = 1e-8
    for node, axis in [(0, 0), (5, 1), (13, 2)]:
        xp, xm = m.positions.copy(), m.positions.copy()
        xp[node, axis] += h
        xm[node, axis] -= h
        grad = (m.volume_energy(xp) - m.volume_energy(xm)) / (2 * h)
        assert grad == pytest.approx(-f[node, axis], rel=1e-5, abs=1e-9 * scale)
    total = m.internal_forces()
    assert np.abs(total.sum(axis=0)).max() < 1e-9 * np.abs(total).max()


def test_volume_term_conserves_energy_undamped_and_lowers_critical_dt():
    vol = box_volume((0.03, 0.03, 0.03), 0.01)
    mat = _elastic(damping=0.0, relax_fraction=0.0, nonlinear=2.0)
    m = MassSpringModel(vol, mat, volume_stiffness="auto")
    assert m.critical_dt() < MassSpringModel(vol, mat).critical_dt()
    rng = np.random.default_rng(1)
    m.positions += rng.normal(0.0, 5e-4, m.positions.shape)
    dt = 0.1 * m.critical_dt()
    e0 = m.kinetic_energy() + m.elastic_energy()
    e = np.empty(5000)
    for k in range(5000):
        m.step(dt)
        e[k] = m.kinetic_energy() + m.elastic_energy()
    assert m.active_integrator == "symplectic"
    assert np.max(np.abs(e - e0)) < 0.1 * e0
    assert abs(e[-500:].mean() - e[:500].mean()) < 0.005 * e0


@pytest.mark.parametrize("preset", ["liver", "silicone"])
def test_capped_volume_term_keeps_the_plain_networks_explicit_limit(preset):
    """"capped" raises the network's Poisson ratio only as far as its P-wave modulus allows: the exact
    explicit limit 2 / sqrt(lambda_max(M^-1 K)) stays within 3 % of the plain network's; "auto"
    (liver nu 0.45, silicone 0.49) shortens it 2-16x. The rest state stores no volume energy."""
    vol = box_volume((0.03, 0.03, 0.03), 0.01)
    mat = tissue.get_material(preset).replace(relax_fraction=0.0)

    def exact_limit(m):
        K = m.stiffness_matrix().toarray()
        minv = 1.0 / np.sqrt(np.repeat(m.masses, 3))
        return 2.0 / math.sqrt(np.linalg.eigvalsh(minv[:, None] * K * minv[None, :]).max())

    plain, capped, auto = (MassSpringModel(vol, mat, volume_stiffness=v) for v in (None, "capped", "auto"))
    assert exact_limit(capped) >= 0.97 * exact_limit(plain)
    assert exact_limit(auto) < 0.5 * exact_limit(plain)
    assert capped.volume_energy() == 0.0


def test_volume_term_critical_dt_bounds_the_explicit_limit():
    vol = box_volume((0.02, 0.02, 0.02), 0.005)
    m = MassSpringModel(vol, _elastic(relax_fraction=0.0, damping=0.0), integrator="symplectic",
                        volume_stiffness="auto", fixed=_faces(vol)[1])
    K = m.stiffness_matrix().toarray()
    free = np.repeat(~m.fixed, 3)
    minv = 1.0 / np.sqrt(np.repeat(m.masses, 3))[free]
    lam = np.linalg.eigvalsh(minv[:, None] * K[free][:, free] * minv[None, :]).max()
    assert m.critical_dt() <= 2.0 / math.sqrt(lam) * (1 + 1e-9)     # Gershgorin: conservative
    assert m.critical_dt() > 0.3 * 2.0 / math.sqrt(lam)              # ... but not absurdly so


def _compress(vol, volume_stiffness, strain=0.2):
    """Implicit, damped ramp of the top plate down by ``strain`` between no-slip plates."""
    from surgsim_envs.tissue.mass_spring import _count_inverted

    top, bot = _faces(vol)
    mat = tissue.get_material("silicone").replace(poisson=0.45, damping=50.0)
    m = MassSpringModel(vol, mat, integrator="implicit", volume_stiffness=volume_stiffness, fixed=top | bot)
    H = np.ptp(vol.nodes[:, 2])
    for k in range(300):
        target = vol.nodes[top].copy()
        target[:, 2] -= strain * H * min(1.0, (k + 1) / 150)
        m.set_fixed(top, target)
        m.step(1e-3)
    return m, _count_inverted(m.positions, vol.tets)


def test_volume_term_stops_tets_inverting_under_20_percent_compression():
    vol = box_volume((0.012, 0.012, 0.012), 0.002)
    plain, inv_plain = _compress(vol, None)
    kept, inv_kept = _compress(vol, "auto")
    assert inv_plain > 0              # the bare network folds (docs/models/mass_spring.md)
    assert inv_kept == 0
    # and it bulges: the mid-height perimeter moves outward (about the section's centroid: the box
    # lattice also shears sideways) by a good fraction of what volume conservation needs
    # (section area +25 % at 20 %: half-width x (1/sqrt(0.8) - 1) = 0.7 mm if uniform)
    X = vol.nodes
    half = 0.5 * np.ptp(X[:, 0])
    mid = np.isclose(X[:, 2], 0.0) & (np.abs(X[:, :2]).max(axis=1) > half - 1e-9)

    def radial_growth(x):
        c = x[mid, :2].mean(axis=0)
        return np.linalg.norm(x[mid, :2] - c, axis=1) - np.linalg.norm(X[mid, :2], axis=1)

    assert radial_growth(kept.positions).min() > 0.3e-3 and radial_growth(kept.positions).mean() > 0.5e-3
    assert radial_growth(plain.positions).mean() < 0.1e-3
    # the relaxed equilibrium (static_solve includes the volume term) agrees and is unfolded too
    from surgsim_envs.tissue.mass_spring import _count_inverted
    x = kept.static_solve()
    assert _count_inverted(x, vol.tets) == 0 and kept.static_lowest_eigenvalue > 0


def test_volume_stiffness_bad_values_are_rejected():
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    with pytest.raises(ConfigError, match="volume_stiffness"):
        MassSpringModel(vol, "liver", volume_stiffness="big")
    with pytest.raises(ConfigError, match="volume_stiffness"):
        MassSpringModel(vol, "liver", volume_stiffness=-1.0)
    m = MassSpringModel(vol, "liver")
    assert m.volume_energy() == 0.0 and not m.volume_forces().any() and m.describe()["volume_stiffness"] is None

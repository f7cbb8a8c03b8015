"""The contact's plane law (surgsim_envs/contact_law/plane.py, built by surgsim_envs/contact/plane_law.py) and fem_static's step that solves it
(surgsim_envs/tissue/condensed_plane_solve.py): each pair's solution satisfies its own law, a
sticking contact set gives the linearised step's solution, and in Palpation-v0 a pressed slide keeps
Coulomb's bound at every step and reads the same forces at the task's 1 ms as at a quarter of it
(under ``-m slow``; tests/test_contact_set.py checks Coulomb's bound and the chatter of a pressed
slide in the default run)."""

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs.contact import ContactModel, ContactParams
from surgsim_envs.contact_law.plane import F0, FN0, KN, KT, MU, MU_CAP, ROW, PlaneContactLaw, pair_force, solve_pair
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry import box_volume
from surgsim_envs.tissue import registry


def _random_row(rng):
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    row = np.zeros(ROW)
    row[0:3] = n
    row[KN] = 10 ** rng.uniform(1.5, 4.0)
    row[FN0] = rng.uniform(0.0, 0.5)
    t = rng.normal(size=3) * 10 ** rng.uniform(-6, -3)
    row[5:8] = t - (t @ n) * n
    row[KT] = row[KN] * rng.uniform(0.3, 2.0)
    row[MU] = rng.uniform(0.05, 1.5)
    row[MU_CAP] = row[MU] * rng.choice([1.0, rng.uniform(1.0, 1.5)])
    pair_force(row, 0.0, 0.0, 0.0, row[F0:F0 + 3])
    return row


def test_each_pair_solution_satisfies_its_own_law():
    """For random pairs, loads and compliances whose off-diagonal coupling stays within 0.3 of the
    diagonal (a tissue surface's: a half-space's is 0.09 at nu 0.45): F = law(d0 + a F), f_n >= 0 and
    |F_t| <= mu_c f_n (stick, slide and open cases all occur)."""
    rng = np.random.default_rng(3)
    out, chk, work = np.empty(3), np.empty(3), np.empty((5, 3))
    seen = set()
    for _ in range(3000):
        row = _random_row(rng)
        m = rng.normal(size=(3, 3))
        m = (m + m.T) / np.abs(np.linalg.eigvalsh(m + m.T)).max()          # symmetric, norm 1
        a = (np.eye(3) + 0.3 * m) * 10 ** rng.uniform(-3.5, -1.0)   # SPD with a surface's coupling, m/N
        d0 = rng.normal(size=3) * 10 ** rng.uniform(-5, -2.5)
        state = solve_pair(row, a, d0, out, work)
        seen.add(state)
        pair_force(row, *(d0 + a @ out), chk)
        assert np.abs(chk - out).max() <= 1e-9 * max(np.abs(out).max(), 1e-6), (state, out, chk)
        n = row[0:3]
        fn = out @ n
        assert fn >= 0.0
        assert np.linalg.norm(out - fn * n) <= row[MU_CAP] * fn * (1 + 1e-9) + 1e-15
    assert seen == {0, 1, 2}


def _slab():
    vol = box_volume((0.04, 0.04, 0.02), 0.005, center=(0.0, 0.0, 0.01))
    model = registry.get("fem_static")(vol, "liver", fixed=np.isclose(vol.nodes[:, 2], 0.0))
    top = np.flatnonzero(np.isclose(model.rest_positions[:, 2], 0.02))
    return model, top[:6]


def test_a_sticking_contact_set_gives_the_linearised_step():
    """Every pair sticks (mu 10) with k_t = k_n: the plane law's force is the linearised one,
    f - k (x - x^n), so the step must match the isotropic-stiffness step to the sweeps' tolerance."""
    model, nodes = _slab()
    k = 300.0
    law = PlaneContactLaw(nodes.astype(np.int64), np.zeros((len(nodes), ROW)), len(nodes))
    rng = np.random.default_rng(0)
    forces = np.zeros_like(model.positions)
    for p, i in enumerate(nodes):
        row = law.data[p]
        row[0:3] = (0.0, 0.0, 1.0)
        row[KN], row[KT], row[MU], row[MU_CAP] = k, k, 10.0, 10.0
        row[FN0] = 0.02 + 0.01 * rng.random()
        row[5:7] = rng.normal(size=2) * 2e-5
        pair_force(row, 0.0, 0.0, 0.0, row[F0:F0 + 3])
        forces[i] = row[F0:F0 + 3]
    stiffness = np.zeros(model.n_nodes)
    stiffness[nodes] = k
    start = model.step_state()
    model.step(1e-3, forces, stiffness)
    linearised = model.positions.copy(), model.integrated_external_forces.copy()
    model.restore_step_state(start, start[0])
    model.step(1e-3, forces, law)
    # the sweeps stop when no pair's force moves by 1e-6 of the largest (PLANE_LAW_TOLERANCE)
    moved = np.abs(linearised[0] - start[0]).max()
    assert moved > 1e-5
    np.testing.assert_allclose(model.positions - start[0], linearised[0] - start[0], rtol=0, atol=1e-5 * moved)
    np.testing.assert_allclose(model.integrated_external_forces, linearised[1], rtol=0,
                               atol=1e-5 * np.abs(linearised[1]).max())
    assert model.last_sweeps < 100


def test_a_plane_law_on_surface_samples_or_a_non_penalty_cap_is_refused():
    cm = ContactModel(3, [0, 1, 2], [0.3], ContactParams(stiffness=100.0, damping=0.0))
    cm.set_friction_cap("integrated")
    with pytest.raises(ConfigError, match="penalty"):
        cm.set_contact_law("plane")
    with pytest.raises(ConfigError, match="linearised"):
        cm.set_contact_law("exact")


def _pressed_slide(dt: float, steps: tuple[int, int] = (40, 30)):
    """Palpation-v0 with the plane law, seed 5: pressed 0.6, then sliding at half speed in x. Returns
    the normal reading at the end of the press, the mean normal and drag readings over the slide,
    and the largest tangential / (mu normal) reading of any control step."""
    env = gym.make("SurgSim/Palpation-v0", dt=dt, contact_law="plane", disable_env_checker=True).unwrapped
    contact = next(iter(env.sim.contacts.values()))
    mu = float(np.max(contact.tool_friction))
    env.reset(seed=5)
    press, normal, drag, worst = 0.0, [], [], 0.0
    for i in range(sum(steps)):
        env.step(np.array([0.0 if i < steps[0] else 0.5, 0.0, 0.6, -1.0], dtype=np.float32))
        rep = contact.report
        if rep.normal_force[0] > 1e-3:
            worst = max(worst, float(rep.tangential_force[0]) / (mu * float(rep.normal_force[0])))
        if i == steps[0] - 1:
            press = float(rep.normal_force[0])
        elif i >= steps[0]:
            normal.append(float(rep.normal_force[0]))
            drag.append(float(env.sim.tool_force("probe")[0]))
    env.close()
    return press, float(np.mean(normal)), float(np.mean(drag)), worst


@pytest.mark.slow
def test_a_pressed_slide_keeps_coulomb_and_reads_the_press_at_half_the_step():
    """The plane law solves each step's friction: no control step's readings exceed mu times the
    normal (the linearised default exceeds it by about 35 %), and the press reads the same at the
    task's 1 ms as at 0.5 ms within 1 %."""
    coarse = _pressed_slide(1e-3)
    fine = _pressed_slide(5e-4)
    assert coarse[3] <= 1.0 + 1e-9 and fine[3] <= 1.0 + 1e-9
    assert coarse[0] == pytest.approx(fine[0], rel=0.01)


@pytest.mark.slow
def test_a_pressed_slide_reads_the_same_at_a_quarter_of_the_step():
    """The pressed slide of scripts/palpation_slide_dt.py (60 control steps of press, 140 of slide at
    half speed, the last 45 held at the workspace's edge): at the task's 1 ms the press and the
    slide's mean normal read within 2 %, its mean drag within 5 %, of 0.25 ms steps."""
    coarse = _pressed_slide(1e-3, (60, 140))
    fine = _pressed_slide(2.5e-4, (60, 140))
    assert coarse[3] <= 1.0 + 1e-9 and fine[3] <= 1.0 + 1e-9
    assert coarse[0] == pytest.approx(fine[0], rel=0.02)
    assert coarse[1] == pytest.approx(fine[1], rel=0.02)
    assert abs(coarse[2]) > 0.05 and coarse[2] == pytest.approx(fine[2], rel=0.05)


def test_the_task_option_is_checked_and_the_plane_law_refused_where_it_cannot_apply():
    with pytest.raises(ConfigError, match="'auto'"):
        gym.make("SurgSim/Palpation-v0", contact_law="exact")
    with pytest.raises(ConfigError, match="plane_contact_law"):
        gym.make("SurgSim/Palpation-v0", contact_law="plane", model="mass_spring", spacing=0.01)
    env = gym.make("SurgSim/Palpation-v0", model="mass_spring", spacing=0.01).unwrapped   # "auto": linearised
    assert next(iter(env.sim.contacts.values())).contact_law == "linearised"
    env.close()

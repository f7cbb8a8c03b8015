"""mass_spring_calibrated under integrator "auto" in the compiled substeps (tissue/calibrated_mass_spring_compiled.py,
the calibrated model): each step the loop takes is the one the generic loop takes (symplectic, "subcycled" n steps of
dt / n, or implicit), with the same state, contact forces, tool wrenches, Maxwell-branch interval and
guard reference. Equal to 1e-12 relative: bit for bit when numba compiles the kernels in the process,
while a kernel loaded from numba's cache may round the fastmath nodal-volume pass's last bit differently
(CHANGELOG.md "Env step: address table, pluggable tissue step")."""

from __future__ import annotations

import collections

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs.scene.step.compiled import registered
from surgsim_envs.tissue.calibrated_mass_spring_compiled import subcycles_for
from surgsim_envs.tissue.base import DT_SAFETY


def _pair(**config):
    """Two Palpation-v0 envs on the calibrated tissue in the same state: compiled, then generic."""
    envs = [gym.make("SurgSim/Palpation-v0", model="mass_spring_calibrated", **{"spacing": 0.01, **config})
            for _ in range(2)]
    for e in envs:
        e.reset(seed=3)
    envs[1].unwrapped.sim.compiled_substeps = False
    return envs


def _press(env, n):
    a = np.random.default_rng(1).uniform(-1, 1, (n, *env.action_space.shape)).astype(np.float32)
    a[:, 2] = np.linspace(-1, 0.8, n)     # press progressively deeper: contact is certain
    a[:, -1] = -1.0                       # never report: the episode keeps going
    return a


def _close(x, y, rtol=1e-12):
    np.testing.assert_allclose(x, y, rtol=0, atol=rtol * max(1.0e-30, float(np.abs(y).max())))


# dt and stiffness such that "auto" takes each kind of step (critical dt ~2 ms at young_scale 1)
CASES = {"symplectic": dict(), "subcycled": dict(dt=2.5e-3, young_scale=(1.0, 1.2)),
         "implicit": dict(dt=5e-3, young_scale=(3.0, 3.0))}


@pytest.mark.parametrize("kind", list(CASES))
def test_auto_steps_compiled_as_the_generic_loop(kind):
    envs = _pair(**CASES[kind])
    s0, s1 = (e.unwrapped.sim for e in envs)
    assert s0.tissue().integrator == "auto"
    assert s0.compiled_runner() is not None and s1.compiled_runner() is None
    used = collections.Counter()
    touched = 0
    for a in _press(envs[0], 12):
        outs = [e.step(a) for e in envs]
        np.testing.assert_allclose(outs[0][0], outs[1][0], rtol=1e-5, atol=1e-6)    # float32 observations
        t0, t1 = s0.tissue(), s1.tissue()
        c0, c1 = next(iter(s0.contacts.values())), next(iter(s1.contacts.values()))
        for x, y in [(t0.positions, t1.positions), (t0.velocities, t1.velocities), (t0._s, t1._s),
                     (t0.integrated_external_forces, t1.integrated_external_forces),
                     (c0.result.forces, c1.result.forces), (c0.result.tool_force, c1.result.tool_force),
                     (s0.data.qpos, s1.data.qpos), (s0.data.xfrc_applied, s1.data.xfrc_applied)]:
            _close(x, y)
        assert (t0.steps, s0.steps, t0._pending_dt) == (t1.steps, s1.steps, t1._pending_dt)
        assert t0.active_integrator == t1.active_integrator
        # the reference (J) sums in another order in the kernel; at rest it is ~1e-31 J of rounding
        assert t0.guard.state()[0] == pytest.approx(t1.guard.state()[0], rel=1e-12, abs=1e-18)
        used[t0.active_integrator] += 1
        touched += int(c0.report.contacts.sum())
    assert touched > 0, "no contact: the comparison would be vacuous"
    assert used[kind] > 0, f"no {kind} step in the run ({dict(used)}): the case tests nothing"
    if kind == "implicit":
        assert s0.tissue().last_cg_iterations == s1.tissue().last_cg_iterations > 0


def test_subcycle_count_is_the_models_choice():
    """The kernel's choice equals CalibratedMassSpringModel._pick: n = ceil(dt / stable dt) up to
    MAX_SUBCYCLES, 0 (implicit) beyond it, for an unknown critical dt, or when the contact stiffness is
    not stable at dt on its own."""
    masses = np.full(4, 1e-3)
    kc = np.zeros(4)
    crit = 1e-3
    assert subcycles_for(0.5 * DT_SAFETY * crit, crit, kc, masses) == 1
    assert subcycles_for(1.5 * DT_SAFETY * crit, crit, kc, masses) == 2
    assert subcycles_for(4.0 * DT_SAFETY * crit, crit, kc, masses) == 4
    assert subcycles_for(4.5 * DT_SAFETY * crit, crit, kc, masses) == 0
    assert subcycles_for(1.5e-3, float("nan"), kc, masses) == 0
    dt = 1.5 * DT_SAFETY * crit
    kc[2] = (DT_SAFETY * 2.0 / dt) ** 2 * masses[2] * 1.01      # contact alone unstable at dt
    assert subcycles_for(dt, crit, kc, masses) == 0
    kc[2] /= 1.03
    assert subcycles_for(dt, crit, kc, masses) == 2
    assert ("ContactModel", "CalibratedMassSpringModel", "auto") in registered()


def _exact_critical_dt(model, masses) -> float:
    """2/sqrt(lambda_max(M^-1 K)) with nodal damping for lumped ``masses`` (ARPACK, tolerance 1e-8)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    free = np.repeat(~model.fixed, 3)
    mi = sp.diags(np.repeat(1.0 / np.sqrt(masses), 3)[free])
    K = model.stiffness_matrix(relaxed=False).tocsr()[free][:, free]
    lam = float(spla.eigsh(mi @ K @ mi, k=1, which="LA", tol=1e-8, return_eigenvectors=False)[0])
    beta = float(np.max(model.b0 / masses))
    return (-beta + np.sqrt(beta * beta + 4.0 * lam)) / lam


def test_sliver_mass_scaling_touches_only_sliver_nodes():
    """Selective mass scaling: a lattice keeps its lumped masses exactly; on the Grasp spleen (lattice cut
    by the organ surface: flat tets) a few nodes get mass, under 1 % in total, and the exact explicit limit
    of the linearised network rises by more than 1.3x (the top mode sat on two sliver nodes)."""
    from surgsim_envs import geometry
    from surgsim_envs.envs.grasp import ORGAN_SPACING
    from surgsim_envs.errors import ConfigError
    from surgsim_envs.tissue import make
    from surgsim_envs.tissue.calibrated_mass_spring import sliver_mass_factors

    box = geometry.box_volume((0.03, 0.03, 0.01), spacing=0.005)
    assert np.all(sliver_mass_factors(box, 4.0) == 1.0)
    spleen = geometry.organ_volume("spleen", spacing=ORGAN_SPACING["spleen"])
    fixed = spleen.nodes[:, 2] <= np.percentile(spleen.nodes[:, 2], 20)
    scaled = make("mass_spring_calibrated", spleen, "spleen", fixed=fixed)
    lumped = np.zeros(spleen.n_nodes)       # the plain row-sum lumped masses (the stiffness does not depend on them)
    np.add.at(lumped, spleen.tets.reshape(-1), np.repeat(scaled.fields["density"] * spleen.tet_volumes() / 4.0, 4))
    raised = scaled.masses > lumped
    assert 0 < raised.sum() < 0.2 * spleen.n_nodes
    np.testing.assert_allclose(scaled.masses[~raised], lumped[~raised], rtol=1e-14)
    assert 1.0 < scaled.masses.sum() / lumped.sum() < 1.01
    assert _exact_critical_dt(scaled, scaled.masses) > 1.3 * _exact_critical_dt(scaled, lumped)
    assert make("mass_spring_calibrated", box, "liver", mass_scaling=None).describe()["mass_scaled_nodes"] == 0
    for bad in (0.5, True, float("nan")):
        with pytest.raises(ConfigError, match="mass_scaling"):
            make("mass_spring_calibrated", box, "liver", mass_scaling=bad)


def test_subcycled_integrator_runs_compiled_across_its_recheck():
    """Integrator "subcycled" (n re-evaluated every AUTO_RECHECK_STEPS steps): the compiled runner steps
    chunk by chunk between the re-evaluations and gives the generic loop's result; the run crosses one."""
    from surgsim_envs.tissue.base import AUTO_RECHECK_STEPS

    # 3 tissue steps per env step: the re-evaluation at step 100 falls inside an env step (loop call)
    envs = _pair(dt=2.5e-3, control_hz=400.0 / 3.0, young_scale=(1.0, 1.2), integrator="subcycled")
    s0, s1 = (e.unwrapped.sim for e in envs)
    assert s0.tissue().integrator == "subcycled" and s0.compiled_runner() is not None
    assert s1.compiled_runner() is None
    assert s0.substeps == 3
    for a in _press(envs[0], 40):
        for e in envs:
            e.step(a)
        t0, t1 = s0.tissue(), s1.tissue()
        for x, y in [(t0.positions, t1.positions), (t0.velocities, t1.velocities), (t0._s, t1._s),
                     (s0.data.qpos, s1.data.qpos)]:
            _close(x, y)
        assert (t0.steps, t0._pending_dt, t0._sub_step) == (t1.steps, t1._pending_dt, t1._sub_step)
    assert t0.steps > AUTO_RECHECK_STEPS and t0._sub_step == AUTO_RECHECK_STEPS, "n not re-evaluated at step 100"
    assert t0._pending_dt < s0.dt, "never sub-cycled: the case tests nothing"


def test_calibrated_table_is_keyed_and_follows_replaced_arrays():
    """The calibrated loop's address table is keyed (``CompiledStep.table_key``: the state version,
    the positions' identity, ``calibrated_mass_spring_compiled.key``), so it is not rebuilt between
    control steps that replace nothing, and a replaced positions array is repacked and stepped, not
    the freed old one."""
    from surgsim_envs.scene.step.loop import POSITIONS_ROW

    env = gym.make("SurgSim/Palpation-v0", model="mass_spring_calibrated", spacing=0.01)
    try:
        env.reset(seed=0)
        sim = env.unwrapped.sim
        tissue, runner = sim.tissue(), sim.compiled_runner()
        assert runner is not None
        act = np.array([0.0, 0.0, 0.5, -1.0], np.float32)
        for _ in range(3):
            env.step(act)
        table, key = runner._table.table, runner._table.key
        env.step(act)
        assert runner._table.key == key and runner._table.table is table      # nothing replaced: no repack
        lifted = tissue.positions + np.array([0.0, 0.0, 1e-4])
        lifted[tissue.fixed] = tissue.positions[tissue.fixed]
        tissue.positions = lifted
        before = lifted.copy()
        env.step(act)
        assert tissue.positions is lifted
        assert runner._table.table[POSITIONS_ROW, 0] == lifted.ctypes.data
        assert not np.array_equal(lifted, before), "the loop did not step the new positions array"
    finally:
        env.close()

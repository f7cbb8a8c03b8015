"""Gross-slip onset from the contact state (bench/slip_onset.py) and in the grasp-and-pull rig."""

import numpy as np
import pytest

from surgsim_envs.bench.material import slip
from surgsim_envs.bench.slip_onset import gross_slip_index
from surgsim_envs.errors import ConfigError


def test_onset_needs_mobilised_friction_sliding_contacts_and_patch_motion():
    n = 50
    share = np.linspace(0, 1, n)
    mob = np.clip(np.linspace(0.2, 1.5, n), 0, 1)   # >= 0.98 from sample 30
    speed = np.where(np.arange(n) > 30, 0.01, 0.001)
    k = gross_slip_index(share, mob, speed, handle_speed=0.01)
    assert k == 31                                        # the last condition to hold is the patch motion
    assert gross_slip_index(share, mob * 0.9, speed, 0.01) is None   # friction never at its cap
    blip = np.zeros(n)
    blip[10:12] = 0.01                                    # two samples are not a slip
    assert gross_slip_index(np.ones(n), np.ones(n), blip, 0.01) is None
    with pytest.raises(ConfigError):
        gross_slip_index(share, mob[:-1], speed, 0.01)


def test_rig_onset_pull_is_mu_times_grip():
    """mass_spring rig at mu = 0.2, where the slide-distance rule read 0.82: within 5 %."""
    res = slip("mass_spring", mu=0.2)
    assert res.slip_onset_pull == pytest.approx(0.2 * res.slip_onset_normal, rel=0.05)


@pytest.mark.slow
@pytest.mark.parametrize("model, mu", [(m, mu) for m in ("mass_spring", "mass_spring_calibrated") for mu in (0.1, 0.6, 1.2)]
                         + [("fem", 0.1), ("fem", 0.6)])
def test_onset_across_mu_and_models(model, mu):
    """Quasi-static pull (handle slower at low mu, longer at high mu). fem (symplectic, 15-20 s a case
    at load ~8) reads 0.980 / 0.981; at mu 1.2 its squeezed, sheared elements invert (TissueUnstableError)."""
    res = slip(model, mu=mu, pull_time=0.6 + 1.0 * mu, handle_speed=0.01 * min(1.0, mu / 0.3))
    assert res.slip_onset_pull == pytest.approx(mu * res.slip_onset_normal, rel=0.05)


@pytest.mark.slow
@pytest.mark.parametrize("model, mu", [(m, mu) for m in ("mass_spring", "mass_spring_calibrated") for mu in (0.1, 0.6)]
                         + [("fem", 0.1)])
def test_onset_with_static_friction_lies_between_kinetic_and_static_grip(model, mu):
    """mu_s = 1.5 mu. The contact law breaks a point away at mu_s f_n and lets it slide at mu f_n
    (exact on a uniform patch: tests/test_static_kinetic_friction.py). A soft grasp is not uniform:
    light edge points break away first and carry only mu f_n while the rest still sticks, so the
    grip gives way between mu * N and mu_s * N (measured 1.04-1.13 mu N, 0.69-0.76 mu_s N, at
    mu 0.1-1.2; fem at mu 0.1: 1.13 mu N; docs/contact.md, "Static and kinetic friction"). Checked: above the kinetic grip
    (static friction adds holding force) and at most the static one."""
    mu_s = 1.5 * mu
    res = slip(model, mu=mu, mu_static=mu_s, pull_time=0.6 + 1.5 * mu, handle_speed=0.01 * min(1.0, mu / 0.3))
    assert res.mu_static == mu_s
    assert 1.0 * mu * res.slip_onset_normal <= res.slip_onset_pull <= mu_s * res.slip_onset_normal


def test_quasi_static_model_without_implicit_contact_is_refused_by_name():
    from surgsim_envs.tissue.capabilities import CapabilityError

    with pytest.raises(CapabilityError, match="neo_hookean.*implicit_contact"):
        slip("neo_hookean", mu=0.6)


def test_bad_handle_is_refused():
    with pytest.raises(ConfigError, match="handle='rope'"):
        slip("mass_spring", mu=0.6, handle="rope")


@pytest.mark.slow
def test_quasi_static_fem_onset_with_a_clamp():
    """fem_static has no inertia: the rig clamps the far end face and slides the jaws (displacement
    control); the clamp's reaction at onset is mu * sum(N) within 5 % (0.969 at dt 0.5 ms, load ~9;
    dt 2 ms samples too coarsely: 0.92). About 5 min under load: the jaws touch ~300 nodes, so each
    condensed contact solve is ~900 x 900."""
    res = slip("fem_static", mu=0.6, dt=5e-4, pull_time=1.2)
    assert res.slip_onset_pull == pytest.approx(0.6 * res.slip_onset_normal, rel=0.05)


@pytest.mark.slow
@pytest.mark.parametrize("model, mu, squeeze", [("fractional", 0.1, 5e-4), ("fractional", 0.6, 5e-4),
                                                ("fractional", 1.2, 5e-4), ("fem", 1.2, 2.5e-4)])
def test_onset_other_models(model, mu, squeeze):
    """fractional: 0.981 / 0.981 / 0.980 (load ~4). fem at mu 1.2 inverts elements with the default
    0.5 mm squeeze: the pull needed, and so the shear strain, scales with mu x squeeze whatever E
    is; with half the squeeze it reads 0.982 (load ~7)."""
    res = slip(model, mu=mu, squeeze=squeeze, pull_time=0.6 + 1.0 * mu, handle_speed=0.01 * min(1.0, mu / 0.3))
    assert res.slip_onset_pull == pytest.approx(mu * res.slip_onset_normal, rel=0.05)

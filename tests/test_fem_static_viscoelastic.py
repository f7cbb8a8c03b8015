"""fem_static's hereditary standard linear solid (equation (4) of surgsim_envs.tissue.fem_static):
creep and relaxation against the exact solutions, the condensed step against a full sparse solve."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry import Volume, box_volume
from surgsim_envs.tissue import registry


def _block(material, size=(0.02, 0.02, 0.01), spacing=0.005, gravity=(0.0, 0.0, 0.0), **kw):
    vol = box_volume(size, spacing, center=(0.0, 0.0, size[2] / 2))
    bottom = np.isclose(vol.nodes[:, 2], 0.0)
    top = np.flatnonzero(np.isclose(vol.nodes[:, 2], size[2]))
    return registry.get("fem_static")(vol, material, fixed=bottom, gravity=gravity, **kw), bottom, top


@pytest.mark.parametrize("g, tau", [(0.5, 1.5), (0.3, 0.2)])
def test_a_held_force_creeps_by_the_standard_linear_solids_creep_compliance(g, tau):
    """Under a force held from t = 0 the displacement follows u_inst E J(t),
    E J(t) = 1 / (1 - g) - g / (1 - g) exp(-(1 - g) t / tau). The update is exact for a displacement
    linear over each step; the force step makes the first step's error O(g h / tau)."""
    material = {"preset": "liver", "young": 3000.0, "poisson": 0.4, "relax_fraction": g, "relax_time": tau}
    model, _, top = _block(material)
    elastic, _, _ = _block({**material, "relax_fraction": 0.0})
    f = np.zeros((model.n_nodes, 3))
    f[top] = [0.0005, 0.0, -0.002]
    u_inst = (elastic.static_solve(f) - elastic.rest_positions)[top, 2].mean()
    h = tau / 200
    t = h * np.arange(1, 601)
    u = np.empty(len(t))
    for k in range(len(t)):
        model.step(h, f)
        u[k] = (model.positions - model.rest_positions)[top, 2].mean()
    creep = 1.0 / (1.0 - g) - g / (1.0 - g) * np.exp(-(1.0 - g) * t / tau)
    assert np.max(np.abs(u / u_inst - creep) / creep) < g * h / tau
    # the long-term equilibrium is the relaxed one, 1 / (1 - g) of the instantaneous
    x = model.static_solve(f)
    assert (x - model.rest_positions)[top, 2].mean() / u_inst == pytest.approx(1.0 / (1.0 - g), rel=1e-9)


def test_a_held_displacement_relaxes_exactly():
    """The top pressed down by delta over the first step h and held: the reaction is
    F_inst [(1 - g) + g gamma exp(-(t - h) / tau)], gamma = tau/h (1 - exp(-h/tau)), exact to
    round-off since the imposed displacement is linear over every step (Dirichlet targets moved
    through set_fixed, so every step solves the elastic problem afresh)."""
    g, tau, h = 0.4, 0.3, 0.01
    material = {"preset": "liver", "young": 5000.0, "poisson": 0.45, "relax_fraction": g, "relax_time": tau}
    model, _, top = _block(material)
    elastic, _, _ = _block({**material, "relax_fraction": 0.0})
    target = model.rest_positions[top] + [0.0, 0.0, -0.0005]
    zero = np.zeros((model.n_nodes, 3))
    elastic.set_fixed(top, target)
    elastic.step(h, zero)
    f_inst = elastic.internal_forces()[top, 2].sum()
    assert f_inst > 0.0                                  # the compressed block pushes the top back up
    model.set_fixed(top, target)
    gamma = tau / h * -np.expm1(-h / tau)
    for k in range(1, 60):
        model.step(h, zero)
        expected = f_inst * ((1.0 - g) + g * gamma * np.exp(-(k - 1) * h / tau))
        assert model.internal_forces()[top, 2].sum() == pytest.approx(expected, rel=1e-9), k


def test_the_condensed_hereditary_step_is_a_full_sparse_solve():
    """Contact stiffness on moving node sets, forces, gravity and steps of two lengths: every step
    equals (c K0 + Kc) u = f_g + f + Kc u_n - K0 s solved on the free dofs, s = g (decay H - gamma u_n)."""
    g, tau = 0.5, 1.5
    model, bottom, top = _block({"preset": "liver"}, gravity=(0.0, 0.0, -9.81))
    n = model.n_nodes
    k0 = model.stiffness_matrix()
    free = ~np.repeat(bottom, 3)
    grav = (model.masses[:, None] * np.array([0.0, 0.0, -9.81])[None, :]).ravel()
    rng = np.random.default_rng(3)
    u, hist = np.zeros(3 * n), np.zeros(3 * n)
    worst = 0.0
    for k in range(20):
        h = (1e-3, 5e-3)[k % 2]
        kc = np.zeros(n)
        kc[rng.choice(top, 4, replace=False)] = 200.0
        f = np.zeros((n, 3))
        f[top[0]] = [0.001, 0.0, -0.002 * (k % 5)]
        model.step(h, f, kc)
        decay, gamma = np.exp(-h / tau), tau / h * -np.expm1(-h / tau)
        c, s = 1.0 - g + g * gamma, g * (decay * hist - gamma * u)
        a = (c * k0 + sp.diags(np.repeat(kc, 3))).tocsc()[free][:, free]
        new = np.zeros(3 * n)
        new[free] = spla.spsolve(a, (grav + f.ravel() + np.repeat(kc, 3) * u - k0 @ s)[free])
        hist, u = decay * hist + gamma * (new - u), new
        worst = max(worst, np.abs((model.positions - model.rest_positions).ravel() - u).max() / np.abs(u).max())
    # two direct solves of the same well-conditioned system differ by O(cond x eps) ~ 1e-13
    assert worst < 1e-9


def test_one_relax_fraction_is_needed_for_the_hereditary_law():
    vol = box_volume((0.02, 0.02, 0.01), 0.005, center=(0.0, 0.0, 0.005))
    labels = (vol.nodes[vol.tets].mean(axis=1)[:, 0] > 0).astype(np.int32)
    vol = Volume(vol.nodes, vol.tets, labels=labels)
    bottom = np.isclose(vol.nodes[:, 2], 0.0)
    regions = {1: {"preset": "liver", "relax_fraction": 0.2}}
    cls = registry.get("fem_static")
    with pytest.raises(ConfigError, match=r"relax_fraction 0.2\.\.0.5.*viscoelastic='relaxed'"):
        cls(vol, "liver", fixed=bottom, region_materials=regions, viscoelastic="hereditary")
    auto = cls(vol, "liver", fixed=bottom, region_materials=regions)
    assert auto.hereditary is None                     # falls back to the relaxed equilibrium
    assert cls(vol, "liver", fixed=bottom).hereditary == (0.5, 1.5)
    assert cls(vol, "liver", fixed=bottom, viscoelastic="relaxed").hereditary is None
    with pytest.raises(ConfigError, match="viscoelastic"):
        cls(vol, "liver", fixed=bottom, viscoelastic="maxwell")

"""The chemical-diffusion surface model (Zhong et al. 2016): discretisation against the paper's formulas,
analytic decay on a sphere, load conservation, the paper's qualitative results (Figs. 9.2-9.6),
scene use and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from surgsim_envs import tissue
from surgsim_envs.bench.diffusion_press import (CONTACT, PAPER_FORCE, contact_forces, load_curve, node_near,
                                                paper_case, press, white_portions)
from surgsim_envs.errors import ConfigError, TissueUnstableError
from surgsim_envs.geometry import Volume, make_volume
from surgsim_envs.geometry.rounded_cube import grid_points_for, rounded_cube_volume
from surgsim_envs.tissue import diffusion_operator as op


def _fan(planar: bool, seed: int = 0):
    rng = np.random.default_rng(seed)
    k = 7
    ang = np.linspace(0, 2 * np.pi, k, endpoint=False) + rng.uniform(-0.3, 0.3, k)
    r = 1.0 + 0.4 * rng.random(k)
    z = np.zeros(k) if planar else 0.15 * rng.standard_normal(k)
    nodes = np.vstack([[0.0, 0.0, 0.0], np.c_[r * np.cos(ang), r * np.sin(ang), z]])
    tris = np.array([[0, 1 + i, 1 + (i + 1) % k] for i in range(k)])
    return nodes, tris, rng.standard_normal(k + 1)


def _paper_update(nodes, tris, C, omega):
    """dC_0/dt of eqs. 9.16-9.18 written out literally (lambda, mu, n_ijk), node 0 at the fan centre."""
    S = op.control_areas(nodes, tris)[0]
    total = 0.0
    for t in tris:
        for j, k in ((t[1], t[2]), (t[2], t[1])):
            Pi, Pj, Pk = nodes[0], nodes[j], nodes[k]
            a, b = Pj - Pi, Pk - Pi
            cross2 = float(np.sum(np.cross(a, b) ** 2))
            m = (Pk - Pi) + (Pk - Pj)
            n = np.cross(m, np.cross(a, a + b))
            n /= np.linalg.norm(n)
            lam = np.linalg.norm(m) / cross2 * ((b @ b) * a - (a @ b) * b) @ n
            mu = np.linalg.norm(m) / cross2 * ((a @ a) * b - (a @ b) * a) @ n
            total += lam * (C[j] - C[0]) + mu * (C[k] - C[0])
    return omega / (6.0 * S) * total


def _our_update(nodes, tris, C, omega, iso_rel=None):
    S = op.control_areas(nodes, tris)
    rel = op.relative_tensors(op.vertex_normals(nodes, tris)) if iso_rel is None else iso_rel
    r, c, v = op.triangle_rates(nodes, tris, np.full(len(nodes), omega), rel, 1.0, S)
    sel = r == 0
    return float(np.sum(v[sel] * (C[c[sel]] - C[0])))


def test_triangle_scheme_is_the_papers_eqs_9_16_to_9_18():
    nodes, tris, C = _fan(planar=True)
    assert _our_update(nodes, tris, C, 0.7) == pytest.approx(_paper_update(nodes, tris, C, 0.7), rel=1e-10)
    # bent ring: our tensor is the vertex tangent projector, the paper's flux uses each triangle's plane
    nodes, tris, C = _fan(planar=False, seed=3)
    assert _our_update(nodes, tris, C, 0.7) == pytest.approx(_paper_update(nodes, tris, C, 0.7), rel=5e-3)
    eye = np.repeat(np.eye(3)[None], len(nodes), axis=0)
    assert _our_update(nodes, tris, C, 0.7, eye) == pytest.approx(_paper_update(nodes, tris, C, 0.7), rel=1e-10)


def _flat_sheet(n: int = 9, h: float = 0.01):
    x, y = np.meshgrid(np.arange(n) * h, np.arange(n) * h, indexing="ij")
    nodes = np.c_[x.ravel(), y.ravel(), np.zeros(n * n)]
    ids = np.arange(n * n).reshape(n, n)
    quads = np.array([[ids[i, j], ids[i + 1, j], ids[i + 1, j + 1], ids[i, j + 1]]
                      for i in range(n - 1) for j in range(n - 1)])
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    vol = Volume(nodes, np.zeros((0, 4), dtype=np.int32), tris, name="sheet")
    vol.quads = quads
    return vol


def test_grid_scheme_eq_9_9_matches_triangles_on_a_uniform_flat_grid():
    vol = _flat_sheet()
    grid = tissue.make("diffusion", vol, "liver", scheme="grid", omega=0.1)
    tri = tissue.make("diffusion", vol, "liver", scheme="triangles", omega=0.1)
    assert grid._full.sum() == 7 * 7                      # interior nodes use eq. 9.9
    C = np.random.default_rng(1).standard_normal(vol.n_nodes)

    def rate(model):
        ptr, idx, val = model._rates
        rows = np.repeat(np.arange(vol.n_nodes), np.diff(ptr))
        out = np.zeros(vol.n_nodes)
        np.add.at(out, rows, val * (C[idx] - C[rows]))
        return out

    inner = np.flatnonzero(grid._full)
    np.testing.assert_allclose(rate(grid)[inner], rate(tri)[inner], rtol=1e-10)
    # and both are omega L^2/tau times the 5-point Laplacian
    ids = np.arange(81).reshape(9, 9)
    i = ids[4, 4]
    lap = (C[ids[3, 4]] + C[ids[5, 4]] + C[ids[4, 3]] + C[ids[4, 5]] - 4 * C[i]) / 0.01 ** 2
    assert rate(grid)[i] == pytest.approx(0.1 * grid.length ** 2 / grid.load_time * lap, rel=1e-10)


def test_sphere_harmonic_decays_at_the_analytic_rate():
    """C = z/R is an eigenfunction of the Laplace-Beltrami operator (eigenvalue 2/R^2): without a
    load it decays as exp(-(2 D / R^2 + 1/tau) t), D = omega L^2 / tau."""
    import trimesh

    sph = trimesh.creation.icosphere(subdivisions=4, radius=0.05)
    vol = Volume(np.asarray(sph.vertices), np.zeros((0, 4), dtype=np.int32), np.asarray(sph.faces), name="sphere")
    m = tissue.make("diffusion", vol, "liver", omega=0.05, load_time=0.05, substeps=1)
    R = 0.05
    m.concentration[:] = m.rest_positions[:, 2] / R
    dt = 0.5 * m.diffusion_critical_dt()
    steps = 200
    for _ in range(steps):
        m.step(dt)
    D = 0.05 * m.length ** 2 / m.load_time
    expect = np.exp(-(2 * D / R ** 2 + 1 / m.load_time) * dt * steps)
    got = float(np.sum(m.concentration * m.rest_positions[:, 2] * m._areas) / np.sum(m.rest_positions[:, 2] ** 2 / R * m._areas))
    assert got == pytest.approx(expect, rel=0.02)


def test_steady_load_is_conserved_and_stepping_reaches_static_solve():
    m = paper_case("isotropic", points=400, scheme="triangles")     # the conservative scheme
    f = contact_forces(m)
    c = m.steady_concentration(f)
    normal = -np.einsum("ij,ij->i", f, m._normals)
    assert float(m._areas @ c) == pytest.approx(float(normal.sum()), rel=1e-9)   # sum S C = applied load
    u_static = press(m)
    u_dyn = press(m, steps=800, dt=1e-3)
    i = node_near(m, CONTACT)
    assert np.linalg.norm(u_static[i]) > 0.005
    assert np.abs(u_dyn - u_static).max() < 0.01 * np.abs(u_static).max()
    assert m.total_load() == pytest.approx(float(normal.sum()), rel=0.01)


def _along(m, u, direction, d):
    return float(np.linalg.norm(u[node_near(m, CONTACT + d * np.asarray(direction))]))


def test_anisotropic_deforms_more_along_the_high_omega_direction():
    """Fig. 9.3: omega 0.08 latitudinal (y at the contact), 0.24 longitudinal (z)."""
    iso, ani = paper_case("isotropic"), paper_case("anisotropic")
    u_iso, u_ani = press(iso), press(ani)
    for d in (0.02, 0.03):
        assert _along(iso, u_iso, (0, 0, 1), d) == pytest.approx(_along(iso, u_iso, (0, 1, 0), d), rel=0.02)
        assert _along(ani, u_ani, (0, 0, 1), d) > 1.3 * _along(ani, u_ani, (0, 1, 0), d)


def test_inhomogeneous_deforms_differently_in_white_and_grey():
    """Fig. 9.4: grey (omega 0.24, with the contact) spreads the dent further than the white
    bands (0.08): at equal distance the grey side dents more than the white side, unlike the
    isotropic cube."""
    m = paper_case("inhomogeneous")
    u = press(m)
    d = 0.03
    assert _along(m, u, (0, 0, 1), d) > 1.08 * _along(m, u, (0, 1, 0), d)
    iso = paper_case("isotropic")
    u_iso = press(iso)
    # the stiffer spreading lowers the peak under the contact
    i = node_near(m, CONTACT)
    assert np.linalg.norm(u[i]) < 0.8 * np.linalg.norm(u_iso[i])


def test_local_deformation_white_portions_stay_undeformed():
    """Fig. 9.5: the white portions with a very low omega are not deformed."""
    m = paper_case("local")
    iso = paper_case("isotropic")
    u, u_iso = np.linalg.norm(press(m), axis=1), np.linalg.norm(press(iso), axis=1)
    white = white_portions(m.rest_positions)
    near_white = white & (m.rest_positions[:, 0] > 0.03)       # the white bands on the pressed face
    assert u_iso[near_white].max() > 0.2 * u_iso.max()          # isotropic: they dent
    assert u[near_white].max() < 0.02 * u.max()                 # local case: they do not


def test_load_deformation_is_nonlinear_only_with_stiffening():
    """Fig. 9.6: the indentation grows less than linearly with force when the bulk stiffens
    (material.nonlinear > 0); with nonlinear = 0 the model is linear."""
    forces = np.array([5.0, 10.0, 20.0, 40.0])
    lin = load_curve(paper_case("isotropic", points=400, material={"preset": "liver", "young": 30_000.0,
                                                                    "nonlinear": 0.0}), forces)
    np.testing.assert_allclose(lin / forces, lin[0] / forces[0], rtol=1e-6)
    stiff = load_curve(paper_case("isotropic", points=400, material={"preset": "liver", "young": 30_000.0,
                                                                      "nonlinear": 5.0}), forces)
    per_newton = stiff / forces
    assert np.all(np.diff(per_newton) < 0)
    assert per_newton[-1] < 0.8 * per_newton[0]


def test_unloading_returns_to_rest():
    m = paper_case("isotropic", points=300)
    press(m, steps=300, dt=1e-3)
    assert np.abs(m.positions - m.rest_positions).max() > 1e-3
    for _ in range(1500):
        m.step(1e-3, np.zeros_like(m.positions))
    assert np.abs(m.positions - m.rest_positions).max() < 1e-5


def test_contract_fields_and_material_scaling():
    m = paper_case("isotropic", points=300)
    assert {"displacement", "stress", "concentration", "omega"} <= set(m.node_fields())
    assert m.has("surface_only") if hasattr(m, "has") else "surface_only" in m.capabilities
    assert m.element_centroids().shape == (m.n_nodes, 3)
    assert m.stable_dt() < m.critical_dt()
    u0 = np.linalg.norm(press(m), axis=1).max()
    m.scale_material("young", 2.0)
    assert np.linalg.norm(press(m), axis=1).max() == pytest.approx(u0 / 2, rel=0.15)
    m.scale_material("young", 1.0)

    def width(model):             # dent at 3 cm relative to the dent under the contact
        u = np.linalg.norm(press(model), axis=1)
        return u[node_near(model, CONTACT + [0, 0, 0.03])] / u[node_near(model, CONTACT)]

    w0 = width(m)
    m.scale_material("omega", 3.0)
    assert width(m) > 1.3 * w0
    m.step(1e-3, contact_forces(m))
    np.testing.assert_allclose(m.integrated_external_forces, contact_forces(m))
    assert m.node_fields("concentration")["concentration"].max() > 0


def test_surface_of_a_tet_volume_interior_nodes_stay_still():
    vol = make_volume("slab", spacing=0.01)
    bottom = np.flatnonzero(vol.nodes[:, 2] < vol.nodes[:, 2].min() + 1e-6)
    m = tissue.make("diffusion", vol, "liver", fixed=bottom)
    interior = np.setdiff1d(np.arange(vol.n_nodes), vol.surface_nodes)
    assert len(interior) > 0 and np.all(m.masses[interior] == 0)
    top = np.argmax(vol.nodes[:, 2] - 0.1 * np.linalg.norm(vol.nodes[:, :2], axis=1))
    f = np.zeros_like(m.positions)
    f[top] = [0, 0, -1.0]
    for _ in range(200):
        m.step(1e-3, f)
    assert m.positions[top, 2] < m.rest_positions[top, 2] - 1e-4
    np.testing.assert_array_equal(m.positions[interior], m.rest_positions[interior])
    np.testing.assert_array_equal(m.positions[bottom], m.rest_positions[bottom])


def test_rounded_cube_geometry():
    vol = rounded_cube_volume(points=900)
    assert vol.n_nodes == grid_points_for(13) == 866
    op.check_surface(vol.nodes, vol.surface)
    import trimesh

    mesh = trimesh.Trimesh(vol.nodes, vol.surface, process=False)
    assert mesh.is_watertight and mesh.volume > 0             # closed, outward normals
    assert 0.8e-3 < mesh.volume < 1.0e-3                       # a 10 cm cube minus its rounded corners
    assert make_volume("rounded_cube").n_nodes == 866


# -------------------------------------------------------------------------------------------
# Bad input
def test_non_manifold_surface_is_rejected():
    nodes = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1.0]])
    tris = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])     # edge (0,1) in three triangles
    vol = Volume(nodes, np.zeros((0, 4), dtype=np.int32), tris)
    with pytest.raises(ConfigError, match="non-manifold edge"):
        tissue.make("diffusion", vol, "liver")
    flipped = Volume(nodes[:4], np.zeros((0, 4), dtype=np.int32), np.array([[0, 1, 2], [0, 1, 3]]))
    with pytest.raises(ConfigError, match="consistently oriented"):
        tissue.make("diffusion", flipped, "liver")


@pytest.mark.parametrize("kw, match", [({"omega": 0.0}, "omega=0.0 must be > 0"), ({"omega": -0.1}, "omega=-0.1 must be > 0"),
                                       ({"omega": 0.08, "omega_long": -1.0}, "omega_long=-1.0 must be > 0"),
                                       ({"load_time": 0.0}, "load_time"), ({"substeps": 0}, "substeps"),
                                       ({"scheme": "fd"}, "scheme")])
def test_bad_parameters(kw, match):
    with pytest.raises(ConfigError, match=match):
        tissue.make("diffusion", rounded_cube_volume(points=100), "liver", **kw)
    vol = rounded_cube_volume(points=100)
    with pytest.raises(ConfigError, match="omega must be"):
        tissue.make("diffusion", vol, "liver", omega=np.r_[0.0, np.full(vol.n_nodes - 1, 0.1)])


def test_dt_above_the_diffusion_bound_is_an_error_and_the_bound_is_real():
    m = paper_case("isotropic", points=400, substeps=1)
    crit = m.diffusion_critical_dt()
    assert m.critical_dt() <= crit
    with pytest.raises(ConfigError, match="diffusion stability bound"):
        m.step(1.5 * crit, contact_forces(m))
    # just below the bound it is stable; far above it (guard bypassed) the concentration diverges
    m.reset()
    f = contact_forces(m)
    for _ in range(300):
        m.step(0.95 * crit, f)
    assert np.isfinite(m.concentration).all() and m.concentration.max() < 1e5
    m.reset()
    m._bound_cache = 10.0                                      # pretend the bound were 10 s
    with pytest.raises(TissueUnstableError, match="concentration diverged"):
        for _ in range(2000):
            m.step(3.0 * crit, f)


def test_auto_substeps_cover_dt():
    m = paper_case("anisotropic", points=400)
    m.step(2e-3, contact_forces(m))
    assert m.substeps * m._diffusion_bound() >= 2e-3


def test_per_node_tensor_reproduces_latitude_longitude_anisotropy():
    vol = rounded_cube_volume(points=300)
    lat_long = tissue.make("diffusion", vol, "liver", omega=0.08, omega_long=0.24, scheme="triangles")
    tensor = 0.08 * lat_long._rel                        # the same tensors given per node
    per_node = tissue.make("diffusion", vol, "liver", omega_tensor=tensor, scheme="triangles")
    np.testing.assert_allclose(per_node._rates[2], lat_long._rates[2], rtol=1e-9, atol=1e-12)
    bad = tensor.copy()
    bad[5] = -bad[5]
    with pytest.raises(ConfigError, match="not positive definite"):
        tissue.make("diffusion", vol, "liver", omega_tensor=bad)
    with pytest.raises(ConfigError, match="needs a volume with a structured quad grid"):
        tissue.make("diffusion", make_volume("slab", spacing=0.01), "liver", scheme="grid")


def test_gravity_sags_each_node_by_m_g_over_k():
    """A body force acts directly on the nodes (not through the concentration): with the bulk
    linear, each free node sags by m g / (S E / h)."""
    vol = rounded_cube_volume(points=100)
    m = tissue.make("diffusion", vol, {"preset": "liver", "nonlinear": 0.0}, gravity=(0.0, 0.0, -9.81))
    for _ in range(3000):
        m.step(1e-3)
    expect = -9.81 * m.masses / (m._areas * m._kappa)
    np.testing.assert_allclose(m.positions[:, 2] - m.rest_positions[:, 2], expect, rtol=1e-3)
    assert np.all(m.concentration == 0.0)
    np.testing.assert_allclose(m.static_solve(np.zeros_like(m.positions)), m.positions, atol=1e-9)


def test_neumann_border_loses_no_load():
    """Eq. 9.8: on an open sheet no flux leaves through the border, so the steady concentration
    still carries exactly the applied load (only the bulk exchange removes it)."""
    vol = _flat_sheet(n=11, h=0.01)
    m = tissue.make("diffusion", vol, "liver", scheme="triangles", omega=0.5)
    f = np.zeros_like(m.positions)
    corner = 0                                            # a border node: the worst case
    f[corner] = [0.0, 0.0, -2.0]
    f[60] = [0.0, 0.0, -1.0]
    c = m.steady_concentration(f)
    assert float(m._areas @ c) == pytest.approx(3.0, rel=1e-9)
    assert c[corner] > c[60] > 0                           # a corner control volume is a quarter

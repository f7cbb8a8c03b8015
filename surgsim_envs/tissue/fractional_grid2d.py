"""Two-dimensional fractional tissue layer on a grid (the variable-order paper, sections II-IV, eqs. 10-23).

Stress-strain law (eqs. 11-13), RL derivative of order q(t)::

    sigma_xx = alpha D^q eps_xx + beta D^q eps_yy,  sigma_xy = gamma D^q eps_xy,  sigma_yy = beta D^q eps_xx + alpha D^q eps_yy

with the equations of motion (7) give (14) and, with ``z = I^(1-q) w`` and ``g = int F + rho v(0)``
(Theorem 2), the state-space form (19), p = 1 - q::

    du/dt = (z + g) / rho,   dg/dt = F,   D^p z = w,   w_x = alpha u_x,xx + (beta + gamma) u_y,xy + gamma u_x,yy
                                                      w_y = alpha u_y,yy + (beta + gamma) u_x,xy + gamma u_y,xx

Space: the (N_x+1) x (N_y+1) grid of step h with the finite differences of eq. 20 (eq. 21); the
interior points are the states, the boundary points carry prescribed displacements (Dirichlet).
*Choice:* eq. 21 as printed puts gamma on u_y,yy and alpha on u_y,xx in the z_y row, which
contradicts eqs. 13, 14 and 19 (alpha u_y,yy + gamma u_y,xx) and breaks the x <-> y symmetry; we
follow eq. 19 (a test checks the mirror symmetry about the diagonal).

Time: step dt, explicit (symplectic) in u and g; ``D^p z_n = w_n`` by Grunwald-Letnikov,
``z_n = dt^p w_n - sum_{k=1}^{min(n,L)} c_k z_{n-k}`` (c_k the GL weights of order p, L the short
memory). q may be a number or a :class:`~surgsim_envs.tissue.fractional_calculus.PiecewiseOrder`.

Relaxation mode (section IV.B): with F = 0 and g(0) = 0 the equilibrium has z = 0, hence
w(u) = 0 (eq. 23): the same equations as the static Kelvin-Voigt/elastic solution (eq. 22) when
alpha = lambda + 2 mu, beta = lambda, gamma = mu. :func:`static_solution` solves them directly.
The equilibrium holds for any short memory L (a truncated GL sum of a constant z is a nonzero
multiple of z, so D^p z = 0 still forces z = 0).

Kelvin-Voigt (eqs. 9-10): :class:`KelvinVoigtGrid2D`. *Choice:* eq. 9 writes the viscous xx
coefficient as (b + 2 mu), adding a viscosity (Pa s) to a modulus (Pa); we read it as the viscous
twin of the elastic law with both viscous Lame coefficients equal to b: viscous
(alpha, beta, gamma) = (3b, b, b).

Units: displacement m, h m, rho kg/m^3 (per unit thickness), alpha/beta/gamma Pa s^q, b Pa s.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from surgsim_envs.errors import ConfigError, TissueUnstableError
from surgsim_envs.tissue import fractional_calculus as fc


class Grid2D:
    """(nx+1) x (ny+1) points x_i = i h, y_j = j h; interior points are the unknowns."""

    def __init__(self, nx: int, ny: int, spacing: float):
        if not all(isinstance(n, (int, np.integer)) and n >= 2 for n in (nx, ny)):
            raise ConfigError(f"nx and ny must be integers >= 2 (at least one interior point), got {nx!r}, {ny!r}")
        if not (math.isfinite(spacing) and spacing > 0):
            raise ConfigError(f"grid spacing must be > 0 m, got {spacing!r}")
        self.nx, self.ny, self.h = int(nx), int(ny), float(spacing)
        i, j = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), indexing="ij")
        self.points = np.stack([i * spacing, j * spacing], axis=-1)       # (nx+1, ny+1, 2)
        self.interior = np.zeros((nx + 1, ny + 1), dtype=bool)
        self.interior[1:-1, 1:-1] = True

    @property
    def n_points(self) -> int:
        return (self.nx + 1) * (self.ny + 1)

    def index(self, i, j):
        return np.asarray(i) * (self.ny + 1) + np.asarray(j)


def operator(grid: Grid2D, alpha: float, beta: float, gamma: float) -> sp.csr_matrix:
    """Sparse (2P, 2P) matrix W with w = W u on the interior rows (zero rows on the boundary);
    u, w ordered (point, component), points row-major (i, j). Eq. 21 (with eq. 19's z_y row)."""
    h2 = grid.h ** 2
    rows, cols, vals = [], [], []
    ii, jj = np.nonzero(grid.interior)
    c = grid.index(ii, jj)

    def add(comp_row, di, dj, comp_col, coef):
        rows.append(2 * c + comp_row)
        cols.append(2 * grid.index(ii + di, jj + dj) + comp_col)
        vals.append(np.full(len(c), coef))

    for comp, other, along_x, along_y in ((0, 1, alpha, gamma), (1, 0, gamma, alpha)):
        for di, dj, coef in ((1, 0, along_x), (-1, 0, along_x), (0, 0, -2 * along_x - 2 * along_y),
                             (0, 1, along_y), (0, -1, along_y)):
            add(comp, di, dj, comp, coef / h2)
        cross = (beta + gamma) / (4 * h2)
        for di, dj, sign in ((1, 1, 1), (-1, -1, 1), (1, -1, -1), (-1, 1, -1)):
            add(comp, di, dj, other, sign * cross)
    n = 2 * grid.n_points
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))


def _interior_dofs(grid: Grid2D) -> np.ndarray:
    pts = np.flatnonzero(grid.interior.ravel())
    return np.stack([2 * pts, 2 * pts + 1], axis=1).ravel()


def static_solution(grid: Grid2D, alpha: float, beta: float, gamma: float, boundary_u) -> np.ndarray:
    """Displacements (nx+1, ny+1, 2) m with w(u) = 0 inside (eqs. 22/23) and ``boundary_u``
    ((nx+1, ny+1, 2); only its boundary values are used) on the boundary."""
    u = np.array(boundary_u, dtype=float).reshape(-1)
    if u.shape != (2 * grid.n_points,):
        raise ConfigError(f"boundary_u must have shape ({grid.nx + 1}, {grid.ny + 1}, 2), got {np.shape(boundary_u)}")
    w = operator(grid, alpha, beta, gamma)
    free = _interior_dofs(grid)
    fixed = np.setdiff1d(np.arange(len(u)), free)
    u[free] = 0.0
    a = w[free][:, free].tocsc()
    u[free] = spla.spsolve(a, -(w[free][:, fixed] @ u[fixed]))
    return u.reshape(grid.nx + 1, grid.ny + 1, 2)


class FractionalGrid2D:
    """State-space fractional layer (eqs. 19/21) with prescribed boundary displacements.

    alpha, beta, gamma: Pa s^q; density: rho (kg/m^3); order: q in [0, 1) (number or
    PiecewiseOrder; p = 1 - q is the order of the z equation); memory: short-memory L (steps).
    """

    def __init__(self, grid: Grid2D, alpha: float, beta: float, gamma: float, *, density: float = 1000.0,
                 order=0.5, memory: int = 1000):
        for key, val in (("alpha", alpha), ("gamma", gamma), ("density", density)):
            if not (math.isfinite(val) and val > 0):
                raise ConfigError(f"{key} must be > 0, got {val!r}")
        if not (isinstance(memory, (int, np.integer)) and memory >= 1):
            raise ConfigError(f"memory must be an integer >= 1 step, got {memory!r}")
        self.grid, self.rho, self.memory = grid, float(density), int(memory)
        self.order = order if isinstance(order, fc.PiecewiseOrder) else fc.PiecewiseOrder((), (fc.check_order(order),))
        if max(self.order.values) >= 1.0:
            raise ConfigError("order q must be < 1 in the state-space form (p = 1 - q > 0)")
        self.w = operator(grid, alpha, beta, gamma)
        self.free = _interior_dofs(grid)
        n = 2 * grid.n_points
        self.u = np.zeros(n)
        self.g = np.zeros(n)
        self.z = np.zeros(n)
        self.time = 0.0
        self.steps = 0
        # z_{n-1}, z_{n-2}, ... newest first in rows [pos, pos + memory) of a double-length buffer
        self._buf = np.zeros((2 * self.memory, len(self.free)))
        self._pos = self.memory
        self._weights = {}

    def critical_dt(self) -> float:
        """Largest stable dt (s) of the explicit scheme, no safety factor: for a mode with
        -W u = kappa rho u the step's characteristic equation ``(zeta - 1)(1 - 1/zeta)^p =
        -kappa dt^(1+p)`` reaches zeta = -1 at ``dt = 2 kappa^(-1/(1+p))``; the largest kappa and
        the largest order q(t) (smallest p) of the schedule give the limit (q = 0: 2/omega,
        q -> 1: the explicit-Euler limit 2/kappa)."""
        f = self.free
        a = -self.w[f][:, f]
        kappa = float(spla.eigs(a.tocsc(), k=1, which="LM", return_eigenvectors=False)[0].real) / self.rho
        p = 1.0 - max(self.order.values)
        return 2.0 * kappa ** (-1.0 / (1.0 + p))

    def set_displacement(self, u) -> None:
        """Set all displacements (nx+1, ny+1, 2) m: the boundary ones stay prescribed."""
        u = np.asarray(u, dtype=float).reshape(-1)
        if u.shape != self.u.shape:
            raise ConfigError(f"displacement must have shape ({self.grid.nx + 1}, {self.grid.ny + 1}, 2)")
        self.u[:] = u

    def _gl(self, p: float, dt: float):
        key = (p, dt)
        if key not in self._weights:
            self._weights[key] = fc.gl_weights(p, self.memory)[1:]
        return self._weights[key]

    def step(self, dt: float, forces=None) -> None:
        """Advance by dt (s) under body forces (nx+1, ny+1, 2) N/m^3 (interior points)."""
        q = float(self.order(self.time))
        p = 1.0 - q
        f = self.free
        if forces is not None:
            self.g[f] += dt * np.asarray(forces, dtype=float).reshape(-1)[f]
        w = (self.w @ self.u)[f]
        c = self._gl(p, dt)
        k = min(self.steps, self.memory)
        past = c[:k] @ self._buf[self._pos:self._pos + k] if k else 0.0
        zf = dt ** p * w - past
        self.z[f] = zf
        if self._pos == 0:                     # amortised O(1): move the newest L-1 rows up once every L steps
            self._buf[self.memory + 1:] = self._buf[:self.memory - 1]
            self._pos = self.memory + 1
        self._pos -= 1
        self._buf[self._pos] = zf
        self.u[f] += dt * (zf + self.g[f]) / self.rho
        self.time += dt
        self.steps += 1
        if not np.all(np.isfinite(self.u)):
            raise TissueUnstableError("fractional_grid2d", dt, float("nan"), "non-finite displacement")

    @property
    def displacement(self) -> np.ndarray:
        return self.u.reshape(self.grid.nx + 1, self.grid.ny + 1, 2)


class KelvinVoigtGrid2D:
    """Kelvin-Voigt layer (eq. 10): rho u'' = W_el u + W_visc u' + F, elastic (lam + 2 mu, lam, mu)
    and viscous (3b, b, b) operators (see the module docstring), semi-implicit Euler."""

    def __init__(self, grid: Grid2D, lam: float, mu: float, b: float, *, density: float = 1000.0):
        if not (mu > 0 and lam + 2 * mu > 0 and b >= 0 and density > 0):
            raise ConfigError(f"need mu > 0, lam + 2 mu > 0, b >= 0, density > 0; got lam={lam}, mu={mu}, b={b}, "
                              f"density={density}")
        self.grid, self.rho = grid, float(density)
        self.w_el = operator(grid, lam + 2 * mu, lam, mu)
        self.w_visc = operator(grid, 3 * b, b, b)
        self.free = _interior_dofs(grid)
        self.u = np.zeros(2 * grid.n_points)
        self.v = np.zeros_like(self.u)
        self.time = 0.0

    def set_displacement(self, u) -> None:
        self.u[:] = np.asarray(u, dtype=float).reshape(-1)

    def step(self, dt: float, forces=None) -> None:
        f = self.free
        acc = (self.w_el @ self.u + self.w_visc @ self.v)[f]
        if forces is not None:
            acc += np.asarray(forces, dtype=float).reshape(-1)[f]
        self.v[f] += dt * acc / self.rho
        self.u[f] += dt * self.v[f]
        self.time += dt
        if not np.all(np.isfinite(self.u)):
            raise TissueUnstableError("kelvin_voigt_grid2d", dt, float("nan"), "non-finite displacement")

    @property
    def displacement(self) -> np.ndarray:
        return self.u.reshape(self.grid.nx + 1, self.grid.ny + 1, 2)

"""Parameter sweep of Vandewalle et al. 2003, Fig. 5: error mu and sigma of the predicted skin against nu and k.

With no patient data, the reference skin is synthetic: the growth model itself, run at a chosen
truth (nu*, k*) on a FINER, different mesh (default 2 mm spacing) than the sweep's (4 mm), so the
sweep cannot match it by construction; it must find (nu*, k*) through the physics. For every
(nu, k) on the grid: build the coarse model (K factored once per nu), grow with k, and take the
signed distances of its skin vertices to the reference skin (:mod:`surgsim_envs.geometry.surface_error`).
The recovered parameters minimise the RMS error ``sqrt(mu^2 + sigma^2)``.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from surgsim_envs.geometry.surface_error import surface_error
from surgsim_envs.planning.maxillofacial import DistractionCase
from surgsim_envs.tissue.growth import GrowthSolver

NUS = (0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45)
KS = (0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 18.0, 20.0, 24.0, 28.0)
TRUTH = (0.35, 12.0)


def grown_skin(case: DistractionCase, spacing: float, poisson: float, k: float | None):
    """``(positions (N,3) m, skin faces)`` of the case grown with k (None: the basic model)."""
    m = case.model(spacing, poisson)
    solver = GrowthSolver.from_model(m)
    pos = solver.rest_positions + solver.basic().reshape(-1, 3) if k is None else solver.grow(k).positions
    return pos, case.skin_faces(m.volume)


@dataclass
class SweepResult:
    nus: np.ndarray
    ks: np.ndarray
    mu: np.ndarray          # (len(nus), len(ks)) m
    sigma: np.ndarray       # m
    truth: tuple
    spacing: float
    reference_spacing: float

    @property
    def rms(self) -> np.ndarray:
        return np.sqrt(self.mu ** 2 + self.sigma ** 2)

    def recovered(self) -> tuple[float, float]:
        i, j = np.unravel_index(np.argmin(self.rms), self.rms.shape)
        return float(self.nus[i]), float(self.ks[j])

    def to_dict(self) -> dict:
        nu, k = self.recovered()
        return {"nus": self.nus.tolist(), "ks": self.ks.tolist(), "mu_m": self.mu.tolist(), "sigma_m": self.sigma.tolist(),
                "truth": list(self.truth), "recovered": [nu, k], "spacing": self.spacing,
                "reference_spacing": self.reference_spacing}


def sweep(case: DistractionCase | None = None, nus=NUS, ks=KS, truth=TRUTH, spacing: float = 0.004,
          reference_spacing: float = 0.002, reference=None, progress: bool = True) -> SweepResult:
    """Run the Fig. 5 sweep (module doc). ``reference``: optional precomputed (positions, faces)."""
    from tqdm import tqdm

    case = case or DistractionCase()
    ref = reference or grown_skin(case, reference_spacing, truth[0], truth[1])
    mu = np.zeros((len(nus), len(ks)))
    sigma = np.zeros_like(mu)
    with tqdm(total=len(nus) * len(ks), desc="growth sweep (nu, k)", unit="run", file=sys.stderr,
              disable=not progress) as bar:
        for i, nu in enumerate(nus):
            m = case.model(spacing, nu)
            solver = GrowthSolver.from_model(m)
            faces = case.skin_faces(m.volume)
            for j, k in enumerate(ks):
                err = surface_error(solver.grow(k).positions, faces, ref[0], ref[1])
                mu[i, j], sigma[i, j] = err.mean, err.std
                bar.update()
    return SweepResult(np.asarray(nus, float), np.asarray(ks, float), mu, sigma, tuple(truth), spacing, reference_spacing)


def plot_sweep(result: SweepResult, path: str) -> None:
    """Fig. 5 analogue: mu and sigma against nu (at the recovered k) and against k (at the recovered
    nu), and the RMS error map over (nu, k) with the truth and the minimum marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    nu_r, k_r = result.recovered()
    i = int(np.argmin(np.abs(result.nus - nu_r)))
    j = int(np.argmin(np.abs(result.ks - k_r)))
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.0))
    ax = axes[0]
    ax.plot(result.nus, result.mu[:, j] * 1e3, "o-", label="mean mu")
    ax.plot(result.nus, result.sigma[:, j] * 1e3, "s-", label="std sigma")
    ax.axvline(result.truth[0], color="k", ls=":", label=f"truth nu* = {result.truth[0]:g}")
    ax.set_xlabel("Poisson ratio nu")
    ax.set_ylabel("skin error (mm)")
    ax.set_title(f"against nu (k = {result.ks[j]:g})", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    ax = axes[1]
    ax.plot(result.ks, result.mu[i] * 1e3, "o-", label="mean mu")
    ax.plot(result.ks, result.sigma[i] * 1e3, "s-", label="std sigma")
    ax.axvline(result.truth[1], color="k", ls=":", label=f"truth k* = {result.truth[1]:g}")
    ax.set_xlabel("growth parameter k")
    ax.set_ylabel("skin error (mm)")
    ax.set_title(f"against k (nu = {result.nus[i]:g})", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    ax = axes[2]
    im = ax.pcolormesh(result.ks, result.nus, result.rms * 1e3, shading="nearest", cmap="viridis")
    fig.colorbar(im, ax=ax, label="rms error sqrt(mu^2 + sigma^2) (mm)")
    ax.plot(result.truth[1], result.truth[0], "w*", ms=14, label="truth (fine mesh)")
    ax.plot(k_r, nu_r, "rx", ms=10, mew=2, label="sweep minimum (coarse mesh)")
    ax.set_xlabel("k")
    ax.set_ylabel("nu")
    ax.legend(fontsize=7, loc="upper right")
    fig.suptitle(f"Synthetic maxillofacial case: reference grown at (nu*, k*) = {result.truth} on a "
                 f"{result.reference_spacing * 1e3:g} mm mesh, sweep on {result.spacing * 1e3:g} mm", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

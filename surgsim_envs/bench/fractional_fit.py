"""Identification of the variable-order fractional law ``sigma = eta D^q(t) eps`` (the variable-order paper, section III).

As in the paper: q is piecewise constant on N equal subintervals of [0, T], and the cost is the
integrated squared error between measured and estimated stress, ``J = int_0^T (sigma_m -
sigma_e)^2 dt`` (trapezoid rule over the record's samples), minimised by a genetic-type global
search: scipy's ``differential_evolution`` over the orders q_1..q_N in [0, 1]. Our one change:
eta enters the estimate linearly, so for every trial q vector the eta that minimises J is taken
in closed form (``eta = int sigma_m s / int s^2`` with ``s = D^q eps``) instead of searching it;
this leaves the same minimum, with one search dimension fewer.

The estimate is computed on a uniform grid of ``grid`` samples (the record is resampled by
linear interpolation) with the L1 scheme (order 2 - q) and read back at the record's times.

For comparison :func:`fit_sls` fits the standard linear solid (E_inf, E1, tau) to the same
record with the same cost (E_inf, E1 by non-negative least squares for each tau, tau by a bounded
1-D search on log tau).

Records: :func:`read_record` reads a CSV of ``time (s), strain (-), stress (Pa)`` (relaxation or
ramp; header optional) or an Instron phantom file of ``../shared/data/tissue_mechanics``
(compression taken positive, kPa converted to Pa).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize as so
from scipy.integrate import trapezoid

from surgsim_envs.bench import viscoelastic_1d as v1
from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue import fractional_calculus as fc

TESTS = ("relax", "ramp")


@dataclass
class StressRecord:
    """A uniaxial record: ``time`` (s), ``strain`` (-), ``stress`` (Pa), from ``source``."""

    time: np.ndarray
    strain: np.ndarray
    stress: np.ndarray
    source: str = ""

    def __post_init__(self):
        self.time = np.asarray(self.time, dtype=float).ravel()
        self.strain = np.asarray(self.strain, dtype=float).ravel()
        self.stress = np.asarray(self.stress, dtype=float).ravel()
        n = len(self.time)
        if n < 5 or self.strain.shape != (n,) or self.stress.shape != (n,):
            raise ConfigError(f"{self.source or 'record'}: time, strain and stress must be equal-length arrays of "
                              f">= 5 samples, got {self.time.shape}, {self.strain.shape}, {self.stress.shape}")
        if not all(np.all(np.isfinite(a)) for a in (self.time, self.strain, self.stress)):
            raise ConfigError(f"{self.source or 'record'}: the record contains NaN/inf")
        if np.any(np.diff(self.time) <= 0):
            raise ConfigError(f"{self.source or 'record'}: time must increase strictly")
        self.time = self.time - self.time[0]

    def until_strain(self, max_strain: float) -> "StressRecord":
        """The record up to the first sample whose strain exceeds ``max_strain``."""
        stop = np.flatnonzero(self.strain > max_strain)
        end = int(stop[0]) if len(stop) else len(self.time)
        if end < 5:
            raise ConfigError(f"max_strain={max_strain} keeps fewer than 5 samples of {self.source}")
        return StressRecord(self.time[:end], self.strain[:end], self.stress[:end], self.source)


def read_record(path: str) -> StressRecord:
    """A :class:`StressRecord` from ``path``: three numeric columns ``time_s, strain, stress_Pa``
    (lines starting with # and a non-numeric header are skipped), or the Instron phantom format
    (metadata lines, then ``Time (s), Compression (mm), Load (N), Engineering Strain [-],
    Engineering Stress (kPa), ...``): time, |engineering strain|, |engineering stress| x 1e3."""
    try:
        with open(path) as fh:
            lines = [ln.strip() for ln in fh if ln.strip() and not ln.lstrip().startswith("#")]
    except OSError as exc:
        raise ConfigError(f"cannot read record {path!r}: {exc}") from None
    header = next((k for k, ln in enumerate(lines) if "Engineering Strain" in ln and "Time" in ln), None)
    if header is not None:
        cols = [c.strip() for c in lines[header].split(",")]
        it, ie = cols.index("Time (s)"), next(i for i, c in enumerate(cols) if c.startswith("Engineering Strain"))
        isg = next(i for i, c in enumerate(cols) if c.startswith("Engineering Stress"))
        scale = 1e3 if "kPa" in cols[isg] else 1.0
        try:
            rows = np.array([[float(x) for x in ln.split(",")[:len(cols)]] for ln in lines[header + 1:]])
        except ValueError as exc:
            raise ConfigError(f"{path}: a data row after the header is not numeric ({exc})") from None
        if rows.ndim != 2 or rows.shape[1] != len(cols):
            raise ConfigError(f"{path}: every data row needs {len(cols)} comma-separated columns")
        return StressRecord(rows[:, it], np.abs(rows[:, ie]), scale * np.abs(rows[:, isg]), path)
    rows = []
    for k, ln in enumerate(lines):
        parts = ln.replace(";", ",").replace("\t", ",").split(",")
        try:
            rows.append([float(parts[0]), float(parts[1]), float(parts[2])])
        except (ValueError, IndexError):
            if k == 0:
                continue
            raise ConfigError(f"{path}: line {k + 1} {ln!r} is not three numbers (time s, strain, stress Pa)") from None
    if len(rows) < 5:
        raise ConfigError(f"{path}: need at least 5 rows of time s, strain, stress Pa; got {len(rows)}")
    arr = np.array(rows)
    return StressRecord(arr[:, 0], arr[:, 1], arr[:, 2], path)


def write_record(path: str, record: StressRecord) -> None:
    """Write ``record`` as the CSV :func:`read_record` reads (time_s, strain, stress_Pa)."""
    np.savetxt(path, np.column_stack([record.time, record.strain, record.stress]), delimiter=",",
               header="time_s,strain,stress_Pa", comments="")


def resample(record: StressRecord, grid: int) -> tuple[np.ndarray, np.ndarray]:
    """(time, strain) on a uniform grid of ``grid`` samples over the record's span."""
    if not (isinstance(grid, (int, np.integer)) and grid >= 10):
        raise ConfigError(f"grid must be an integer >= 10 samples, got {grid!r}")
    t = np.linspace(0.0, record.time[-1], int(grid))
    return t, np.interp(t, record.time, record.strain)


def integrated_squared_error(time, measured, estimated) -> float:
    """``int (sigma_m - sigma_e)^2 dt`` (Pa^2 s), trapezoid rule."""
    return float(trapezoid((np.asarray(measured) - np.asarray(estimated)) ** 2, time))


@dataclass
class FractionalFit:
    """Identified ``eta`` (Pa s^q) and ``orders`` (one per piece, ``breaks`` in s), the cost
    (Pa^2 s), ``residual`` (RMS stress error, Pa), ``relative_residual`` (RMS / RMS of the data),
    and the estimate ``predicted`` (Pa) at the record's times."""

    eta: float
    order: fc.PiecewiseOrder
    cost: float
    residual: float
    relative_residual: float
    predicted: np.ndarray
    evaluations: int
    info: dict = field(default_factory=dict)

    @property
    def orders(self) -> tuple:
        return self.order.values

    def params(self) -> dict:
        out = {"eta": self.eta}
        out.update({f"q{i + 1}": q for i, q in enumerate(self.order.values)})
        return out


@dataclass
class SLSFit:
    """Standard linear solid: ``e_inf``, ``e1`` (Pa), ``tau`` (s); same error measures as FractionalFit."""

    e_inf: float
    e1: float
    tau: float
    cost: float
    residual: float
    relative_residual: float
    predicted: np.ndarray

    def params(self) -> dict:
        e0 = self.e_inf + self.e1
        return {"young": e0, "relax_fraction": self.e1 / e0 if e0 > 0 else 0.0, "relax_time": self.tau}


def _errors(record, predicted):
    rms = float(np.sqrt(np.mean((predicted - record.stress) ** 2)))
    scale = float(np.sqrt(np.mean(record.stress ** 2))) or 1.0
    return rms, rms / scale


def fit_fractional(record: StressRecord, *, pieces: int = 3, grid: int = 400, memory: int | None = None,
                   seed: int | None = 0, maxiter: int = 300, popsize: int = 20, tol: float = 1e-10) -> FractionalFit:
    """Identify eta and q_1..q_N (N = ``pieces`` equal subintervals of the record) by
    differential evolution on the integrated squared stress error (see the module docstring)."""
    if not (isinstance(pieces, (int, np.integer)) and 1 <= pieces <= 20):
        raise ConfigError(f"pieces (number of constant-order subintervals) must be an integer in [1, 20], got {pieces!r}")
    t, eps = resample(record, grid)
    h = float(t[1] - t[0])
    duration = float(record.time[-1])
    count = [0]

    def shape(qs):
        order = fc.PiecewiseOrder.uniform(qs, duration)
        s = fc.derivative(eps, h, order, kind="caputo", scheme="l1", memory=memory)
        return np.interp(record.time, t, s), order

    def best_eta(s):
        den = trapezoid(s * s, record.time)
        return max(float(trapezoid(record.stress * s, record.time)) / den, 0.0) if den > 0 else 0.0

    def cost(qs):
        count[0] += 1
        s, _ = shape(qs)
        return integrated_squared_error(record.time, record.stress, best_eta(s) * s)

    res = so.differential_evolution(cost, [(0.0, 1.0)] * int(pieces), seed=seed, maxiter=maxiter, popsize=popsize,
                                    tol=tol, polish=True)
    s, order = shape(np.clip(res.x, 0.0, 1.0))
    eta = best_eta(s)
    if not eta > 0:
        raise ConfigError(f"{record.source}: no positive eta fits this record (is the stress positive when the "
                          "strain grows? compression should be given as positive strain and stress)")
    pred = eta * s
    rms, rel = _errors(record, pred)
    return FractionalFit(eta, order, float(res.fun), rms, rel, pred, count[0],
                         {"grid": int(grid), "memory": memory, "success": bool(res.success), "message": str(res.message)})


def fit_sls(record: StressRecord, *, grid: int = 400, tau_bounds=(1e-3, 1e4)) -> SLSFit:
    """Standard linear solid fitted with the same cost: NNLS for (E_inf, E1) at each tau, bounded
    search over log tau (a coarse scan, then refinement around the best point)."""
    t, eps = resample(record, grid)

    def solve(log_tau):
        tau = math.exp(log_tau)
        a = np.column_stack([np.interp(record.time, t, v1.sls_stress(t, eps, 1.0, 0.0, tau)),
                             np.interp(record.time, t, v1.sls_stress(t, eps, 0.0, 1.0, tau))])
        w = np.sqrt(np.gradient(record.time))[:, None]
        coef, _ = so.nnls(a * w, record.stress * w[:, 0])
        pred = a @ coef
        return integrated_squared_error(record.time, record.stress, pred), coef, pred

    lo, hi = (math.log(b) for b in tau_bounds)
    scan = np.linspace(lo, hi, 60)
    costs = [solve(x)[0] for x in scan]
    k = int(np.argmin(costs))
    res = so.minimize_scalar(lambda x: solve(x)[0], bounds=(scan[max(k - 1, 0)], scan[min(k + 1, len(scan) - 1)]),
                             method="bounded")
    c, coef, pred = solve(res.x)
    rms, rel = _errors(record, pred)
    return SLSFit(float(coef[0]), float(coef[1]), math.exp(res.x), c, rms, rel, pred)


def plot_fits(record: StressRecord, fits: dict, path: str, title: str = "") -> None:
    """Measured stress against each fit's estimate ({label: FractionalFit | SLSFit}), and the orders."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, axq) = plt.subplots(2, 1, figsize=(6.0, 5.2), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax.plot(record.time, record.stress / 1e3, "k.", ms=2, label="measured")
    for label, f in fits.items():
        ax.plot(record.time, f.predicted / 1e3, "-", lw=1.4, label=f"{label} (RMS {f.residual / 1e3:.3g} kPa)")
        if isinstance(f, FractionalFit):
            axq.step(record.time, f.order(record.time), where="post", label=f"q(t), {label}")
    ax.set_ylabel("stress (kPa)")
    ax.legend(fontsize=7)
    ax.set_title(title or record.source, fontsize=8)
    axq.set_ylabel("order q")
    axq.set_ylim(-0.05, 1.05)
    axq.set_xlabel("time (s)")
    ax2 = ax.twinx()
    ax2.plot(record.time, record.strain, color="0.7", lw=0.8)
    ax2.set_ylabel("strain", color="0.5")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def check_test(record: StressRecord, test: str) -> str:
    """A note when the record does not look like ``test`` ("relax": ends with a hold; "ramp": strain
    increases); ConfigError for an unknown test."""
    if test not in TESTS:
        raise ConfigError(f"test must be one of {TESTS} for the 1-D fractional fit, got {test!r}")
    span = float(np.ptp(record.strain)) or 1.0
    tail = record.strain[int(0.8 * len(record.strain)):]
    if test == "relax" and np.ptp(tail) > 0.02 * span:
        return "note: the strain still changes over the last 20 % of the record (no hold): is this a relaxation test?"
    if test == "ramp" and np.any(np.diff(record.strain) < -0.01 * span):
        return "note: the strain decreases somewhere: a ramp test should load monotonically"
    return ""


def run_cli(args) -> int:
    """``surgsim fit --model fractional --test relax|ramp --data FILE.csv`` (called from bench/fit.py)."""
    import json

    record = read_record(args.data)
    if args.max_strain is not None:
        record = record.until_strain(args.max_strain)
    note = check_test(record, args.test)
    frac = fit_fractional(record, pieces=args.pieces, seed=args.seed, grid=args.grid)
    sls = fit_sls(record, grid=args.grid)
    if args.plot:
        plot_fits(record, {f"fractional, {args.pieces} pieces": frac, "SLS": sls}, args.plot,
                  title=f"{args.test}: {record.source}")
    if args.json:
        print(json.dumps({"model": "fractional", "test": args.test, "params": frac.params(), "breaks_s": list(frac.order.breaks),
                          "cost_Pa2s": frac.cost, "residual_Pa": frac.residual, "relative_residual": frac.relative_residual,
                          "sls": {"params": sls.params(), "residual_Pa": sls.residual,
                                  "relative_residual": sls.relative_residual}, "note": note}, indent=2))
        return 0
    if note:
        print(note)
    print(f"fractional (sigma = eta D^q(t) eps, {args.pieces} pieces, breaks {', '.join(f'{b:.4g}' for b in frac.order.breaks) or '-'} s):")
    print(f"{'eta':>15} = {frac.eta:.6g} Pa s^q")
    for i, q in enumerate(frac.order.values):
        print(f"{'q' + str(i + 1):>15} = {q:.4f}")
    print(f"{'residual':>15} = {frac.residual:.4g} Pa RMS ({100 * frac.relative_residual:.2f} % of data RMS); "
          f"cost {frac.cost:.4g} Pa^2 s")
    p = sls.params()
    tau = f"{p['relax_time']:.4g} s" if p["relax_fraction"] > 1e-6 else "not identifiable (no relaxing part)"
    print(f"SLS: E0 = {p['young']:.6g} Pa, relax_fraction = {p['relax_fraction']:.4f}, tau = {tau}; "
          f"residual {sls.residual:.4g} Pa RMS ({100 * sls.relative_residual:.2f} %)")
    if args.plot:
        print(f"plot: {args.plot}")
    return 0

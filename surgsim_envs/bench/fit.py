"""``surgsim fit``: fit a model's material parameters to measured force data (the grasping simulation paper, eq. 4).

Least squares, ``min sum_k (F_model(x_k; p) - F_k)^2`` over the data points (x = depth in m for
``indent``, time in s for ``relax``):

* indent: p = E. The tests are linear elastic in the small-strain regime, so the force scales with
  E: one simulation at the material's E gives the shape, and the best E is a closed-form
  projection (one model evaluation).
* relax: p = (E, relax_fraction, relax_time). E again enters linearly (solved in closed form for
  every trial); (relax_fraction, relax_time) are found by ``scipy.optimize.least_squares``
  (a few dozen relaxation simulations of a coarse block).

CSV: two columns (x, force in N), optional header line. The plot shows data against the fit.

Constitutive (1-D stress-strain) fits are registered in ``STRESS_STRAIN_FITS`` (model name ->
module with ``run_cli(args)``): ``--model fractional --test relax|ramp --data FILE.csv`` reads a
``time_s, strain, stress_Pa`` record instead (the variable-order paper, :mod:`surgsim_envs.bench.fractional_fit`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize as so

from surgsim_envs.errors import ConfigError
from surgsim_envs.materials import get_material

#: model name -> module whose ``run_cli(args)`` fits a 1-D stress-strain record (time, strain, stress)
STRESS_STRAIN_FITS: dict[str, str] = {
    "fractional": "surgsim_envs.bench.fractional_fit",
}


@dataclass
class FitResult:
    """Fitted ``params`` (SI), ``residual`` (RMS of force misfit, N), ``relative_residual``
    (RMS / RMS of the data), the data ``x``, ``force`` and the fitted ``predicted`` force (N)."""

    model: str
    test: str
    params: dict
    residual: float
    relative_residual: float
    x: np.ndarray
    force: np.ndarray
    predicted: np.ndarray
    evaluations: int = 0
    info: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {"model": self.model, "test": self.test, "params": self.params, "residual": self.residual,
                "relative_residual": self.relative_residual, "evaluations": self.evaluations}


def read_csv(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Two numeric columns (x, force N) from ``path``; a non-numeric first line is a header."""
    try:
        with open(path) as fh:
            lines = [ln.strip() for ln in fh if ln.strip() and not ln.startswith("#")]
    except OSError as exc:
        raise ConfigError(f"cannot read data file {path!r}: {exc}") from None
    rows = []
    for k, ln in enumerate(lines):
        parts = ln.replace(";", ",").replace("\t", ",").split(",")
        try:
            rows.append([float(parts[0]), float(parts[1])])
        except (ValueError, IndexError):
            if k == 0:
                continue
            raise ConfigError(f"{path}: line {k + 1} {ln!r} is not two numbers (x, force N)") from None
    if len(rows) < 3:
        raise ConfigError(f"{path}: need at least 3 data rows (x, force N), got {len(rows)}")
    arr = np.array(rows)
    return arr[:, 0], arr[:, 1]


def _scale(pred: np.ndarray, force: np.ndarray) -> float:
    den = float(pred @ pred)
    if den <= 0:
        raise ConfigError("the model predicts zero force at the data points; check units (m, s, N) and the test setup")
    return float(pred @ force) / den


def fit_indent(model, x, force, material="liver", *, progress=None, **indent_opts) -> FitResult:
    """Fit E (Pa) to an indentation curve: depths ``x`` (m), forces (N). ``progress()``, if given,
    is called after every model run."""
    from surgsim_envs.bench.material import indent

    from surgsim_envs.bench.material import model_class

    x, force = _check(x, force)
    mat = get_material(material)
    cls = model_class(model)
    count = [0]

    def shape_for(extra):
        res = indent(cls, mat, depth=float(x.max()), time_steps=0, **{"n_depths": 16, **indent_opts, **extra})
        count[0] += 1
        if progress is not None:
            progress()
        return res, np.interp(x, np.concatenate([[0.0], res.depth]), np.concatenate([[0.0], res.force]))

    # models may name shape parameters to search as well (class attribute fit_shape_parameters,
    # {name: (low, high)} > 0, searched on a log scale one after the other); young stays closed-form
    extra: dict = {}
    for name, (lo, hi) in dict(getattr(cls, "fit_shape_parameters", {})).items():
        def misfit(log_v, name=name):
            _, sh = shape_for({**extra, name: float(math.exp(log_v))})
            return float(np.sum((_scale(sh, force) * sh - force) ** 2))

        sol = so.minimize_scalar(misfit, bounds=(math.log(lo), math.log(hi)), method="bounded",
                                 options={"xatol": 0.02, "maxiter": 30})
        extra[name] = float(math.exp(sol.x))
    res, shape = shape_for(extra)
    s = _scale(shape, force)
    pred = s * shape
    return _result(res.model, "indent", {"young": s * mat.young, **extra}, x, force, pred, count[0])


def fit_relax(model, x, force, material="liver", *, max_evaluations: int = 40, progress=None,
              **relax_opts) -> FitResult:
    """Fit E (Pa), relax_fraction and relax_time (s) to a ramp-and-hold curve: times ``x`` (s), forces (N).
    ``progress()``, if given, is called after every model run.

    relax_opts go to :func:`surgsim_envs.bench.material.relax` (strain, ramp_time, size, spacing...);
    hold_time defaults to the data's duration."""
    from surgsim_envs.bench.material import model_class, relax

    x, force = _check(x, force)
    caps = getattr(model_class(model), "capabilities", None)
    if caps is not None and "viscoelastic" not in caps:        # contract v2 capability
        name = model_class(model).name
        raise ConfigError(f"model '{name}' does not honour relax_fraction / relax_time (it lacks the capability "
                          f"'viscoelastic'); a relaxation fit means nothing for it: use --test indent")
    mat = get_material(material)
    ramp = float(relax_opts.get("ramp_time", 0.2))
    opts = {"hold_time": max(float(x.max()) - ramp, 1e-3), "samples": 400, **relax_opts}
    cls = model_class(model)
    count = [0]
    cache = {}

    def shape(params):
        g1, log_tau = params
        key = (round(g1, 10), round(log_tau, 10))
        if key not in cache:
            m = mat.replace(relax_fraction=float(np.clip(g1, 0.0, 0.95)), relax_time=float(math.exp(log_tau)))
            r = relax(cls, m, **opts)
            count[0] += 1
            if progress is not None:
                progress()
            cache[key] = np.interp(x, r.time, r.force)
        return cache[key]

    def residual(params):
        sh = shape(params)
        return _scale(sh, force) * sh - force

    g0 = min(max(mat.relax_fraction, 0.1), 0.9)
    sol = so.least_squares(residual, [g0, math.log(mat.relax_time)], bounds=([0.0, math.log(1e-3)], [0.95, math.log(1e3)]),
                           max_nfev=max_evaluations, diff_step=1e-3, x_scale=[0.1, 0.3])
    sh = shape(sol.x)
    s = _scale(sh, force)
    params = {"young": s * mat.young, "relax_fraction": float(sol.x[0]), "relax_time": float(math.exp(sol.x[1]))}
    return _result(cls.name, "relax", params, x, force, s * sh, count[0])


def _check(x, force):
    x, force = np.asarray(x, dtype=float).ravel(), np.asarray(force, dtype=float).ravel()
    if x.shape != force.shape or len(x) < 3 or not (np.all(np.isfinite(x)) and np.all(np.isfinite(force))):
        raise ConfigError(f"data must be two finite arrays of equal length >= 3, got {x.shape} and {force.shape}")
    if np.any(x < 0):
        raise ConfigError("data x (depth m or time s) must be >= 0")
    return x, force


def _result(model, test, params, x, force, pred, evals) -> FitResult:
    rms = float(np.sqrt(np.mean((pred - force) ** 2)))
    scale = float(np.sqrt(np.mean(force ** 2))) or 1.0
    return FitResult(model, test, params, rms, rms / scale, x, force, pred, evals)


def fit(model, test: str, x, force, material="liver", **opts) -> FitResult:
    """Fit ``model`` to data of ``test`` ("indent" or "relax"); see :func:`fit_indent`, :func:`fit_relax`."""
    if test == "indent":
        return fit_indent(model, x, force, material, **opts)
    if test == "relax":
        return fit_relax(model, x, force, material, **opts)
    raise ConfigError(f"test must be 'indent' or 'relax', got {test!r}")


def plot_fit(result: FitResult, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    scale = 1e3 if result.test == "indent" else 1.0
    ax.plot(result.x * scale, result.force, "o", ms=3, label="data")
    ax.plot(result.x * scale, result.predicted, "-", label=f"{result.model} fit")
    ax.set_xlabel("depth (mm)" if result.test == "indent" else "time (s)")
    ax.set_ylabel("force (N)")
    ax.set_title(", ".join(f"{k}={v:.4g}" for k, v in result.params.items()) + f"; RMS {result.residual:.3g} N", fontsize=8)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--model", required=True, help="registered model name (surgsim models)")
    parser.add_argument("--test", required=True, choices=["indent", "relax", "ramp"],
                        help="indent, relax (force data) or, for stress-strain models (fractional), relax / ramp")
    parser.add_argument("--data", required=True, help="CSV: depth_m,force_N (indent) or time_s,force_N (relax); "
                        "stress-strain models: time_s,strain,stress_Pa (or an Instron phantom file)")
    parser.add_argument("--material", default="liver", help="starting material preset (default liver)")
    parser.add_argument("--radius", type=float, default=0.005, help="indent: sphere radius m")
    parser.add_argument("--thickness", type=float, default=0.03, help="indent: slab thickness m")
    parser.add_argument("--spacing", type=float, default=None, help="mesh spacing m (indent: under the sphere)")
    parser.add_argument("--unbonded", action="store_true", help="indent: slab slides on its base")
    parser.add_argument("--strain", type=float, default=0.05, help="relax: compression strain")
    parser.add_argument("--ramp-time", type=float, default=0.2, help="relax: ramp duration s")
    parser.add_argument("--plot", default="fit.png", help="plot of data against fit (default fit.png)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="model option for the fit runs (repeatable), e.g. --option length=depth")
    parser.add_argument("--pieces", type=int, default=3, help="fractional: constant-order subintervals of q(t) (default 3)")
    parser.add_argument("--grid", type=int, default=400, help="fractional: uniform grid samples of the estimate (default 400)")
    parser.add_argument("--seed", type=int, default=0, help="fractional: differential-evolution seed (default 0)")
    parser.add_argument("--max-strain", type=float, default=None, help="fractional: use the record up to this strain")


def run(args: argparse.Namespace) -> int:
    if args.model in STRESS_STRAIN_FITS:
        import importlib

        return int(importlib.import_module(STRESS_STRAIN_FITS[args.model]).run_cli(args) or 0)
    if args.test == "ramp":
        raise ConfigError(f"--test ramp is a stress-strain fit, available for models {sorted(STRESS_STRAIN_FITS)}; "
                          f"for {args.model!r} use --test indent or relax")
    x, force = read_csv(args.data)
    if args.test == "indent":
        opts = {"indenter_radius": args.radius, "thickness": args.thickness, "bonded": not args.unbonded}
        if args.spacing:
            opts["spacing"] = args.spacing
    else:
        opts = {"strain": args.strain, "ramp_time": args.ramp_time}
        if args.spacing:
            opts["spacing"] = args.spacing
    for item in args.option:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ConfigError(f"--option must be KEY=VALUE, got {item!r}")
        try:
            opts[key] = float(value)
        except ValueError:
            opts[key] = value
    from tqdm import tqdm

    # model runs: the bounded searches stop on tolerance, so the count is open-ended
    with tqdm(desc=f"fit {args.model} ({args.test})", unit="model run", file=sys.stderr,
              bar_format="{desc}: {n} model runs [{elapsed}, {rate_fmt}]") as bar:
        result = fit(args.model, args.test, x, force, args.material, progress=lambda: bar.update(1), **opts)
    if args.plot:
        plot_fit(result, args.plot)
    if args.json:
        print(json.dumps(result.as_dict(), indent=2))
    else:
        for k, v in result.params.items():
            print(f"{k:>15} = {v:.6g}")
        print(f"{'residual':>15} = {result.residual:.4g} N RMS ({100 * result.relative_residual:.2f} % of data RMS)")
        if args.plot:
            print(f"plot: {args.plot}")
    return 0

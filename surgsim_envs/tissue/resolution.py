"""Pick the cheapest tissue model, integrator and resolution that meets an accuracy and a compute budget.

This is the pure selection logic behind ``resolution="auto"`` in scenes and tasks. It lives in
the tissue layer (it is a statement about tissue models, and needs only json + the measured
table) so that :mod:`surgsim_envs.scene` can use it without importing :mod:`surgsim_envs.bench`,
which sits above the scene.

The rule (documented in docs/benchmarks.md, "Speed against accuracy"):

1. candidates are the rows of the measured table (``surgsim bench accuracy``; a copy ships in
   ``surgsim_envs/tissue/data/accuracy_table.json``, data of the tissue layer) for ``scene`` with a measured cost, optionally
   restricted to some models and integrators; baseline rows (MuJoCo flex) never qualify;
2. a row qualifies if its force error against the reference is <= ``error_tolerance`` (fraction,
   0.1 = 10 %) and its cost of simulating 1 ms (``us_per_ms``: wall time of all physics steps
   needed for 1 ms, so explicit models that need sub-steps pay for every one) is <=
   ``step_budget_us`` microseconds;
3. among qualifying rows the one with the lowest cost wins (ties: lower error, then coarser mesh);
   so a looser budget never makes the mesh finer by itself: a tighter tolerance does;
4. if none qualifies a :class:`ConfigError` names the closest option: the row with the smallest
   ``max(error / tolerance, cost / budget)``, with its error and cost, so the caller knows which
   limit to relax.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from typing import Any, Iterable

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: the shipped measured table (written by ``surgsim bench accuracy``; data only, no bench import)
TABLE_PATH = os.path.join(os.path.dirname(__file__), "data", "accuracy_table.json")


@dataclass(frozen=True)
class Choice:
    """A table row: ``model``, ``integrator``, ``spacing`` (m, mesh spacing at the tool), ``nodes`` of
    the benchmark mesh, ``error`` (fraction), ``us_per_ms`` (us of compute per simulated ms),
    ``dt`` (s) of the model's physics step."""

    model: str
    integrator: str
    spacing: float
    nodes: int
    error: float
    us_per_ms: float
    dt: float
    scene: str = "indent"


def load_table(path: str | None = None) -> list[dict[str, Any]]:
    """Rows of a measured accuracy table (default: the shipped one, :data:`TABLE_PATH`)."""
    path = path or TABLE_PATH
    try:
        with open(path) as fh:
            data = json.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"accuracy table {path!r} not found; create one with `surgsim bench accuracy --out DIR`") from None
    except json.JSONDecodeError as exc:
        raise ConfigError(f"accuracy table {path!r} is not valid JSON ({exc}); regenerate it with "
                          "`surgsim bench accuracy --out DIR`") from None
    rows = data["rows"] if isinstance(data, dict) and "rows" in data else data
    if not isinstance(rows, list):
        raise ConfigError(f"accuracy table {path!r} must hold a list of rows (or {{'rows': [...]}})")
    return rows


def _valid(row: dict) -> bool:
    try:
        return all(math.isfinite(float(row[k])) for k in ("error", "us_per_ms")) and not row.get("baseline")
    except (KeyError, TypeError, ValueError):
        return False


def choose(error_tolerance: float, step_budget_us: float, scene: str = "indent", *,
           table: str | Iterable[dict] | None = None, models: Iterable[str] | None = None,
           integrators: Iterable[str] | None = None) -> Choice:
    """The cheapest (model, integrator, spacing) with force error <= ``error_tolerance`` (fraction)
    and compute <= ``step_budget_us`` microseconds per simulated millisecond.

    table: path of a table JSON or an iterable of rows (default: the shipped table).
    models, integrators: restrict to these names. Baseline rows (MuJoCo flex) are never chosen.
    """
    validate.positives(error_tolerance=error_tolerance, step_budget_us=step_budget_us,
                       fix="error_tolerance is a fraction like 0.1; step_budget_us in microseconds like 1000")
    rows = load_table(table) if table is None or isinstance(table, str) else list(table)
    allowed = None if models is None else set(models)
    allowed_int = None if integrators is None else set(integrators)
    rows = [r for r in rows if r.get("scene", "indent") == scene and _valid(r)
            and (allowed is None or r["model"] in allowed)
            and (allowed_int is None or r.get("integrator") in allowed_int)]
    if not rows:
        raise ConfigError(f"the accuracy table has no measured rows for scene {scene!r}"
                          + (f" and models {sorted(allowed)}" if allowed else "")
                          + (f" and integrators {sorted(allowed_int)}" if allowed_int else "")
                          + "; run `surgsim bench accuracy` for it")
    ok = [r for r in rows if r["error"] <= error_tolerance and r["us_per_ms"] <= step_budget_us]
    if not ok:
        best = min(rows, key=lambda r: max(r["error"] / error_tolerance, r["us_per_ms"] / step_budget_us))
        raise ConfigError(
            f"no model meets error <= {error_tolerance:.3g} and cost <= {step_budget_us:.3g} us per simulated ms "
            f"(scene {scene!r}); closest: {best['model']}/{best['integrator']} at spacing {best['spacing'] * 1e3:.3g} mm "
            f"with error {best['error']:.3g} and {best['us_per_ms']:.3g} us/ms. Relax the tolerance or the budget.")
    best = min(ok, key=lambda r: (r["us_per_ms"], r["error"], -r["spacing"]))
    return Choice(best["model"], best["integrator"], float(best["spacing"]), int(best["nodes"]), float(best["error"]),
                  float(best["us_per_ms"]), float(best.get("dt", math.nan)), scene)


#: m, the finest spacing a resolution may ask for: a tenth of a millimetre (a 1 cm organ at that
#: spacing is already 10^6 nodes; a subnormal spacing overflows every node count)
MIN_SPACING = 1e-4


def check_resolution(resolution, what: str = "resolution") -> None:
    """Raise ConfigError unless ``resolution`` is None, ``"auto"`` or a spacing in m in
    [MIN_SPACING, 0.1)."""
    if resolution is None or (isinstance(resolution, str) and resolution == "auto"):
        return
    if not validate.is_real_number(resolution) or not MIN_SPACING <= resolution < 0.1:   # NaN fails the comparison
        raise ConfigError(f"{what}={validate.short_repr(resolution)} must be 'auto', a spacing in m in "
                          f"[{MIN_SPACING:g}, 0.1) (e.g. 0.005), or None for the default")


def resolve_resolution(resolution, *, model: str | None = None, error_tolerance: float = 0.1,
                       step_budget_us: float = 5_000.0, scene: str = "indent", table=None,
                       integrator: str | None = None) -> tuple[str, float | None]:
    """Turn a scene/task ``resolution`` into ``(model, spacing)``.

    resolution: ``"auto"`` (choose from the measured table with :func:`choose`, restricted to
        ``model`` and ``integrator`` if given), a spacing in m (returned as is), or None (the
        organ's default spacing).
    Returns the model name (``model`` unless chosen) and the spacing in m (None = default).
    """
    check_resolution(resolution)
    if resolution is None:
        return model, None
    if resolution == "auto":
        pick = choose(error_tolerance, step_budget_us, scene, table=table,
                      models=None if model is None else [model],
                      integrators=None if integrator is None else [integrator])
        return pick.model, pick.spacing
    return model, float(resolution)

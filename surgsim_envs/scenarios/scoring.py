"""Scoring of a recorded scenario run: metrics, per-criterion results, safety violations.

Metrics (SI units) computed from a :class:`~surgsim_envs.scenarios.recording.Recording`:

=====================  ====  ==================================================================
criterion              unit  value
=====================  ====  ==================================================================
``completion``         --    1 when every phase ran to its end (0 when the run stopped early)
``time``               s     simulated time of the run
``path_length``        m     length of the tool origin's path
``peak_force``         N     largest total normal contact force on the tool
``mean_force``         N     mean normal force over the samples in contact
``time_above_limit``   s     time the normal force exceeded ``scoring.safety_limit``
``slip_events``        --    gross slips: the pull force drops by > 25 % from a peak at which
                             at least half the contact nodes slide (see :func:`slip_events`)
``inclusion_error``    m     palpation: x-y distance from the stiffest press to the inclusion
=====================  ====  ==================================================================

Each criterion scores 1 at or below its ``target``, 0 at or above its ``limit`` (linear in
between) and passes below its ``limit``; the scenario score is ``100 *`` the weighted mean.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: criterion -> (unit, description)
CRITERIA: dict[str, tuple[str, str]] = {
    "completion": ("", "every phase ran to its end"),
    "time": ("s", "simulated time of the run"),
    "path_length": ("m", "length of the tool path"),
    "peak_force": ("N", "largest normal contact force"),
    "mean_force": ("N", "mean normal force while in contact"),
    "time_above_limit": ("s", "time above the safety force limit"),
    "slip_events": ("", "gross slips of the grasp"),
    "inclusion_error": ("m", "x-y error of the located inclusion"),
}
CONTACT_THRESHOLD = 0.01  # N: a sample is "in contact" above this normal force


@dataclass
class CriterionResult:
    """One criterion's outcome: ``value`` (unit), ``score`` in [0, 1], ``passed``."""

    name: str
    value: float | None
    unit: str
    target: float | None
    limit: float | None
    weight: float
    score: float
    passed: bool

    def as_dict(self) -> dict:
        return {"value": self.value, "unit": self.unit, "target": self.target, "limit": self.limit,
                "weight": self.weight, "score": self.score, "passed": self.passed}


def safety_violations(t: np.ndarray, force: np.ndarray, limit: float) -> list[dict]:
    """Intervals where ``force`` (N) > ``limit`` (N): [{"start", "end", "duration" s, "peak" N}]."""
    above = force > limit
    out = []
    i, n = 0, len(t)
    while i < n:
        if above[i]:
            j = i
            while j + 1 < n and above[j + 1]:
                j += 1
            end = t[j + 1] if j + 1 < n else t[j]
            out.append({"start": float(t[i]), "end": float(end), "duration": float(end - t[i]),
                        "peak": float(force[i:j + 1].max())})
            i = j + 1
        else:
            i += 1
    return out


def slip_events(rec, drop: float = 0.25, min_force: float = 0.05, min_share: float = 0.5) -> list[float]:
    """Times (s) at which the grasp slips grossly: the pull force (N) falls by more than ``drop``
    of its running peak (at least ``min_force``) while at least ``min_share`` of the contact nodes
    slide at that peak. Release phases are ignored. After an event the detector re-arms once the
    pull force has risen by half again above its lowest value since the event."""
    skip = rec.phase_mask("release")
    share = np.where(rec.contacts > 0, rec.slipping / np.maximum(rec.contacts, 1), 0.0)
    out: list[float] = []
    peak_k, armed, low = None, True, np.inf
    for k in range(len(rec.t)):
        if skip[k]:
            peak_k = None
            continue
        p = rec.pull_force[k]
        if not armed:
            low = min(low, p)
            if p > max(1.5 * low, min_force):
                armed, peak_k = True, k
            continue
        if peak_k is None or p >= rec.pull_force[peak_k]:
            peak_k = k
            continue
        pk = rec.pull_force[peak_k]
        if pk >= min_force and p < (1.0 - drop) * pk and share[peak_k] >= min_share:
            out.append(float(rec.t[peak_k]))
            armed, low, peak_k = False, p, None
    return out


def slip_onset(rec) -> dict | None:
    """The grasping simulation paper's slip onset (Fig. 5, red points): during pull phases the pull force peaks and then
    falls as the contact nodes slide along the jaws. Returns {"time" s, "pull_force" N,
    "normal_force" N} at that peak when nodes were slipping there, else None.

    A scene records node counts only (its contact points include surface samples), so this is the
    pull peak with sliding nodes, not the grasp-and-pull rig's onset from each point's slip
    (:mod:`surgsim_envs.bench.slip_onset`). Both read the contact state, neither a threshold on
    friction / (mu N); in the rig the two agree where the pull peaks before the grasp slides
    (mass_spring mu 1.0: onset 0.439 s, peak 0.435 s), while at low mu the pull can still rise
    after the onset, to the sliding friction (docs/material_tests.md, "Slip onset")."""
    mask = rec.phase_mask("pull")
    if not mask.any():
        return None
    idx = np.flatnonzero(mask)
    k = idx[int(np.argmax(rec.pull_force[idx]))]
    if rec.slipping[k] <= 0 or k == idx[-1]:
        return None  # still rising at the end of the pull, or no sliding: no gross slip
    return {"time": float(rec.t[k]), "pull_force": float(rec.pull_force[k]),
            "normal_force": float(rec.normal[k]), "tangential_force": float(rec.tangential[k])}


def inclusion_estimate(rec, surface_z: float, tip_radius: float) -> np.ndarray | None:
    """(2,) m x-y where the tissue is stiffest: per press (contact episode) the ratio of force to
    indentation (N/m) at the deepest point; the estimate is the centroid of the stiffest presses
    (upper half of the range above the median, weighted by the excess). None without presses."""
    depth = surface_z - (rec.position[:, 2] - tip_radius)
    contact = (rec.normal > CONTACT_THRESHOLD) & (depth > 2e-4)
    presses = []  # (x, y, stiffness N/m)
    i, n = 0, len(rec.t)
    while i < n:
        if contact[i]:
            j = i
            while j + 1 < n and contact[j + 1]:
                j += 1
            k = i + int(np.argmax(depth[i:j + 1]))
            if depth[k] > 1e-3:  # shallow touches say little about the stiffness below
                presses.append((rec.position[k, 0], rec.position[k, 1], rec.normal[k] / depth[k]))
            i = j + 1
        else:
            i += 1
    if not presses:
        return None
    arr = np.asarray(presses)
    k = arr[:, 2]
    # centroid of the presses in the upper half of the stiffness range, weighted by the excess
    # over the median: between grid points when two neighbours are both stiff
    base = np.median(k)
    w = np.clip(k - (base + 0.5 * (k.max() - base)), 0.0, None)
    if w.sum() <= 0:
        return arr[int(np.argmax(k)), :2].copy()
    return (arr[:, :2] * w[:, None]).sum(axis=0) / w.sum()


def compute_metrics(rec, safety_limit: float, completed: bool, inclusion_truth=None, surface_z=None,
                    tip_radius: float = 0.0) -> dict:
    """All metric values (see :data:`CRITERIA`) plus slip onset and the inclusion estimate."""
    t = rec.t
    dt = np.diff(t, append=t[-1] + (t[-1] - t[-2] if len(t) > 1 else 0.0)) if len(t) else np.zeros(0)
    in_contact = rec.normal > CONTACT_THRESHOLD
    m = {
        "completion": 1.0 if completed else 0.0,
        "time": float(t[-1]) if len(t) else 0.0,
        "path_length": float(np.linalg.norm(np.diff(rec.position, axis=0), axis=1).sum()) if len(t) > 1 else 0.0,
        "peak_force": float(rec.normal.max()) if len(t) else 0.0,
        "mean_force": float(rec.normal[in_contact].mean()) if in_contact.any() else 0.0,
        "time_above_limit": float(dt[rec.normal > safety_limit].sum()),
        "peak_tangential_force": float(rec.tangential.max()) if len(t) else 0.0,
        "peak_pull_force": float(rec.pull_force.max()) if len(t) else 0.0,
    }
    slips = slip_events(rec)
    m["slip_events"] = float(len(slips))
    m["slip_event_times"] = slips
    m["slip_onset"] = slip_onset(rec)
    m.update(grasp_figures(rec))
    if inclusion_truth is not None and surface_z is not None:
        est = inclusion_estimate(rec, surface_z, tip_radius)
        m["inclusion_truth"] = [float(v) for v in inclusion_truth[:2]]
        m["inclusion_estimate"] = None if est is None else [float(v) for v in est]
        m["inclusion_error"] = None if est is None else float(np.linalg.norm(est - np.asarray(inclusion_truth[:2])))
    return m


def grasp_figures(rec) -> dict:
    """The grasping simulation paper figures of a grasp: normal force (N) at the end of the first close_jaws phase and
    of the hold after it, the relaxed fraction, and the linearity (R^2 of a straight-line fit) of
    the normal force against time while the jaws close in contact."""
    spans = rec.phase_spans
    close = next((s for s in spans if s["type"] == "close_jaws"), None)
    if close is None:
        return {}
    hold = next((s for s in spans if s["type"] == "hold" and s["index"] == close["index"] + 1), None)
    out = {}
    cm = rec.phase == close["index"]
    if cm.any():
        out["normal_end_close"] = float(rec.normal[cm][-1])
        t, f = rec.t[cm], rec.normal[cm]
        touch = f > CONTACT_THRESHOLD
        if touch.sum() >= 3:
            tt, ff = t[touch], f[touch]
            coef = np.polyfit(tt, ff, 1)
            resid = ff - np.polyval(coef, tt)
            ss = float(((ff - ff.mean()) ** 2).sum())
            out["close_linearity_r2"] = 1.0 - float((resid ** 2).sum()) / ss if ss > 0 else 1.0
            out["close_slope"] = float(coef[0])
    if hold is not None:
        hm = rec.phase == hold["index"]
        if hm.any():
            out["normal_end_hold"] = float(rec.normal[hm][-1])
            if out.get("normal_end_close", 0.0) > 0:
                out["relaxed_fraction"] = 1.0 - out["normal_end_hold"] / out["normal_end_close"]
    return out


def default_criteria(safety_limit: float, palpation: bool) -> dict:
    """Criteria used when a scenario gives none: completion, peak force and time above the limit."""
    from surgsim_envs.scenarios.schema import CriterionSpec

    out = {"completion": CriterionSpec(weight=1.0),
           "peak_force": CriterionSpec(target=0.7 * safety_limit, limit=1.5 * safety_limit, weight=1.0),
           "time_above_limit": CriterionSpec(target=0.0, limit=1.0, weight=1.0)}
    if palpation:
        out["inclusion_error"] = CriterionSpec(target=0.005, limit=0.02, weight=2.0)
    return out


def score_criteria(metrics: dict, criteria: dict) -> tuple[float, list[CriterionResult]]:
    """(score 0-100, per-criterion results). A criterion whose metric is missing (e.g.
    ``inclusion_error`` when the probe never touched) scores 0 and fails."""
    results = []
    for name, spec in criteria.items():
        unit = CRITERIA[name][0]
        value = metrics.get(name)
        if name == "completion":
            ok = bool(value)
            results.append(CriterionResult(name, value, unit, None, None, spec.weight, 1.0 if ok else 0.0, ok))
            continue
        if value is None:
            results.append(CriterionResult(name, None, unit, spec.target, spec.limit, spec.weight, 0.0, False))
            continue
        frac = (spec.limit - value) / (spec.limit - spec.target)
        s = float(min(max(frac, 0.0), 1.0))
        results.append(CriterionResult(name, float(value), unit, spec.target, spec.limit, spec.weight, s,
                                       bool(value < spec.limit)))
    total_w = sum(r.weight for r in results)
    score = 100.0 * sum(r.weight * r.score for r in results) / total_w if total_w > 0 else 0.0
    return score, results

"""Stability map: presets stable at their default dt, guard verdict beyond the explicit limit, implicit margin."""

import numpy as np
import pytest

from surgsim_envs import geometry, tissue
from surgsim_envs.bench.stability import block_model, guard_verdict, stable_limit
from surgsim_envs.errors import TissueUnstableError
from surgsim_envs.materials import PRESETS


# FEM with stiff skin (~35 CG iterations per implicit step) and nearly incompressible silicone take
# 10-20 s, every other FEM preset 10-25 s (quiet): the default run keeps fem-liver (the tasks'
# organ material) and every mass_spring preset; the rest run with -m slow.
_SLOW_PRESETS = {("fem", p) for p in PRESETS if p != "liver"}


@pytest.mark.parametrize("model,preset", [
    pytest.param(m, p, marks=[pytest.mark.slow] if (m, p) in _SLOW_PRESETS else [])
    for m in ("mass_spring", "fem") for p in sorted(PRESETS)])
def test_presets_stable_at_default_dt(model, preset):
    # every shipped preset is stable at the default dt (1 ms) with the default integrator
    # ("auto": explicit below 0.8 x critical_dt(), implicit above) for 1 s of simulated time
    vol = geometry.make_volume("slab")
    z = vol.nodes[:, 2]
    t = tissue.make(model, vol, preset, fixed=np.isclose(z, z.min()))
    assert t.integrator == "auto"
    expected = "symplectic" if 1e-3 <= 0.8 * t.critical_dt() else "implicit"
    assert guard_verdict(t, 1e-3, steps=1000) is None
    assert t.time == pytest.approx(1.0)
    assert np.all(np.isfinite(t.positions)) and t.inverted_elements() == 0
    if model == "fem":          # the FEM critical dt is a constant (rest stiffness): the choice never changes
        assert t.active_integrator == expected


@pytest.mark.parametrize("model", ["mass_spring", "fem"])
def test_beyond_explicit_limit_guard_raises_and_implicit_has_10x_margin(model):
    t = block_model(model, 4000.0, 0.005, "symplectic")
    row = stable_limit(t, steps=200, rel_tol=0.05)
    assert not row["capped"]
    verdict = guard_verdict(t, 1.2 * row["dt_unstable"], steps=200)
    assert isinstance(verdict, TissueUnstableError)          # a verdict, not NaN
    assert verdict.model == model and verdict.dt == pytest.approx(1.2 * row["dt_unstable"])
    assert np.isfinite(verdict.critical_dt) and "integrator='implicit'" in str(verdict)   # names the fix
    assert 0.5 < row["dt_limit"] / row["critical_dt"] < 2.0   # the estimate is in the right place
    implicit = block_model(model, 4000.0, 0.005, "implicit")
    assert guard_verdict(implicit, 10.0 * row["dt_unstable"], steps=100) is None


# --- load scaling: the stability-map load is a fixed strain (top_load = strain x E x area), not a fixed force
def test_stability_load_scales_with_young_and_keeps_strain_small():
    from surgsim_envs.bench.stability import LOAD_STRAIN, top_load

    soft = block_model("fem", 1e3, 0.0075, "implicit")
    stiff = block_model("fem", 1e5, 0.0075, "implicit")
    assert top_load(stiff) == pytest.approx(100.0 * top_load(soft))
    assert top_load(soft) == pytest.approx(LOAD_STRAIN * 1e3 * 0.03 * 0.03)
    # the soft block is compressed by a few percent under it, not crushed
    assert guard_verdict(soft, 1e-3, steps=300) is None
    z = soft.rest_positions[:, 2]
    top = np.isclose(z, z.max())
    strain = -np.mean(soft.positions[top, 2] - z[top]) / z.max()
    assert 0.2 * LOAD_STRAIN < strain < 3.0 * LOAD_STRAIN


def test_soft_block_limit_is_the_explicit_limit():
    # at E = 1 kPa the old fixed 0.2 N load inverted elements; with the scaled load the measured
    # limit is the explicit one, near the model's own critical_dt() estimate
    t = block_model("fem", 1e3, 0.0075, "symplectic")
    row = stable_limit(t, steps=200, rel_tol=0.1)
    assert not row["capped"]
    assert 0.5 < row["dt_limit"] / row["critical_dt"] < 2.0
    # the load does not crush the block: at the measured limit nothing inverts (beyond it the
    # explicit instability may show first as inverted elements)
    assert guard_verdict(t, row["dt_limit"], steps=200) is None and t.inverted_elements() == 0

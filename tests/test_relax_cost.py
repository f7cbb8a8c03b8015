"""bench/relax_cost.py: the viscoelastic step against the elastic one, alternately in one process."""

import pytest

from surgsim_envs.bench.relax_cost import format_rows, relax_row
from surgsim_envs.tissue import registry


def test_relax_row_times_both_models_at_one_dt():
    row = relax_row(registry.get("fem"), "symplectic", 60, repeats=1, steps=2, warmup=1)
    assert row["model"] == "fem" and row["integrator"] == "symplectic"
    assert 0 < row["dt_s"] <= 1e-3
    assert row["viscoelastic_us"] > 0 and row["elastic_us"] > 0
    assert row["viscoelastic_over_elastic"] == pytest.approx(row["viscoelastic_us"] / row["elastic_us"], rel=1e-2)
    assert "fem" in format_rows([row])

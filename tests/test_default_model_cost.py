"""bench/default_model_cost.py: the default env against the plain mass_spring network."""

import math

from surgsim_envs.bench.default_model_cost import default_vs_plain, plain_network
from surgsim_envs.tissue.mass_spring import MassSpringModel


def test_plain_network_drops_the_point_load_options_and_restores_them():
    before = dict(MassSpringModel.point_load_options)
    assert before == {"volume_stiffness": "capped"}
    with plain_network():
        assert MassSpringModel.point_load_options == {}
    assert MassSpringModel.point_load_options == before


def test_palpation_default_against_the_plain_network_both_timed():
    from surgsim_envs.envs.palpation import PalpationConfig

    row = default_vs_plain("SurgSim/Palpation-v0", steps=3, repeats=1)
    assert row["default_model"] == PalpationConfig.model
    assert row["plain_volume_stiffness"] is None
    assert row["default_step_us"] > 0 and row["plain_step_us"] > 0
    assert math.isclose(row["default_over_plain"], row["default_step_us"] / row["plain_step_us"])
    assert MassSpringModel.point_load_options == {"volume_stiffness": "capped"}

"""``surgsim bench envs --env-options``: gym.make keyword arguments for the single-env figures."""

import argparse

import pytest

from surgsim_envs.bench.envs_speed import add_arguments, parse_env_options, run
from surgsim_envs.errors import ConfigError


def test_env_options_are_a_json_object_of_make_arguments():
    assert parse_env_options(None) == {}
    assert parse_env_options('{"model": "fem_static", "spacing": 0.005}') == {"model": "fem_static", "spacing": 0.005}
    with pytest.raises(ConfigError, match=r"is not JSON"):
        parse_env_options("model=fem_static")
    with pytest.raises(ConfigError, match=r"must be a JSON object"):
        parse_env_options("[1, 2]")


def test_env_options_refuse_the_figures_that_build_the_defaults():
    p = argparse.ArgumentParser()
    add_arguments(p)
    args = p.parse_args(["--tasks", "SurgSim/Palpation-v0", "--env-options", '{"model": "fem_static"}'])
    with pytest.raises(ConfigError, match="--workers 0 --no-model-ratio"):
        run(args)

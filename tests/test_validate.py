"""The validation vocabulary (surgsim_envs/validate.py): every check returns the canonical value
or raises ConfigError naming the value, the bound and the fix."""

from __future__ import annotations

import math

import numpy as np
import pytest

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError


def test_real_accepts_numbers_in_range_and_returns_floats():
    assert validate.real(3, "x", lo=0, hi=5) == 3.0 and isinstance(validate.real(3, "x"), float)
    assert validate.real(np.float32(0.5), "x", lo=0, hi=1) == 0.5
    assert validate.real(np.int64(2), "x") == 2.0
    assert validate.real(np.array(0.25), "x") == 0.25           # a 0-d array is a scalar (configs refuse it)
    with pytest.raises(ConfigError, match=r"x=array\(0.25\) is a 0-d array; pass the number itself"):
        validate.config_value(np.array(0.25), "x")
    with pytest.raises(ConfigError, match="not ndarray"):
        validate.real(np.array([0.25]), "x")


@pytest.mark.parametrize("value, message", [
    (float("nan"), "x=nan m must be finite"),
    (float("inf"), "x=inf m must be finite"),
    (10**400, "must be finite"),                      # an int too large for a float is not a number here
    (-(10**400), "must be finite"),
    (True, "x=True m must be a real number .* not bool"),
    ("1", "must be a real number .* not str"),
    (1j, "not complex"),
    (None, "not NoneType"),
    (6.0, r"x=6.0 m is outside \[0, 5\] m; fix it"),
    (-1, r"is outside \[0, 5\] m"),
])
def test_real_refuses_with_the_value_the_bound_and_the_fix(value, message):
    with pytest.raises(ConfigError, match=message):
        validate.real(value, "x", lo=0, hi=5, unit="m", fix="fix it")


def test_open_bounds_and_positive():
    with pytest.raises(ConfigError, match=r"outside \(0, 1\]"):
        validate.positive(0.0, "x", hi=1)
    assert validate.positive(1e-300, "x") == 1e-300
    with pytest.raises(ConfigError, match=r"\[0, 1\)"):
        validate.real(1.0, "x", lo=0, hi=1, hi_open=True)


def test_integer_refuses_floats_bools_and_out_of_range():
    assert validate.integer(np.int32(7), "n", lo=1, hi=10) == 7
    with pytest.raises(ConfigError, match="n=7.0 must be an integer, not float"):
        validate.integer(7.0, "n")
    with pytest.raises(ConfigError, match="n=True must be an integer, not bool"):
        validate.integer(True, "n")
    with pytest.raises(ConfigError, match=r"n=11 is outside \[1, 10\]"):
        validate.integer(11, "n", lo=1, hi=10)


def test_steps_duration_and_rate_carry_machine_bounds():
    with pytest.raises(ConfigError, match=r"10,000,000 physics steps"):
        validate.steps(10**12, "hold_steps")
    with pytest.raises(ConfigError, match=r"outside \(0, 3600\] s"):
        validate.duration(1e9, "hold_time")
    with pytest.raises(ConfigError, match="fps=inf Hz must be finite"):
        validate.rate(math.inf, "fps")
    assert validate.steps(validate.MAX_PHYSICS_STEPS, "n") == validate.MAX_PHYSICS_STEPS


def test_boolean_choice_text_path_seed(tmp_path):
    assert validate.boolean(np.bool_(True), "b") is True
    with pytest.raises(ConfigError, match="b=1 must be True or False"):
        validate.boolean(1, "b")
    assert validate.choice("a", "c", ["a", "b"]) == "a"
    with pytest.raises(ConfigError, match=r"c=5 is not one of \['5'\]"):
        validate.choice(5, "c", ["5"])              # compared by type too: 5 is not "5"
    with pytest.raises(ConfigError, match="t='' must be a non-empty string"):
        validate.text("", "t")
    f = tmp_path / "f.txt"
    f.write_text("x")
    assert validate.path(str(f), "p") == f
    with pytest.raises(ConfigError, match="is not an existing file"):
        validate.path(tmp_path / "missing", "p")
    with pytest.raises(ConfigError, match=r"--seed=-1 is outside \[0, "):
        validate.seed(-1, "--seed")


def test_grid_nodes_counts_before_allocating():
    assert validate.grid_nodes((0.1, 0.1, 0.02), 0.01, "slab") == 11 * 11 * 3
    with pytest.raises(ConfigError, match=r"gives about 2e\+11 nodes, above the limit of 1,000,000"):
        validate.grid_nodes((0.1, 0.1, 0.02), 1e-5, "slab", hi=1_000_000)


def test_one_sided_bounds_read_as_one():
    with pytest.raises(ConfigError, match=r"k=-1 must be > 0; e.g. 20"):
        validate.positive(-1, "k", fix="e.g. 20")
    with pytest.raises(ConfigError, match=r"x=2.0 m must be <= 1 m"):
        validate.real(2.0, "x", hi=1.0, unit="m")


def test_positives_checks_each_keyword_in_order_and_names_the_first_bad_one():
    assert validate.positives(radius=0.005, young=5000, fix="SI units") == (0.005, 5000.0)
    with pytest.raises(ConfigError, match=r"young=-1 must be > 0; SI units"):
        validate.positives(radius=0.005, young=-1, thickness=0.0, fix="SI units")
    with pytest.raises(ConfigError, match=r"radius=nan m must be finite"):
        validate.positives(radius=float("nan"), unit="m")

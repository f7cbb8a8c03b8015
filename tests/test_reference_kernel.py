"""The reference kernel timed beside ``surgsim bench envs`` (bench/reference_kernel.py): a real spring
network whose forces are right, and the bench reports the env step in units of it."""

import argparse
import json

import numpy as np
import pytest

from surgsim_envs.bench import envs_speed
from surgsim_envs.bench.reference_kernel import (DAMPING, DT, MASS, STIFFNESS, reference_kernel_us, reference_network,
                                                 reference_step, spring_forces)


def _numpy_forces(x, v, si, sj, rest, k, c):
    d = x[sj] - x[si]
    length = np.linalg.norm(d, axis=1)
    u = d / length[:, None]
    t = k * (length - rest) + c * np.einsum("ij,ij->i", v[sj] - v[si], u)
    f = np.zeros_like(x)
    np.add.at(f, si, t[:, None] * u)
    np.add.at(f, sj, -t[:, None] * u)
    return f


def test_the_network_is_the_documented_lattice():
    x, v, si, sj, rest = reference_network()
    assert x.shape == (1000, 3) and len(si) == 5940
    assert np.all(si != sj) and len({(a, b) for a, b in zip(si, sj)}) == 5940      # no spring twice
    np.testing.assert_allclose(np.unique(rest.round(12)), [0.01, 0.01 * np.sqrt(2)])


def test_forces_match_numpy_and_sum_to_zero():
    x, v, si, sj, rest = reference_network(seed=3)
    v = np.random.default_rng(4).normal(0.0, 0.01, x.shape)
    f = np.empty_like(x)
    spring_forces(x, v, si, sj, rest, STIFFNESS, DAMPING, f)
    expected = _numpy_forces(x, v, si, sj, rest, STIFFNESS, DAMPING)
    np.testing.assert_allclose(f, expected, rtol=1e-10, atol=1e-14)
    assert np.abs(f).max() > 1e-3                          # the jitter loads the springs
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-12)   # internal forces: no net force


def test_a_step_conserves_momentum_and_moves_the_nodes():
    x, v, si, sj, rest = reference_network()
    x0 = x.copy()
    f = np.empty_like(x)
    for _ in range(50):
        reference_step(x, v, si, sj, rest, STIFFNESS, DAMPING, 1.0 / MASS, DT, f)
    np.testing.assert_allclose(v.sum(axis=0) * MASS, 0.0, atol=1e-12)
    assert np.abs(x - x0).max() > 1e-6 and np.all(np.isfinite(x))


def test_reference_time_is_positive_and_finite():
    us = reference_kernel_us(calls=5, repeats=1)
    assert np.isfinite(us) and us > 0


def test_bench_envs_reports_the_step_in_reference_kernels(capsys):
    p = argparse.ArgumentParser()
    envs_speed.add_arguments(p)
    args = p.parse_args(["--tasks", "SurgSim/Palpation-v0", "--steps", "5", "--repeats", "1", "--workers", "0", "--json"])
    assert envs_speed.run(args) == 0
    row = json.loads(capsys.readouterr().out)["envs"][0]
    assert row["reference_kernel_us"] > 0
    assert row["env_step_in_reference_kernels"] == pytest.approx(1e6 / row["steps_per_s"] / row["reference_kernel_us"])

"""Resets of a few batched worlds restore the recorded reset state row by row (batch/simulation.py
``reset_worlds``, ``reset_kernels.restore_rows``): the first reset runs MuJoCo Warp's ``reset_data`` +
``forward`` and records one world's row of every per-world ``Data`` array; a later reset must give
the listed worlds exactly those rows (every field, not only the state) and must not touch any row
of the other worlds."""

import dataclasses

import numpy as np
import pytest

from surgsim_envs.batch.backend import available

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")


def _rows(data, W):
    """{field: (W, ...) host copy} of every Data array whose leading dimension is the world count."""
    import warp as wp

    out = {}

    def walk(d, prefix=""):
        for f in dataclasses.fields(d):
            a = getattr(d, f.name)
            if isinstance(a, wp.array):
                if a.ndim >= 1 and a.shape[0] == W and a.size:
                    out[prefix + f.name] = a.numpy().copy()
            elif dataclasses.is_dataclass(a):
                walk(a, prefix + f.name + ".")

    walk(data)
    return out


@pytest.mark.parametrize("task", ["SurgSim/Grasp-v0", "SurgSim/Palpation-v0"])
def test_a_later_reset_restores_every_row_and_touches_no_other_world(task):
    from gymnasium.envs.registration import load_env_creator

    from surgsim_envs.envs import BATCHED

    W = 3
    env = load_env_creator(BATCHED[task])(W, device="cpu")
    sim = env.sim
    env.reset(seed=0)                                 # the first reset: MuJoCo Warp's reset_data + forward
    fresh = _rows(sim.tools.data, W)
    assert len(fresh) > 50
    rng = np.random.default_rng(0)
    for _ in range(4):
        env.step(rng.uniform(-1, 1, (W,) + env.single_action_space.shape))
    moved = _rows(sim.tools.data, W)
    assert any(not np.array_equal(moved[k][1], fresh[k][1]) for k in ("qpos", "qvel", "xpos"))
    sim.reset_worlds([1])
    after = _rows(sim.tools.data, W)
    for name in fresh:
        np.testing.assert_array_equal(after[name][1], fresh[name][1], err_msg=f"reset world, field {name}")
        for w in (0, 2):
            np.testing.assert_array_equal(after[name][w], moved[name][w], err_msg=f"world {w}, field {name}")
    np.testing.assert_array_equal(sim.tissue_positions()[1], sim.topology.rest)
    env.close()

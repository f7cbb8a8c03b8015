"""Ray RLlib creators with per-worker seeding. The seeding tests need no Ray; the
local-mode training run is marked ``distributed`` (``pytest -m distributed``, needs the
[distributed] extra) and skips without Ray."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

# DESIGN.md: with torch installed, triton must be imported before MuJoCo/EGL is (else torch's
# optimiser set-up segfaulted here, in RLlib's learner build)
if importlib.util.find_spec("triton") is not None:
    import triton  # noqa: F401

import numpy as np
import pytest

from surgsim_envs.integrations.rllib import SLOTS_PER_WORKER, make_creator, worker_seed
from surgsim_envs.errors import ConfigError

TASK = "SurgSim/PalpationPress-v0"


class EnvContext(dict):
    """Stand-in for ray.rllib.env.EnvContext: a dict with worker and vector indices."""

    def __init__(self, config, worker_index, vector_index):
        super().__init__(config)
        self.worker_index, self.vector_index = worker_index, vector_index


def test_worker_seeds_are_distinct_and_checked():
    seeds = {worker_seed(7, w, v) for w in range(4) for v in range(3)}
    assert len(seeds) == 12 and min(seeds) == 7
    with pytest.raises(ConfigError, match="vector_index"):
        worker_seed(0, 1, SLOTS_PER_WORKER)
    with pytest.raises(ConfigError, match="worker_index"):
        worker_seed(0, -1, 0)


def test_creator_seeds_each_worker_differently_and_reproducibly():
    create = make_creator(TASK)
    centres = {}
    for w, v in [(1, 0), (1, 1), (2, 0)]:
        env = create(EnvContext({"seed": 3}, w, v))
        _, info = env.reset()                         # RLlib resets without a seed
        centres[(w, v)] = tuple(np.round(info["inclusion_centre_m"], 6))
        env.close()
    assert len(set(centres.values())) == 3            # every (worker, slot) explores another episode
    again = create(EnvContext({"seed": 3}, 1, 1))
    _, info = again.reset()
    assert tuple(np.round(info["inclusion_centre_m"], 6)) == centres[(1, 1)]
    _, info2 = again.reset()                          # later resets continue the env's generator
    assert tuple(np.round(info2["inclusion_centre_m"], 6)) != centres[(1, 1)]
    again.close()


def test_creator_passes_task_config_and_rejects_unknown_fields():
    env = make_creator(TASK)({"seed": 0, "max_presses": 9})
    assert env.unwrapped.config.max_presses == 9
    env.close()
    with pytest.raises(ConfigError, match="no_such_field"):
        make_creator(TASK)({"no_such_field": 1})


@pytest.mark.distributed
@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason="Ray RLlib not installed (the [distributed] extra)")
def test_train_rllib_local_mode(tmp_path):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
    import train_rllib

    assert train_rllib.main(["--task", TASK, "--iterations", "1", "--batch", "32", "--local",
                             "--out", str(tmp_path)]) == 0
    assert (tmp_path / "result.json").is_file()

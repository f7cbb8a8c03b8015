"""organ= in the grasp tasks: a registered name, a closed mesh file or a Volume."""

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401
from surgsim_envs.envs.registry import TASKS
from surgsim_envs.errors import ConfigError

#: the tasks built on the grasp scene (their organ= option)
GRASP_TASKS = [t for t, spec in TASKS.items() if spec.scene == "grasp"]

trimesh = pytest.importorskip("trimesh")


def _bean(path):
    """A closed capsule 9 cm long along x, 4 cm thick (m), written to ``path``."""
    mesh = trimesh.creation.capsule(height=0.05, radius=0.02, count=(16, 16))
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (0, 1, 0)))
    mesh.export(path)
    return mesh


@pytest.mark.parametrize("task", GRASP_TASKS)
def test_grasp_tasks_take_a_mesh_file_as_organ(tmp_path, task):
    mesh = _bean(tmp_path / "bean.stl")
    env = gym.make(task, organ=str(tmp_path / "bean.stl"))
    env.reset(seed=0)
    tissue = env.unwrapped.sim.tissue()
    nodes = tissue.positions
    extent = nodes.max(axis=0) - nodes.min(axis=0)
    assert extent == pytest.approx(mesh.extents, rel=0.15)      # the mesh's size, not the spleen's
    for _ in range(2):
        obs, reward, *_ = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        assert np.all(np.isfinite(obs)) and np.isfinite(reward)
    env.close()


def test_grasp_task_takes_a_volume_as_organ(tmp_path):
    from surgsim_envs.geometry import organ_volume

    _bean(tmp_path / "bean.obj")
    vol = organ_volume(str(tmp_path / "bean.obj"), spacing=0.012)
    env = gym.make("SurgSim/Grasp-v0", organ=vol)
    env.reset(seed=0)
    assert env.unwrapped.sim.tissue().n_nodes == vol.n_nodes
    env.close()


def test_bad_organs_are_refused_by_name(tmp_path):
    with pytest.raises(ConfigError, match=r"no such mesh file"):
        gym.make("SurgSim/Grasp-v0", organ=str(tmp_path / "kidney.stl"))
    with pytest.raises(ConfigError, match=r"organ='pancreas'; choose one of \['liver_lobe', 'spleen'\]"):
        gym.make("SurgSim/Grasp-v0", organ="pancreas")
    open_mesh = trimesh.creation.box(extents=(0.05, 0.03, 0.03))
    trimesh.Trimesh(open_mesh.vertices, open_mesh.faces[:-2]).export(tmp_path / "open.stl")
    with pytest.raises(ConfigError, match=r"(?i)watertight|closed|hole"):
        gym.make("SurgSim/Grasp-v0", organ=str(tmp_path / "open.stl"))

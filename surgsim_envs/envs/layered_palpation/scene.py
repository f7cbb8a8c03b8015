"""The picture of a LayeredPalpation-v0 press: a MuJoCo scene of the wall and the probe.

The task solves each press quasi-statically on its own ``layered`` tissue (no MuJoCo in the
physics). For ``render_mode="rgb_array"`` and the dm_control loader it keeps a
:class:`~surgsim_envs.scene.Simulation` of the same wall (same organ, spacing and size, placed in
the task's frame) and a free probe, built on first use (seconds). :meth:`PressScene.show` copies
the task tissue's node positions into the scene's tissue, puts the probe's sphere centre at the
press and sets the scene clock; the scene is never stepped. Units m, s.
"""

from __future__ import annotations

import mujoco
import numpy as np

from surgsim_envs.errors import ConfigError


class PressScene:
    """A render/dm_control scene mirroring ``tissue`` (a task's wall of tissue ``model``, built on
    ``organ``, a Volume, or when None on the registered abdominal wall at ``spacing`` m and ``size``
    (x, y) m), probe tip ``radius`` m; ``sim`` is the Simulation."""

    def __init__(self, tissue, spacing: float, size, radius: float, render_width: int, render_height: int,
                 model: str = "layered", organ=None):
        from surgsim_envs.scene.builder import build_scene
        from surgsim_envs.scene.config import ProbeConfig, SceneConfig, TissueConfig
        from surgsim_envs.scene.simulation import Simulation

        rest = tissue.rest_positions
        z_mid = 0.5 * float(rest[:, 2].min() + rest[:, 2].max())
        self.home = np.array([0.0, 0.0, float(rest[:, 2].max()) + 0.03])
        if organ is None:
            tc = TissueConfig(name="wall", organ="abdominal_wall", model=model, material=None, spacing=spacing,
                              volume_options={"size": tuple(size)}, position=(0.0, 0.0, z_mid), anchors=("bottom",))
        else:
            tc = TissueConfig(name="wall", organ=organ, model=model, material=tissue.material, spacing=None,
                              position=(0.0, 0.0, z_mid), anchors=("bottom",))
        cfg = SceneConfig(tissues=[tc], tools=[ProbeConfig(position=tuple(self.home), drive="free",
                                                            tip_radius=radius)],
                          dt=1e-3, render_width=int(render_width), render_height=int(render_height))
        self.sim = sim = Simulation(build_scene(cfg))
        self.tissue = sim.tissue("wall")
        if self.tissue.n_nodes != tissue.n_nodes or \
                not np.allclose(self.tissue.rest_positions, rest, atol=1e-9 + 1e-6 * float(spacing)):
            raise ConfigError("LayeredPalpation render scene: the scene's wall does not match the task's wall "
                              f"({self.tissue.n_nodes} vs {tissue.n_nodes} nodes); render with render_mode=None")
        self.probe = sim.tool("probe")

    def show(self, tissue, centre, time_s: float) -> None:
        """Mirror ``tissue``'s node positions, the probe at sphere centre ``centre`` (3,) m, clock ``time_s``."""
        self.tissue.positions[:] = tissue.positions
        d = self.sim.data
        d.qpos[self.probe.qpos_adr] = np.asarray(centre, dtype=np.float64) - self.home
        d.qvel[:] = 0.0
        d.time = float(time_s)
        mujoco.mj_kinematics(self.sim.model, d)


__all__ = ["PressScene"]

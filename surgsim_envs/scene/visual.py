"""The render-only twin of a scene: the physics model plus the tissue flexes, used only for frames.

Measured (CHANGELOG.md, "Env step: visual geometry out of the physics step"): a MuJoCo flex of world-body
vertices is recomputed by ``mj_flex`` inside every ``mj_step1``, although those vertices never
move in MuJoCo: the grasp scene's 2,562-vertex smooth spleen surface made ``mj_step1`` cost
~130 us instead of ~8 us. The physics model (``Simulation.model``) therefore has NO flex; this
module compiles a second model from the same spec with the flexes added, and only when a frame is
first asked for. :meth:`VisualTwin.sync` copies the physics state (qpos, qvel, act, mocap, ctrl,
time) into the twin's MjData, runs ``mj_forward`` on it and then writes the deformed tissue
surfaces into ``flexvert_xpos`` (``mj_forward`` resets world-body flex vertices to rest, so the
write comes after it). Body, geom, joint, actuator and camera ids are the same in both models
(flexes on the world body add no bodies, geoms or dofs).
"""

from __future__ import annotations

import mujoco

from surgsim_envs.errors import ConfigError

#: MjData fields copied from the physics data before each frame
_STATE_FIELDS = ("qpos", "qvel", "act", "mocap_pos", "mocap_quat", "ctrl", "qfrc_applied", "xfrc_applied")


class VisualTwin:
    """A render model (physics spec + tissue flexes) and its MjData, compiled on first use.

    spec: the scene's MjSpec WITHOUT flexes (it is copied, not changed); bindings:
    {name: TissueBinding} whose flexes are added to the copy.
    """

    def __init__(self, spec: mujoco.MjSpec, bindings: dict):
        self._spec = spec
        self.bindings = bindings
        self._model: mujoco.MjModel | None = None
        self._data: mujoco.MjData | None = None

    @property
    def model(self) -> mujoco.MjModel:
        """The render MjModel (compiled on first access)."""
        if self._model is None:
            vspec = self._spec.copy()
            for binding in self.bindings.values():
                binding.add_to(vspec)
            try:
                self._model = vspec.compile()
            except Exception as exc:
                raise ConfigError(f"the render model (scene + tissue surfaces) does not compile: {exc}") from exc
            for binding in self.bindings.values():
                binding.bind(self._model)
            self._data = mujoco.MjData(self._model)
        return self._model

    @property
    def data(self) -> mujoco.MjData:
        """The render MjData (state as of the last :meth:`sync`)."""
        _ = self.model
        return self._data

    def sync(self, physics_model: mujoco.MjModel, physics_data: mujoco.MjData) -> mujoco.MjData:
        """Copy the physics state into the render data, run ``mj_forward`` and write the tissue
        surfaces; return the render MjData, ready for ``Renderer.update_scene`` / viewer sync."""
        m = self.model
        d = self._data
        for name in _STATE_FIELDS:
            getattr(d, name)[:] = getattr(physics_data, name)
        d.time = physics_data.time
        # parameters a task may change at run time (e.g. Slippage turns an actuator into a motor)
        m.actuator_gainprm[:] = physics_model.actuator_gainprm
        m.actuator_biasprm[:] = physics_model.actuator_biasprm
        mujoco.mj_forward(m, d)
        for binding in self.bindings.values():
            binding.write(d)
        return d

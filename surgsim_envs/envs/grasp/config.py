"""Grasp-v0's settings: :class:`GraspConfig` (SI units) and its checks."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from surgsim_envs.envs.checks import check_positive, check_range, check_task_length, check_weights
from surgsim_envs.envs.grasp.scene import GraspSceneConfig


@dataclass
class GraspConfig(GraspSceneConfig):
    """Grasp-v0 settings (SI units): the shared grasp-scene fields (:class:`GraspSceneConfig`) plus
    the task's target and reward. Ranges are (low, high) sampled uniformly per episode."""

    tissue_subcycles: int | str = "auto"   # 2 tissue + contact steps of dt per MuJoCo step at the defaults
    #                                        (MuJoCo at 0.8 ms; see resolved_subcycles); 1 = one each
    max_step: float = 0.001            # m per control step (5 cm/s at 50 Hz)
    workspace: float = 0.06            # m, wrist target |offset| from home per axis
    target_offset_x: Sequence[float] = (0.012, 0.02)  # m, along the pull direction (out of the organ)
    target_offset_z: Sequence[float] = (0.0, 0.005)   # m, lift
    # reward
    hold_force: float = 0.03           # N, a jaw "holds" above this normal force
    damage_force: float = 1.0          # N per jaw
    force_weight: float = 1.0
    slip_weight: float = 0.1
    progress_weight: float = 5.0
    contact_weight: float = 0.03      # per step, times the fraction of jaws pressing on the tissue
    drop_penalty: float = 0.5
    success_bonus: float = 5.0
    tolerance: float = 0.005           # m

    def validate(self) -> None:
        super().validate()
        for key in ("max_step", "workspace", "hold_force", "damage_force", "tolerance"):
            check_positive(getattr(self, key), f"GraspConfig.{key}")
        check_task_length(self.tolerance, "GraspConfig.tolerance")
        check_task_length(self.max_step, "GraspConfig.max_step", lo=1e-6)     # 1 um per control step at least
        check_weights(self, ("force_weight", "slip_weight", "progress_weight", "contact_weight", "drop_penalty",
                             "success_bonus"), "GraspConfig")
        w = float(self.workspace)
        within = f"(within +-workspace={w:g} m)"
        check_range(self.target_offset_x, f"target_offset_x {within}", -w, w)
        check_range(self.target_offset_z, f"target_offset_z {within}", -w, w)

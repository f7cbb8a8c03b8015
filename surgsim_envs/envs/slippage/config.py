"""Slippage-v0's settings: :class:`SlippageConfig` (SI units) and its checks."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from surgsim_envs import validate
from surgsim_envs.envs.checks import check_positive, check_range, check_weights
from surgsim_envs.envs.grasp.scene import GraspSceneConfig


#: s, the longest settle a reset runs (the default 0.4 s settles the grasp)
MAX_SETTLE_SECONDS = 10.0


@dataclass
class SlippageConfig(GraspSceneConfig):
    """Slippage-v0 settings (SI units): the shared grasp-scene fields (:class:`GraspSceneConfig`)
    plus the pull and the task's own reward (no fields of Grasp-v0's reward)."""

    episode_seconds: float = 3.0
    dt: float = 4e-4                   # s; the squeezed, strain-stiffened tissue needs < 0.5 ms
    mu: Sequence[float] = (0.3, 1.0)
    young_scale: Sequence[float] = (0.8, 1.2)
    closing_speed: float = 0.05
    initial_closure: float = 0.7       # action value the jaws close to during the settle
    settle_time: float = 0.4           # s
    replay_approach: bool = True       # restore the settle's contact-free start from a snapshot (scene/approach_snapshot.py)
    pull_rate: Sequence[float] = (0.03, 0.06)       # N/s
    pull_amplitude: Sequence[float] = (0.0, 0.03)   # N
    pull_frequency: Sequence[float] = (0.5, 2.0)   # Hz
    max_pull: float = 3.0              # N, motor limit
    pull_damping: float = 2.0          # N s/m on the wrist's along-axis joint
    slip_weight: float = 1.0           # per mm of slip
    squeeze_weight: float = 0.05       # per N of excess squeeze per step
    drop_penalty: float = 5.0
    hold_reward: float = 0.3           # per control step while the grasp holds (dropping early never pays)
    max_slip: float = 0.015            # m, loss of grasp
    slip_tolerance: float = 0.008      # m, success

    def validate(self) -> None:
        super().validate()
        for key in ("max_pull", "pull_damping", "max_slip", "slip_tolerance"):
            check_positive(getattr(self, key), f"SlippageConfig.{key}")
        validate.duration(self.settle_time, "SlippageConfig.settle_time", hi=MAX_SETTLE_SECONDS,
                          fix=f"the grasp settles in about 0.4 s; at most {MAX_SETTLE_SECONDS:g} s (each reset runs "
                              "the whole settle)")
        check_weights(self, ("slip_weight", "squeeze_weight", "drop_penalty", "hold_reward"), "SlippageConfig")
        validate.boolean(self.replay_approach, "SlippageConfig.replay_approach")
        validate.real(self.initial_closure, "SlippageConfig.initial_closure", lo=-1.0, hi=1.0,
                      fix="an action value from fully open (-1) to closed (+1)")
        check_range(self.pull_rate, "pull_rate", 0.0, 10.0)
        check_range(self.pull_amplitude, "pull_amplitude", 0.0, 10.0)
        check_range(self.pull_frequency, "pull_frequency", 0.0, 50.0)


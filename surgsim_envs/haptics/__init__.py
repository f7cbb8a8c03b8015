"""Haptics: device interface, simulated devices, the 1 kHz servo loop, force extrapolation and a
UDP bridge. Nothing here imports the MuJoCo scene at import time; the servo talks to any object
following :class:`~surgsim_envs.haptics.protocol.HapticPhysics` (see ``docs/haptics.md``).
"""

from surgsim_envs.haptics.device import DeviceLimits, DeviceState, HapticDevice
from surgsim_envs.haptics.extrapolation import (
    ForceExtrapolator,
    HoldExtrapolator,
    LinearExtrapolator,
    StiffnessExtrapolator,
    linear_step_bound,
    make_extrapolator,
)
from surgsim_envs.haptics.fake_physics import SpringWallPhysics
from surgsim_envs.haptics.keyboard import KeyboardDevice
from surgsim_envs.haptics.protocol import HapticPhysics
from surgsim_envs.haptics.recording import ForceLog
from surgsim_envs.haptics.replay import ReplayDevice, load_poses, save_poses
from surgsim_envs.haptics.scripted import ScriptedDevice, TrajectorySpec, press_spec
from surgsim_envs.haptics.servo import DeviceMapping, ServoConfig, ServoLoop, ServoStats
from surgsim_envs.haptics.servo_process import ProcessServoLoop
from surgsim_envs.haptics.udp_bridge import UdpDevice, UdpHapticClient

__all__ = [
    "DeviceLimits", "DeviceState", "HapticDevice", "ForceExtrapolator", "HoldExtrapolator", "LinearExtrapolator",
    "StiffnessExtrapolator", "linear_step_bound", "make_extrapolator", "SpringWallPhysics", "KeyboardDevice",
    "HapticPhysics", "ForceLog", "ReplayDevice", "load_poses", "save_poses", "ScriptedDevice", "TrajectorySpec",
    "press_spec", "DeviceMapping", "ServoConfig", "ServoLoop", "ProcessServoLoop", "ServoStats", "UdpDevice", "UdpHapticClient",
]

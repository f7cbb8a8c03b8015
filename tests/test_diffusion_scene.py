"""The diffusion model (Zhong et al. 2016) in scenes and tasks through the generic path: a probe presses
the surface of a tet slab (interior nodes unused); Palpation-v0 refuses it (no subsurface stiffness)."""

from __future__ import annotations

import numpy as np
import pytest

from surgsim_envs.scene import HapticProxyConfig, ProbeConfig, SceneConfig, Simulation, TissueConfig, build_scene


def _sim():
    t = TissueConfig(name="slab", organ="slab", model="diffusion", material="liver", spacing=0.01, anchors=("bottom",),
                     position=(0.0, 0.0, 0.01), volume_options={"size": (0.06, 0.06, 0.02)},
                     options={"integrator": "symplectic"})
    probe = ProbeConfig(name="probe", tip_radius=0.008, position=(0.0, 0.0, 0.03), drive="proxy")
    return Simulation(build_scene(SceneConfig(name="t", tissues=[t], tools=[probe],
                                              proxies=[HapticProxyConfig(name="hand", tool="probe")], dt=5e-4,
                                              cameras=[])))


def test_probe_dents_the_diffusion_surface_and_feels_it():
    sim = _sim()
    tissue = sim.tissue()
    assert tissue.has("surface_only") if hasattr(tissue, "has") else "surface_only" in tissue.capabilities
    sim.set_proxy_pose("hand", [0.0, 0.0, 0.025])        # tip bottom 3 mm below the rest surface
    sim.run(0.4)
    felt = sim.proxy_force("hand")
    assert felt[2] > 0.05
    assert felt[2] == pytest.approx(sim.tool_force("probe")[2], rel=0.1)       # quasi-static balance
    dent = tissue.rest_positions[:, 2] - tissue.positions[:, 2]
    top = tissue.rest_positions[:, 2] > 0.0199
    assert dent[top].max() > 5e-4
    # the load spread: a ring of top nodes 1-2 cm from the probe dents too, less than the centre
    r = np.linalg.norm(tissue.rest_positions[:, :2], axis=1)
    ring = top & (r > 0.009) & (r < 0.021)
    assert 0.05 * dent[top].max() < dent[ring].mean() < dent[top].max()
    sim.set_proxy_pose("hand", [0.0, 0.0, 0.04])          # lift off: the surface comes back
    sim.run(0.5)
    assert np.abs(tissue.positions - tissue.rest_positions).max() < 1e-4


def test_palpation_task_refuses_the_surface_only_diffusion_model():
    """Palpation-v0 needs an inclusion below the surface to stiffen it (capability
    ``subsurface_stiffness``): the surface-only model lacks it and is refused by name before anything
    is built (tests/test_task_force_invariants.py measures the reason)."""
    gym = pytest.importorskip("gymnasium")
    import surgsim_envs.envs  # noqa: F401  (registers the tasks)
    from surgsim_envs.tissue.capabilities import CapabilityError

    with pytest.raises(CapabilityError, match="'diffusion' cannot serve SurgSim/Palpation-v0.*'subsurface_stiffness'"):
        gym.make("SurgSim/Palpation-v0", model="diffusion")


def _haptic_press(rate_hz, method):
    from surgsim_envs.haptics import DeviceLimits, DeviceMapping, ScriptedDevice, ServoConfig, ServoLoop, TrajectorySpec
    from surgsim_envs.haptics import scene_adapter

    phys = scene_adapter.make_haptic_simulation("palpation", spacing=0.01, model="diffusion", organ="slab")
    top = scene_adapter.tissue_top(phys) + float(phys.tool.config.tip_radius)
    home = phys.home_position.copy()
    bottom = top - 0.004 - home[2]
    dev = ScriptedDevice(TrajectorySpec(waypoints=[[0, 0, 0], [0, 0, bottom], [0, 0, bottom]], speeds=0.02,
                                        dwell=[0.0, 0.1, 0.05], profile="minimum_jerk"), limits=DeviceLimits(max_force=10.0))
    with dev:
        loop = ServoLoop(dev, phys, ServoConfig(extrapolation=method, mapping=DeviceMapping(origin=tuple(home))))
        stats = loop.run_simulated(dev.duration, physics_rate_hz=rate_hz)
    return dev.force_log.forces[:, 2], stats


def test_force_extrapolation_covers_250hz_physics_at_1khz_haptics():
    """Sec. 9.6.3: when the physics runs below 1 kHz, extrapolation fills the servo ticks. A 4 mm
    press on the diffusion slab: physics at 250 Hz, servo at 1 kHz, against physics at 1 kHz."""
    ref, st = _haptic_press(None, "linear")
    assert st.physics_updates == len(ref)
    assert ref.max() > 0.1
    rms = {}
    for method in ("hold", "linear", "stiffness"):
        f, st = _haptic_press(250, method)
        assert st.physics_updates == pytest.approx(len(f) / 4, abs=1)
        rms[method] = float(np.sqrt(np.mean((f - ref) ** 2)))
    assert rms["linear"] < 0.5 * rms["hold"] and rms["stiffness"] < 0.5 * rms["hold"]
    assert rms["linear"] < 0.01 * ref.max()

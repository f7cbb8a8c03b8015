"""What every task's device bookkeeping shares (``device_outputs=True``): host arrays uploaded to the
env's Warp device, and for the grasp scene's tasks (Grasp-v0, Slippage-v0) the observation launch.

A task's device terms (``PalpationDeviceTerms``, ``GraspDeviceTerms``, ``SlippageDeviceTerms``) set
``wp`` (the warp module), ``device``, ``W`` (worlds) and, for the grasp scene, ``K`` (its kernel
module with an ``observe`` kernel), ``sim``, ``state``, ``params``, ``body``, ``jaw_qpos``,
``jaw_columns`` and ``tool_rows``.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np


class DeviceTerms:
    """Base of a task's per-world state and kernels on the device."""

    def _host(self, values, dtype):
        """``values`` (host) as a new array on the device."""
        return self.wp.array(np.ascontiguousarray(values, dtype=dtype), device=self.device)


class GraspSceneDeviceTerms(DeviceTerms):
    """The grasp scene's observation: ``K.observe`` writes the (W, OBS_WIDTH) observation and the
    episode metrics the numpy path's info carries."""

    OBS_WIDTH: ClassVar[int] = 0

    def observe(self) -> tuple:
        """(observations (W, OBS_WIDTH) float32, {info name: (W,) array}: steps int64, mu, mu_static,
        young_scale, slip_distance_m, peak_force_N float64): fresh device arrays."""
        wp, W, sim = self.wp, self.W, self.sim
        arrays = sim.arrays()
        geom_fn, geom_ft = sim.geom_sum_arrays()
        obs = wp.empty((W, self.OBS_WIDTH), dtype=wp.float32, device=self.device)
        metrics = {"steps": wp.empty(W, dtype=wp.int64, device=self.device)}
        for key in ("mu", "mu_static", "young_scale", "slip_distance_m", "peak_force_N"):
            metrics[key] = wp.empty(W, dtype=wp.float64, device=self.device)
        wp.launch(self.K.observe, dim=W, device=self.device,
                  inputs=[self.state, self.params, arrays["xpos"], self.body, arrays["qpos"], self.jaw_qpos, geom_fn,
                          geom_ft, self.jaw_columns, arrays["tool_contacts"], arrays["tool_slipping"], self.tool_rows],
                  outputs=[obs, metrics["steps"], metrics["mu"], metrics["mu_static"], metrics["young_scale"],
                           metrics["slip_distance_m"], metrics["peak_force_N"]])
        return obs, metrics

"""Project-wide exception types."""

from __future__ import annotations


class SurgSimError(Exception):
    """Base class of all surgsim_envs errors."""


class ConfigError(SurgSimError, ValueError):
    """Bad user input: the message names the value and how to fix it."""


class NonFiniteInputError(ConfigError):
    """An input array (external forces, stiffness, an action) holds NaN or inf; the message names
    the array, where and the value. Raised before the input can reach the simulation state."""


class TissueUnstableError(SurgSimError, RuntimeError):
    """A tissue simulation diverged (NaN/inf, energy blow-up, inverted elements).

    Attributes: ``model`` (registry name), ``dt`` (s), ``critical_dt`` (s, the model's estimate),
    ``reason`` (what the guard saw).
    """

    def __init__(self, model: str, dt: float, critical_dt: float, reason: str):
        self.model = model
        self.dt = float(dt)
        self.critical_dt = float(critical_dt)
        self.reason = reason
        super().__init__(
            f"tissue model '{model}' became unstable at dt={dt:.3g} s "
            f"(estimated critical dt {critical_dt:.3g} s): {reason}. "
            "Reduce dt below the critical estimate, use an implicit integrator "
            "(integrator='implicit'), or soften the material."
        )

    def __reduce__(self):  # picklable across processes (e.g. gymnasium async vector envs)
        return (type(self), (self.model, self.dt, self.critical_dt, self.reason))


class RenderingUnavailableError(SurgSimError, RuntimeError):
    """No OpenGL context could be created for offscreen rendering."""

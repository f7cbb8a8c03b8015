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

    #: the advice of a divergence of an explicit step
    EXPLICIT_ADVICE = ("Reduce dt below the critical estimate, use an implicit integrator "
                       "(integrator='implicit'), or soften the material.")

    def __init__(self, model: str, dt: float, critical_dt: float, reason: str, advice: str | None = None):
        self.model = model
        self.dt = float(dt)
        self.critical_dt = float(critical_dt)
        self.reason = reason
        self.advice = self.EXPLICIT_ADVICE if advice is None else advice
        super().__init__(
            f"tissue model '{model}' became unstable at dt={dt:.3g} s "
            f"(estimated critical dt {critical_dt:.3g} s): {reason}. {self.advice}"
        )

    def __reduce__(self):  # picklable across processes (e.g. gymnasium async vector envs)
        return (type(self), (self.model, self.dt, self.critical_dt, self.reason, self.advice))


class RenderingUnavailableError(SurgSimError, RuntimeError):
    """No OpenGL context could be created for offscreen rendering."""


class GrowthDivergedError(TissueUnstableError):
    """The tissue-growth iteration (Vandewalle et al. 2003, section 2.3) diverged: the growth per iteration grew.

    Attributes: ``model``, ``alpha`` (the stability factor, 1/Pa), ``alpha_limit`` (1/Pa, the
    largest alpha guaranteed to converge), ``iteration``, ``reason``.
    """

    def __init__(self, model: str, alpha: float, alpha_limit: float, iteration: int, reason: str):
        self.model = model
        self.alpha = float(alpha)
        self.alpha_limit = float(alpha_limit)
        self.iteration = int(iteration)
        self.reason = reason
        self.dt = float("nan")
        self.critical_dt = float("nan")
        RuntimeError.__init__(
            self,
            f"tissue growth of model '{model}' diverged at iteration {iteration} with alpha={alpha:.4g} 1/Pa: "
            f"{reason}. Use a smaller stability factor: alpha < {alpha_limit:.4g} 1/Pa always converges "
            "(alpha='auto' picks the fastest safe value).")

    def __reduce__(self):
        return (type(self), (self.model, self.alpha, self.alpha_limit, self.iteration, self.reason))


class StaticSolveError(SurgSimError, RuntimeError):
    """A static (equilibrium) solve found no equilibrium within its iteration and load-step limits;
    the message names where it stopped, the residual or update it reached, and what to change."""


class GrowthNotConvergedError(SurgSimError, RuntimeError):
    """The tissue-growth iteration did not reach its threshold within ``max_iter`` iterations."""


class VectorEnvWorkerError(SurgSimError, RuntimeError):
    """A worker process of a SurgSim vector env (surgsim_envs/vector/env.py) died or did not answer
    in time; the message names the worker, its env indices and what it was doing."""

"""Benchmarks: virtual material tests, analytic references, speed against accuracy, stability maps."""

from surgsim_envs.bench.choose import Choice, choose, resolve_resolution

__all__ = ["choose", "resolve_resolution", "Choice"]

"""Pick the cheapest tissue model and resolution that meets an accuracy and a compute budget.

The selection logic lives in :mod:`surgsim_envs.tissue.resolution` (so that scenes can use it
without importing the bench layer above them); this module re-exports it as the benchmark API.
The rule is documented there and in docs/benchmarks.md, "Speed against accuracy".
"""

from __future__ import annotations

from surgsim_envs.tissue.resolution import (TABLE_PATH, Choice, check_resolution, choose, load_table,
                                            resolve_resolution)

__all__ = ["TABLE_PATH", "Choice", "check_resolution", "choose", "load_table", "resolve_resolution"]

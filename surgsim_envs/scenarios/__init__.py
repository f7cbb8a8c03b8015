"""Scripted trainee scenarios: a TOML file of phases, run by a script, a haptic device or a
policy, scored and reported.

>>> from surgsim_envs.scenarios import load_scenario, run_scenario, write_report
>>> sc = load_scenario("tasks/grasp_slippage_mu_sweep.toml")           # doctest: +SKIP
>>> results = run_scenario(sc, duration_scale=0.25)                     # doctest: +SKIP
>>> write_report(results, "out/")                                       # doctest: +SKIP

Importing this package does not import MuJoCo; running a scenario does. See docs/scenarios.md.
"""

from surgsim_envs.scenarios.loader import load_scenario, loads_scenario, parse_scenario
from surgsim_envs.scenarios.phases import PHASE_TYPES, Phase
from surgsim_envs.scenarios.schema import (CriterionSpec, PolicySpec, Scenario, ScenarioMeta, SceneOverrides,
                                           ScoringSpec, TraineeSpec)
from surgsim_envs.scenarios.scoring import CRITERIA


def run_scenario(*args, **kwargs):
    """See :func:`surgsim_envs.scenarios.runner.run_scenario`."""
    from surgsim_envs.scenarios.runner import run_scenario as _run

    return _run(*args, **kwargs)


def write_report(*args, **kwargs):
    """See :func:`surgsim_envs.scenarios.report.write_report`."""
    from surgsim_envs.scenarios.report import write_report as _write

    return _write(*args, **kwargs)


__all__ = ["PHASE_TYPES", "Phase", "CriterionSpec", "PolicySpec", "Scenario", "ScenarioMeta", "SceneOverrides",
           "ScoringSpec", "TraineeSpec", "load_scenario", "loads_scenario", "parse_scenario", "CRITERIA",
           "run_scenario", "write_report"]

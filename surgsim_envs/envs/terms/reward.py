"""Reward terms: each declared once with its function and the config field holding its weight.

A task lists its :class:`RewardTerm` s in order; the :class:`RewardManager` calls each term's
function ``fn(env, weight) -> weighted value`` after the task has updated its state for the step,
puts every value in ``info["reward_terms"]`` (term name -> float) and sums them **in the declared
order** (float addition is not associative: the order is part of the reward's definition).

The weight goes into the term function rather than being multiplied on afterwards, so a term such
as ``weight * jaws / 3`` keeps its own operation order (``(weight * jaws) / 3`` and
``weight * (jaws / 3)`` differ in the last bit).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from surgsim_envs.errors import ConfigError


@dataclass(frozen=True)
class RewardTerm:
    """One reward term: ``name`` (its key in ``info["reward_terms"]``), ``fn(env, weight)`` returning
    the weighted value (a float; the sign is the term's: costs are negative), ``weight`` the name of
    the config field holding its weight (None: the term has no weight and gets 1.0), ``doc`` what
    it rewards and in which unit its weight is."""

    name: str
    fn: Callable[[Any, float], float]
    weight: str | None = None
    doc: str = ""


class RewardManager:
    """The reward of a task from its ordered :class:`RewardTerm` s (see the module docstring)."""

    def __init__(self, terms, config):
        terms = tuple(terms)
        names = [t.name for t in terms]
        if len(set(names)) != len(names) or not names:
            raise ConfigError(f"reward terms need distinct names, got {names}")
        for t in terms:
            if t.weight is not None and not hasattr(config, t.weight):
                raise ConfigError(f"reward term {t.name!r} names weight field {t.weight!r}, which "
                                  f"{type(config).__name__} does not have")
        self.terms = terms
        self.names = tuple(names)
        self._calls = tuple((t.name, t.fn, (lambda c, w=t.weight: float(getattr(c, w))) if t.weight else
                             (lambda c: 1.0)) for t in terms)

    def compute(self, env) -> tuple[float, dict[str, float]]:
        """``(reward, {term name: weighted value})`` for the env's current step. A term whose
        function returns None does not apply this step (e.g. a reward paid only on the step that
        ends the episode) and is left out of both."""
        config = env.config
        values = {}
        for name, fn, weight in self._calls:
            v = fn(env, weight(config))
            if v is not None:
                values[name] = float(v)
        return float(sum(values.values())), values

"""Term declarations shared by every task (Isaac Lab's manager-based style): observation terms
(name, unit, bounds), reward terms (function and weight; each value in ``info["reward_terms"]``),
termination terms and the action terms of the tools. A task's own term functions live in its
folder (``envs/<task>/terms.py``); its declarations list them once."""

from surgsim_envs.envs.terms.observation import ObsTerm, observation_space_of
from surgsim_envs.envs.terms.reward import RewardManager, RewardTerm
from surgsim_envs.envs.terms.termination import TerminationTerm, any_terminated

__all__ = ["ObsTerm", "observation_space_of", "RewardTerm", "RewardManager", "TerminationTerm", "any_terminated"]

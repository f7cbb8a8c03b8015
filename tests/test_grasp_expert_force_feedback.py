"""Grasp-v0's scripted expert trims its closure on the jaw forces, so it serves a stiff model as well as the
explicit network: under the quasi-static FEM (forces near the converged reference, 2-5x the network's) the
same closure without the trim drives the jaws far past the reward's damage force."""

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401
from surgsim_envs.envs.grasp import grasp_expert

SEEDS = range(100, 104)


def full_closure(env, close_steps: int = 30):
    """The force-blind policy: close fully, wait ``close_steps`` steps, carry to the target fully closed."""
    step, n = env.unwrapped.config.max_step, [0]

    def policy(obs):
        n[0] += 1
        move = np.clip(obs[3:6] / step * 0.6, -0.6, 0.6) if n[0] > close_steps else np.zeros(3)
        return np.array([*move, 1.0], dtype=np.float32)

    return policy


def _episodes(env, make_policy):
    wins, returns, peaks = 0, [], []
    for seed in SEEDS:
        obs, _ = env.reset(seed=seed)
        policy, total = make_policy(env), 0.0
        while True:
            obs, r, term, trunc, info = env.step(policy(obs))
            total += float(r)
            if term or trunc:
                break
        wins += bool(info["success"])
        returns.append(total)
        peaks.append(info["peak_force_N"])
    return wins, float(np.mean(returns)), float(np.median(peaks))


def test_the_expert_grasps_a_stiff_model_without_crushing_it():
    env = gym.make("SurgSim/Grasp-v0", model="fem_static")
    wins, ret, peak = _episodes(env, grasp_expert)
    _, blind_ret, blind_peak = _episodes(env, full_closure)
    assert wins == len(SEEDS), f"the expert carried {wins} of {len(SEEDS)} grasps to the target"
    assert peak < 0.5 * blind_peak, (peak, blind_peak)
    # the reward pays the hold and charges the damage: the trimmed grasp gains, the crushing one loses
    assert ret > 0.0 > blind_ret, f"force feedback returned {ret:.2f}, the force-blind closure {blind_ret:.2f}"
    env.close()

"""The batched env's reward terms are the single env's declared terms (envs/palpation/terms.py).

Names and order come from ``PalpationEnv.REWARD_TERMS`` (read here, not listed), and over a scripted
press (move, a still press, a deep press, a held report) every term of every world equals the single
env's with the same seed and actions. Bound: the physics bound of tests/test_batch_equivalence.py
(MuJoCo Warp's float32 tool pose; forces within 1e-4 of their magnitude) carried through each term:
1e-4 relative plus 1e-6 absolute (for the damage term, 1e-4 of the force times its weight). The event terms (coverage, press site, localisation) are then equal
because the same events fire on the same steps.
"""

import numpy as np
import pytest

from surgsim_envs.batch.backend import available

#: the single env the batched worlds are (the model and lattice the batched kernels step)
BATCHED = {"model": "mass_spring", "spacing": 0.01}

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")

# 50 control steps, report allowed at once; the default tissue pushes back only 0.2-0.45 N at the deepest
# press (seeds 5-8), below the default 1.5 N damage threshold, so the threshold is lowered to 0.2 N for
# the deep press to exercise the damage term
SHORT = dict(episode_seconds=0.5, min_report_seconds=0.0, damage_force=0.2)
RTOL, ATOL = 1e-4, 1e-6


def _action(k):
    """Move, press still (quasi-static samples), press to the deepest (force above the damage
    threshold), lift, hold report (ends the episode with the localisation term)."""
    if k < 4:
        return [1.0, 0.5, -1.0, -1.0]
    if k < 12:
        return [0.0, 0.0, 0.6, -1.0]
    if k < 20:
        return [0.0, 0.0, 1.0, -1.0]
    return [0.0, 0.0, -1.0, 1.0]


def _bound(name, want, env):
    """The physics bound carried through a term: 1e-4 of the term, plus 1e-6; for the damage term,
    -w (|F| - threshold), the force's own bound (1e-4 |F|) times w, since near the threshold a
    1e-4 change of |F| is a far larger share of the small excess."""
    if name == "damage" and want != 0.0:
        from surgsim_envs.envs.terms.force import vector_norm

        e = env.unwrapped
        return RTOL * e.config.damage_weight * vector_norm(e.readings()[1]) + ATOL
    return RTOL * abs(want) + ATOL


def _declared_names():
    from surgsim_envs.envs.palpation import PalpationEnv

    return tuple(t.name for t in PalpationEnv.REWARD_TERMS)


def _batched(num_envs):
    import gymnasium as gym

    return gym.make_vec("SurgSim/Palpation-v0", num_envs=num_envs, vectorization_mode="vector_entry_point",
                        device="cpu", max_episode_steps=50, **SHORT)


@pytest.mark.parametrize("num_envs", [1, 4])
def test_reward_terms_equal_the_single_envs_over_a_press(num_envs):
    import gymnasium as gym

    seed = 5
    venv = _batched(num_envs)
    singles = [gym.make("SurgSim/Palpation-v0", max_episode_steps=50, **SHORT, **BATCHED) for _ in range(num_envs)]
    venv.reset(seed=seed)
    for i, env in enumerate(singles):
        env.reset(seed=seed + i)
    names = _declared_names()
    seen = {name: 0.0 for name in names}
    done = np.zeros(num_envs, dtype=bool)
    for k in range(50):
        a = np.array(_action(k), dtype=np.float32)
        _, r, te, tr, info = venv.step(np.tile(a, (num_envs, 1)))
        assert tuple(info["reward_terms"]) == names
        for w, env in enumerate(singles):
            if done[w]:
                continue
            _, r1, te1, tr1, i1 = env.step(a)
            single = i1["reward_terms"]
            assert tuple(n for n in single if n != "final") == names
            bounds = {name: _bound(name, single[name], env) for name in names}
            for name in names:
                got, want = info["reward_terms"][name][w], single[name]
                assert abs(got - want) <= bounds[name], (name, w, k, got, want)
                seen[name] = max(seen[name], abs(want))
            assert abs(r[w] - r1) <= RTOL * abs(r1) + sum(bounds.values()), (w, k, r[w], r1)
            assert (te[w], tr[w]) == (te1, tr1), (w, k)
            done[w] = te1 or tr1
        if done.all():
            break
    assert done.all(), "the held report must end every episode"
    for name in names:
        assert seen[name] > 0.0, f"the script must exercise the {name!r} term"


def test_a_term_declared_in_the_single_env_shows_up_in_the_batched_env(monkeypatch):
    from surgsim_envs.envs.palpation import PalpationEnv
    from surgsim_envs.envs.terms.reward import RewardTerm

    extra = RewardTerm("probe_height", lambda env, weight: weight * float(env.readings()[0][2]), "time_cost")
    declared = tuple(PalpationEnv.REWARD_TERMS)
    monkeypatch.setattr(PalpationEnv, "REWARD_TERMS", (extra,) + declared[1:][::-1])
    venv = _batched(2)
    venv.reset(seed=0)
    _, _, _, _, info = venv.step(np.zeros((2, 4), dtype=np.float32))
    names = tuple(t.name for t in PalpationEnv.REWARD_TERMS)
    assert tuple(info["reward_terms"]) == names and venv.reward_term_names == names
    assert "damage" not in info["reward_terms"]
    height = info["reward_terms"]["probe_height"]
    assert np.all(height > 0.0), "the added term's function runs for every world"

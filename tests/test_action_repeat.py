"""``action_repeat``: a step is k control periods with the action held. A constant action gives
the stop that k single-period steps give, bit for bit (single and vector class, stops that end
within a step included); the limit counts steps of k periods; a trained model with a repeat
decides every k periods on the 20 ms core; a bad value is one line."""

from __future__ import annotations

import numpy as np
import pytest

from wsp_env.envs import WSPBrakingEnv, WSPBrakingVectorEnv

OPTS = {"speed_kmh": 30.0, "rail": "soap", "mu_contaminated": 0.08, "pattern": "uniform"}


def _single(k: int, action: float = 0.2):
    env = WSPBrakingEnv(action_repeat=k)
    obs, _ = env.reset(seed=5, options=OPTS)
    a = np.full(env.action_space.shape, action, dtype=np.float32)
    rewards, steps = [], 0
    while True:
        obs, r, term, trunc, info = env.step(a)
        rewards.append(r)
        steps += 1
        if term or trunc:
            return obs, rewards, steps, info["metrics"], env


@pytest.mark.parametrize("k", [2, 3, 7])
def test_single_env_repeat_is_k_single_steps(k):
    obs1, r1, n1, m1, _ = _single(1)
    obsk, rk, nk, mk, env = _single(k)
    assert mk == m1  # the same stop
    np.testing.assert_array_equal(obsk, obs1)  # the stop's last observation
    assert nk == -(-n1 // k)  # the last step holds the rest
    assert sum(rk) == pytest.approx(sum(r1), rel=1e-12)
    # each repeated step's reward is the sum of its periods'
    np.testing.assert_allclose(rk[0], sum(r1[:k]), rtol=1e-12)
    assert env.max_episode_steps == -(-15000 // k)


def test_vector_env_repeat_matches_single_periods_with_stops_ending_inside_a_step():
    k, n = 4, 3
    speeds = [25.0, 30.0, 41.0]
    first: dict[str, list] = {}
    for repeat in (1, k):
        venv = WSPBrakingVectorEnv(num_envs=n, action_repeat=repeat)
        venv.reset(seed=11, options=[{**OPTS, "speed_kmh": v} for v in speeds])
        a = np.full((n, venv.single_action_space.shape[0]), 0.3, dtype=np.float32)
        metrics: list = [None] * n
        for _ in range(20000):
            _, _, term, trunc, info = venv.step(a)
            for e in np.flatnonzero(term | trunc):
                if metrics[e] is None:
                    metrics[e] = info["final_info"][e]["metrics"]
            if all(m is not None for m in metrics):
                break
        first[str(repeat)] = metrics
    assert first["1"] == first[str(k)]
    assert len({m["stopping_time_s"] for m in first["1"]}) == n  # they end at other times


def test_vector_limit_counts_steps_of_k_periods():
    venv = WSPBrakingVectorEnv(num_envs=2, action_repeat=5, max_time_s=1.0)
    assert venv.max_episode_steps == 10 and venv.period_limit == 50
    venv.reset(seed=0, options={**OPTS, "speed_kmh": 200.0, "rail": "dry"})
    a = np.zeros((2, venv.single_action_space.shape[0]), dtype=np.float32)
    for _ in range(9):
        _, _, term, trunc, info = venv.step(a)
        assert not (term | trunc).any()
    _, _, term, trunc, info = venv.step(a)  # the 10th step: 50 periods, 1.0 s
    assert trunc.all() and not term.any()
    assert info["final_info"][0]["metrics"]["stopping_time_s"] == pytest.approx(1.0, abs=0.021)


@pytest.mark.parametrize("bad", [0, 51, 2.5, True, "3"])
def test_bad_action_repeat_is_one_line(bad):
    with pytest.raises(ValueError, match=r"^action_repeat: must be an integer 1-50, got "):
        WSPBrakingEnv(action_repeat=bad)


def test_a_trained_model_with_a_repeat_decides_every_k_periods():
    """On the 20 ms core (evaluation), the policy holds its action k periods; its decisions
    are the model's actions on the observations at the decision periods."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO

    from wsp_env.agents.sb3_vec import SB3VecEnv
    from wsp_env.envs import make_core
    from wsp_env.policy import SB3Policy

    k = 3
    venv = SB3VecEnv(num_envs=2, action_repeat=k)
    model = PPO("MlpPolicy", venv, n_steps=8, batch_size=16, seed=0, device="cpu")
    policy = SB3Policy.from_model(model, {"action_repeat": k})
    assert policy.action_repeat == k and "action_repeat" not in policy.env_kwargs
    core = make_core(2)
    for e in range(2):
        core.reset_env(e, {**OPTS, "speed_kmh": 40.0 + 10 * e}, seed=e)
    policy.bind(core)
    policy.reset(np.arange(2))
    held = []
    for t in range(7):
        obs = core.obs.copy()
        a = policy.act(obs)
        if t % k == 0:
            want, _ = model.predict(obs, deterministic=True)
            np.testing.assert_allclose(a, want, atol=1e-6)
        held.append(a)
        core.step(core.check_actions(a))
    assert np.array_equal(held[0], held[1]) and np.array_equal(held[0], held[2])
    assert np.array_equal(held[3], held[5]) and not np.array_equal(held[0], held[3])
    # a stop restarted mid-repeat decides at its next period
    policy.reset(np.array([1]))
    a = policy.act(core.obs.copy())
    np.testing.assert_allclose(a[1], model.predict(core.obs, deterministic=True)[0][1], atol=1e-6)

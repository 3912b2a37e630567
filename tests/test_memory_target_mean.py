"""``memory_target_mean=True`` (slip-target mode): each valve's mean slip-target action over the
stop's control periods so far, appended after the memory features and before the action mode's
tail. Off by default; it changes nothing else; it starts anew at every reset (the vector env's
autoresets included); it is the running mean of the actions the agent gave, clipped, counted
per control period (``action_repeat`` weights a step by its periods); it survives a state
round trip; and a wrong setting is one line."""

from __future__ import annotations

import numpy as np
import pytest

from wsp_env.envs import WSPBrakingEnv, WSPBrakingVectorEnv

SOAP = {"rail": "soap", "mu_contaminated": 0.07, "speed_kmh": 120.0, "pattern": "uniform"}
N = 4  # uic_z1's axles, one valve each
ST = {"action_mode": "slip_target"}


def test_off_by_default_and_nothing_else_changes():
    """Without it the observation is the slip-target mode's; with it the kernel's part, the
    rewards, the metrics and the tail (the last action) are the same, bit for bit."""
    plain, mean = WSPBrakingEnv(**ST), WSPBrakingEnv(**ST, memory_target_mean=True)
    width = plain.observation_space.shape[0]
    assert mean.observation_space.shape[0] == width + N
    a, _ = plain.reset(seed=5, options=SOAP)
    b, _ = mean.reset(seed=5, options=SOAP)
    head = width - N
    np.testing.assert_array_equal(b[head : head + N], 1.0)  # before the first period: the tail's
    rng = np.random.default_rng(0)
    while True:
        action = rng.uniform(-1.2, 1.2, N).astype(np.float32)
        a, ra, term, trunc, info_a = plain.step(action)
        b, rb, _, _, info_b = mean.step(action)
        np.testing.assert_array_equal(a[:head], b[:head])
        np.testing.assert_array_equal(a[head:], b[-N:])  # the tail stays last
        assert ra == rb
        if term or trunc:
            break
    assert info_a["metrics"] == info_b["metrics"]


@pytest.mark.parametrize(("repeat", "memory"), [(1, False), (3, True)])
def test_the_running_mean_of_the_clipped_actions_per_control_period(repeat, memory):
    """Step by step the observed entries are the mean of every action so far, clipped to
    [-1, 1], each counted ``action_repeat`` times (once per control period): a hand-kept sum
    agrees to float32; with the memory features they sit after those, which stay the memory
    features (``memory_obs``)."""
    env = WSPBrakingEnv(**ST, memory_target_mean=True, action_repeat=repeat, memory_features=memory)
    obs, _ = env.reset(seed=2, options={**SOAP, "speed_kmh": 60.0})
    width = env.observation_space.shape[0]
    sl = slice(width - 2 * N, width - N)
    rng = np.random.default_rng(1)
    total, periods = np.zeros(N), 0
    for i in range(120):
        action = rng.uniform(-1.5, 1.5, N).astype(np.float32)
        if i % 40 == 0:
            action[:] = 1.0 if i % 80 else -1.0
        obs, _, term, trunc, _ = env.step(action)
        total += repeat * np.clip(action.astype(np.float64), -1.0, 1.0)
        periods += repeat
        np.testing.assert_allclose(obs[sl], total / periods, rtol=0, atol=1e-6)
        np.testing.assert_allclose(obs[-N:], np.clip(action, -1.0, 1.0), atol=0)
        if memory:
            width_k = env.core.kernel_obs_dim
            np.testing.assert_array_equal(
                obs[width_k : width_k + 3 * N], env.core.memory_obs()[0].astype(np.float32)
            )
        assert not (term or trunc)
    assert env.core.memory_target_periods[0] == 120 * repeat


def test_starts_anew_at_each_vector_autoreset_and_is_each_envs_own():
    """Environment 1's mean is, step by step, the one of the same stop run alone while
    environment 0 ends and starts anew; the new stop's entries are the tail's value (1) and
    then the mean of the new stop's actions only."""
    options = [{**SOAP, "speed_kmh": v} for v in (30.0, 90.0)]
    venv = WSPBrakingVectorEnv(num_envs=2, **ST, memory_target_mean=True)
    obs, _ = venv.reset(seed=1, options=options)
    alone = WSPBrakingVectorEnv(num_envs=1, **ST, memory_target_mean=True)
    alone.reset(seed=[2], options=[options[1]])
    width = venv.single_observation_space.shape[0]
    sl = slice(width - 2 * N, width - N)
    ended = False
    for t in range(3000):
        action = np.full((2, N), -0.5 if t < 100 else 0.5, dtype=np.float32)
        obs, _, term, trunc, info = venv.step(action)
        alone_obs = alone.step(action[1:])[0]
        np.testing.assert_array_equal(obs[1], alone_obs[0])
        if term[0] or trunc[0]:
            assert t > 100
            final = info["final_obs"][0][sl]
            want = (-0.5 * 100 + 0.5 * (t + 1 - 100)) / (t + 1)  # the ended stop's mean
            np.testing.assert_allclose(final, want, atol=1e-6)
            np.testing.assert_array_equal(obs[0, sl], 1.0)  # the new stop's: no period yet
            obs = venv.step(action)[0]
            np.testing.assert_array_equal(obs[0, sl], 0.5)  # its own actions only
            ended = True
            break
    assert ended


def test_state_round_trip_continues_bit_for_bit():
    venv = WSPBrakingVectorEnv(num_envs=2, **ST, memory_target_mean=True)
    venv.reset(seed=4, options=[SOAP, SOAP])
    rng = np.random.default_rng(3)
    for _ in range(50):
        venv.step(rng.uniform(-1, 1, (2, N)).astype(np.float32))
    state = venv.core.state_dict()
    other = WSPBrakingVectorEnv(num_envs=2, **ST, memory_target_mean=True)
    other.reset(seed=9)
    other.core.load_state_dict(state)
    for _ in range(30):
        a = rng.uniform(-1, 1, (2, N)).astype(np.float32)
        np.testing.assert_array_equal(venv.step(a)[0], other.step(a)[0])


def test_bad_settings_are_one_line():
    with pytest.raises(ValueError, match=r"^memory_target_mean: must be True or False, got 1$"):
        WSPBrakingEnv(**ST, memory_target_mean=1)
    with pytest.raises(ValueError, match=r"^memory_target_mean: .* needs action_mode "):
        WSPBrakingEnv(action_mode="continuous", memory_target_mean=True)

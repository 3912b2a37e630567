"""``memory_features=True``: per axle the time in the current measured slide, the time since
the last release and a sliding-energy estimate, appended after the kernel's observation (before
an action mode's tail). Off by default; they change nothing else; zero at every reset (the
vector env's autoresets included); each follows its definition period by period; the energy
estimate never falls and follows the true per-axle sliding energy within stated factors, with
ideal and with the benchmark's wheel-tier sensors; with ``action_repeat`` the timers grow by the
step's periods."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wsp_env.core.braking import MEMORY_ENERGY_SCALE_MJ, MEMORY_TIME_SCALE_S
from wsp_env.envs import WSPBrakingEnv, WSPBrakingVectorEnv
from wsp_env.envs.tiers import TIER_SENSORS
from wsp_env.policy import make_policy

SOAP = {"rail": "soap", "mu_contaminated": 0.07, "speed_kmh": 120.0, "pattern": "uniform"}
N = 4  # uic_z1's axles
DT = 0.02


def test_off_by_default_and_nothing_else_changes():
    """The kernel's observation, the rewards and the metrics are those of the plain env, bit
    for bit; the residual mode's tail stays last."""
    plain, mem = WSPBrakingEnv(), WSPBrakingEnv(memory_features=True)
    width = plain.observation_space.shape[0]
    assert width == 23 and mem.observation_space.shape[0] == width + 3 * N
    a, _ = plain.reset(seed=3, options=SOAP)
    b, _ = mem.reset(seed=3, options=SOAP)
    np.testing.assert_array_equal(b[width:], 0.0)
    policy = make_policy("classical")
    policy.bind(plain.core)
    policy.reset(np.arange(1))
    while True:
        action = policy.act(a[None])[0]
        a, ra, term, trunc, info_a = plain.step(action)
        b, rb, _, _, info_b = mem.step(action)
        np.testing.assert_array_equal(a, b[:width])
        assert ra == rb
        if term or trunc:
            break
    assert info_a["metrics"] == info_b["metrics"]
    res = WSPBrakingEnv(action_mode="residual")
    both = WSPBrakingEnv(action_mode="residual", memory_features=True)
    x, _ = res.reset(seed=3, options=SOAP)
    y, _ = both.reset(seed=3, options=SOAP)
    for _ in range(300):
        step = np.full(4, -0.1, dtype=np.float32)
        x = res.step(step)[0]
        y = both.step(step)[0]
    np.testing.assert_array_equal(x[:width], y[:width])
    np.testing.assert_array_equal(x[-4:], y[-4:])  # the classical WSP's requests, last


def _run_none(speed_kmh: float, seeds=(0, 1), mus=(0.05, 0.08)):
    """Locked wheels (``none``) on soap, every seed at every adhesion level: per step the
    energy estimate (unclipped, the core's array; NaN once the stop ended) and each stop's
    final metrics."""
    cases = [(s, mu) for mu in mus for s in seeds]
    venv = WSPBrakingVectorEnv(num_envs=len(cases), memory_features=True)
    venv.reset(
        seed=[s for s, _ in cases],
        options=[{**SOAP, "speed_kmh": speed_kmh, "mu_contaminated": mu} for _, mu in cases],
    )
    core = venv.core
    rows, metrics = [], [None] * len(cases)
    ones = np.ones((len(cases), N), dtype=np.float32)
    while True:
        _, _, term, trunc, info = venv.step(ones)
        rows.append(core.memory_energy_J.copy())
        for e in np.flatnonzero(term | trunc):
            metrics[e] = metrics[e] or info["final_info"][e]["metrics"]
            rows[-1][e] = np.nan  # autoreset: a new stop's memory
        if all(m is not None for m in metrics):
            return np.array(rows), metrics


def test_zero_at_reset_and_at_each_vector_autoreset():
    """Each environment's memory starts at zero with its stop and is its own: across the other
    environment's autoresets it is, step by step, bit for bit the memory of the same stop run
    alone."""
    options = [{**SOAP, "speed_kmh": v} for v in (30.0, 90.0)]
    venv = WSPBrakingVectorEnv(num_envs=2, memory_features=True)
    obs, _ = venv.reset(seed=1, options=options)
    alone = WSPBrakingVectorEnv(num_envs=1, memory_features=True)
    alone_obs, _ = alone.reset(seed=[2], options=[options[1]])  # env 1's seed: 1 + 1
    width = venv.core.kernel_obs_dim
    np.testing.assert_array_equal(obs[:, width:], 0.0)
    ended = 0
    ones = np.ones((2, N), dtype=np.float32)
    for _ in range(1500):  # env 0's stop ends at 589 (then a drawn one), env 1's at 2043
        obs, _, term, trunc, info = venv.step(ones)
        alone_obs, _, alone_term, _, _ = alone.step(ones[:1])
        assert not alone_term[0]
        np.testing.assert_array_equal(obs[1], alone_obs[0])
        for name in ("memory_slide_s", "memory_since_release_s", "memory_energy_J"):
            np.testing.assert_array_equal(getattr(venv.core, name)[1], getattr(alone.core, name)[0])
        assert not (term[1] or trunc[1])
        if term[0] or trunc[0]:
            final = info["final_obs"][0][width:]
            assert final[2 * N :].min() > 0.0  # the ended stop's energy estimate
            np.testing.assert_array_equal(obs[0, width:], 0.0)  # the new stop's
            ended += 1
        # one environment's row, as a final observation takes it
        np.testing.assert_array_equal(venv.core.memory_obs(1), venv.core.memory_obs()[1])
    assert ended >= 1


def test_timers_grow_by_the_step_with_action_repeat():
    """``action_repeat=5``: the memory advances every control period inside a step, so on
    locked wheels (no release, one long slide) the release timer grows by exactly 5 x 20 ms per
    step from the stop's start and the slide timer by as much through the slide."""
    k = 5
    env = WSPBrakingEnv(memory_features=True, action_repeat=k)
    env.reset(seed=0, options={**SOAP, "speed_kmh": 60.0})
    core = env.core
    since, slide = [], []
    for _ in range(300):
        _, _, term, trunc, _ = env.step(np.ones(N, dtype=np.float32))
        if term or trunc:
            break
        since.append(core.memory_since_release_s[0].copy())
        slide.append(core.memory_slide_s[0].copy())
    since, slide = np.array(since), np.array(slide)
    steps = np.arange(1, len(since) + 1)[:, None]
    np.testing.assert_allclose(since, np.broadcast_to(steps * k * DT, since.shape), atol=1e-9)
    sliding = slide[:, 0] > 0.0
    assert sliding.sum() > 50
    grows = np.diff(slide[:, 0])[sliding[1:] & sliding[:-1]]
    np.testing.assert_allclose(grows, k * DT, atol=1e-9)


def test_timers_follow_their_definitions_period_by_period():
    """With the classical WSP on soap: the slide timer grows by 20 ms while the measured slip
    ``v_ref - v_i`` exceeds ``max(3 km/h, 20 % v_ref)`` and is 0 otherwise; the release timer
    is 0 in a period whose valve command vented (under 5 % of the demand) and grows otherwise.
    Both happen (slides start and end, valves vent and refill); the observation shows them
    scaled by 10 s."""
    env = WSPBrakingEnv(memory_features=True)
    obs, _ = env.reset(seed=0, options={**SOAP, "speed_kmh": 80.0})
    core = env.core
    policy = make_policy("classical")
    policy.bind(core)
    policy.reset(np.arange(1))
    width = core.kernel_obs_dim
    slide = np.zeros(N)
    since = np.zeros(N)
    spells_ended = vents = 0
    for _ in range(5000):
        obs, _, term, trunc, _ = env.step(policy.act(obs[None, :width])[0])
        if term or trunc:
            break
        v_ref = core.reference_speed_mps[0]
        slip = v_ref - core.measured_wheel_speed_mps[0]
        sliding = slip > max(3.0 / 3.6, 0.2 * v_ref)
        spells_ended += int(((slide > 0.1) & ~sliding).sum())
        slide = np.where(sliding, slide + DT, 0.0)
        vent = (core.sim.cmd[0] >= 0.0) & (core.sim.cmd[0] < 0.05)
        vents += int(vent.sum())
        since = np.where(vent, 0.0, since + DT)
        np.testing.assert_allclose(core.memory_slide_s[0], slide, atol=1e-9)
        np.testing.assert_allclose(core.memory_since_release_s[0], since, atol=1e-9)
        scaled = np.concatenate([slide, since]) / MEMORY_TIME_SCALE_S
        np.testing.assert_allclose(obs[width : width + 2 * N], np.minimum(scaled, 5.0), atol=1e-6)
    assert term and spells_ended >= 1 and vents >= 10


def test_slide_timer_grows_through_a_locked_slide_and_resets_when_it_ends():
    """Locked wheels: the measured slip is the reference itself, a slide while the reference
    is above 3 km/h; the timer grows through it (seconds) and is back at 0 once the reference
    falls below."""
    env = WSPBrakingEnv(memory_features=True)
    env.reset(seed=0, options={**SOAP, "speed_kmh": 60.0})
    timer = []
    while True:
        _, _, term, trunc, _ = env.step(np.ones(N, dtype=np.float32))
        timer.append(env.core.memory_slide_s[0].copy())
        if term or trunc:
            break
    timer = np.array(timer)
    assert timer.max() > 5.0
    peak = int(np.argmax(timer[:, 0]))
    np.testing.assert_allclose(np.diff(timer[: peak + 1, 0])[-50:], DT, atol=1e-9)
    assert (timer[peak + 1 :] == 0.0).all() and peak < len(timer) - 1


@pytest.mark.parametrize("speed_kmh", [60.0, 160.0])
def test_energy_estimate_never_falls_and_tracks_the_true_sliding_energy(speed_kmh):
    """Locked wheels on soap 0.05 and 0.08, two seeds: the estimate never falls and ends
    within 1-3.3 times each axle's true sliding energy. Locked wheels are the estimate's worst
    case and an overestimate: the pads hold more than the rail carries (most on the lowest
    adhesion), which the reference's fall below the train (no wheel to anchor on) only partly
    offsets. Measured (``scripts/memory_energy_study.py``: soap 0.05-0.08 at 60-160 km/h, four
    seeds): 1.05-3.14 with ideal sensors, 1.04-3.15 with the benchmark's wheel-sensor tier.
    With the classical WSP (wheels turning near the train's speed, the reference anchored) it
    reads 0.63-1.05 of the truth (ideal sensors) and 0.59-1.05 (wheel tier) over the same
    stops (low: the reference sags a little below the train between anchors, and the stop's
    pad scale, 0.9-1.1, is unknown to it): asserted within 0.5-1.2 on soap 0.07, both sensor
    sets."""
    rows, metrics = _run_none(speed_kmh)
    for e, m in enumerate(metrics):
        energy = rows[: np.flatnonzero(np.isnan(rows[:, e, 0]))[0], e]
        assert (np.diff(energy, axis=0) >= 0.0).all()
        true_J = np.array([ax["sliding_energy_kJ"] for ax in m["axles"]]) * 1e3
        ratio = energy[-1] / true_J
        assert ((ratio > 1.0) & (ratio < 3.3)).all(), ratio
    # the classical WSP: wheels near the train's speed
    for sensors in (None, dataclasses.asdict(TIER_SENSORS["wheels"])):
        venv = WSPBrakingVectorEnv(num_envs=2, memory_features=True, sensors=sensors)
        obs, _ = venv.reset(seed=[0, 1], options={**SOAP, "speed_kmh": speed_kmh})
        policy = make_policy("classical")
        policy.bind(venv.core)
        policy.reset(np.arange(2))
        done: list = [None, None]
        while not all(d is not None for d in done):
            obs, _, term, trunc, info = venv.step(policy.act(obs))
            for e in np.flatnonzero(term | trunc):
                if done[e] is None:
                    final = info["final_obs"][e][venv.core.kernel_obs_dim + 2 * N :]
                    axles = info["final_info"][e]["metrics"]["axles"]
                    true_MJ = np.array([ax["sliding_energy_kJ"] / 1e3 for ax in axles])
                    done[e] = final * MEMORY_ENERGY_SCALE_MJ / true_MJ
        ratio = np.concatenate(done)
        assert ((ratio > 0.5) & (ratio < 1.2)).all(), ratio


def test_bad_memory_features_is_one_line():
    with pytest.raises(ValueError, match=r"^memory_features: must be True or False, got 'yes'$"):
        WSPBrakingEnv(memory_features="yes")

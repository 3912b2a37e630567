"""The sensor model, the shared reference-speed estimator and the safety watchdog
(``wsp_env.core.sensors``, ``core.kernel``): what every controller sees and what stands between
any controller and the valves."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import compiled_once_for_int64

from wsp_env import threads
from wsp_env.core import kernel as K
from wsp_env.core.config import ConfigError
from wsp_env.core.kernel import env_step_parallel
from wsp_env.envs import WSPBrakingVectorEnv
from wsp_env.evaluation.runner import run_one
from wsp_env.physics.integrator import LOCK_TRAIN_SPEED, LOCK_WHEEL_SPEED
from wsp_env.policy import NoWSP

LEVEL_DRY = {"rail": "dry", "speed_kmh": 100.0, "pattern": "uniform", "gradient_permille": 0.0,
             "load_factor": 1.0}  # fmt: skip


def _readings(n_steps: int, **kwargs):
    """Wheel-speed and accelerometer readings against the truth over a dry stop, every step."""
    venv = WSPBrakingVectorEnv(num_envs=64, **kwargs)
    venv.reset(seed=11, options=LEVEL_DRY)
    core = venv.core
    wheel_err, acc_err = [], []
    for _ in range(n_steps):
        v0 = core.sim.speed_mps.copy()
        venv.step(np.ones((64, 4), dtype=np.float32))
        true_wheel = core.sim.wheel_speed_mps
        wheel_err.append(core.measured_wheel_speed_mps - true_wheel)
        acc_err.append(core.accelerometer_reading_mps2 - (v0 - core.sim.speed_mps) / 0.02)
    return core, np.array(wheel_err), np.array(acc_err)


def test_wheel_speed_noise_has_the_drawn_spread_and_no_bias():
    """sigma 0.5 km/h per reading: the sample standard deviation over 64 stops x 200 readings x
    4 axles within 3 % of it (the sample's own spread is 0.3 %), the mean within 0.01 km/h;
    the readings of two axles are independent."""
    _, err, _ = _readings(200, sensors={"wheel_speed_noise_kmh": [0.5, 0.5]})
    err_kmh = 3.6 * err
    assert err_kmh.std() == pytest.approx(0.5, rel=0.03)
    assert abs(err_kmh.mean()) < 0.01
    corr = np.corrcoef(err_kmh[:, :, 0].ravel(), err_kmh[:, :, 1].ravel())[0, 1]
    assert abs(corr) < 0.03


def test_wheel_speed_quantum_and_scale_error():
    """Readings are multiples of the resolution; each axle's scale error lies within its bound
    and shows in the reading's ratio to the truth."""
    core, _, _ = _readings(
        50, sensors={"wheel_speed_quantum_kmh": 0.1, "wheel_speed_scale_error": 0.01}
    )
    q = 0.1 / 3.6
    meas = core.measured_wheel_speed_mps
    assert np.allclose(meas / q, np.round(meas / q), atol=1e-6)
    scale = core.axle_wsp[:, :, K.AW_SCALE]
    assert np.all(np.abs(scale - 1.0) <= 0.01) and np.unique(scale).size == scale.size
    ratio = meas / core.sim.wheel_speed_mps
    assert np.allclose(ratio, scale, atol=q / core.sim.wheel_speed_mps.min())


def test_accelerometer_bias_noise_and_lag_statistics():
    """The bias is drawn per stop within +-b (uniform: its spread b / sqrt(3)); the noise's
    spread after the 0.1 s lag is sigma sqrt(k / (2 - k)), k = 1 - exp(-dt / tau), and a fixed
    bias option sets it exactly."""
    b, sigma, tau = 0.3, 0.2, 0.1
    sensors = {"accelerometer_bias_mps2": b, "accelerometer_noise_mps2": sigma,
               "accelerometer_lag_s": tau}  # fmt: skip
    core, _, acc = _readings(300, accelerometer=True, sensors=sensors)
    bias = core.sensor_par[:, K.SP_ACC_BIAS]
    assert np.all(np.abs(bias) <= b) and bias.std() == pytest.approx(b / np.sqrt(3), rel=0.25)
    settled = acc[50:] - bias  # past the lag's start-up; the train's deceleration is steady
    k = 1.0 - np.exp(-0.02 / tau)
    assert settled.std(axis=0).mean() == pytest.approx(sigma * np.sqrt(k / (2 - k)), rel=0.1)
    venv = WSPBrakingVectorEnv(num_envs=2, accelerometer=True, sensors=sensors)
    venv.reset(seed=1, options={**LEVEL_DRY, "accelerometer_bias_mps2": -0.25})
    assert np.all(venv.core.sensor_par[:, K.SP_ACC_BIAS] == -0.25)


def test_same_seed_same_readings_serial_and_parallel():
    """The noise comes from per-env generators seeded from the env's seed: the same seed gives
    the same readings, and the 64-env parallel step draws what 1-env serial steps draw."""
    sensors = {"wheel_speed_noise_kmh": [0.3, 0.3]}
    with threads.applied(threads.thread_policy("evaluate", cores=2)):  # whatever WSP_CORES says
        big = WSPBrakingVectorEnv(num_envs=64, sensors=sensors)
    assert big.core._step_fn is env_step_parallel
    big.reset(seed=[100 + i for i in range(64)], options=LEVEL_DRY)
    one = WSPBrakingVectorEnv(num_envs=1, sensors=sensors)
    one.reset(seed=[105], options=LEVEL_DRY)
    for _ in range(20):
        big.step(np.ones((64, 4), dtype=np.float32))
        one.step(np.ones((1, 4), dtype=np.float32))
    assert np.array_equal(
        big.core.measured_wheel_speed_mps[5], one.core.measured_wheel_speed_mps[0]
    )
    # both paths run one compiled call tree: prange's unsigned index would otherwise compile
    # the whole of it a second time (some 15 s on a 2-core machine, in every fresh process)
    for fn in (K.env_step_one, K.estimate_and_supervise, K.sense_and_estimate, K.write_obs):
        compiled_once_for_int64(fn)


def test_the_shared_reference_is_pulled_down_when_it_drifts_above_the_train():
    """An accelerometer reading 0.6 m/s^2 too little lets the reference drift above a train
    whose wheels all slide (locked wheels: nothing anchors it, and it ends far above); venting
    one axle lets its wheel spin up and roll freely, and the estimator anchors on it and comes
    down to the train within 1 km/h (the correction the environment's reference lacked)."""
    opts = {"rail": "soap", "speed_kmh": 120.0, "pattern": "uniform", "mu_contaminated": 0.06,
            "gradient_permille": 0.0, "accelerometer_bias_mps2": -0.6}  # fmt: skip
    venv = WSPBrakingVectorEnv(num_envs=1, accelerometer=True, watchdog={"enabled": False})
    venv.reset(seed=2, options=opts)
    core = venv.core
    for _ in range(400):  # 8 s of locked wheels
        venv.step(np.ones((1, 4), dtype=np.float32))
    drift = 3.6 * (core.reference_speed_mps[0] - core.sim.speed_mps[0])
    assert drift > 5.0
    action = np.ones((1, 4), dtype=np.float32)
    action[0, 3] = -1.0  # vent the last axle
    for _ in range(250):  # a locked wheel spins up at ~8 m/s^2 on this soap: 4 s to the train
        venv.step(action)
    err = 3.6 * (core.reference_speed_mps[0] - core.sim.speed_mps[0])
    assert abs(err) < 1.0, (drift, err)


# the benchmark's wheels+accel sensors (tiers.TIER_SENSORS), the bias fixed by each test
BENCH_ACCEL = {"accelerometer_noise_mps2": 0.05, "accelerometer_lag_s": 0.1,
               "wheel_speed_noise_kmh": (0.0, 0.05), "wheel_speed_quantum_kmh": 0.02,
               "wheel_speed_scale_error": 0.005}  # fmt: skip


def _released_every_3_s(bias: float, gradient: float, gain: float):
    """A soap stop from 140 km/h with every axle applied in full (they slide) and the last one
    vented 1.5 s in every 3 s (the periodic release that gives the estimator its anchors)."""
    venv = WSPBrakingVectorEnv(
        num_envs=1, accelerometer=True, watchdog={"enabled": False}, sensors=BENCH_ACCEL,
        estimator={"accel_offset_gain": gain},
    )  # fmt: skip
    opts = {"rail": "soap", "speed_kmh": 140.0, "pattern": "uniform", "mu_contaminated": 0.06,
            "gradient_permille": gradient, "accelerometer_bias_mps2": bias,
            "load_factor": 1.0}  # fmt: skip
    venv.reset(seed=3, options=opts)
    core, err_kmh = venv.core, []
    action = np.ones((1, 4), dtype=np.float32)
    for i in range(1000):  # 20 s
        action[0, 3] = -1.0 if i % 150 >= 75 else 1.0
        venv.step(action)
        err_kmh.append(3.6 * (core.reference_speed_mps[0] - core.sim.speed_mps[0]))
    return core.wsp[0, K.W_ACC_CORR], np.abs(err_kmh).mean()


@pytest.mark.parametrize("bias,gradient", [(-0.3, 0.0), (0.3, 0.0), (0.0, 20.0), (-0.3, -25.0)])
def test_the_estimator_learns_the_accelerometer_offset_at_its_anchors(bias, gradient):
    """A specific-force sensor's offset is its bias less g times the gradient (module
    docstring); the estimator's correction is added to its deceleration reading, so it must
    converge to minus that offset. Within 0.05 m/s^2 after 20 s (six anchors at gain 0.5 leave
    1/64 of the offset; the readings' noise, 0.05 m/s^2 each, averages over seconds, the
    0.1 s lag at the vents' edges is under 0.01 m/s^2 over a 3 s span, and the anchoring
    wheel's 0.5 % scale error misreads the fall between anchors by 0.5 % of the train's
    deceleration, under 0.005 m/s^2). Where the offset is
    0.2 m/s^2 or more the reference's mean error falls to under half of what it is without."""
    offset = bias - 9.81 * gradient / 1000.0
    corr, err = _released_every_3_s(bias, gradient, 0.5)
    assert corr == pytest.approx(-offset, abs=0.05)
    _, err_off = _released_every_3_s(bias, gradient, 0.0)
    if abs(offset) >= 0.2:
        assert err < 0.5 * err_off, (err, err_off)


@pytest.mark.parametrize("seed", [1, 3])
def test_a_wheel_spinning_up_slowly_on_leaves_is_no_anchor(seed):
    """Every axle locked for 7 s on leaves (mu 0.028, -18 per mille, 49 km/h), then vented:
    the wheels spin up at ~1.3 m/s^2 (5 km/h a second), between two 20 ms readings now and
    then by less than the 0.5 m/s^2 a free-rolling wheel may still gain. On one reading the
    estimator took such a wheel for free and set the reference to it, ~45 km/h below the train
    (the benchmark's sealed stop 272 under -v2); on the acceleration filtered over 0.1 s it
    waits for the wheels to reach the train, and the reference stays within the accelerometer's
    drift (the gradient's 0.18 m/s^2 over the 12 s: under 12 km/h)."""
    worst = {}
    for tau in (0.0, 0.1):
        venv = WSPBrakingVectorEnv(
            num_envs=1, accelerometer=True, watchdog={"enabled": False}, sensors=BENCH_ACCEL,
            estimator={"free_roll_filter_s": tau},
        )  # fmt: skip
        venv.reset(seed=seed, options={"rail": "leaves", "speed_kmh": 49.0, "pattern": "uniform",
                                       "mu_contaminated": 0.028, "gradient_permille": -18.0,
                                       "load_factor": 1.0})  # fmt: skip
        core, low = venv.core, 0.0
        for i in range(600):
            venv.step(np.full((1, 4), 1.0 if i < 350 else -1.0, dtype=np.float32))
            if i >= 350:
                low = min(low, 3.6 * (core.reference_speed_mps[0] - core.sim.speed_mps[0]))
        worst[tau] = low
    assert worst[0.0] < -30.0 and worst[0.1] > -12.0, worst


def test_the_reference_age_is_observed_and_resets_at_an_anchor():
    venv = WSPBrakingVectorEnv(num_envs=1)
    venv.reset(seed=2, options={"rail": "soap", "speed_kmh": 120.0, "mu_contaminated": 0.06})
    core = venv.core
    for _ in range(300):
        venv.step(np.full((1, 4), 0.3, dtype=np.float32))  # working: out of apply
    age = core.wsp[0, K.W_AGE]
    assert age > 3.0 and core.obs[0, -1] == pytest.approx(age / 10.0, rel=1e-5)
    action = np.full((1, 4), 0.3, dtype=np.float32)
    action[0, 0] = -1.0
    for _ in range(250):
        venv.step(action)
    assert core.wsp[0, K.W_AGE] < 0.5


class _Vent:
    """A policy that vents every valve for the whole stop."""

    name = "vent"
    privileged = False

    def bind(self, core):
        self.shape = (core.n_envs, core.n_valves)

    def reset(self, env_ids):
        pass

    def act(self, obs):
        return -np.ones(self.shape, dtype=np.float32)


@pytest.mark.parametrize("rail,speed,gradient", [("soap", 100.0, 0.0), ("leaves", 100.0, 0.0),
                                                 ("dry", 120.0, 0.0)])  # fmt: skip
def test_the_watchdog_stops_a_policy_that_vents_forever(rail, speed, gradient):
    """Without the watchdog a vent-forever stop runs for kilometres; with it, the minimum-
    deceleration supervision restores the demand. Where the full demand does not lock every
    axle (dry) it stands to standstill, and the stop is the locked-wheel stop plus at most the
    distance run at the initial speed while the supervision waits (the demand's build-up, its
    3 s and the filter's 2 x 1 s). Where it locks every axle (soap, leaves) it gives way, the
    policy vents again, and the safety time restores every axle for good 10 s later: the bound
    gains those 10 s at the initial speed. Without giving way (``give_way_locked_s`` 0, the
    watchdog before 2026-11-27) the first bound holds on every rail."""
    case = {"gradient_permille": gradient}
    locked, _ = run_one("uic_z1", rail, speed, NoWSP(), 3, case)
    vent, _ = run_one("uic_z1", rail, speed, _Vent(), 3, case)
    stand, _ = run_one(
        "uic_z1", rail, speed, _Vent(), 3, case, {"watchdog": {"give_way_locked_s": 0.0}}
    )
    free, _ = run_one("uic_z1", rail, speed, _Vent(), 3, case, {"watchdog": {"enabled": False}})
    t_build = locked["equivalent_build_up_time_s"] * 2.0
    bound = locked["stopping_distance_m"] + speed / 3.6 * (t_build + 3.0 + 2.0)
    assert stand["stopping_distance_m"] <= bound
    assert stand["watchdog"]["min_deceleration"] == 1 and stand["watchdog"]["gave_way"] == 0
    assert vent["watchdog"]["min_deceleration"] == 1
    if rail == "dry":
        assert vent["watchdog"]["gave_way"] == 0
        assert vent["stopping_distance_m"] == stand["stopping_distance_m"]
    else:
        assert vent["watchdog"]["gave_way"] == 1 and vent["watchdog"]["safety_time_axles"] == 4
        assert vent["stopping_distance_m"] <= bound + speed / 3.6 * 10.0
    assert free["stopping_distance_m"] > 3.0 * vent["stopping_distance_m"]
    assert locked["watchdog"]["total"] == 0


@pytest.mark.parametrize("give_way_s", [0.2, 0.0])
def test_the_override_gives_way_once_every_axle_has_locked_under_it(give_way_s):
    """A policy that vents on soap trips the minimum-deceleration supervision (6.3 s); its full
    demand locks every axle while the train still runs at tens of km/h. With the default
    ``give_way_locked_s`` the override ends after every axle has read locked against the shared
    reference for longer than 0.2 s (counted here from the readings): the valves obey the
    policy again at once, and the supervision does not trip a second time although the policy
    withholds the brakes again.
    With 0 the full demand stands to the end of the stop, the axles locked."""
    venv = WSPBrakingVectorEnv(num_envs=1, watchdog={"give_way_locked_s": give_way_s})
    venv.reset(seed=3, options={"rail": "soap", "speed_kmh": 100.0, "pattern": "uniform",
                                "gradient_permille": 0.0, "load_factor": 1.0})  # fmt: skip
    core = venv.core
    vent = -np.ones((1, 4), dtype=np.float32)
    limit = core.watchdog.give_way_locked_s
    state, locked_for, gave_way_at, before = [], 0.0, None, 0.0
    for step in range(1, 1500):
        venv.step(vent)
        override = core.wsp[0, K.W_OVERRIDE]  # after the period; its commands obeyed ``before``
        if core.sim.speed_mps[0] < 2.0:
            break
        state.append(override)
        wheels, v_ref = core.measured_wheel_speed_mps[0], core.wsp[0, K.W_VREF]
        if before == 1.0:
            np.testing.assert_array_equal(core.sim.cmd[0], 1.0)  # the full demand
            # every axle locked at this period's end, counted as the kernel counts (the same
            # float additions): it gives way in the first period the count passes the limit
            every = bool(np.all(wheels < LOCK_WHEEL_SPEED)) and v_ref > LOCK_TRAIN_SPEED
            counted = locked_for + 0.02 if every else 0.0
            due = limit > 0.0 and counted > limit
            assert (override == 2.0) == due, (step, counted)
            if due:
                gave_way_at = step * 0.02
                assert core.sim.speed_mps[0] > 10.0  # a real lock: the train runs on
            locked_for = counted
        elif before == 2.0 and step * 0.02 < gave_way_at + 9.9:  # before the safety time
            np.testing.assert_array_equal(core.sim.cmd[0], 0.0)  # the policy's vent
        before = override
    state = np.array(state)
    trip = int(np.argmax(state > 0.0))
    assert 6.0 < (trip + 1) * 0.02 < 7.0
    assert np.all(np.diff(state[trip:]) >= 0.0) and set(state[trip:]) <= {1.0, 2.0}
    if give_way_s > 0.0:
        assert gave_way_at is not None and gave_way_at < 6.3 + 3.0 and state[-1] == 2.0
    else:
        assert gave_way_at is None and np.all(state[trip:] == 1.0)
        assert np.all(core.sim.wheel_speed_mps[0] < LOCK_WHEEL_SPEED)


def test_the_override_only_ever_trips_then_gives_way_after_a_lock_on_the_benchmark_stops():
    """An invariant over 48 stops of the benchmark's distribution (every rail, gradients,
    sensor errors) under actions that vent, hold and apply at random: each stop's override goes
    0 -> 1 -> 2 and never back, and it gives way only after every axle has read locked against
    the shared reference for more than ``give_way_locked_s`` (counted here from the readings,
    independently of the kernel's timer). Some stops must trip and some give way, or the
    invariant tests nothing."""
    import gymnasium as gym

    venv = gym.make_vec("WSPBraking-UICZ1-Accel-v3", num_envs=48)
    venv.reset(seed=5)
    core = venv.unwrapped.core
    rng = np.random.default_rng(5)
    before = np.zeros(48)
    locked_for = np.zeros(48)
    tripped = gave_way = 0
    top = np.linspace(-0.7, 1.0, 48)[:, None]  # from mostly venting to anything

    def draw() -> np.ndarray:
        return rng.uniform(-1.0, top, (48, 4)).astype(np.float32)

    action = draw()
    for _ in range(2000):
        if rng.random() < 0.005:  # a new random action every 4 s or so: long enough to matter
            action = draw()
        _, _, term, trunc, _ = venv.step(action)
        now = core.wsp[:, K.W_OVERRIDE].copy()
        done = term | trunc
        locked = np.all(core.measured_wheel_speed_mps < LOCK_WHEEL_SPEED, axis=1) & (
            core.wsp[:, K.W_VREF] > LOCK_TRAIN_SPEED
        )
        for e in np.flatnonzero(~done):
            assert now[e] >= before[e] and now[e] - before[e] <= 1.0  # 0 -> 1 -> 2 only
            if before[e] == 1.0 and now[e] == 2.0:
                assert locked[e] and locked_for[e] + 0.02 > 0.2 - 1e-9
                gave_way += 1
            if before[e] == 0.0 and now[e] == 1.0:
                tripped += 1
        locked_for = np.where(locked & (before == 1.0), locked_for + 0.02, 0.0)
        before = np.where(done, 0.0, now)
        locked_for[done] = 0.0
    assert tripped >= 3 and gave_way >= 1


def test_the_watchdog_leaves_the_classical_wsp_alone_on_the_quick_suite():
    """The frozen classical WSP never trips it on the `quick` suite (soap, leaves, oil, a step:
    it is a backstop, not a controller; on the sealed set it never intervened either)."""
    from wsp_env.evaluation import load_suite, run_suite
    from wsp_env.policy import make_policy

    res, _ = run_suite("uic_z1", load_suite("quick"), make_policy("classical"), record="none")
    assert all(r["watchdog"]["total"] == 0 for r in res)


@pytest.mark.parametrize(
    "kwargs,needle",
    [
        ({"sensors": {"wheel_speed_noise_kmh": [0.5, 0.1]}}, "wheel_speed_noise_kmh"),
        ({"sensors": {"wheel_speed_noise_kmh": [-1.0, 0.1]}}, "wheel_speed_noise_kmh"),
        ({"sensors": {"accelerometer_lag_s": float("nan")}}, "accelerometer_lag_s"),
        ({"sensors": {"wheel_speed_scale_error": 0.5}}, "wheel_speed_scale_error"),
        ({"sensors": {"phonic_teeth": 80}}, "phonic_teeth"),
        ({"watchdog": {"safety_time_s": 0.0}}, "safety_time_s"),
        ({"watchdog": {"min_decel_mps2": -1.0}}, "min_decel_mps2"),
        ({"watchdog": {"give_way_locked_s": -0.1}}, "give_way_locked_s"),
        ({"estimator": {"ref_adapt_margin": 0.5}}, "ref_adapt_margin"),
        ({"estimator": {"accel_offset_gain": 1.5}}, "accel_offset_gain"),
        ({"estimator": {"free_roll_filter_s": -0.1}}, "free_roll_filter_s"),
        ({"accelerometer_bias_mps2": -0.1}, "accelerometer_bias_mps2"),
    ],
)
def test_bad_sensor_watchdog_and_estimator_settings_are_one_line(kwargs, needle):
    with pytest.raises((ConfigError, ValueError)) as err:
        WSPBrakingVectorEnv(num_envs=1, **kwargs)
    msg = str(err.value)
    assert needle in msg and "\n" not in msg


@pytest.mark.parametrize(
    "options,needle",
    [
        ({"accelerometer_bias_mps2": 3.0}, "accelerometer_bias_mps2"),
        ({"accelerometer_bias_mps2": "x"}, "accelerometer_bias_mps2"),
        ({"wheel_speed_noise_kmh": -0.1}, "wheel_speed_noise_kmh"),
        ({"gradient_permille": 150.0}, "gradient_permille"),
    ],
)
def test_bad_sensor_options_are_one_line(options, needle):
    venv = WSPBrakingVectorEnv(num_envs=1, accelerometer=True)
    with pytest.raises(ConfigError) as err:
        venv.reset(seed=0, options=options)
    assert needle in str(err.value) and "\n" not in str(err.value)

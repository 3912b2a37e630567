"""The Gymnasium environment: API checkers, determinism, vector = singles, reward, SB3."""

from __future__ import annotations

import itertools
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import wsp_env  # noqa: F401  (registers WSPBraking-v0)
from wsp_env import threads
from wsp_env.core import kernel as K
from wsp_env.core.kernel import env_step_parallel
from wsp_env.envs import WSPBrakingEnv, WSPBrakingVectorEnv

VEHICLES = ["uic_z1", "e402b", "etr1000", "regiolis"]


@pytest.mark.parametrize("vehicle", VEHICLES)
@pytest.mark.parametrize("mode", ["continuous", "discrete"])
def test_gymnasium_and_sb3_checkers_pass(vehicle, mode):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = WSPBrakingEnv(vehicle=vehicle, action_mode=mode)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any checker warning fails the test
        check_env(env, skip_render_check=True)
        sb3_check_env(WSPBrakingEnv(vehicle=vehicle, action_mode=mode), warn=True)


def test_make_and_make_vec_work():
    env = gym.make("WSPBraking-v0", vehicle="uic_z1")
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    venv = gym.make_vec(
        "WSPBraking-v0", num_envs=3, vectorization_mode="vector_entry_point", vehicle="regiolis"
    )
    obs, _ = venv.reset(seed=0)
    assert obs.shape == (3, 4 * 16 + 3 + 16)  # regiolis: 16 axles, 16 valves, the ref's age
    assert isinstance(venv.unwrapped, WSPBrakingVectorEnv)
    assert venv.metadata["autoreset_mode"].name == "SAME_STEP"


def _rollout(env, seed, n_steps, actions):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for t in range(n_steps):
        obs, r, term, trunc, _ = env.step(actions[t])
        out.append(np.append(obs, r))
        if term or trunc:
            obs, _ = env.reset()
            out.append(obs)
    return out


def test_same_seed_same_trajectory():
    actions = np.random.default_rng(0).uniform(-1, 1, size=(300, 4)).astype(np.float32)
    a = _rollout(WSPBrakingEnv(), 7, 300, actions)
    b = _rollout(WSPBrakingEnv(), 7, 300, actions)
    c = _rollout(WSPBrakingEnv(), 8, 300, actions)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not np.array_equal(a[0], c[0])


@pytest.mark.parametrize("vehicle,n", [("uic_z1", 4), ("etr1000", 3), ("uic_z1", 70)])
def test_vector_env_equals_single_envs(vehicle, n):
    """Seeds s..s+N-1 in the vector env give exactly the single envs' trajectories, resets
    included (short episodes: low speed). N = 70 uses the parallel kernel (the two-core
    evaluate policy's, whatever share of the cores this test process has)."""
    steps = 400
    scenario = {"speed_kmh": [5.0, 15.0]}
    policy = threads.thread_policy("evaluate", cores=2)
    with threads.applied(policy):
        venv = WSPBrakingVectorEnv(num_envs=n, vehicle=vehicle, scenario=scenario)
    assert (venv.core._step_fn is env_step_parallel) == (n >= policy.parallel_min_envs)
    singles = [WSPBrakingEnv(vehicle=vehicle, scenario=scenario) for _ in range(n)]
    rng = np.random.default_rng(1)
    acts = rng.uniform(-0.5, 1, size=(steps, n, venv.core.n_valves)).astype(np.float32)
    vobs, _ = venv.reset(seed=100)
    sobs = [s.reset(seed=100 + i)[0] for i, s in enumerate(singles)]
    np.testing.assert_array_equal(vobs, np.stack(sobs))
    ended = 0
    for t in range(steps):
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(acts[t])
        for i, s in enumerate(singles):
            o, r, term, trunc, info = s.step(acts[t, i])
            assert r == vrew[i] and term == vterm[i] and trunc == vtrunc[i]
            if term or trunc:
                ended += 1
                np.testing.assert_array_equal(o, vinfo["final_obs"][i])
                assert info["metrics"] == vinfo["final_info"][i]["metrics"]
                o, _ = s.reset()
            np.testing.assert_array_equal(o, vobs[i])
    assert ended >= n // 2  # autoresets were exercised (most envs ended at least once)


def test_distance_term_sums_to_stopping_distance():
    env = WSPBrakingEnv(reward={"distance_scale_m": 250.0})
    env.reset(seed=3, options={"speed_kmh": 100.0, "rail": "soap"})
    total = 0.0
    while True:
        _, _, term, trunc, info = env.step(np.full(4, 0.6, dtype=np.float32))
        total += info["reward_terms"]["distance"]
        if term or trunc:
            break
    assert term
    d = info["metrics"]["stopping_distance_m"]
    assert -total * 250.0 == pytest.approx(d, rel=1e-9)
    assert info["metrics"]["episode_reward_terms"]["distance"] == pytest.approx(total, rel=1e-12)


def test_reward_penalises_sliding_without_wsp():
    """Full demand on soap locks wheels: the lock and damage terms are clearly negative."""
    env = WSPBrakingEnv()
    env.reset(seed=0, options={"speed_kmh": 120.0, "rail": "soap", "mu_contaminated": 0.07})
    while True:
        _, _, term, trunc, info = env.step(np.ones(4, dtype=np.float32))
        if term or trunc:
            break
    terms = info["metrics"]["episode_reward_terms"]
    assert terms["lock"] < -1 and terms["damage"] < -1 and terms["air"] == 0.0
    assert terms["air"] == 0.0  # no valve ever vented


def test_options_fix_every_drawn_parameter():
    env = WSPBrakingEnv()
    opts = {
        "speed_kmh": 90.0,
        "rail": "oil",
        "mu_contaminated": 0.05,
        "pattern": "uniform",
        "load_factor": 1.1,
        "pad_factor": 0.95,
        "gradient_permille": 3.0,
        "demand": "service",
    }
    _, info = env.reset(seed=1, options=opts)
    _, info2 = env.reset(seed=2, options=opts)
    assert info["scenario"] == info2["scenario"]
    s = info["scenario"]
    assert s["speed_kmh"] == 90.0 and s["rail"] == "oil" and s["mu_contaminated"] == 0.05
    assert s["demand_fraction"] == 0.85 and s["gradient_permille"] == 3.0
    with pytest.raises(ValueError, match=r"options\.colour"):
        env.reset(options={"colour": "red"})


def test_bad_actions():
    env = WSPBrakingEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.array([0.0, np.nan, 0.0, 0.0], dtype=np.float32))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3, dtype=np.float32))
    _, _, _, _, info = env.step(np.array([3.0, -2.0, 0.5, 0.5], dtype=np.float32))
    assert info["action_clipped"] == 2
    denv = WSPBrakingEnv(action_mode="discrete")
    denv.reset(seed=0)
    with pytest.raises(ValueError, match="vent"):
        denv.step(np.array([0, 1, 2, 3]))


def test_discrete_hold_vent_fill():
    env = WSPBrakingEnv(action_mode="discrete")
    env.reset(seed=0, options={"speed_kmh": 100.0, "rail": "wet"})
    for _ in range(150):
        env.step(np.array([2, 2, 2, 2]))
    p = env.core.sim.pressure_bar[0].copy()
    env.step(np.array([1, 0, 2, 1]))  # the fill command still acts for the valve dead time
    p1 = env.core.sim.pressure_bar[0].copy()
    assert p1[0] >= p[0]
    for _ in range(10):
        env.step(np.array([1, 0, 2, 1]))
    p, p2 = p1, env.core.sim.pressure_bar[0]
    assert p2[0] == pytest.approx(p[0], abs=1e-9) and p2[3] == pytest.approx(p[3], abs=1e-9)
    assert p2[1] < 0.5 * p[1]
    assert p2[2] >= p[2] - 1e-9


def test_bogie_valves_and_privileged_observation():
    env = WSPBrakingEnv(vehicle="etr1000", valve_group="bogie", privileged=True)
    assert env.action_space.shape == (16,)
    obs, _ = env.reset(seed=0, options={"rail": "soap", "speed_kmh": 200.0})
    n = 32
    base = 4 * n + 2 + 16
    assert obs.shape == (base + 1 + 2 * n + 1,)  # the reference's age last
    assert obs[base] == pytest.approx(200 / 360, rel=1e-6)  # true speed / max speed
    assert 0.0 < obs[base + 1] < 0.3  # friction level of axle 1


def test_render_rgb_array():
    env = WSPBrakingEnv(render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.zeros(4, dtype=np.float32))
    img = env.render()
    assert img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8
    assert img.std() > 10  # not a blank image
    assert set(WSPBrakingEnv.metadata["render_modes"]) == {"human", "rgb_array"}


def test_render_reuses_one_figure_and_shows_a_capped_history():
    """One figure for every frame; frames change as the env steps, their shape does not; the
    history holds the last 10 s (501 rows at 20 ms) and starts anew at reset; nothing is kept
    without a render_mode; close() drops the figure."""
    env = WSPBrakingEnv(render_mode="rgb_array")
    env.reset(seed=0, options={"rail": "soap", "speed_kmh": 120.0})
    history = env.render_history
    assert history.length[0] == 1
    first = env.render()
    figure = env.renderer.figure
    frames = [first]
    for _ in range(600):  # 12 s
        env.step(np.ones(4, dtype=np.float32))
        if len(frames) < 3:
            frames.append(env.render())
    assert history.capacity == 501 and history.length[0] == 501
    rows = history.window(0)
    assert np.all(np.diff(rows[:, 0]) > 0)  # oldest first, in time order
    assert rows[-1, 0] == pytest.approx(env.core.sim.time_s[0])
    assert rows[-1, 0] - rows[0, 0] == pytest.approx(10.0)
    frames.append(env.render())
    assert env.renderer.figure is figure
    assert all(f.shape == first.shape == (480, 640, 3) for f in frames)
    assert all(np.any(a != b) for a, b in itertools.pairwise(frames))
    env.reset(seed=1)
    assert history.length[0] == 1 and env.renderer.figure is figure
    env.close()
    assert env.renderer.figure is None
    plain = WSPBrakingEnv()
    assert plain.render_history is None and plain.render() is None
    with pytest.raises(ValueError, match="render_mode"):
        WSPBrakingEnv(render_mode="rgb_array_list")


def test_vector_render_frames_per_env_on_one_figure():
    venv = WSPBrakingVectorEnv(num_envs=2, render_mode="rgb_array")
    venv.reset(seed=0, options={"rail": "soap", "speed_kmh": 100.0})
    for _ in range(20):
        venv.step(np.ones((2, 4), dtype=np.float32))
    a, b = venv.render()
    figure = venv.renderer.figure
    assert a.shape == b.shape == (480, 640, 3) and np.any(a != b)  # two stops, two frames
    venv.render()
    assert venv.renderer.figure is figure and list(venv.render_history.length) == [21, 21]
    venv.close()
    with pytest.raises(ValueError, match="render_mode"):
        WSPBrakingVectorEnv(num_envs=2, render_mode="human")


def test_render_human_does_not_raise_headless():
    """``render_mode="human"`` under MPLBACKEND=Agg (no window to show): steps draw, render()
    returns None, close() works (a fresh interpreter, so the backend is the one chosen)."""
    import os
    import subprocess
    import sys

    code = (
        "import numpy as np, gymnasium as gym, wsp_env\n"
        "env = gym.make('WSPBraking-v0', render_mode='human')\n"
        "env.reset(seed=0)\n"
        "for _ in range(5): env.step(np.ones(4, dtype=np.float32))\n"
        "assert env.render() is None\n"
        "assert env.unwrapped.renderer.figure is not None\n"
        "env.close()\n"
        "import matplotlib.pyplot as plt; assert plt.get_fignums() == []\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, "MPLBACKEND": "Agg"},
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert run.returncode == 0, run.stderr


def test_spec_shows_the_step_limit_and_truncation_keeps_metrics():
    """The made env's spec carries its own step limit (no TimeLimit: the ids register none);
    truncation comes after exactly that many steps, with ``metrics``, also where a TimeLimit
    rebuilt from the spec truncates on the same step; the vector env takes
    ``max_episode_steps`` itself."""
    assert gym.spec("WSPBraking-v0").max_episode_steps is None
    assert gym.make("WSPBraking-v0").spec.max_episode_steps == 15000  # 300 s / 20 ms
    assert gym.make("WSPBraking-UICZ1-v3").spec.max_episode_steps == 30000  # 600 s / 20 ms
    assert gym.make("WSPBraking-v0", max_time_s=60.0).spec.max_episode_steps == 3000
    venv = gym.make_vec("WSPBraking-v0", num_envs=2, vectorization_mode="vector_entry_point")
    assert venv.spec.max_episode_steps == 15000
    # a stop that lasts: 200 km/h on soap, every valve venting, no watchdog
    slow = {"speed_kmh": 200.0, "rail": "soap", "gradient_permille": 0.0}
    vent = np.full(4, -1.0, dtype=np.float32)

    def run(env):
        env.reset(seed=0, options=slow)
        for n in range(1, 10_000):
            _, _, terminated, truncated, info = env.step(vent)
            if terminated or truncated:
                return n, terminated, truncated, info
        raise AssertionError("no end")

    env = gym.make("WSPBraking-v0", max_time_s=1.0, watchdog={"enabled": False})
    assert env.spec.max_episode_steps == 50
    n, terminated, truncated, info = run(env)
    assert (n, terminated, truncated) == (50, False, True) and "metrics" in info
    assert info["metrics"]["stopping_time_s"] == pytest.approx(1.0)
    rebuilt = gym.make(env.spec)  # a TimeLimit at 50: the same step as the env's own
    assert "TimeLimit" in str(rebuilt)
    n, _, truncated, info = run(rebuilt)
    assert n == 50 and truncated and "metrics" in info
    # 300 s: the float sum of the time stays under 300 s after 15,000 steps; the count ends it
    env = WSPBrakingEnv(watchdog={"enabled": False}, max_time_s=300.0)
    env.reset(seed=0, options={**slow, "gradient_permille": -20.0})
    for n in range(1, 15_001):
        _, _, terminated, truncated, info = env.step(vent)
        assert not terminated and (truncated == (n == 15_000))
    assert "metrics" in info and env.core.sim.time_s[0] < 300.0
    # the vector env: max_episode_steps is its own step limit, final_info has the metrics
    venv = gym.make_vec(
        "WSPBraking-v0", num_envs=2, vectorization_mode="vector_entry_point", max_episode_steps=50
    )
    assert venv.spec.max_episode_steps == 50
    venv.reset(seed=0, options=slow)
    for n in range(1, 51):
        _, _, terminated, truncated, info = venv.step(np.tile(vent, (2, 1)))
        assert not terminated.any() and truncated.all() == (n == 50)
    assert all("metrics" in info["final_info"][i] for i in range(2))


def test_sb3_ppo_trains_on_the_batched_env():
    """A few thousand PPO steps through the native vector env adapter."""
    import torch
    from stable_baselines3 import PPO

    from wsp_env.agents.sb3_vec import SB3VecEnv

    torch.set_num_threads(1)
    venv = SB3VecEnv(num_envs=8, scenario={"speed_kmh": [20.0, 40.0]})
    model = PPO("MlpPolicy", venv, n_steps=256, batch_size=512, n_epochs=2, seed=0, device="cpu")
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(total_timesteps=4096)
    assert model.num_timesteps >= 4096
    after = list(model.policy.parameters())
    assert any(not torch.equal(a, b) for a, b in zip(after, before, strict=True))
    obs = venv.reset()
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (8, 4) and np.isfinite(action).all()


def test_bench_quick_writes_contract_keys(tmp_path):
    """`wsp-env bench --json` writes the DESIGN §8 keys (tiny counts: a smoke test, no timing)."""
    import json

    from wsp_env.cli import main

    out = tmp_path / "bench.json"
    assert main(["bench", "--quick", "--repeats", "1", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    for key in ("single_env_steps_per_s", "vector_env_steps_per_s", "vector_num_envs", "n_axles"):
        assert key in result
    assert result["vector_num_envs"] == 1024 and result["n_axles"] == 4
    assert result["single_env_steps_per_s"] > 0 and result["cartpole_vector_steps_per_s"] > 0


def _locked_stop_reference_error(**kwargs):
    """Largest |v_ref - V| (km/h) over a no-WSP soap stop (every wheel locks), and the env."""
    venv = WSPBrakingVectorEnv(num_envs=1, vehicle="uic_z1", **kwargs)
    opts = {"rail": "soap", "speed_kmh": 100.0, "pattern": "uniform", "gradient_permille": 0.0,
            "mu_contaminated": 0.06}  # fmt: skip
    venv.reset(seed=5, options=opts)
    err = 0.0
    for _ in range(5000):
        _, _, term, trunc, _ = venv.step(np.ones((1, 4), dtype=np.float32))
        if (term | trunc).any():
            break
        err = max(err, abs(venv.core.wsp[0, K.W_VREF] - venv.core.sim.speed_mps[0]) * 3.6)
    return err, venv


def test_accelerometer_keeps_the_reference_on_the_train_when_every_wheel_slides():
    """Without it the reference of a locked-wheel stop falls at its 2.5 m/s^2 limit, far below
    the train; with an accelerometer (no bias) it follows the train; the reading is the last
    observation and the default observation is unchanged."""
    plain, venv0 = _locked_stop_reference_error()
    aided, venv1 = _locked_stop_reference_error(accelerometer=True, accelerometer_bias_mps2=0.0)
    assert plain > 20.0 and aided < 0.5, (plain, aided)
    assert venv1.core.obs_dim == venv0.core.obs_dim + 1 == 24


def test_accelerometer_reads_specific_force_with_a_bias_drawn_per_episode():
    """On a gradient it misses g sin(theta) (uphill reads less deceleration than the train
    has); the bias is drawn within its bound, reproducibly, after the scenario (the scenario
    draws are the same with and without the accelerometer)."""
    opts = {"rail": "dry", "speed_kmh": 80.0, "pattern": "uniform", "gradient_permille": 20.0}
    venv = WSPBrakingVectorEnv(num_envs=1, accelerometer=True, accelerometer_bias_mps2=0.0)
    venv.reset(seed=1, options=opts)
    for _ in range(300):
        venv.step(np.ones((1, 4), dtype=np.float32))
    v0 = venv.core.sim.speed_mps[0]
    venv.step(np.ones((1, 4), dtype=np.float32))
    true_decel = (v0 - venv.core.sim.speed_mps[0]) / 0.02
    reading = venv.core.wsp[0, K.W_ACC]
    assert reading == pytest.approx(true_decel - 9.80665 * 0.02, rel=1e-3, abs=2e-3)
    assert venv.core.obs[0, -2] == pytest.approx(reading / 10.0, rel=1e-6)  # then the age
    biases = []
    for acc in (True, False):
        v = WSPBrakingVectorEnv(num_envs=8, accelerometer=acc, accelerometer_bias_mps2=0.05)
        _, info = v.reset(seed=3)
        biases.append(v.core.sensor_par[:, K.SP_ACC_BIAS].copy())
        drawn = [{k: v for k, v in s.items() if k != "sensors"} for s in info["scenario"]]
        if acc:
            scen_acc = drawn
        else:
            assert drawn == scen_acc
    assert np.all(np.abs(biases[0]) <= 0.05) and np.unique(biases[0]).size == 8
    assert np.all(biases[1] == 0.0)


def test_sb3_adapter_reports_episodes_and_takes_seeds_and_options():
    """``infos[i]["episode"]`` as VecMonitor writes it (return = the summed rewards, length =
    the steps); ``seed()`` and ``set_options()`` reach the next reset, per environment too."""
    from wsp_env.agents.sb3_vec import SB3VecEnv

    venv = SB3VecEnv(num_envs=2)
    venv.seed(7)
    venv.set_options({"rail": "dry", "speed_kmh": 30.0, "pattern": "uniform"})
    venv.reset()
    core = venv.venv.core
    assert list(core.sim.speed_mps * 3.6) == pytest.approx([30.0, 30.0])
    total, steps, done = np.zeros(2), np.zeros(2, dtype=int), np.zeros(2, dtype=bool)
    episodes = [None, None]
    while not done.all():
        venv.step_async(np.ones((2, 4), dtype=np.float32))
        _, rewards, dones, infos = venv.step_wait()
        for i in range(2):
            if not done[i]:
                total[i] += rewards[i]
                steps[i] += 1
                if dones[i]:
                    episodes[i] = infos[i]["episode"]
                    done[i] = True
    for i in range(2):
        assert episodes[i]["l"] == steps[i]
        assert episodes[i]["r"] == pytest.approx(total[i], rel=1e-5)
    venv.set_options([{"rail": "dry", "speed_kmh": 30.0}, {"rail": "soap", "speed_kmh": 50.0}])
    venv.seed(3)
    venv.reset()
    assert [d["rail"] for d in (core.describe(0), core.describe(1))] == ["dry", "soap"]
    assert list(core.sim.speed_mps * 3.6) == pytest.approx([30.0, 50.0])
    first = core.describe(1)["mu_contaminated"]
    venv.set_options([{"rail": "dry", "speed_kmh": 30.0}, {"rail": "soap", "speed_kmh": 50.0}])
    venv.seed(3)
    venv.reset()
    assert core.describe(1)["mu_contaminated"] == first  # same seed, same draw
    venv.reset()  # seeds and options are used once
    assert core.describe(0)["speed_kmh"] != 30.0 or core.describe(1)["speed_kmh"] != 50.0


def test_sb3_adapter_get_attr_set_attr_env_method_per_env():
    """The rule of ``agents/sb3_vec.py``: the batch's per-environment state per index, shared
    attributes the same object for every index (whatever their shape: 4 envs, 4 axles),
    the core's per-environment queries per index, batch-wide methods refused by name."""
    from wsp_env.agents.sb3_vec import SB3VecEnv

    venv = SB3VecEnv(num_envs=4)
    core = venv.venv.core
    venv.set_options([{"speed_kmh": 40.0 + 20.0 * i, "rail": "dry"} for i in range(4)])
    venv.reset()
    for _ in range(3):
        venv.step_async(np.ones((4, 4), dtype=np.float32))
        venv.step_wait()
    ret = venv.get_attr("episode_return")
    assert ret == [core.episode_return[i] for i in range(4)] and len(set(ret)) == 4
    assert venv.get_attr("episode_steps", [1, 3]) == [3, 3]
    ref = venv.get_attr("reference_speed_mps", 2)
    assert ref == [core.reference_speed_mps[2]]
    obs = venv.get_attr("obs", [0, 3])
    assert np.array_equal(obs[0], core.obs[0]) and np.array_equal(obs[1], core.obs[3])
    assert venv.get_attr("rngs", [1]) == [core.rngs[1]]
    shared = venv.get_attr("valve_of_axle")  # (4,) with 4 envs: still shared, not sliced
    assert all(v is core.valve_of_axle for v in shared) and len(shared) == 4
    assert venv.get_attr("render_mode", [0, 1]) == [None, None]
    assert venv.get_attr("observation_space", 0) == [venv.observation_space]
    scen = venv.env_method("describe", indices=[0, 3])
    assert [d["speed_kmh"] for d in scen] == [40.0, 100.0]
    metrics = venv.env_method("episode_info", indices=1)
    assert metrics[0]["episode_return"] == pytest.approx(core.episode_return[1])
    assert venv.env_method("watchdog_interventions")[2] == core.watchdog_interventions(2)
    venv.set_attr("episode_return", 0.0, indices=[1, 2])
    assert list(core.episode_return[1:3]) == [0.0, 0.0] and core.episode_return[0] != 0.0
    venv.set_attr("custom_flag", 7)  # shared: for all at once
    assert venv.get_attr("custom_flag", [2]) == [7]
    with pytest.raises(AttributeError, match="'custom_flag'"):
        venv.set_attr("custom_flag", 8, indices=[0])
    with pytest.raises(AttributeError, match="'no_such_thing'"):
        venv.get_attr("no_such_thing")
    with pytest.raises(AttributeError, match="'reset'"):
        venv.env_method("reset", indices=[0])
    with pytest.raises(AttributeError, match="'no_such_method'"):
        venv.env_method("no_such_method")

"""The learner's reward weighted per stop (``training.stop_weight``, config ``stop_weight``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wsp_env.agents.sb3_vec import SB3VecEnv
from wsp_env.training.stop_weight import (
    G_MPS2,
    StopWeightConfig,
    StopWeightedReward,
    braking_distance_m,
    stop_weight,
)

CFG = StopWeightConfig()


def _scenario(speed_kmh=100.0, mu=0.05, gradient=0.0, demand=1.0):
    return {"speed_kmh": speed_kmh, "mu_contaminated": mu, "gradient_permille": gradient,
            "demand_fraction": demand}  # fmt: skip


def test_weight_is_the_reference_over_the_braking_distance():
    """Analytic cases: an adhesion-limited stop (mu g), a demand-limited one (the demand's
    deceleration), the gradient adding to (uphill) or taking from the deceleration, and the
    floor on the deceleration where a downhill gradient cancels the adhesion."""
    v = 100.0 / 3.6
    # adhesion-limited, level: d = v^2 / (2 mu g)
    d = v * v / (2 * 0.05 * G_MPS2)
    assert stop_weight(_scenario(mu=0.05), CFG) == pytest.approx(500.0 / d)
    # dry rail, emergency: the demand's 1.2 m/s^2 bounds it, service demand 85 % of that
    assert stop_weight(_scenario(mu=0.3), CFG) == pytest.approx(500.0 / (v * v / (2 * 1.2)))
    assert stop_weight(_scenario(mu=0.3, demand=0.85), CFG) == pytest.approx(
        500.0 / (v * v / (2 * 1.02))
    )
    # 20 per mille uphill adds g sin(atan(0.02)) to the deceleration
    up = stop_weight(_scenario(mu=0.05, gradient=20.0), CFG)
    a = G_MPS2 * (0.05 + math.sin(math.atan(0.02)))
    assert up == pytest.approx(500.0 / (v * v / (2 * a)))
    # downhill beyond the adhesion: the floor min_decel_mps2 (0.2)
    assert stop_weight(_scenario(mu=0.03, gradient=-25.0), CFG) == pytest.approx(
        500.0 / (v * v / (2 * 0.2))
    )


@settings(max_examples=200, deadline=None)
@given(
    speed=st.floats(5.0, 350.0),
    mu=st.floats(0.005, 0.5),
    gradient=st.floats(-40.0, 40.0),
    demand=st.floats(0.1, 1.0),
)
def test_weight_is_bounded_and_falls_with_speed(speed, mu, gradient, demand):
    """Within [min_weight, max_weight]; a faster stop of the same rail weighs no more; more
    adhesion weighs no less (a shorter stop)."""
    w = stop_weight(_scenario(speed, mu, gradient, demand), CFG)
    assert CFG.min_weight <= w <= CFG.max_weight
    assert stop_weight(_scenario(speed * 1.5, mu, gradient, demand), CFG) <= w
    assert stop_weight(_scenario(speed, mu * 1.5, gradient, demand), CFG) >= w


def test_wrapper_weights_each_stop_and_leaves_the_statistics_alone():
    """Same seeds with and without the wrapper: each step's reward is the plain one times the
    current stop's weight (from its own scenario), the weight changes at the autoreset (the
    ending step still at the old stop's), and the episode statistics stay the plain return."""
    scenario = {"speed_kmh": [20.0, 60.0], "gradient_permille": [-20, 20]}
    kwargs = {"num_envs": 3, "scenario": scenario, "max_time_s": 2.0}
    plain, wrapped = SB3VecEnv(**kwargs), StopWeightedReward(SB3VecEnv(**kwargs), CFG)
    plain.seed(5)
    wrapped.seed(5)
    plain.reset()
    wrapped.reset()
    weights = np.array([stop_weight(s, CFG) for s in plain.env_method("describe")])
    np.testing.assert_array_equal(wrapped.weights, weights)
    assert len(set(weights.round(9))) == 3  # three different stops
    action = np.ones((3, 4), dtype=np.float32)
    resets = np.zeros(3, dtype=int)
    for _ in range(300):
        plain.step_async(action)
        wrapped.step_async(action)
        _, r0, d0, i0 = plain.step_wait()
        _, r1, d1, i1 = wrapped.step_wait()
        np.testing.assert_array_equal(d0, d1)
        np.testing.assert_allclose(r1, (r0.astype(np.float64) * weights).astype(np.float32))
        for e in np.flatnonzero(d0):
            assert i1[e]["episode"]["r"] == i0[e]["episode"]["r"]  # the plain return
            new = stop_weight(plain.env_method("describe", indices=[int(e)])[0], CFG)
            assert wrapped.weights[e] == new
            resets[e] += 1
            weights[e] = new
    assert (resets >= 2).all(), resets  # every environment went through autoresets


def test_training_env_weighs_under_the_normalisation():
    """``make_training_env``: the weight sits on the adapter, under VecNormalize (so the
    normalisation sees the weighted reward the critic learns), and only when configured."""
    from stable_baselines3.common.vec_env import VecNormalize

    from wsp_env.training.config import parse_train_config
    from wsp_env.training.train import make_training_env

    base = {"algo": "ppo", "n_timesteps": 64, "n_envs": 2, "normalize": True, "n_steps": 32,
            "batch_size": 64}  # fmt: skip
    env = make_training_env(parse_train_config({**base, "stop_weight": {"reference_m": 300.0}}))
    assert isinstance(env, VecNormalize) and isinstance(env.venv, StopWeightedReward)
    assert env.venv.cfg.reference_m == 300.0 and isinstance(env.venv.venv, SB3VecEnv)
    assert isinstance(make_training_env(parse_train_config(base)).venv, SB3VecEnv)


def test_fit_script_reads_gain_against_distance(tmp_path, capsys):
    """``scripts/stop_weight_fit.py``: the gain of each scored stop against its estimated
    distance; a gain exactly proportional to it has no spread left."""
    import json
    import sys

    sys.path.insert(0, "scripts")
    try:
        import stop_weight_fit
    finally:
        sys.path.pop(0)
    runs = {"none": [], "classical": []}
    for i, (speed, mu) in enumerate([(60, 0.05), (100, 0.05), (140, 0.08), (160, 0.03)]):
        cond = _scenario(speed, mu)
        d = braking_distance_m(cond, CFG)
        runs["none"].append({"scenario": f"s{i}", "seed": i, "return": -3 * d / 100})
        runs["classical"].append({"scenario": f"s{i}", "seed": i, "return": -d / 100,
                                  "conditions": cond})  # fmt: skip
    path = tmp_path / "bench.json"
    path.write_text(json.dumps({"run_results": runs}))
    assert stop_weight_fit.main([str(path)]) == 0
    out = capsys.readouterr().out
    assert "4 scored stops; corr(log G, log d_est) 1.00" in out and "of G / d_est 1.0x" in out


def test_a_stop_without_an_adhesion_level_is_refused():
    with pytest.raises(ValueError, match="stop_weight: the stop has no adhesion level"):
        stop_weight({**_scenario(), "mu_contaminated": None}, CFG)

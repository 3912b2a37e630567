"""Plausibility and accountability of the calibration loop (issue 11, item 4): physical bounds
on every effect, unusable channels reported with their reason, the re-test of added effects,
and a confidence on each."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_discovery import synthetic_trace

from wsp_env.calibration.balance_retest import retest_balance
from wsp_env.calibration.discovery import Result, Step, discover
from wsp_env.calibration.plausibility import implausible, negligible, negligible_force
from wsp_env.calibration.residuals import channels
from wsp_env.calibration.traces import read_trace
from wsp_env.cli import main


@pytest.fixture(scope="module")
def gradient_trace(tmp_path_factory):
    return read_trace(synthetic_trace(tmp_path_factory.mktemp("g"), "g", gradient_permille=-10.0))


@pytest.mark.parametrize(
    "category,params,word",
    [
        ("sensor", {"speed_scale_error": -0.16}, "ground-speed scale"),
        ("wheel_radius", {"axle_1_radius_error": 0.0, "axle_2_radius_error": 0.12}, "radius"),
        ("gradient", {"gradient_permille": 80.0}, "gradient"),
        ("pad_friction", {"scale": 0.3}, "pad friction"),
        ("unmeasured_brake_force", {"force_at_full_demand_N": 2e5}, "unmeasured"),
        ("pressure_lag", {"lag_s": 3.0}, "pressure lag"),
        ("running_resistance", {"delta_a_N": -5e4, "delta_c_N_per_mps2": 0.0}, "resistance"),
        ("running_resistance", {"factor": -1.0}, "propelling"),
        ("unmeasured_brake_force", {"force_at_full_demand_N": -700.0}, "propelling"),
        ("running_resistance", {"factor": 400.0}, "weight"),
        ("load_transfer", {"bogie_pitch_kN_per_mps2": 400.0}, "bogie pitch"),
        ("sensor", {"speed_lag_s": float("nan")}, "not finite"),
    ],
)
def test_implausible_effects_are_named(gradient_trace, category, params, word):
    reason = implausible(category, params, gradient_trace)
    assert reason is not None and word in reason


@pytest.mark.parametrize(
    "category,params",
    [
        ("sensor", {"speed_scale_error": 0.015}),
        ("wheel_radius", {"axle_1_radius_error": 0.0, "axle_2_radius_error": 0.008}),
        ("gradient", {"gradient_permille": -12.0}),
        ("pad_friction", {"scale": 0.85}),
        ("unmeasured_brake_force", {"force_at_full_demand_N": 5000.0}),
        ("pressure_lag", {"lag_s": 0.3}),
        ("load_transfer", {"bogie_pitch_kN_per_mps2": 10.0}),
        ("running_resistance", {"factor": 3.0}),  # a storm headwind on a short train
    ],
)
def test_plausible_effects_pass(gradient_trace, category, params):
    assert implausible(category, params, gradient_trace) is None


def test_a_compensating_effect_is_dropped_by_the_retest(gradient_trace):
    """A gradient-only trace where an unmeasured brake force had been added first (as a greedy
    search can, the two shapes being alike while braking): with the gradient in, the force
    earns nothing and is dropped, with its reason; the gradient keeps its joint value."""
    trace = gradient_trace
    ch = channels(trace)["train_speed_balance_kmh"]
    rmse = ch.rmse
    result = Result({}, {})
    force = Step("unmeasured brake force", "unmeasured_brake_force", ch.name + "_kmh",
                 {"force_at_full_demand_N": 1.0}, rmse, 0.5 * rmse, -50.0)  # fmt: skip
    grade = Step("gradient", "gradient", ch.name + "_kmh", {"gradient_permille": 0.0},
                 0.5 * rmse, 0.01, -50.0)  # fmt: skip
    result.added = [force, grade]
    res = retest_balance(trace, result, ch.residual, ch.mask)
    assert [s.category for s in result.added] == ["gradient"]
    assert result.dropped[0]["category"] == "unmeasured_brake_force"
    assert "re-test" in result.dropped[0]["reason"]
    assert grade.parameters["gradient_permille"] == pytest.approx(-10.0, abs=0.3)
    assert grade.confidence["retest_delta_bic"] < -10.0
    assert np.sqrt(np.mean(res[ch.mask] ** 2)) < 0.2 * rmse


def test_every_added_effect_carries_a_confidence(gradient_trace):
    result = discover(gradient_trace)
    assert [s.category for s in result.added] == ["gradient"]
    conf = result.added[0].confidence
    assert conf["delta_bic"] < -10.0 and conf["cut_pct"] > 50.0
    assert conf["cut_over_noise_floor"] > 2.0 and conf["retest_delta_bic"] < -10.0


def test_a_channel_without_samples_is_reported_not_used(gradient_trace):
    """A record that starts with the brakes applied (no coasting lead-in): the coasting
    channel has no sample, says so and why, and nothing is chosen on it."""
    import dataclasses

    p = gradient_trace.p_cyl_bar.copy()
    p[:, :] = np.maximum(p, p.max())  # braked from the first sample
    trace = dataclasses.replace(gradient_trace, p_cyl_bar=p)
    result = discover(trace)
    health = result.channel_health["coasting_creep_pct"]
    assert health["usable"] is False and "coasting" in health["reason"]
    assert result.channel_health["train_speed_balance_kmh"]["usable"] is True
    assert all(s.channel != "coasting_creep_pct" for s in result.added)


def test_calibrate_json_carries_channels_and_dropped(tmp_path):
    path = synthetic_trace(tmp_path, "cli", gradient_permille=-8.0)
    out = tmp_path / "cal.json"
    assert main(["calibrate", str(path), "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert set(data["channels"]) == set(data["errors_before"])
    assert all(h["usable"] for h in data["channels"].values())
    assert data["dropped_effects"] == []
    assert data["added_effects"][0]["confidence"]["retest_delta_bic"] < -10.0


def test_two_forces_that_cancel_are_negligible_together(gradient_trace):
    """Weaker pads and an extra brake force of the same size explain nothing a force could:
    the pair search judges their sum (each alone is large)."""
    weight = float(gradient_trace.vehicle["mass_kg"]) * 9.80665
    n = len(gradient_trace.time_s)
    big = np.full(n, 0.01 * weight)  # 10 permille each
    assert negligible_force(big, gradient_trace, "one") is None
    reason = negligible_force(big - 0.999 * big, gradient_trace, "pads + extra force together")
    assert reason is not None and "together" in reason


@pytest.mark.parametrize(
    "category,params,small",
    [
        ("pad_friction", {"scale": 0.99, "slope_per_mps": -0.0008}, True),  # 1-2 % over the stop
        ("pad_friction", {"scale": 0.90}, False),
        ("running_resistance", {"factor": 0.8}, True),  # inside a Davis formula's third
        ("running_resistance", {"factor": 2.0}, False),
    ],
)
def test_pads_and_resistance_inside_their_own_tolerance_are_negligible(
    gradient_trace, category, params, small
):
    reason = negligible(category, params, gradient_trace)
    assert (reason is not None) == small, reason


def test_forces_that_cancel_are_a_compensation():
    from types import SimpleNamespace

    from wsp_env.calibration.plausibility import cancelling_forces

    trace = SimpleNamespace(
        v_train_kmh=np.linspace(100.0, 0.0, 101),
        vehicle={"brake": {"p_threshold_bar": 0.2}},
        p_cyl_bar=np.full((101, 4), 3.0),
    )
    push = np.full(101, -5000.0)
    brake = np.full(101, 4000.0)
    assert "cancel" in cancelling_forces(push, brake, trace, "a and b")
    assert cancelling_forces(push, -brake, trace, "a and b") is None  # they add up
    assert cancelling_forces(push, 0.3 * brake, trace, "a and b") is None  # one dominates

"""The three equation-error channels see their own effect families and stay at the noise floor
on a trace without extra effects (DESIGN §7)."""

from __future__ import annotations

import numpy as np
import pytest

from wsp_env.calibration.residuals import channels
from wsp_env.calibration.synthetic import simulate_trace
from wsp_env.calibration.traces import read_trace
from wsp_env.core.config import load_rail
from wsp_env.evaluation.trace_writer import SensorModel

SENSORS = SensorModel(sample_period_s=0.1, speed_noise_kmh=0.1, pressure_noise_bar=0.01)
CASES = {
    "clean": {},
    "gradient": {"gradient_permille": -15.0},
    "radius": {"wheel_radius_error": (0.0, 0.01, 0.0, 0.0)},
    # one axle off the others (a monotone rise is the base law's cleaning along the train)
    "adhesion_per_axle": {"axle_mu_factor": (1.0, 0.6, 1.0, 1.0)},
}


@pytest.fixture(scope="module")
def rmse(tmp_path_factory):
    d = tmp_path_factory.mktemp("res")
    out = {}
    for name, effect in CASES.items():
        csv_path, _, _ = simulate_trace(
            d / name, load_rail("soap"), 120.0, sensors=SENSORS, mu_contaminated=0.08,
            pattern="uniform", **effect,
        )  # fmt: skip
        out[name] = {k: ch.rmse for k, ch in channels(read_trace(csv_path)).items()}
    return out


def test_clean_trace_sits_at_the_sensor_noise_floor(rmse):
    assert rmse["clean"]["train_speed_balance_kmh"] < 0.3  # sensor noise 0.1 km/h
    assert rmse["clean"]["coasting_creep_pct"] < 0.3


def test_gradient_shows_in_the_train_speed_balance_only(rmse):
    assert (
        rmse["gradient"]["train_speed_balance_kmh"] > 20 * rmse["clean"]["train_speed_balance_kmh"]
    )
    assert rmse["gradient"]["coasting_creep_pct"] < 2 * rmse["clean"]["coasting_creep_pct"]


def test_wheel_radius_shows_in_the_coasting_creep_only(rmse):
    # 1 % on one axle of four: RMS over axles ~ 0.5 %
    assert rmse["radius"]["coasting_creep_pct"] == pytest.approx(0.5, abs=0.15)
    assert rmse["radius"]["train_speed_balance_kmh"] < 2 * rmse["clean"]["train_speed_balance_kmh"]


def test_per_axle_adhesion_shows_in_the_adhesion_fit(rmse):
    assert rmse["adhesion_per_axle"]["adhesion_fit_kN"] > 1.2 * rmse["clean"]["adhesion_fit_kN"]
    assert rmse["adhesion_per_axle"]["coasting_creep_pct"] < 2 * rmse["clean"]["coasting_creep_pct"]


def test_the_balance_anchor_is_known_to_the_noise_over_its_independent_values():
    """``anchor_se_kmh``: the sensor's noise over the samples in the first ``ANCHOR_S`` of the
    mask, or where the reader found updates, one update's noise over the updates there (plus
    the one the first interpolated samples lean on)."""
    import types

    from wsp_env.calibration.residuals import ANCHOR_S, anchor_se_kmh

    t = np.arange(0.0, 10.0, 0.1)
    mask = t >= 2.0
    trace = types.SimpleNamespace(
        time_s=t, ground_speed_noise_kmh=0.1, v_train_update_s=None, v_train_update_noise_kmh=None
    )
    n_window = int(np.sum(mask & (t <= 2.0 + ANCHOR_S + 1e-9)))
    assert anchor_se_kmh(trace, mask) == pytest.approx(0.1 / np.sqrt(n_window))
    trace.v_train_update_s, trace.v_train_update_noise_kmh = 0.5, 0.3
    expected = 0.3 / np.sqrt(ANCHOR_S / 0.5 + 1.0)
    assert anchor_se_kmh(trace, mask) == pytest.approx(expected, rel=0.05)
    assert anchor_se_kmh(trace, np.zeros_like(mask)) == 0.0

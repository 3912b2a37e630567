"""The brake's lag measured on the wheels (``calibration/wheel_lag.py``), judged on traces of
the independent generator (``calibration/independent.py``), which shares no code with it."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest
from test_independent_traces import independent_trace

from wsp_env.calibration.discovery import discover
from wsp_env.calibration.wheel_lag import wheel_lag


def _trace(tmp_path, seed, effects=(), **overrides):
    """The independent generator's trace, read back (``test_independent_traces``)."""
    return independent_trace(tmp_path, seed, effects, **overrides)[0]


@pytest.mark.parametrize("seed,lag", [(62001, 0.4), (62002, 0.4), (61012, 0.2)])
def test_the_wheels_measure_a_brake_that_follows_the_pressure_late(tmp_path, seed, lag):
    """Within 0.05 s (the logger's own sampling reads +-0.04 s on clean traces: an averaging
    logger and a sample-and-hold one place the pressure and the wheels a little apart)."""
    w = wheel_lag(_trace(tmp_path, seed, [("pressure_lag", lag)], contaminant="soap"))
    assert w is not None and w.episodes >= 4
    assert w.lag_s == pytest.approx(lag, abs=0.05)
    assert w.se_s < 0.05


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_on_a_clean_stop_the_wheels_answer_the_pressure_at_once(tmp_path, seed):
    w = wheel_lag(_trace(tmp_path, seed, contaminant="soap"))
    assert w is not None
    assert abs(w.lag_s) < 0.05


def test_a_late_ground_speed_does_not_enter(tmp_path):
    """0.4 s of ground-speed lag: the wheels still read the brake on time; and replacing the
    ground speed altogether leaves the estimate exactly as it was (slides are judged against
    the fastest axle), as does a pad scale (it multiplies the torque)."""
    trace = _trace(tmp_path, 81003, [("sensor_lag", 0.4)], contaminant="soap")
    w = wheel_lag(trace)
    assert w is not None and abs(w.lag_s) < 0.05
    other = dataclasses.replace(trace, v_train_kmh=np.roll(trace.v_train_kmh, 7) * 1.05)
    assert wheel_lag(other).lag_s == w.lag_s
    meta = copy.deepcopy(trace.meta)
    meta["vehicle"]["brake"]["torque_gain_Nm_per_bar"] *= 1.3
    stronger = dataclasses.replace(trace, meta=meta)
    assert wheel_lag(stronger).lag_s == pytest.approx(w.lag_s, abs=0.01)


def test_a_stop_without_slides_measures_nothing(tmp_path):
    """Clean seed 0 of the power study: a wet rail, no wheel slides, no valve acts."""
    assert wheel_lag(_trace(tmp_path, 0)) is None


# pressure lags of 0.2 s the balance missed: three under its noise floor (an averaging logger
# reads them 0.14 s against the logged pressure, under the balance's 0.15 s resolution), two
# taken for a late ground speed (the two are twins on the balance)
@pytest.mark.parametrize("seed", [61001, 61017, 61005, 61015])
def test_a_pressure_lag_the_balance_missed_is_found_on_the_wheels(tmp_path, seed):
    trace = _trace(tmp_path, seed, [("pressure_lag", 0.2)])
    result = discover(trace)
    cats = [s.category for s in result.added]
    assert cats == ["pressure_lag"], [(s.category, s.parameters) for s in result.added]
    step = result.added[0]
    assert step.parameters["lag_s"] == pytest.approx(0.2, abs=0.05)
    assert step.confidence["wheel_lag_s"] == step.parameters["lag_s"]
    assert result.wheel_lag["verdict"] == "late"


# pair 3 of the power study (a 4 kN unmeasured brake force and a 0.3 s pressure lag): the force
# was added first (a lag looks like a constant force during the stop) and the lag, alone on
# what the force left, only undid it; with the wheels' lag the force is refitted alongside it
@pytest.mark.parametrize("seed", [502009, 502018])
def test_a_lag_the_wheels_measured_is_found_under_a_force_effect(tmp_path, seed):
    trace = _trace(tmp_path, seed, [("unmeasured_brake_force", 4000.0), ("pressure_lag", 0.3)])
    result = discover(trace)
    found = {s.category: s for s in result.added if s.channel == "train_speed_balance_kmh"}
    assert set(found) == {"unmeasured_brake_force", "pressure_lag"}, list(found)
    assert found["pressure_lag"].parameters["lag_s"] == pytest.approx(0.3, abs=0.06)

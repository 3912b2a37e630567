"""Seed 000 §3 adhesion estimation and Eq. 9 fit on synthetic traces with known parameters."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from wsp_env.calibration.adhesion_estimate import eq9, estimate_adhesion, fit_polach
from wsp_env.calibration.synthetic import simulate_trace
from wsp_env.calibration.traces import read_trace
from wsp_env.config import RecoveryConfig, load_rail
from wsp_env.trace_io import SensorModel

MU0, K, K_ROZV = 0.1497, 30.0, 0.0291  # seed 000 Table 4, axle 1


@pytest.fixture(scope="module")
def fits(tmp_path_factory):
    """ETR 1000 soap law (Eq. 9), no recovery or cleaning, classical WSP, 50 Hz, no noise."""
    rail = dataclasses.replace(
        load_rail("soap_etr1000"),
        recovery=RecoveryConfig(w_lim=math.inf, w_max=math.inf),
        clean_energy_J_per_m=math.inf,
        pass_removal=0.0,
    )
    d = tmp_path_factory.mktemp("est")
    csv_path, _, _ = simulate_trace(
        d / "t", rail, 150.0, sensors=SensorModel(sample_period_s=0.02), mu_contaminated=MU0,
        pattern="uniform",
    )  # fmt: skip
    trace = read_trace(csv_path)
    return [fit_polach(a) for a in estimate_adhesion(trace)]


def test_eq9_reads_table4_units():
    assert eq9(np.array([1.0]), np.array([20.0]), MU0, K, K_ROZV)[0] == pytest.approx(
        MU0 / (1 + K_ROZV * 20), rel=1e-6
    )


def test_polach_parameters_recovered_per_bogie(fits):
    """mu0 and K_rozv of each bogie's axle pair within 10 % / 25 % of the generating values.

    Single axles are off by about +-15 %, in a fixed pattern: the metadata cannot describe the
    bogie-pitch load transfer (only the body's), so leading axles of each bogie look grippier
    and trailing ones slipperier. That is a missing effect for the calibration loop to find.
    """
    for pair in ((0, 1), (2, 3)):
        mu0 = np.mean([fits[i].mu0 for i in pair])
        k_rozv = np.mean([fits[i].K_rozv for i in pair])
        assert mu0 == pytest.approx(MU0, rel=0.10)
        assert k_rozv == pytest.approx(K_ROZV, rel=0.25)
    assert fits[0].mu0 > fits[1].mu0 and fits[2].mu0 > fits[3].mu0
    for f in fits:
        assert f.K == pytest.approx(K, rel=0.25) and f.n_points > 50 and f.rmse < 0.015

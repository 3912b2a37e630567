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


def test_fitted_curves_follow_the_generating_law(fits):
    """Each bogie's mean fitted Eq. 9 curve within 15 % of the generating one over the WSP's
    operating range (creepage up to 0.2 at 100 km/h), with the bogie-pitch signature.

    Not yet the 10 % parameter recovery issue 5 asks for: single axles are up to ~20 % off in a
    fixed pattern because the metadata cannot describe the bogie-pitch load transfer (only the
    body's), so leading axles of each bogie look grippier; and mu0 and K_rozv trade off against
    each other in the fit. The first is a missing effect for the calibration loop to add.
    """
    xi = np.linspace(0.01, 0.2, 20)
    true = eq9(xi, 100.0 * xi, MU0, K, K_ROZV)
    for pair in ((0, 1), (2, 3)):
        mean = np.mean(
            [eq9(xi, 100.0 * xi, fits[i].mu0, fits[i].K, fits[i].K_rozv) for i in pair], axis=0
        )
        assert np.max(np.abs(mean / true - 1)) < 0.15
    assert fits[0].mu0 > fits[1].mu0 and fits[2].mu0 > fits[3].mu0
    for f in fits:
        assert f.n_points > 50 and f.rmse < 0.015


@pytest.mark.parametrize("seed", [0, 1])
def test_soap_cleaning_shows_in_the_fitted_mu0_oil_does_not(tmp_path, seed):
    """Seed 000 Table 4 / Figs. 6-8: on soap the trailing bogie's axles fit a higher mu0 (the
    leading ones cleaned the rail); on oil they do not. Compared per bogie, because single axles
    carry the bogie-pitch load-transfer bias the metadata cannot remove."""
    from wsp_env.calibration.synthetic import simulate_trace
    from wsp_env.config import load_rail

    sensors = SensorModel(sample_period_s=0.1, speed_noise_kmh=0.1, pressure_noise_bar=0.01)
    ratios = {}
    for rail, mu in (("soap", 0.08), ("oil", 0.06)):
        csv_path, _, _ = simulate_trace(
            tmp_path / rail, load_rail(rail), 120.0, sensors=sensors, seed=seed,
            mu_contaminated=mu, pattern="uniform",
        )  # fmt: skip
        m = [f.mu0 for f in (fit_polach(a) for a in estimate_adhesion(read_trace(csv_path)))]
        ratios[rail] = (m[2] + m[3]) / (m[0] + m[1])
    assert ratios["soap"] > 1.05
    assert ratios["oil"] < 1.02

"""The coasting-creep channel's candidate effects: a wheel radius per axle, a ground-speed scale.

On the coasting samples each axle's apparent creep ``100 (V - v_i) / V`` should be nil; a radius
error ``e`` on one axle reads ``100 e / (1 + e)`` on that axle alone, a ground-speed scale error
``s`` reads ``100 s / (1 + s)`` on every axle alike. Each candidate carries its own test (an
offset against its standard error, ``RADIUS_Z_MIN``), not the RMSE against the per-sample noise
that the balance channel's candidates face (``discovery``).
"""

from __future__ import annotations

import math

import numpy as np

from wsp_env.calibration.selection import Candidate, bic

# an axle's coasting offset must stand this many standard errors out of the axle sensors' noise
RADIUS_Z_MIN = 6.0
RADIUS_MIN_SAMPLES = 4
RADIUS_MIN_SCATTER_PCT = 0.01  # the speed loggers' resolution, in creep %
SENSOR_CORRELATION_S = 1.0  # a ground speed's error stays correlated for a GPS fix period


def _fit_radius(trace, residual, mask):
    """One axle's radius against the others: its coasting creep less the median of the axles
    coasting at the same sample. The ground-speed sensor's noise, lag and scale are common to
    every axle and cancel in that difference, so a wheel's offset is judged against the axle
    sensors' noise alone, averaged over every coasting sample — what makes a 0.5 s lead-in
    usable. An axle qualifies when its mean offset stands ``RADIUS_Z_MIN`` standard errors
    out (robust scatter of the differences); the others keep radius error 0. A radius error
    common to every axle is a ground-speed scale to this channel (``_fit_sensor_coasting``).
    Returns the parameters, the residual less the offsets and the test's statistics."""
    n_ax = residual.shape[1]
    if n_ax < 3:
        return None
    vals = np.where(mask, residual, np.nan)
    rows = mask.sum(axis=1) >= 3
    ref = np.full(len(residual), np.nan)
    ref[rows] = np.nanmedian(vals[rows], axis=1)
    diff = vals - ref[:, None]
    params: dict[str, float] = {}
    offsets = np.zeros(n_ax)
    z = np.zeros(n_ax)
    for i in range(n_ax):
        d = diff[:, i][np.isfinite(diff[:, i])]
        if d.size < RADIUS_MIN_SAMPLES:
            continue
        mean = float(d.mean())
        scatter = max(1.4826 * float(np.median(np.abs(d - np.median(d)))), RADIUS_MIN_SCATTER_PCT)
        z[i] = mean / (scatter / math.sqrt(d.size))
        if abs(z[i]) >= RADIUS_Z_MIN:
            offsets[i] = mean
    if not offsets.any():
        return None
    for i in range(n_ax):
        # apparent creep 100 (V - v/(1+e)) / V ~ 100 e / (1 + e)
        params[f"axle_{i + 1}_radius_error"] = offsets[i] / (100.0 - offsets[i])
    new = residual - offsets[None, :]
    ok = np.isfinite(diff)
    rss0 = float(np.sum(diff[ok] ** 2))
    rss1 = float(np.sum((diff - offsets[None, :])[ok] ** 2))
    stats = _own_test(rss0, rss1, int(ok.sum()), int(np.count_nonzero(offsets)), np.abs(z).max())
    return params, new, stats


def _own_test(rss0: float, rss1: float, n: int, k: int, z_max: float) -> dict[str, float]:
    """The statistics a coasting candidate's own test reports (``discover`` reads them)."""
    return {
        "delta_bic": bic(rss1, n, k) - bic(rss0, n, 0),
        "k": k,
        "gain": 1.0 - math.sqrt(rss1 / max(rss0, 1e-300)),
        "z_max": float(z_max),
    }


def _fit_sensor_coasting(trace, residual, mask):
    """One scale error of the ground speed: the same apparent creep on every coasting axle.

    Judged on its own test, like the radius: at each sample the median creep of the coasting
    axles (one worn wheel does not move it), and the mean of those medians against its
    standard error — the robust scatter of the medians with one independent value per
    ``SENSOR_CORRELATION_S`` of coasting, since the ground speed's error is common to every
    axle and held between fixes. It qualifies at ``RADIUS_Z_MIN`` standard errors. (A test of
    the channel's RMSE against the per-sample noise, as on the balance, needs an offset of
    sqrt(3) sample sigmas: a 1.5 % scale under a 0.3 km/h GPS at 80 km/h was never tried.)"""
    rows = mask.sum(axis=1) >= min(3, residual.shape[1])
    if rows.sum() < RADIUS_MIN_SAMPLES:
        return None
    med = np.nanmedian(np.where(mask, residual, np.nan)[rows], axis=1)
    offset = float(med.mean())
    dt = float(np.median(np.diff(trace.time_s)))
    n_eff = min(float(med.size), max(med.size * dt / SENSOR_CORRELATION_S, 1.0))
    scatter = max(1.4826 * float(np.median(np.abs(med - np.median(med)))), RADIUS_MIN_SCATTER_PCT)
    z = offset / (scatter / math.sqrt(n_eff))
    if abs(z) < RADIUS_Z_MIN:
        return None
    new = residual - offset
    rss0 = float(np.sum(residual[mask] ** 2))
    stats = _own_test(rss0, float(np.sum(new[mask] ** 2)), int(mask.sum()), 1, abs(z))
    # apparent creep 100 (V (1 + s) - V) / (V (1 + s)) = 100 s / (1 + s)
    return {"speed_scale_error": offset / (100.0 - offset)}, new, stats


CANDIDATES_COASTING = [
    Candidate("wheel radius per axle", "wheel_radius", "coasting_creep_pct", 4, _fit_radius),
    Candidate("ground-speed scale", "sensor", "coasting_creep_pct", 1, _fit_sensor_coasting),
]

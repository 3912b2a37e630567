"""Equation-error channels that can see a missing effect (DESIGN §7, "Which error").

An open-loop replay of measured pressures diverges from measured wheel speeds even with a
perfect model (braked wheels under WSP are marginally stable), so each channel below closes the
model on measured quantities and tests one equation:

* **train-speed balance** (km/h): the train speed predicted from the measured pressures and
  wheel speeds alone, through the brake and wheelset equations —
  ``V(t) = V(0) - 1/M [ int (sum_i T_i / r + R(V)) dt + sum_i J (v_i(t) - v_i(0)) / r^2 ]`` with
  ``T_i = gain (p_i - p_th)^+`` and ``R`` the nominal resistance (metadata ``resistance``, else
  none) — against the measured train speed, over the intervals where every wheel turns (a
  locked wheel's brake force is not known from its pressure); the starting speed ``V(0)`` is
  the mean over the first ``ANCHOR_S`` rather than one noisy sample. Sees gradient, resistance, pad
  friction, unmeasured brake forces, pressure lag, ground-speed sensor errors. Its floor is
  about the sensor noise.
* **adhesion fit** (kN): the adhesion force at each critical point (``adhesion_estimate``)
  against the force of one Eq. 9 law fitted to all axles' critical points, with seed 002's
  recovery where the data call for it (``fit_base_law``). Sees
  position-dependent adhesion, load transfer, per-axle differences (cleaning).
* **coasting creep** (%): apparent creepage ``(V - v_i) / V`` of each axle while it is unbraked
  (the nominal model says 0). Sees wheel-radius errors and ground-speed sensor bias.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wsp_env.calibration.adhesion_estimate import censored_points, fit_base_law, pooled_points
from wsp_env.calibration.recurrence import lag_pass
from wsp_env.calibration.traces import Trace, braked

MIN_SPEED_KMH = 10.0
# a *measured* wheel speed below this reads as locked: above the speed sensors' noise
# (0.05-0.5 km/h), unlike the simulator's exact 0.1 m/s (physics.integrator.is_locked)
LOCK_KMH = 1.0
COAST_MIN_S = 2.0
ANCHOR_S = 1.0  # the balance's starting speed: the mean over this first stretch of the record


@dataclass
class Channel:
    """One residual channel: per-sample residual, the samples it is defined on, its RMSE."""

    name: str
    unit: str
    residual: np.ndarray
    mask: np.ndarray
    rmse: float
    detail: dict[str, float] = field(default_factory=dict)


def brake_force_N(trace: Trace) -> np.ndarray:
    """(T, n_axles) brake force at the rail, ``gain (p - p_th)^+ / r``, from the metadata."""
    return trace.brake_torque_Nm() / float(trace.vehicle["wheel_radius_m"])


def resistance_N(trace: Trace, v_mps: np.ndarray) -> np.ndarray:
    res = trace.vehicle.get("resistance") or {}
    a, b, c = (float(res.get(k, 0.0)) for k in ("a_N", "b_N_per_mps", "c_N_per_mps2"))
    return a + v_mps * (b + v_mps * c)


def balance_intervals(trace: Trace) -> np.ndarray:
    """Sample intervals on which the balance holds: every wheel turning at both ends.

    A locked wheel's brake torque is static friction, not ``gain (p - p_th)``: its force is
    unknown from the brake equation, so lock episodes are left out of the balance (and the
    prediction carries on from the measured speed after them).
    """
    turning = (trace.v_axle_kmh > LOCK_KMH).all(axis=1) | (trace.v_train_kmh < LOCK_KMH)
    return turning[1:] & turning[:-1]


def masked_cumtrapz(t: np.ndarray, y: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Running integral of ``y`` over the valid intervals only."""
    inc = 0.5 * (y[1:] + y[:-1]) * np.diff(t) * valid
    return np.concatenate([[0.0], np.cumsum(inc)])


def masked_cumdiff(y: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Running sum of the increments of ``y`` over the valid intervals only."""
    return np.concatenate([[0.0], np.cumsum(np.diff(y) * valid)])


def balance_mask(trace: Trace) -> np.ndarray:
    """Samples the balance channel is scored on: above ``MIN_SPEED_KMH``, every wheel turning."""
    valid = balance_intervals(trace)
    return (trace.v_train_kmh > MIN_SPEED_KMH) & np.concatenate([[True], valid])


def _anchor_window(t: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The samples the balance's starting speed is the mean of: the first ``ANCHOR_S`` of
    ``mask``."""
    return mask & (t <= t[mask][0] + ANCHOR_S)


def anchored(y: np.ndarray, t: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``y`` less its mean over the first ``ANCHOR_S`` of ``mask``.

    The balance starts from one logged speed sample, noise and all; anchoring on a short mean
    instead takes that noise out. Every effect's signature in the balance goes through the
    same operation (it is linear and idempotent), so fits stay unbiased.
    """
    if not mask.any():
        return y
    return y - float(y[_anchor_window(t, mask)].mean())


def anchor_se_kmh(trace: Trace, mask: np.ndarray) -> float:
    """The standard error (km/h) of the balance's starting speed (``anchored``): the ground
    speed's noise over the independent values in the first ``ANCHOR_S`` of ``mask`` — every
    sample, or where the reader found updates held or averaged between (``Trace.
    v_train_update_s``), the updates there, each with one update's noise (``Trace.
    v_train_update_noise_kmh``); a sample between two updates carries both, so one more than
    the window spans. A 1 Hz GPS fix on a 1 s lead-in leaves the whole stop's balance offset by
    about one fix's noise."""
    if not mask.any():
        return 0.0
    t = trace.time_s
    first = _anchor_window(t, mask)
    update = trace.v_train_update_s
    if update and trace.v_train_update_noise_kmh is not None:
        n_independent = float(np.ptp(t[first])) / update + 1.0
        noise = trace.v_train_update_noise_kmh
    else:
        n_independent = float(first.sum())
        noise = trace.ground_speed_noise_kmh
    return noise / float(np.sqrt(max(n_independent, 1.0)))


def train_speed_balance(trace: Trace) -> Channel:
    veh = trace.vehicle
    mass = float(veh["mass_kg"])
    r = float(veh["wheel_radius_m"])
    inertia = float(veh.get("wheelset_inertia_kgm2", 0.0))
    t = trace.time_s
    v = trace.v_train_kmh / 3.6
    wheels = trace.v_axle_kmh / 3.6
    valid = balance_intervals(trace)
    force = brake_force_N(trace).sum(axis=1) + resistance_N(trace, v)
    spin = inertia * masked_cumdiff(wheels.sum(axis=1), valid) / r**2
    predicted_drop = (masked_cumtrapz(t, force, valid) + spin) / mass
    measured_drop = -masked_cumdiff(v, valid)
    residual = 3.6 * (predicted_drop - measured_drop)
    mask = balance_mask(trace)
    residual = anchored(residual, t, mask)
    rmse = float(np.sqrt(np.mean(residual[mask] ** 2))) if mask.any() else float("nan")
    # sampling uncertainty of the force integral: per interval, half the gap between the left
    # and right Riemann sums (a 10 Hz log of a valve venting at 10 bar/s is far from smooth),
    # accumulated as independent errors
    gap = 0.5 * np.abs(np.diff(force)) * np.diff(t) * valid
    sampling = 3.6 * np.sqrt(np.concatenate([[0.0], np.cumsum(gap**2)])) / mass
    detail = {"sampling_rmse": float(np.sqrt(np.mean(sampling[mask] ** 2))) if mask.any() else 0.0}
    return Channel("train_speed_balance", "kmh", residual, mask, rmse, detail)


def adhesion_fit(trace: Trace) -> Channel:
    """Critical-point forces against one Eq. 9 law fitted to all axles' critical points; the
    residual (kN) sits at each point's sample (``mask`` marks them). The RMSE is weighted by
    each point's effective variance (``adhesion_estimate``)."""
    pts = pooled_points(trace, MIN_SPEED_KMH)
    base = fit_base_law(trace, pts, censored_points(trace, MIN_SPEED_KMH))
    residual = np.zeros_like(trace.p_cyl_bar)
    mask = np.zeros(residual.shape, dtype=bool)
    if base is None:
        return Channel("adhesion_fit", "kN", residual, mask, float("nan"))
    fit = base.fit
    residual[pts.sample, pts.axle] = fit.residual_kN
    mask[pts.sample, pts.axle] = True
    mu0, K, k_rozv = (float(x) for x in fit.params[:3])
    detail = {"mu0": mu0, "K": K, "K_rozv": k_rozv, "chi2": fit.chi2}
    if base.cleaning:
        detail["cleaning_gain"] = float(fit.params[-1])
    if base.recovery_kW is not None:
        detail.update(
            recovery_w_lim_kW=base.recovery_kW[0],
            recovery_w_max_kW=sum(base.recovery_kW),
            recovery_gain=float(fit.params[3]),
        )
    return Channel("adhesion_fit", "kN", residual, mask, fit.rmse, detail)


def coasting_creep(trace: Trace) -> Channel:
    v = trace.v_train_kmh
    creep = 100.0 * (v[:, None] - trace.v_axle_kmh) / np.maximum(v[:, None], 1.0)
    # coasting = the train unbraked (every axle) since the start of the record (before the
    # first application), or for COAST_MIN_S in a row. One axle vented by its WSP while the
    # others brake is no coasting wheel: it spins back up from a slide (on a contaminated rail
    # for seconds), and the braking train's deceleration turns the ground speed's timing into
    # apparent creep (held-out clean independent traces on oil read 1-3 % there, which the
    # radius test took for worn leading wheels)
    unbraked = ~braked(trace).any(axis=1)
    coasting = np.zeros_like(unbraked)
    t = trace.time_s
    run_start = None
    for k in range(len(t)):
        if unbraked[k]:
            run_start = k if run_start is None else run_start
            if run_start == 0 or t[k] - t[run_start] >= COAST_MIN_S:
                coasting[k] = True
        else:
            run_start = None
    mask = np.repeat(coasting[:, None], trace.n_axles, axis=1) & (v[:, None] > MIN_SPEED_KMH)
    rmse = float(np.sqrt(np.mean(creep[mask] ** 2))) if mask.any() else float("nan")
    return Channel("coasting_creep", "pct", creep, mask, rmse, {"samples": float(mask.sum())})


def channels(trace: Trace) -> dict[str, Channel]:
    """All three channels of the nominal model, keyed ``<name>_<unit>`` as in DESIGN §8."""
    out = {}
    for ch in (train_speed_balance(trace), adhesion_fit(trace), coasting_creep(trace)):
        out[f"{ch.name}_{ch.unit}"] = ch
    return out


def first_order(t: np.ndarray, u: np.ndarray, tc: np.ndarray) -> np.ndarray:
    """``u`` (samples x columns) through first-order lags ``tc dy/dt = u - y`` (one time constant
    per column, s; 0 passes the column through), exact for ``u`` linear between samples (the
    same reading of the log as the balance's trapezoid integral), starting at rest on ``u[0]``.
    One compiled pass over the samples (``recurrence.lag_pass``)."""
    u = np.asarray(u, dtype=np.float64)
    tc = np.broadcast_to(np.asarray(tc, dtype=np.float64), u.shape[1:])
    live = tc > 0.0
    tcs = np.where(live, tc, 1.0)
    dt = np.diff(t)
    a = np.exp(-dt[:, None] / tcs[None, :])  # (samples - 1, columns)
    slope = np.diff(u, axis=0) / dt[:, None]
    y = lag_pass(np.ascontiguousarray(u), np.ascontiguousarray(a),
                 np.ascontiguousarray(slope), np.ascontiguousarray(tcs))  # fmt: skip
    return np.where(live[None, :], y, u)

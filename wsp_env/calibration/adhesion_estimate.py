"""Adhesion from measured data (seed 000 §3): pressure -> brake torque -> adhesion force -> mu,
creepage from ground and axle speeds, critical points, and a Polach (Eq. 9) fit per axle.

Per axle ``i`` and sample:

* brake torque from the nominal linear law ``T = gain (p - p_th)^+`` (seed 000 Eqs. 3–6,
  ``TRACE_FORMAT.md``);
* the wheelset equation ``J domega/dt = F r - T`` solved for the adhesion force
  ``F = (T + J domega/dt) / r``, with ``domega/dt`` from a Savitzky–Golay derivative of the
  measured axle speed (robust to sensor noise; window ``smooth_s``);
* normal load: static load from the metadata (or ``m g / n``) plus the body's load transfer
  ``+- m a h / L`` on the leading / trailing bogie when CoG height and bogie spacing are given
  (seed 000 §3: "a simplified model of the vehicle"); ``a`` from ``a_train_mps2`` or ``-dV/dt``;
* ``mu = F / N`` (Eq. 7), creepage ``xi = (V - v_i) / V`` (Eq. 8), sliding speed ``DV = V - v_i``;
* **critical points**: where the creepage derivative changes sign (WSP turning points, at which
  the used adhesion equals the available one), plus the low-sliding points (0 < DV < 0.2 km/h)
  that carry the curve's initial slope; speeds below ``min_speed_kmh`` are dropped (seed 001:
  at low speed small slides give meaningless creepage);
* Eq. 9 fitted to the critical points by bounded least squares: ``mu0``, ``K``, ``K_rozv``
  (``DV`` in km/h, as in ``physics.adhesion``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from wsp_env.calibration.traces import Trace

G = 9.80665


@dataclass
class AxleAdhesion:
    """Per-sample estimates for one axle (arrays over the trace's samples)."""

    mu: np.ndarray
    creepage: np.ndarray
    sliding_kmh: np.ndarray
    force_N: np.ndarray
    normal_N: np.ndarray
    critical: np.ndarray  # indices of the critical points


@dataclass
class PolachFit:
    """Seed 000 Eq. 9 parameters of one axle (Table 4 layout) and the fit quality."""

    mu0: float
    K: float
    K_rozv: float
    rmse: float
    n_points: int


def _uniform_derivative(t: np.ndarray, y: np.ndarray, window_s: float) -> np.ndarray:
    """d y / d t with a Savitzky–Golay filter on a uniform resampling of ``t``."""
    dt = float(np.median(np.diff(t)))
    grid = np.arange(t[0], t[-1] + 0.5 * dt, dt)
    yg = np.interp(grid, t, y)
    win = max(5, round(window_s / dt) | 1)  # odd
    win = min(win, len(grid) if len(grid) % 2 else len(grid) - 1)
    if win <= 3:
        d = np.gradient(yg, dt)
    else:
        d = savgol_filter(yg, win, polyorder=2, deriv=1, delta=dt)
    return np.interp(t, grid, d)


def normal_loads(trace: Trace, decel: np.ndarray) -> np.ndarray:
    """(T, n_axles) normal loads in N: static (metadata) plus body load transfer if known."""
    veh = trace.vehicle
    n = trace.n_axles
    mass = float(veh["mass_kg"])
    loads = veh.get("axle_static_load_kN")
    static = np.asarray(loads, dtype=float) * 1e3 if loads else np.full(n, mass * G / n)
    out = np.tile(static, (len(decel), 1))
    h, L = veh.get("cog_height_m"), veh.get("bogie_centre_distance_m")
    if h and L and n % 2 == 0:
        dn = mass * decel * h / L  # front bogie gains, rear loses; shared by its axles
        half = n // 2
        out[:, :half] += dn[:, None] / half
        out[:, half:] -= dn[:, None] / half
    return np.maximum(out, 0.05 * static)


def estimate_adhesion(
    trace: Trace, smooth_s: float = 0.5, min_speed_kmh: float = 20.0
) -> list[AxleAdhesion]:
    """Seed 000 §3 estimation for every axle of ``trace``."""
    veh = trace.vehicle
    brake = veh.get("brake", {})
    gain = float(brake.get("torque_gain_Nm_per_bar", 0.0))
    p_th = float(brake.get("p_threshold_bar", 0.0))
    r = float(veh["wheel_radius_m"])
    inertia = float(veh.get("wheelset_inertia_kgm2", 0.0))
    t = trace.time_s
    v = trace.v_train_kmh / 3.6
    if "a_train_mps2" in trace.optional:
        decel = trace.optional["a_train_mps2"]
    else:
        decel = -_uniform_derivative(t, v, smooth_s)
    normal = normal_loads(trace, decel)
    out = []
    for i in range(trace.n_axles):
        wheel = trace.v_axle_kmh[:, i] / 3.6
        omega_dot = _uniform_derivative(t, wheel, smooth_s) / r
        torque = gain * np.maximum(0.0, trace.p_cyl_bar[:, i] - p_th)
        force = (torque + inertia * omega_dot) / r
        mu = force / normal[:, i]
        slide = v - wheel
        creep = np.where(v > 1.0, slide / np.maximum(v, 1.0), 0.0)
        braking = (torque > 0.05 * gain) & (trace.v_train_kmh > min_speed_kmh)
        dcreep = np.diff(creep)
        turning = np.flatnonzero(np.sign(dcreep[:-1]) * np.sign(dcreep[1:]) < 0) + 1
        low = np.flatnonzero((slide * 3.6 > 0.0) & (slide * 3.6 < 0.2))
        critical = np.unique(np.concatenate([turning, low]))
        critical = critical[braking[critical] & (mu[critical] > 0) & (creep[critical] >= 0)]
        out.append(AxleAdhesion(mu, creep, 3.6 * slide, force, normal[:, i], critical))
    return out


def eq9(xi: np.ndarray, dv_kmh: np.ndarray, mu0: float, K: float, k_rozv: float) -> np.ndarray:
    """Seed 000 Eq. 9 (DV in km/h): mu0 (1 - exp(-|K xi| / mu0 (1 + K_rozv |DV|))) / (...)."""
    d = 1.0 + k_rozv * np.abs(dv_kmh)
    return mu0 * (1.0 - np.exp(-np.abs(K * xi) / mu0 * d)) / d


def fit_polach(axle: AxleAdhesion) -> PolachFit:
    """Bounded least-squares fit of Eq. 9 to an axle's critical points."""
    idx = axle.critical
    xi, dv, mu = axle.creepage[idx], axle.sliding_kmh[idx], axle.mu[idx]
    if idx.size < 5:
        return PolachFit(float("nan"), float("nan"), float("nan"), float("nan"), int(idx.size))
    mu0_start = float(np.quantile(mu, 0.9))

    def resid(p: np.ndarray) -> np.ndarray:
        return eq9(xi, dv, *p) - mu

    sol = least_squares(
        resid,
        x0=[max(mu0_start, 0.02), 30.0, 0.02],
        bounds=([0.005, 0.5, 0.0], [1.0, 1e4, 1.0]),
        x_scale=[0.05, 30.0, 0.02],
    )
    rmse = float(np.sqrt(np.mean(sol.fun**2)))
    return PolachFit(float(sol.x[0]), float(sol.x[1]), float(sol.x[2]), rmse, int(idx.size))

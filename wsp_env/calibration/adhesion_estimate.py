"""Adhesion from measured data (seed 000 §3): pressure -> brake torque -> adhesion force -> mu,
creepage from ground and axle speeds, critical points, and a Polach (Eq. 9) fit.

Per axle ``i`` the seed's wheelset equation ``J domega/dt = F r - T`` is solved for the
adhesion force ``F``, with the brake torque from the nominal linear law
``T = gain (p - p_th)^+`` (seed 000 Eqs. 3–6, ``docs/trace_format.md``), the normal load from the
metadata (static, plus the load transfer: per axle if the metadata gives it, else the body's
``+- m a h / L`` on the leading / trailing bogie; ``normal_loads``), ``mu = F / N`` (Eq. 7),
creepage ``xi = (V - v_i) / V`` (Eq. 8) and sliding speed ``DV = V - v_i``.

**Critical points** (seed 000 §3, Fig. 4) are the samples where the creepage derivative changes
sign — the used adhesion equals the available one there — plus the low-sliding points
(``0 < DV < 0.2 km/h``, here at a sample *and* both neighbours: a wheel rolling with the
train, not one passing through on its way back from a slide) that carry the curve's initial
slope. At a critical point the creepage, hence the force, is stationary, which is what makes a
logged trace usable: a 10 Hz log cannot resolve a wheel that decelerates at 15 m/s² one tenth of
a second and accelerates the next, so the wheelset equation is not differentiated but
integrated over ``[t_k-1, t_k+1]`` with ``F`` constant there::

    F_k = ( mean T over [t_k-1, t_k+1] + J (omega_k+1 - omega_k-1) / (t_k+1 - t_k-1) ) / r

(the torque mean by the trapezoid rule). A turning point whose parabola vertex lies more than
``VERTEX_MAX`` of a sample from ``t_k`` is dropped: the force is not stationary across its window.
Speeds below ``min_speed_kmh`` are dropped (seed 001: at low speed small slides give meaningless
creepage).

**Fit** (Eq. 9: ``mu0``, ``K``, ``K_rozv``; ``DV`` in km/h as in ``physics.adhesion``): bounded
least squares, each point weighted by its *effective variance* (Orear 1982)
``sigma^2 = sigma_F^2 + (N df/dxi sigma_xi)^2``: the creepage of a point on the curve's steep
initial slope is known only to ``~ sqrt(2) sigma_v / V`` from noisy speed sensors, and on that
slope this is worth more force than the whole force error. ``sigma_F`` combines the inertia
term's sensor noise, the pressure noise and ``FORCE_REL_ERROR`` of the force (normal loads the
metadata cannot describe: bogie pitch). The weights follow the fitted curve's slope
(re-weighted ``REWEIGHT`` times). RMSEs are weighted the same way, in kN of a well-resolved
point.

**Recovery** (``fit_base_law``): on a contaminant that sliding removes (soap), the used adhesion
at a slide's turning point depends on the sliding power that came before it, as in the
simulator (seed 002 Eqs. 9–14). The base law can therefore blend Eq. 9 toward a recovered
curve with the filtered removed fraction, when the data call for it (BIC); W_lim and W_max come
from a grid, the recovered level is fitted.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import bilinear, lfilter, savgol_filter

from wsp_env.calibration.traces import Trace, noise_std

G = 9.80665
LOW_SLIDING_KMH = 0.2  # seed 000 §3: low-sliding critical points, 0 < DV < 0.2 km/h
VERTEX_MAX = 0.3  # samples: a turning point's parabola vertex must lie this close to t_k
TURNING_SIGNIFICANCE = 3.0  # a turning point's curvature against the sensor noise's
SPEED_RESOLUTION_KMH = 0.01  # floor of the speed-noise estimate (logger resolution)
FORCE_REL_ERROR = 0.02  # relative force error beyond sensor noise (unknown load distribution)
REWEIGHT = 2
CENSOR_SHARE = 0.5  # censored bounds weigh at most half as much as the critical points


@dataclass
class CriticalPoints:
    """Critical points (of one axle, or pooled), one entry per point.

    ``sample`` is the sample index in the trace, ``axle`` the axle index (0 = leading);
    ``position_m`` the distance the train has run; ``sigma_force_N`` / ``sigma_creepage`` are
    the standard errors of the force and creepage estimates (module docstring).
    """

    sample: np.ndarray
    axle: np.ndarray
    creepage: np.ndarray
    sliding_kmh: np.ndarray
    position_m: np.ndarray
    force_N: np.ndarray
    normal_N: np.ndarray
    decel_mps2: np.ndarray
    sigma_force_N: np.ndarray
    sigma_creepage: np.ndarray

    @property
    def mu(self) -> np.ndarray:
        return self.force_N / self.normal_N

    def __len__(self) -> int:
        return int(self.sample.size)

    def select(self, keep: np.ndarray) -> CriticalPoints:
        return CriticalPoints(*(getattr(self, f.name)[keep] for f in dataclasses.fields(self)))

    @staticmethod
    def concatenate(parts: list[CriticalPoints]) -> CriticalPoints:
        names = [f.name for f in dataclasses.fields(CriticalPoints)]
        return CriticalPoints(*(np.concatenate([getattr(p, n) for p in parts]) for n in names))


@dataclass
class PolachFit:
    """Seed 000 Eq. 9 parameters of one axle (Table 4 layout) and the fit quality."""

    mu0: float
    K: float
    K_rozv: float
    rmse: float  # weighted RMS residual of mu
    n_points: int


def _uniform_derivative(t: np.ndarray, y: np.ndarray, window_s: float) -> np.ndarray:
    """d y / d t by a Savitzky–Golay filter on a uniform resampling of ``t``."""
    dt = float(np.median(np.diff(t)))
    grid = np.arange(t[0], t[-1] + 0.5 * dt, dt)
    yg = np.interp(grid, t, y)
    win = max(5, round(window_s / dt) | 1)  # odd
    win = min(win, len(grid) if len(grid) % 2 else len(grid) - 1)
    if win <= 3:
        return np.interp(t, grid, np.gradient(yg, dt))
    return np.interp(t, grid, savgol_filter(yg, win, polyorder=2, deriv=1, delta=dt))


def train_deceleration(trace: Trace, smooth_s: float = 1.0) -> np.ndarray:
    """Train deceleration (m/s², positive when slowing): the logged ``a_train_mps2`` if
    present, else a Savitzky–Golay derivative of the (smooth) train speed."""
    if "a_train_mps2" in trace.optional:
        return np.asarray(trace.optional["a_train_mps2"], dtype=float)
    return -_uniform_derivative(trace.time_s, trace.v_train_kmh / 3.6, smooth_s)


def normal_loads(trace: Trace, decel: np.ndarray) -> np.ndarray:
    """(T, n_axles) normal loads in N: static (metadata) plus the quasi-static load transfer.

    The transfer is the metadata's ``axle_load_transfer_kN_per_mps2`` (body and bogie pitch per
    axle, N = N_static + k a) when given; else the body's ``+- m a h / L`` on the leading /
    trailing bogie from ``cog_height_m`` and ``bogie_centre_distance_m``, plus, where the
    metadata gives ``bogie_pivot_height_m`` and ``bogie_wheelbase_m``, each bogie's pitch
    (``bogie_pitch_kg``: ``+`` on its leading axle, ``-`` on its trailing one). Without a pivot
    height the bogie pitch is left to the calibration loop's ``load_transfer`` effect.
    The geometry describes one car (two two-axle bogies ``L`` apart); a vehicle of ``4 c``
    axles is read as a rake of ``c`` such cars of mass ``m / c`` each, every car body pitching
    on its own bogies (coupled coaches: the couplers carry the longitudinal force, not the
    body's pitch moment), so axles 1-2 of each car gain and 3-4 lose ``(m / c) a h / L / 2``.
    Any other axle count keeps the one-body reading (front half gains, rear half loses).
    """
    veh = trace.vehicle
    n = trace.n_axles
    mass = float(veh["mass_kg"])
    loads = veh.get("axle_static_load_kN")
    static = np.asarray(loads, dtype=float) * 1e3 if loads else np.full(n, mass * G / n)
    out = np.tile(static, (len(decel), 1))
    transfer = veh.get("axle_load_transfer_kN_per_mps2")
    h, L = veh.get("cog_height_m"), veh.get("bogie_centre_distance_m")
    if transfer is not None and len(transfer) == n:
        out += decel[:, None] * np.asarray(transfer, dtype=float)[None, :] * 1e3
    elif h and L and n % 4 == 0:
        cars = n // 4
        dn = (mass / cars) * decel * h / L / 2.0  # per axle of a car's leading / trailing bogie
        sign = np.tile([1.0, 1.0, -1.0, -1.0], cars)
        out += dn[:, None] * sign[None, :]
        pitch = bogie_pitch_kg(veh, mass / cars)
        if pitch:
            out += pitch * decel[:, None] * np.tile([1.0, -1.0], 2 * cars)[None, :]
    elif h and L and n % 2 == 0:
        dn = mass * decel * h / L  # front bogie gains, rear loses; shared by its axles
        half = n // 2
        out[:, :half] += dn[:, None] / half
        out[:, half:] -= dn[:, None] / half
    return np.maximum(out, 0.05 * static)


def bogie_pitch_kg(veh: dict[str, Any], car_mass_kg: float) -> float:
    """Each bogie's pitch from the metadata's geometry, in kg (N of load on its leading axle,
    off its trailing one, per m/s^2 of deceleration), or 0 without a pivot height and wheelbase.

    Quasi-static moments about a bogie's wheel-rail contacts: the body's share of the braking
    inertia (half the body's mass) enters at the pivot height ``h_p``, the bogie's own at its
    centre of gravity ``h_b``; the wheelbase ``w`` turns the moment into a load pair::

        k = ((m_car - 2 m_b) / 2 h_p + m_b h_b) / w

    (``m_b`` = ``bogie_mass_kg``, 0 when not given: the whole car's half then enters at the
    pivot)."""
    h_p, w = veh.get("bogie_pivot_height_m"), veh.get("bogie_wheelbase_m")
    if not (h_p and w):
        return 0.0
    m_b = float(veh.get("bogie_mass_kg") or 0.0)
    h_b = float(veh.get("bogie_cog_height_m") or 0.0)
    return float(((car_mass_kg - 2.0 * m_b) / 2.0 * h_p + m_b * h_b) / w)


def estimate_adhesion(trace: Trace, min_speed_kmh: float = 20.0) -> list[CriticalPoints]:
    """Seed 000 §3: the critical points of every axle of ``trace`` (module docstring)."""
    veh = trace.vehicle
    r = float(veh["wheel_radius_m"])
    torques = trace.brake_torque_Nm()
    gains = trace.axle_torque_gains()
    inertia = float(veh.get("wheelset_inertia_kgm2", 0.0))
    t = trace.time_s
    v = trace.v_train_kmh / 3.6
    decel = train_deceleration(trace)
    normal = normal_loads(trace, decel)
    x_m = trace.distance_m()
    sigma_v = max(noise_std(trace.v_train_kmh), SPEED_RESOLUTION_KMH) / 3.6
    sigma_p = noise_std(trace.p_cyl_bar)
    out = []
    for i in range(trace.n_axles):
        wheel = trace.v_axle_kmh[:, i] / 3.6
        torque = torques[:, i]
        gain = float(gains[i])
        slide = v - wheel
        creep = np.where(v > 1.0, slide / np.maximum(v, 1.0), 0.0)
        # turning points whose parabola vertex (uniform-grid form) lies near the sample
        d1 = np.zeros_like(creep)
        d2 = np.zeros_like(creep)
        d1[1:-1] = 0.5 * (creep[2:] - creep[:-2])
        d2[1:-1] = creep[2:] - 2.0 * creep[1:-1] + creep[:-2]
        dcreep = np.diff(creep)
        turning = np.zeros(creep.size, dtype=bool)
        turning[1:-1] = np.sign(dcreep[:-1]) * np.sign(dcreep[1:]) < 0
        turning &= np.abs(d1) < VERTEX_MAX * np.abs(d2)
        # and a real extremum, not sensor noise: the second difference of the creepage must
        # stand out of the noise's (std sqrt(6) sigma_xi) by TURNING_SIGNIFICANCE
        sigma_xi = np.sqrt(2.0) * sigma_v / np.maximum(v, 1.0)
        turning &= np.abs(d2) > TURNING_SIGNIFICANCE * np.sqrt(6.0) * sigma_xi
        in_band = (slide * 3.6 > 0.0) & (slide * 3.6 < LOW_SLIDING_KMH)
        low = np.zeros(creep.size, dtype=bool)
        low[1:-1] = in_band[1:-1] & in_band[:-2] & in_band[2:]
        k = np.flatnonzero(turning | low)
        # the wheelset equation integrated over [t_k-1, t_k+1] with F constant there
        span = t[k + 1] - t[k - 1]
        torque_mean = (
            (torque[k - 1] + torque[k]) * (t[k] - t[k - 1])
            + (torque[k] + torque[k + 1]) * (t[k + 1] - t[k])
        ) / (2.0 * span)
        fk = (torque_mean + inertia * (wheel[k + 1] - wheel[k - 1]) / (r * span)) / r
        sigma_f = np.hypot(
            inertia * np.sqrt(2.0) * sigma_v / (r * r * span), gain * sigma_p / r
        )  # fmt: skip
        pts = CriticalPoints(
            sample=k,
            axle=np.full(k.size, i),
            creepage=creep[k],
            sliding_kmh=3.6 * slide[k],
            position_m=x_m[k],
            force_N=fk,
            normal_N=normal[k, i],
            decel_mps2=decel[k],
            sigma_force_N=np.hypot(sigma_f, FORCE_REL_ERROR * np.abs(fk)),
            sigma_creepage=sigma_xi[k],
        )
        keep = (
            (torque[k] > 0.05 * gain)
            & (v[k] * 3.6 > min_speed_kmh)
            & (pts.force_N > 0)
            & (pts.creepage >= 0)
        )
        out.append(pts.select(keep))
    return out


# ---- censored evidence: what rolling wheels prove about the rail ----------------------------

CENSOR_BIN_M = 25.0  # one bound per axle and this much rail: the binding (largest) one
CENSOR_MIN_TORQUE = 0.3  # of the axle's largest torque: a real brake demand, not a release
CENSOR_ROLL_KMH = 0.5  # rolling: |V - v| below this (or 4 sensor sigmas) here and either side
CENSOR_CALM_S = 2.0  # and no slide of its own for this long (a recovering rail is not the law's)


@dataclass
class CensoredPoints:
    """Braked samples where a wheel rolled with the train: the rail offered *at least* the force
    the wheel transmitted (``force_N``), whatever the law says — a lower bound on the available
    adhesion at that rail position and speed (issue 11, item 3). Where the rail gets better and
    the wheels stop sliding, these are the only adhesion evidence left."""

    sample: np.ndarray
    axle: np.ndarray
    position_m: np.ndarray
    speed_kmh: np.ndarray
    force_N: np.ndarray
    normal_N: np.ndarray
    decel_mps2: np.ndarray
    sigma_force_N: np.ndarray

    def __len__(self) -> int:
        return int(self.sample.size)


def censored_points(trace: Trace, min_speed_kmh: float = 20.0) -> CensoredPoints:
    """Per axle and ``CENSOR_BIN_M`` of rail, the braked rolling sample with the largest used
    adhesion: ``F = (T - J a / r) / r`` (the wheelset equation of a wheel decelerating with the
    train), the brake torque at least ``CENSOR_MIN_TORQUE`` of the axle's largest, the wheel
    within ``max(CENSOR_ROLL_KMH, 4 sigma)`` of the train speed at the sample and both
    neighbours and for ``CENSOR_CALM_S`` before, above ``min_speed_kmh``."""
    veh = trace.vehicle
    r = float(veh["wheel_radius_m"])
    inertia = float(veh.get("wheelset_inertia_kgm2", 0.0))
    torques = trace.brake_torque_Nm()
    gains = trace.axle_torque_gains()
    t = trace.time_s
    v_kmh = trace.v_train_kmh
    decel = train_deceleration(trace)
    normal = normal_loads(trace, decel)
    x_m = trace.distance_m()
    sigma_p = noise_std(trace.p_cyl_bar)
    parts = []
    for i in range(trace.n_axles):
        torque = torques[:, i]
        slide = v_kmh - trace.v_axle_kmh[:, i]
        sigma_kmh = max(noise_std(trace.v_axle_kmh[:, i]), noise_std(v_kmh), SPEED_RESOLUTION_KMH)
        band = np.abs(slide) < max(CENSOR_ROLL_KMH, 4.0 * sigma_kmh)
        rolling = np.zeros_like(band)
        rolling[1:-1] = band[1:-1] & band[:-2] & band[2:]
        # not within CENSOR_CALM_S after a slide of its own: the rail under a wheel that has
        # just slid is recovering (seed 002 Eqs. 9-14), a level the degraded law need not reach
        slid_at = np.where(~band, t, -np.inf)
        last_slide = np.maximum.accumulate(slid_at)
        rolling &= t - last_slide > CENSOR_CALM_S
        top = float(torque.max()) if torque.size else 0.0
        keep = rolling & (torque > CENSOR_MIN_TORQUE * top) & (v_kmh > min_speed_kmh) & (top > 0)
        k = np.flatnonzero(keep)
        if k.size == 0:
            continue
        force = (torque[k] - inertia * decel[k] / r) / r
        mu = force / normal[k, i]
        bins = np.floor(x_m[k] / CENSOR_BIN_M).astype(int)
        best: dict[int, int] = {}
        for j, b in enumerate(bins):
            if b not in best or mu[j] > mu[best[b]]:
                best[b] = j
        sel = np.array(sorted(best.values()), dtype=int)
        kk = k[sel]
        sigma = np.hypot(float(gains[i]) * sigma_p / r, FORCE_REL_ERROR * np.abs(force[sel]))
        parts.append((kk, np.full(kk.size, i), x_m[kk], v_kmh[kk], force[sel], normal[kk, i],
                      decel[kk], sigma))  # fmt: skip
    if not parts:
        empty = np.zeros(0)
        return CensoredPoints(empty.astype(int), empty.astype(int), *[empty] * 6)
    cols = [np.concatenate(c) for c in zip(*parts, strict=True)]
    return CensoredPoints(*cols)


PEAK_CREEP_GRID = np.logspace(-4.0, -0.3, 48)


PEAK_SPEED_NODES = 40  # more speeds than this: the peak interpolated between as many nodes


def eq9_peak(speed_kmh: np.ndarray, mu0: float, K: float, k_rozv: float) -> np.ndarray:
    """The largest adhesion Eq. 9 offers at each train speed (over the creepage, ``DV = xi V``).

    The peak is a smooth, monotone function of the speed: for many speeds (the censored bounds
    of a long stop, evaluated at every step of a fit) it is computed at ``PEAK_SPEED_NODES``
    evenly spaced speeds and interpolated linearly (on a 40-200 km/h span, nodes 4 km/h apart:
    within 0.1 % of the direct maximum)."""
    return eq9_peaks(speed_kmh, np.array([[mu0, K, k_rozv]], dtype=float))[0]


def eq9_peaks(speed_kmh: np.ndarray, params: np.ndarray) -> np.ndarray:
    """``eq9_peak`` for a batch of laws at once: ``params`` ``(B, 3)`` (mu0, K, K_rozv per
    row), the result ``(B, len(speed_kmh))``; each row the same numbers as ``eq9_peak`` with
    that row's parameters (the same element-wise operations, broadcast)."""
    v = np.asarray(speed_kmh, dtype=float)
    p = np.asarray(params, dtype=float)[:, :, None, None]
    xi = PEAK_CREEP_GRID[None, :]
    at = (
        v
        if v.size <= PEAK_SPEED_NODES
        else np.linspace(float(v.min()), float(v.max()), PEAK_SPEED_NODES)
    )
    peak = eq9(xi, xi * at[:, None], p[:, 0], p[:, 1], p[:, 2]).max(axis=-1)
    if v.size <= PEAK_SPEED_NODES:
        return peak
    return np.stack([np.interp(v, at, row) for row in peak])


def pooled_points(trace: Trace, min_speed_kmh: float = 20.0) -> CriticalPoints:
    """Every axle's critical points in one set (``axle`` tells them apart)."""
    return CriticalPoints.concatenate(estimate_adhesion(trace, min_speed_kmh))


def eq9(xi: np.ndarray, dv_kmh: np.ndarray, mu0: float, K: float, k_rozv: float) -> np.ndarray:
    """Seed 000 Eq. 9 (DV in km/h): mu0 (1 - exp(-|K xi| / mu0 (1 + K_rozv |DV|))) / (...)."""
    d = 1.0 + k_rozv * np.abs(dv_kmh)
    return mu0 * (1.0 - np.exp(-np.abs(K * xi) / mu0 * d)) / d


def eq9_slope(
    xi: np.ndarray,
    dv_kmh: np.ndarray,
    mu0: float,
    K: float,
    k_rozv: float,
    half_width: np.ndarray | float | None = None,
) -> np.ndarray:
    """d eq9 / d xi at fixed train speed (``DV = xi V``, so DV moves with xi): the derivative,
    or with ``half_width`` the secant over ``[xi - w, xi + w]`` (clipped at zero creepage) —
    the slope a creepage known to ``+- w`` sees on a curved law."""
    w = np.maximum(1e-6, 1e-3 * np.abs(xi)) if half_width is None else half_width
    nonzero = np.abs(xi) > 1e-9
    speed_kmh = np.where(nonzero, dv_kmh / np.where(nonzero, xi, 1.0), 0.0)
    hi = xi + w
    lo = np.maximum(xi - w, 0.0) if half_width is not None else xi - w
    up = eq9(hi, hi * speed_kmh, mu0, K, k_rozv)
    down = eq9(lo, lo * speed_kmh, mu0, K, k_rozv)
    return (up - down) / (hi - lo)


class BatchedDifferences:
    """A residual function of a batch of parameter vectors, for ``least_squares``: ``one(p)``
    is the residuals at one vector (the optimiser's own evaluations), and the object is the
    map-like ``workers`` through which scipy's finite-difference Jacobian (``'2-point'``, its
    steps and quotients unchanged) evaluates its ``n_params`` perturbed vectors: here all in one
    batched call instead of one call each (the Jacobian was 80 % of a fit's evaluations). For
    real steps only (``jac='2-point'`` or ``'3-point'``, not ``'cs'``): it ignores scipy's
    ``fun`` and evaluates the vectors itself."""

    def __init__(self, residuals: Callable[[np.ndarray], np.ndarray]) -> None:
        self.residuals = residuals

    def one(self, p: np.ndarray) -> np.ndarray:
        return self.residuals(np.asarray(p, dtype=float)[None])[0]

    def __call__(self, fun: Callable, xs: Any) -> list[np.ndarray]:
        rows = self.residuals(np.array([np.asarray(x, dtype=float) for x in xs]))
        return list(rows)


@dataclass
class LawFit:
    """A pooled Eq. 9 law (plus extensions) fitted to critical points."""

    params: np.ndarray  # mu0, K, K_rozv, [mu_rec / mu0 with recovery], then the extensions'
    residual_kN: np.ndarray  # measured - model force per point
    sigma_kN: np.ndarray  # effective standard error per point
    at_bound: bool  # an extension parameter ran to its bound (not identified)
    n_law: int = 3  # parameters of the law itself (4 with recovery)
    # censored bounds the law violates: used force - the law's peak force where > 0, else 0
    censored_kN: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    censored_sigma_kN: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))

    @property
    def rmse(self) -> float:
        """Weighted RMS residual (kN): ``sqrt(sum (r/s)^2 / sum 1/s^2)`` over the critical
        points and the censored bounds the law violates."""
        w = 1.0 / self.sigma_kN**2
        hit = self.censored_kN > 0.0
        wc = 1.0 / self.censored_sigma_kN[hit] ** 2
        num = np.sum(w * self.residual_kN**2) + np.sum(wc * self.censored_kN[hit] ** 2)
        return float(np.sqrt(num / (np.sum(w) + np.sum(wc))))

    @property
    def chi2(self) -> float:
        return float(
            np.sum((self.residual_kN / self.sigma_kN) ** 2)
            + np.sum((self.censored_kN / np.maximum(self.censored_sigma_kN, 1e-12)) ** 2)
        )


BASE_START, BASE_LOW, BASE_HIGH = [0.1, 30.0, 0.02], [0.005, 0.5, 0.0], [1.0, 1e4, 1.0]
# recovery: mu_rec / mu0 from 1 to 2 (seed 002 Table 5: 0.10 / 0.08 = 1.25; a rail whose
# friction more than doubles under sliding is not a recovering contaminant but a cleaner rail,
# which the per-axle and position effects describe)
GAIN_STARTS, GAIN_LOW, GAIN_HIGH = (1.25, 1.6), 1.0, 2.0


def fit_law(
    pts: CriticalPoints,
    factor_of: Callable[[np.ndarray], np.ndarray] | None = None,
    n_extra: int = 0,
    start: list[float] | None = None,
    low: list[float] | None = None,
    high: list[float] | None = None,
    removed: np.ndarray | None = None,
    law_start: np.ndarray | None = None,
    censored: CensoredPoints | None = None,
    censored_factor_of: Callable[[np.ndarray], np.ndarray] | None = None,
    reweight: int = REWEIGHT,
) -> LawFit | None:
    """Eq. 9 for every point, times ``factor_of(extra_params)`` (a per-point multiplier on
    the force, ``None``: 1), by effective-variance weighted least squares (module docstring).

    ``removed``: per point, the filtered fraction of contaminant removed (``removed_fraction``);
    the law then blends toward the recovered curve, seed 002 Eq. 12 as the simulator reads it
    (``physics.adhesion``): ``mu = (1 - K_W) eq9(mu0) + K_W eq9(mu_rec)`` — the recovered curve
    is the same law at ``mu_rec = g mu0``, its sliding-speed fall-off kept (sliding still costs
    the wheel that slides, as in the simulator) — with ``g`` a fourth law parameter in [1, 2]
    (fitted from two starts: the blend makes the problem multimodal). ``law_start``: the law's
    parameters to start from (one start; an extension starts from the fitted base law).
    ``censored`` (``censored_points``): lower bounds — the law's peak at each bound's speed,
    times ``censored_factor_of`` (the extensions' factor there), must reach the force a rolling
    wheel transmitted; a shortfall enters the least squares as a one-sided residual (weighted
    by the bound's error, at most ``CENSOR_SHARE`` of the points' weight in all).
    ``reweight``: how often the weights follow the fitted slope (fewer: a quicker screening fit).
    Returns ``None`` with fewer than 5 points."""
    if len(pts) < 5:
        return None
    force = pts.force_N / 1e3
    normal = pts.normal_N / 1e3
    n_law = 3 if removed is None else 4
    rec_low, rec_high = ([], []) if removed is None else ([GAIN_LOW], [GAIN_HIGH])
    lo = np.array(BASE_LOW + rec_low + list(low or []), dtype=float)
    hi = np.array(BASE_HIGH + rec_high + list(high or []), dtype=float)
    scale = np.concatenate([[0.05, 30.0, 0.02], [0.25] * (n_law - 3), np.ones(n_extra)])

    n_cens = 0 if censored is None else len(censored)
    if n_cens:
        c_force = censored.force_N / 1e3
        c_normal = censored.normal_N / 1e3
        c_sigma = censored.sigma_force_N / 1e3
        # many bounds on one rail must not outvote the points: cap their total weight
        share = CENSOR_SHARE * len(pts) / max(n_cens, 1)
        c_sigma = c_sigma / np.sqrt(min(share, 1.0))

    # every function below takes a batch of parameter vectors, P (B, n_params), and returns
    # (B, ...): the finite-difference Jacobian's B = n_params evaluations run as one
    # (``BatchedDifferences``), each row the same numbers as a call with that row alone
    def shortfall(P: np.ndarray) -> np.ndarray:
        if not n_cens:
            return np.zeros((len(P), 0))
        peak = eq9_peaks(censored.speed_kmh, P[:, :3]) * c_normal
        if censored_factor_of is not None:
            peak = peak * np.stack([censored_factor_of(p[n_law:]) for p in P])
        return np.maximum(c_force - peak, 0.0)

    def model(P: np.ndarray) -> np.ndarray:
        mu0, K, k_rozv = P[:, 0:1], P[:, 1:2], P[:, 2:3]
        mu = eq9(pts.creepage, pts.sliding_kmh, mu0, K, k_rozv)
        if removed is not None:
            recovered = eq9(pts.creepage, pts.sliding_kmh, P[:, 3:4] * mu0, K, k_rozv)
            mu = (1.0 - removed) * mu + removed * recovered
        f = mu * normal
        if factor_of is None:
            return f
        return f * np.stack([factor_of(p[n_law:]) for p in P])

    if law_start is not None:
        starts = [list(np.clip(law_start[:n_law], lo[:n_law], hi[:n_law]))]
    else:
        mu0 = max(float(np.quantile(pts.mu, 0.9)), 0.02)
        gains = GAIN_STARTS if removed is not None else (None,)
        starts = [[mu0, *BASE_START[1:]] + ([] if g is None else [g]) for g in gains]
    best: LawFit | None = None
    for law0 in starts:
        p0 = np.array(law0 + list(start or []), dtype=float)
        sigma = pts.sigma_force_N / 1e3
        for _ in range(reweight + 1):
            s = sigma

            def residuals(P: np.ndarray, s: np.ndarray = s) -> np.ndarray:
                r = (model(P) - force) / s
                return np.concatenate([r, shortfall(P) / c_sigma], axis=1) if n_cens else r

            batched = BatchedDifferences(residuals)
            sol = least_squares(batched.one, p0, bounds=(lo, hi), x_scale=scale, workers=batched)
            p0 = sol.x
            mult = factor_of(p0[n_law:]) if factor_of is not None else 1.0
            # secant over the creepage's +-2 sigma: a point whose creepage is lost in the sensor
            # noise may sit anywhere on the steep initial slope (the degraded law's slope, also
            # with recovery: the recovered curve rises as steeply)
            slope = eq9_slope(pts.creepage, pts.sliding_kmh, *p0[:3], 2.0 * pts.sigma_creepage)
            slope = slope * normal * mult
            sigma = np.hypot(pts.sigma_force_N / 1e3, slope * pts.sigma_creepage)
        span = hi - lo
        hit = (np.abs(p0 - lo) < 1e-4 * span) | (np.abs(p0 - hi) < 1e-4 * span)
        fit = LawFit(p0, force - model(p0[None])[0], s, bool(hit[n_law:].any()), n_law)
        if n_cens:
            fit.censored_kN, fit.censored_sigma_kN = shortfall(p0[None])[0], c_sigma
        if best is None or fit.chi2 < best.chi2:
            best = fit
    return best


# seed 002 Table 5: the removal fraction's second-order lag (Eq. 11)
RECOVERY_TAU_S, RECOVERY_ZETA = 0.1, 1.0
# W_lim and W_max - W_lim (kW of sliding power) tried for the recovery; none = no recovery
RECOVERY_GRID_KW = tuple(
    (w, span) for w in (0.5, 1.0, 2.0, 4.0, 8.0) for span in (2.0, 5.0, 10.0, 20.0)
)
RECOVERY_MIN_DELTA_BIC = 10.0
RECOVERY_NONE = 1e-6  # a cell whose removed fraction stays under this at every point is no recovery
RECOVERY_FULL_FITS = 4  # of the 20 grid cells, after a quick screening (``fit_base_law``)


def removed_fraction(trace: Trace, w_lim_kW: float, w_span_kW: float) -> np.ndarray:
    """(T, n_axles) filtered fraction of contaminant removed, seed 002 Eqs. 10–11 and 13.

    The specific sliding power is read as watts (``physics.adhesion``, basis ``sliding_power``):
    ``W = F DV`` with the brake force ``gain (p - p_th)^+ / r`` standing for the adhesion force
    of a sliding wheel; ``K_W = clip((W - W_lim) / (W_max - W_lim), 0, 1)`` goes through the
    second-order lag of Eq. 11 (Table 5: tau 0.1 s, zeta 1), discretised by Tustin (Eq. 13) at
    the trace's median sample period.
    """
    force = trace.brake_torque_Nm() / float(trace.vehicle["wheel_radius_m"])
    sliding = np.maximum(trace.v_train_kmh[:, None] - trace.v_axle_kmh, 0.0) / 3.6
    k_w = np.clip((force * sliding / 1e3 - w_lim_kW) / w_span_kW, 0.0, 1.0)
    dt = float(np.median(np.diff(trace.time_s)))
    wn = 1.0 / RECOVERY_TAU_S
    b, a = bilinear([wn * wn], [1.0, 2.0 * RECOVERY_ZETA * wn, wn * wn], fs=1.0 / dt)
    return lfilter(b, a, k_w, axis=0)


@dataclass
class BaseLaw:
    """The adhesion channel's nominal law: Eq. 9, with recovery where the data call for it."""

    fit: LawFit
    recovery_kW: tuple[float, float] | None  # (W_lim, W_max - W_lim), or None
    removed: np.ndarray | None  # per point, the filtered removed fraction
    cleaning: bool = False  # the law carries the cleaning along the train (last parameter)


def fit_base_law(
    trace: Trace, pts: CriticalPoints, censored: CensoredPoints | None = None
) -> BaseLaw | None:
    """Eq. 9 alone, or with recovery (``RECOVERY_GRID_KW``; the best by chi-square) if that
    lowers the BIC by ``RECOVERY_MIN_DELTA_BIC`` (three more parameters: W_lim, W_max,
    mu_rec / mu0). No bar on the RMSE cut: a strong effect elsewhere in the data (per-axle
    adhesion, say) dilutes the cut that recovery alone brings, not its evidence."""
    plain = fit_law(pts, censored=censored)
    if plain is None:
        return None
    base = BaseLaw(plain, None, None)
    # the grid is screened with quick fits (the weights not re-followed) and the best
    # RECOVERY_FULL_FITS cells fitted in full (neighbouring cells fit alike and the quick
    # ranking among them is not the full one): an 8-axle trace with 2000 points took 12 s
    screened: list[tuple[float, tuple[float, float], np.ndarray]] = []
    for w_lim, w_span in RECOVERY_GRID_KW:
        removed = removed_fraction(trace, w_lim, w_span)[pts.sample, pts.axle]
        if not np.any(removed > RECOVERY_NONE):  # no slide reached W_lim: the plain law, and
            continue  # an unidentified gain that only slows the fit (a wet stop: 12 of 20 cells)
        quick = fit_law(pts, removed=removed, censored=censored, reweight=0)
        if quick is not None:
            screened.append((quick.chi2, (w_lim, w_span), removed))
    best: BaseLaw | None = None
    for _, grid, removed in sorted(screened, key=lambda q: q[0])[:RECOVERY_FULL_FITS]:
        fit = fit_law(pts, removed=removed, censored=censored)
        if fit is not None and (best is None or fit.chi2 < best.fit.chi2):
            best = BaseLaw(fit, grid, removed)
    n = len(pts)
    if best is not None:
        dbic = n * np.log(best.fit.chi2 / plain.chi2) + 3 * np.log(n)
        if dbic < -RECOVERY_MIN_DELTA_BIC:
            base = best
    if trace.n_axles < 2:
        return base
    # cleaning along the train (DESIGN §3, seed 000 Table 4, seed 002 Fig. 8): one more parameter
    cleaned = fit_law(
        pts, cleaning_factor(pts.axle, trace.n_axles), 1, [0.1], [0.0], [CLEANING_MAX],
        base.removed, None, censored, cleaning_factor(censored.axle, trace.n_axles)
        if censored is not None else None,
    )  # fmt: skip
    if cleaned is not None and not cleaned.at_bound:
        dbic = n * np.log(cleaned.chi2 / base.fit.chi2) + np.log(n)
        if dbic < -RECOVERY_MIN_DELTA_BIC:
            return BaseLaw(cleaned, base.recovery_kW, base.removed, cleaning=True)
    return base


CLEANING_MAX = 3.0  # the last axle's rail at most 4x the first's (contaminated -> clean soap)


def cleaning_factor(axle: np.ndarray, n_axles: int) -> Callable[[np.ndarray], np.ndarray]:
    """The rail the axles behind see, cleaned by those ahead: a friction factor
    ``1 + c (1 - exp(-3 j / (n - 1)))`` on axle ``j`` (0 = leading), rising fastest behind the
    first axles and levelling off along a long train; ``c`` the rear's gain (fitted, >= 0)."""
    j = np.asarray(axle, dtype=float) / max(n_axles - 1, 1)
    shape = (1.0 - np.exp(-3.0 * j)) / (1.0 - np.exp(-3.0))

    def factor_of(p: np.ndarray) -> np.ndarray:
        return 1.0 + p[-1] * shape

    return factor_of


def fit_polach(points: CriticalPoints) -> PolachFit:
    """Eq. 9 fitted to one axle's critical points (seed 000 Table 4)."""
    fit = fit_law(points)
    if fit is None:
        return PolachFit(float("nan"), float("nan"), float("nan"), float("nan"), len(points))
    mu0, K, k_rozv = (float(x) for x in fit.params[:3])
    return PolachFit(mu0, K, k_rozv, fit.rmse / float(np.mean(points.normal_N / 1e3)), len(points))

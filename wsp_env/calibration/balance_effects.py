"""The train-speed balance channel's candidate effects: force, lag and ground-speed fits.

Regressors in the balance channel enter linearly: an extra retarding force ``dF(t) = -c phi(t)``
changes the predicted speed by ``+c/M int phi dt``, so the least-squares coefficient ``c`` of the
regressor ``1/M int phi dt`` gives the force as ``-c phi``. A pressure lag and a ground-speed lag
are fitted on a grid of lags (``LAG_GRID_S``, ``SPEED_LAG_GRID_S``); the wheels' own reading of
the brake's lag (``wheel_lag``) is judged by ``wheel_verdict`` and the wheels' check between the
two lags by ``ground_speed_trail_s``. Pairs of one-parameter force effects are fitted jointly
(``pair_terms``, ``fit_lag_with``).

The logger's own timing (a lag under ``plausibility.LAG_MIN_S``) is part of the nominal model:
``timing_signatures``, ``timing_verdict`` and ``lag_beyond_timing`` judge a force effect or a
longer lag against it. ``step_columns`` and ``params_from`` give an added effect's regressors and
its parameters from their coefficients (the joint refit of ``balance_retest`` and the timing's).

The loop that uses them, and why, is described in ``discovery``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from wsp_env.calibration.plausibility import LAG_MIN_S, implausible, negligible
from wsp_env.calibration.residuals import (
    anchor_se_kmh,
    anchored,
    balance_intervals,
    balance_mask,
    brake_force_N,
    coasting_creep,
    first_order,
    masked_cumdiff,
    masked_cumtrapz,
    resistance_N,
)
from wsp_env.calibration.selection import MIN_DELTA_BIC, MIN_REDUCTION, Candidate, Step, bic
from wsp_env.calibration.traces import Trace
from wsp_env.calibration.wheel_lag import RESOLUTION_S, WheelLag

G = 9.80665


# ---- linear fits on the balance channel ------------------------------------------------------


def fit_linear(
    trace: Trace, residual: np.ndarray, mask: np.ndarray, regressors: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Least squares of the balance residual on ``regressors``, anchored as the residual is."""
    X = np.stack([anchored(r, trace.time_s, mask) for r in regressors], axis=1)
    coef, *_ = np.linalg.lstsq(X[mask], residual[mask], rcond=None)
    return coef, residual - X @ coef


def _balance_regressor(trace: Trace, force: np.ndarray) -> np.ndarray:
    """Change of the predicted speed (km/h) for an extra retarding force ``force`` (N)."""
    valid = balance_intervals(trace)
    change = 3.6 * masked_cumtrapz(trace.time_s, force, valid) / float(trace.vehicle["mass_kg"])
    return anchored(change, trace.time_s, balance_mask(trace))


def _fit_gradient(trace, residual, mask):
    mass = float(trace.vehicle["mass_kg"])
    reg = _balance_regressor(trace, np.full(len(trace.time_s), mass * G))
    coef, res = fit_linear(trace, residual, mask, [reg])
    return {"gradient_permille": -1000.0 * coef[0]}, res


def _fit_resistance(trace, residual, mask):
    v = trace.v_train_kmh / 3.6
    regs = [_balance_regressor(trace, np.ones_like(v)), _balance_regressor(trace, v * v)]
    coef, res = fit_linear(trace, residual, mask, regs)
    return {"delta_a_N": -coef[0], "delta_c_N_per_mps2": -coef[1]}, res


def _fit_resistance_factor(trace, residual, mask):
    """The metadata's running resistance ``R(V) = A + B V + C V^2`` off by a factor (one
    parameter: a resistance formula taken from another train, a rake longer than declared);
    ``None`` when the metadata gives no resistance to scale."""
    nominal = resistance_N(trace, trace.v_train_kmh / 3.6)
    if not np.any(nominal > 0.0):
        return None
    coef, res = fit_linear(trace, residual, mask, [_balance_regressor(trace, nominal)])
    return {"factor": 1.0 - coef[0]}, res


def _fit_pad_scale(trace, residual, mask):
    brake = brake_force_N(trace).sum(axis=1)
    coef, res = fit_linear(trace, residual, mask, [_balance_regressor(trace, brake)])
    return {"scale": 1.0 - coef[0]}, res


def _fit_pad(trace, residual, mask):
    brake = brake_force_N(trace).sum(axis=1)
    dv = trace.v_train_kmh / 3.6 - 100.0 / 3.6
    regs = [_balance_regressor(trace, brake), _balance_regressor(trace, brake * dv)]
    coef, res = fit_linear(trace, residual, mask, regs)
    return {"scale": 1.0 - coef[0], "slope_per_mps": -coef[1]}, res


def _demand_fraction(trace: Trace) -> np.ndarray:
    p_max = float(trace.vehicle.get("brake", {}).get("p_max_bar", 0.0)) or float(
        trace.p_cyl_bar.max()
    )
    if "p_demand_bar" in trace.optional:
        return trace.optional["p_demand_bar"] / p_max
    return trace.p_cyl_bar.max(axis=1) / p_max  # envelope of the cylinders: the demand shape


def _fit_unmeasured(trace, residual, mask):
    coef, res = fit_linear(
        trace, residual, mask, [_balance_regressor(trace, _demand_fraction(trace))]
    )
    return {"force_at_full_demand_N": -coef[0]}, res


# the pressure-lag grid (s): from below the reporting threshold to a few tenths beyond the
# longest plausible pipe and cylinder filling behind the sensor
LAG_GRID_S = np.arange(0.02, 0.81, 0.02)
# the pressure time constant's grid (s): a cylinder filling through a restriction
TIME_CONSTANT_GRID_S = np.arange(0.04, 0.81, 0.04)
# both together, a dead time then a first-order lag: a coarser grid of (dead time, constant)
BOTH_GRID = [(float(d), float(c)) for d in np.arange(0.04, 0.41, 0.04)
             for c in np.arange(0.05, 0.61, 0.05)]  # fmt: skip
# the ground-speed lag grid (s): a held GPS fix, filtered, up to about a second and a half
SPEED_LAG_GRID_S = np.arange(0.02, 1.51, 0.02)

# A pressure lag's shape: (dead time s, first-order time constant s). Its parameters are
# ``lag_s`` (the dead time) and / or ``time_constant_s``; either missing is zero.
Shape = tuple[float, float]


def lag_shape(params: dict[str, float]) -> Shape:
    """(dead time, time constant) of a pressure-lag effect's parameters."""
    return float(params.get("lag_s", 0.0)), float(params.get("time_constant_s", 0.0))


def _as_shape(tau: float | Shape) -> Shape:
    return (float(tau), 0.0) if np.isscalar(tau) else (float(tau[0]), float(tau[1]))


def lag_signatures(
    trace: Trace, taus: np.ndarray | list[float] | list[Shape] = LAG_GRID_S
) -> tuple[np.ndarray, list[np.ndarray]]:
    """The un-lagged brake force's balance regressor and, for each lag, how the balance
    residual changes when the brake force follows the logged pressure that much later: the
    residual *less* that column is what is left (coefficient 1 for the lag alone; with a
    pad-friction scale s in the model its coefficient is s). A lag is a dead time (s) or a
    ``Shape`` (dead time, then a first-order time constant: ``first_order``). The brake force
    and its regressor are computed once for the whole grid."""
    t = trace.time_s
    brake = brake_force_N(trace).sum(axis=1)
    nominal = _balance_regressor(trace, brake)
    shapes = [_as_shape(tau) for tau in taus]
    delayed = np.stack([np.interp(t - d, t, brake, left=0.0) for d, _ in shapes], axis=1)
    tcs = np.array([c for _, c in shapes])
    if np.any(tcs > 0.0):
        delayed = first_order(t, delayed, tcs)
    sigs = [nominal - _balance_regressor(trace, delayed[:, j]) for j in range(len(shapes))]
    return nominal, sigs


def _fit_shapes(
    trace: Trace, residual: np.ndarray, mask: np.ndarray, shapes: list[Shape]
) -> tuple[Shape, np.ndarray]:
    """The shape on ``shapes`` that leaves the least squared balance residual, and that
    residual (the lag alone: no free gain)."""
    best: tuple[float, Shape, np.ndarray] = (math.inf, (0.0, 0.0), residual)
    for shape, sig in zip(shapes, lag_signatures(trace, shapes)[1], strict=True):
        res = residual - sig
        rss = float(np.sum(res[mask] ** 2))
        if rss < best[0]:
            best = (rss, shape, res)
    return best[1], best[2]


def shape_params(shape: Shape) -> dict[str, float]:
    """A shape's effect parameters: ``lag_s`` where it has a dead time, ``time_constant_s``
    where it has a first-order lag."""
    out = {}
    if shape[0] > 0.0 or shape[1] <= 0.0:
        out["lag_s"] = float(shape[0])
    if shape[1] > 0.0:
        out["time_constant_s"] = float(shape[1])
    return out


def fit_lag(
    trace: Trace, residual: np.ndarray, mask: np.ndarray
) -> tuple[dict[str, float], np.ndarray]:
    """A dead time on its grid: the brake force follows the logged pressure ``tau`` later
    (replacing the force by its lagged version changes the prediction by the integral of
    (lagged - brake) / M: no free gain, the lag alone)."""
    shape, res = _fit_shapes(trace, residual, mask, [(float(x), 0.0) for x in LAG_GRID_S])
    return shape_params(shape), res


def fit_time_constant(
    trace: Trace, residual: np.ndarray, mask: np.ndarray
) -> tuple[dict[str, float], np.ndarray]:
    """A first-order lag on its grid: the brake force follows the logged pressure through
    ``tc dF/dt = F_logged - F`` (a cylinder filling through a restriction), no dead time."""
    shapes = [(0.0, float(x)) for x in TIME_CONSTANT_GRID_S]
    shape, res = _fit_shapes(trace, residual, mask, shapes)
    return shape_params(shape), res


def fit_lag_and_time_constant(
    trace: Trace, residual: np.ndarray, mask: np.ndarray
) -> tuple[dict[str, float], np.ndarray]:
    """A dead time followed by a first-order lag, both on the grid ``BOTH_GRID`` (two
    parameters: it must earn the second against either shape alone, ``discovery``)."""
    shape, res = _fit_shapes(trace, residual, mask, BOTH_GRID)
    return shape_params(shape), res


# the pressure-lag candidates' fits by shape: the wheels name a shape (``wheel_lag``)
LAG_FITS = {
    "dead_time": fit_lag,
    "first_order": fit_time_constant,
    "both": fit_lag_and_time_constant,
}
LAG_FIT_SET = (fit_lag, fit_time_constant, fit_lag_and_time_constant)


# The wheels measure the brake's lag behind the logged pressure on their own clock
# (``wheel_lag``: the ground speed's timing does not enter, an averaging logger shifts wheels
# and pressures alike). On 50 clean independent traces it read -0.04 to +0.04 s (the logger's
# sampling), under a 0.2 s lag 0.13-0.21 s: a lag it measures at WHEEL_LAG_MIN_S or more,
# WHEEL_LAG_Z standard errors from 0, is the brake's; one it measures below WHEEL_LAG_MIN_S by
# as many standard errors says the brake is on time, whatever the balance's lag is (then a
# late ground speed).
WHEEL_LAG_MIN_S = RESOLUTION_S
WHEEL_LAG_Z = 3.0


# The wheels name the lag's shape and measure its size (``wheel_lag``). A dead time is taken at
# their value: the balance cannot tell a late brake from the ground speed's own lag (a GPS
# held between fixes trails by half a fix period), and on independent traces with a 0.2 s dead
# time the balance's own best was 0.16-0.30 s where the wheels' reading gives a 9 % median
# error. A first-order lag the wheels read short: 0.14-0.30 s for a 0.3 s constant (their
# smoothest force blurs the filter's tail into the logger's own averaging), up to 2.2 times
# short, never long; there the balance, which integrates the brake force over the whole stop,
# sets the constant between their value and ``WHEEL_WINDOW`` times it. A wider window lets the
# balance take the ground speed's own lag into the brake's (at 2.5 the power study's 0.3 s
# constants read a median 47 % long, at 2 a median 20 %, with the cut 4 points less).
WHEEL_WINDOW = 2.0


def wheel_window(wheels: WheelLag) -> list[Shape]:
    """The shapes the balance may fit for a lag the wheels measured (above): their dead time
    itself, or their time constant up to ``WHEEL_WINDOW`` times it on its grid; for both
    shapes at once, their dead time with that window of constants."""
    if wheels.shape == "dead_time":
        return [(float(wheels.lag_s), 0.0)]
    dead, v = (0.0, float(wheels.lag_s)) if wheels.shape == "first_order" else (
        float(wheels.lag_s), float(wheels.time_constant_s))  # fmt: skip
    grid = TIME_CONSTANT_GRID_S
    vals = sorted({v, *(float(x) for x in grid if v <= x <= v * WHEEL_WINDOW)})
    return [(dead, x) for x in vals]


def fit_lag_in(
    trace: Trace, residual: np.ndarray, mask: np.ndarray, shapes: list[Shape]
) -> tuple[dict[str, float], np.ndarray]:
    """The best of the given lag shapes on the balance (``wheel_window``'s), the lag alone."""
    shape, res = _fit_shapes(trace, residual, mask, shapes)
    return shape_params(shape), res


def wheel_verdict(wheels: WheelLag | None) -> str:
    """``"late"``, ``"on_time"`` or ``"unknown"`` (no slides, or not clear either way). Both
    shapes at once are late by their own test: they beat each shape alone, no lag included, by
    ``wheel_lag.BOTH_Z`` standard errors, with each part at least ``WHEEL_LAG_MIN_S``."""
    if wheels is None:
        return "unknown"
    if wheels.shape == "both":
        return "late"
    if wheels.lag_s >= WHEEL_LAG_MIN_S and wheels.lag_s >= WHEEL_LAG_Z * wheels.se_s:
        return "late"
    if wheels.lag_s + WHEEL_LAG_Z * wheels.se_s < WHEEL_LAG_MIN_S:
        return "on_time"
    return "unknown"


def fit_lag_at(
    trace: Trace, residual: np.ndarray, params: dict[str, float]
) -> tuple[dict[str, float], np.ndarray]:
    """The balance with the brake force following the logged pressure through the lag of
    ``params`` (``lag_s`` and / or ``time_constant_s``: a given shape, not a grid's best)."""
    sig = lag_signatures(trace, [lag_shape(params)])[1][0]
    return dict(params), residual - sig


def fit_lag_with(
    trace: Trace,
    residual: np.ndarray,
    mask: np.ndarray,
    partner: np.ndarray | None,
    taus: np.ndarray | list[float] | list[Shape] = LAG_GRID_S,
) -> tuple[Shape, float, np.ndarray]:
    """A pressure lag fitted jointly with one force effect: on the lag grid, the partner's
    coefficient by least squares with the lag's signature fixed. ``partner``: the force
    effect's balance regressor (``pair_terms``), ``None`` for the pad friction, whose scale
    acts on the brake force as it reaches the rail, i.e. the lagged one: the model is then
    ``s x brake(t - tau)``. ``taus``: dead times or ``Shape``s. Returns (the shape, the
    partner's coefficient in the convention of ``pair_terms``, new residual)."""
    best: tuple[float, Shape, float, np.ndarray] = (math.inf, (0.0, 0.0), 0.0, residual)
    nominal, sigs = lag_signatures(trace, taus)
    for tau, sig in zip(taus, sigs, strict=True):
        if partner is None:
            # residual = nominal - s lagged (+ noise): s = -coefficient, c = 1 - s
            lagged = nominal - sig
            coef, res = fit_linear(trace, residual - nominal, mask, [lagged])
            c = 1.0 + float(coef[0])
        else:
            coef, res = fit_linear(trace, residual - sig, mask, [partner])
            c = float(coef[0])
        rss = float(np.sum(res[mask] ** 2))
        if rss < best[0]:
            best = (rss, _as_shape(tau), c, res)
    return best[1], best[2], best[3]


def _fit_sensor_balance(trace, residual, mask):
    """Ground speed logged as (1 + s) V: the predicted logged speed scales its change by 1 + s.

    In the balance channel this looks like scaling every force; the coasting channel tells the
    two apart (a speed scale error shows as the same apparent creep on every coasting axle), so
    a scale that the coasting data contradicts is rejected (``None``).
    """
    # residual = predicted - measured drop = drop - (1 + s) drop = -s x (true speed drop)
    drop = -masked_cumdiff(trace.v_train_kmh, balance_intervals(trace))
    coef, res = fit_linear(trace, residual, mask, [drop])
    s = -coef[0]
    coasting = coasting_creep(trace)
    if coasting.mask.any():
        observed = coasting.residual[coasting.mask]
        se = observed.std() / math.sqrt(observed.size) + 0.02
        if abs(observed.mean() - 100.0 * s / (1.0 + s)) > 3.0 * se:
            return None
    return {"speed_scale_error": s}, res


def _speed_lag_signature(predicted_drop: np.ndarray, t: np.ndarray, tau: float) -> np.ndarray:
    """How the balance residual changes when the logged ground speed is the true one ``tau``
    late: the logged drop is the true drop ``tau`` earlier, so the residual (predicted less
    logged drop) grows by ``drop(t) - drop(t - tau)`` — the exact shift, not its first order
    ``tau a`` (at a few tenths of a second a braking train's deceleration changes within the
    lag). The true drop is taken as the model's ``predicted_drop``, not as the logged speed
    shifted: that one carries the speed's noise, and a shifted copy of the noise would fit
    the residual's own noise (a spurious edge over every other candidate)."""
    return predicted_drop - np.interp(t - tau, t, predicted_drop, left=predicted_drop[0])


# how far (standard errors, ``anchor_se_kmh``) the balance's starting speed may be off when a
# ground-speed lag is fitted
ANCHOR_Z = 2.0


def fit_sensor_lag(
    trace: Trace, residual: np.ndarray, mask: np.ndarray
) -> tuple[dict[str, float], np.ndarray] | None:
    """Ground speed logged ``tau`` late: a grid over the lag (``_speed_lag_signature``) on the
    drop the current model predicts (the residual plus the logged drop).

    On a stop that starts braking soon after the record does, a lag's signature (``tau a``
    from the brake application on) is much like the whole balance shifted by an error in its
    starting speed — a 1-2 Hz GPS on a 1-2 s lead-in leaves one or a few fixes to anchor on.
    So the lag is chosen with such a shift fitted alongside, bounded by ``ANCHOR_Z`` standard
    errors of the anchor (``anchor_se_kmh``); the residual returned is the lag's alone."""
    t = trace.time_s
    predicted = residual - masked_cumdiff(trace.v_train_kmh, balance_intervals(trace))
    bound = ANCHOR_Z * anchor_se_kmh(trace, mask)

    def rss_shifted(res: np.ndarray) -> float:
        shift = float(np.clip(res[mask].mean(), -bound, bound))
        return float(np.sum((res[mask] - shift) ** 2))

    best = (rss_shifted(residual), 0.0, residual)
    for tau in SPEED_LAG_GRID_S:
        res = residual - anchored(_speed_lag_signature(predicted, t, float(tau)), t, mask)
        rss = rss_shifted(res)
        if rss < best[0]:
            best = (rss, float(tau), res)
    if best[1] <= 0.0:  # a lag cannot lead
        return None
    return {"speed_lag_s": best[1]}, best[2]


# the wheels' check on a lag: samples where every axle runs within this fraction of the fastest
# (no axle sliding, every creep small), and the fewest such samples it needs
ROLLING_SPREAD = 0.03
ROLLING_MIN_SAMPLES = 30
# a ground speed leading the wheels by more than this is no timing: the creep model misfits
TRAIL_PLAUSIBLE_S = 0.5


def ground_speed_trail_s(trace: Trace) -> tuple[float, float] | None:
    """How far the logged ground speed trails the wheel speeds (s), with its standard error.

    The balance channel cannot tell a ground-speed lag from a pressure lag: either one makes
    the predicted speed fall ``tau a`` ahead of the logged one. The wheel speeds can: they
    are on time with the train (up to their creep), so a ground speed logged late reads
    ``tau a`` above the fastest wheel while the train decelerates at ``a``, and a brake force
    that follows the pressure late leaves wheels and ground speed in step. On the samples
    where every axle rolls within ``ROLLING_SPREAD`` of the fastest (no slide), the gap
    ``V - max v_i`` is fitted as ``c0 + trail a + k a V``: ``c0`` the sensors' offsets, the
    last term the fastest wheel's creep (its slip speed grows with the force and the speed),
    ``a`` the deceleration the logged pressures give. The error is inflated for the
    residuals' correlation (a GPS speed interpolated between fixes). ``None``: too few
    rolling samples or no deceleration to speak of."""
    wheel = trace.v_axle_kmh.max(axis=1)
    rolling = balance_mask(trace) & (trace.v_axle_kmh.min(axis=1) > (1 - ROLLING_SPREAD) * wheel)
    if rolling.sum() < ROLLING_MIN_SAMPLES:
        return None
    v = trace.v_train_kmh
    force = brake_force_N(trace).sum(axis=1) + resistance_N(trace, v / 3.6)
    decel = 3.6 * force / float(trace.vehicle["mass_kg"])  # km/h per s
    X = np.stack([np.ones(rolling.sum()), decel[rolling], decel[rolling] * v[rolling] / 100], 1)
    y = (v - wheel)[rolling]
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    e = y - X @ coef
    dof = max(len(y) - 3, 1)
    cov = np.linalg.pinv(X.T @ X) * float(e @ e) / dof
    rho = float(np.clip(np.corrcoef(e[1:], e[:-1])[0, 1], 0.0, 0.95)) if len(e) > 3 else 0.0
    se = math.sqrt(max(float(cov[1, 1]), 0.0) * (1 + rho) / (1 - rho))
    return float(coef[1]), se


# one-parameter force effects that can also act together (a gradient *and* weaker pads)
def pair_terms(trace: Trace) -> dict[str, tuple[np.ndarray, Callable[[float], dict[str, float]]]]:
    mass = float(trace.vehicle["mass_kg"])
    brake = brake_force_N(trace).sum(axis=1)
    return {
        "gradient": (
            _balance_regressor(trace, np.full(len(trace.time_s), mass * G)),
            lambda c: {"gradient_permille": -1000.0 * c},
        ),
        "pad_friction": (_balance_regressor(trace, brake), lambda c: {"scale": 1.0 - c}),
        "unmeasured_brake_force": (
            _balance_regressor(trace, _demand_fraction(trace)),
            lambda c: {"force_at_full_demand_N": -c},
        ),
    }


PAIR_NAMES = {
    "gradient": "gradient",
    "pad_friction": "pad friction",
    "unmeasured_brake_force": "unmeasured brake force",
    "pressure_lag": "pressure lag",
}


CANDIDATES_BALANCE = [
    Candidate("gradient", "gradient", "train_speed_balance_kmh", 1, _fit_gradient),
    Candidate(
        "running resistance x factor",
        "running_resistance",
        "train_speed_balance_kmh",
        1,
        _fit_resistance_factor,
    ),
    Candidate(
        "running resistance", "running_resistance", "train_speed_balance_kmh", 2, _fit_resistance
    ),
    Candidate("pad friction", "pad_friction", "train_speed_balance_kmh", 1, _fit_pad_scale),
    Candidate(
        "speed-dependent pad friction", "pad_friction", "train_speed_balance_kmh", 2, _fit_pad
    ),
    Candidate(
        "unmeasured brake force",
        "unmeasured_brake_force",
        "train_speed_balance_kmh",
        1,
        _fit_unmeasured,
    ),
    Candidate("pressure lag", "pressure_lag", "train_speed_balance_kmh", 1, fit_lag),
    Candidate(
        "pressure time constant", "pressure_lag", "train_speed_balance_kmh", 1, fit_time_constant
    ),
    Candidate(
        "pressure lag and time constant",
        "pressure_lag",
        "train_speed_balance_kmh",
        2,
        fit_lag_and_time_constant,
    ),
    Candidate("ground-speed scale", "sensor", "train_speed_balance_kmh", 1, _fit_sensor_balance),
    Candidate("ground-speed lag", "sensor", "train_speed_balance_kmh", 1, fit_sensor_lag),
]


# ---- an added effect's balance regressors (the re-test's joint refit and the timing's) -------


def step_columns(trace: Trace, step: Step, nominal_residual: np.ndarray) -> list[np.ndarray] | None:
    """The balance regressors of an added effect (``None``: chosen on another channel);
    ``nominal_residual``: the balance channel's residual under the nominal model."""
    if step.channel != "train_speed_balance_kmh":
        return None
    mass = float(trace.vehicle["mass_kg"])
    brake = brake_force_N(trace).sum(axis=1)
    v = trace.v_train_kmh / 3.6
    drop = -masked_cumdiff(trace.v_train_kmh, balance_intervals(trace))
    if step.category == "gradient":
        return [_balance_regressor(trace, np.full(len(v), mass * G))]
    if step.category == "running_resistance":
        if "factor" in step.parameters:
            return [_balance_regressor(trace, resistance_N(trace, v))]
        return [_balance_regressor(trace, np.ones_like(v)), _balance_regressor(trace, v * v)]
    if step.category == "pad_friction":
        cols = [_balance_regressor(trace, brake)]
        if "slope_per_mps" in step.parameters:
            cols.append(_balance_regressor(trace, brake * (v - 100.0 / 3.6)))
        return cols
    if step.category == "unmeasured_brake_force":
        return [_balance_regressor(trace, _demand_fraction(trace))]
    if step.category == "pressure_lag":
        # the lag's signature, negated: its coefficient is -1 when the lag is all there is
        return [-lag_signatures(trace, [lag_shape(step.parameters)])[1][0]]
    if "speed_scale_error" in step.parameters:
        return [drop]
    if "speed_lag_s" in step.parameters:  # on the nominal model's predicted drop
        predicted = nominal_residual + drop
        return [_speed_lag_signature(predicted, trace.time_s, step.parameters["speed_lag_s"])]
    return None


def params_from(step: Step, coef: np.ndarray) -> dict[str, float]:
    """An effect's parameters from its columns' joint least-squares coefficients."""
    c = [float(x) for x in coef]
    cat, p = step.category, step.parameters
    if cat == "gradient":
        return {"gradient_permille": -1000.0 * c[0]}
    if cat == "running_resistance":
        if "factor" in p:
            return {"factor": 1.0 - c[0]}
        return {"delta_a_N": -c[0], "delta_c_N_per_mps2": -c[1]}
    if cat == "pad_friction":
        out = {"scale": 1.0 - c[0]}
        if "slope_per_mps" in p:
            out["slope_per_mps"] = -c[1]
        return out
    if cat == "unmeasured_brake_force":
        return {"force_at_full_demand_N": -c[0]}
    if "speed_scale_error" in p:
        return {"speed_scale_error": -c[0]}
    return dict(p)  # a lag (pressure or ground speed) keeps its grid value


# ---- the logger's own timing: part of the nominal model, not an effect ----------------------

# Lags inside the logging's timing resolution (``plausibility.LAG_MIN_S``: the log period, a
# ground speed held and averaged, a GPS receiver's own latency) are not reported, but they
# are in every trace: on clean independent traces the balance's best explanation is often a
# 0.08-0.14 s lag, and a force effect that absorbs part of that lag's signature (a resistance,
# a gradient: during the stop a lag looks like a constant force) was then taken in its place.
# So a force effect must earn its place against that timing: fitted jointly with the best
# sub-resolution lag (pressure or ground speed, whichever fits), it must cut the RMSE the
# timing alone leaves by ``MIN_REDUCTION`` and keep a reportable size.
TIMING_GRID_S = LAG_GRID_S[LAG_GRID_S < LAG_MIN_S - 1e-9]


def timing_signatures(trace: Trace, residual: np.ndarray, mask: np.ndarray) -> list[np.ndarray]:
    """The balance residual's change for each sub-resolution lag (``TIMING_GRID_S``) of the
    brake force and of the ground speed (anchored; subtract to apply), and no lag at all."""
    t = trace.time_s
    predicted = residual - masked_cumdiff(trace.v_train_kmh, balance_intervals(trace))
    sigs = [np.zeros_like(residual)]
    sigs += list(lag_signatures(trace, TIMING_GRID_S)[1])
    sigs += [anchored(_speed_lag_signature(predicted, t, float(tau)), t, mask)
             for tau in TIMING_GRID_S]  # fmt: skip
    return sigs


def _timing_alone(residual: np.ndarray, mask: np.ndarray, timing: list[np.ndarray]) -> float:
    """The balance's RMSE with the best sub-resolution lag (``timing_signatures``) applied."""
    rss = min(float(np.sum((residual - sig)[mask] ** 2)) for sig in timing)
    return math.sqrt(rss / int(mask.sum()))


def _against_timing(
    trace: Trace,
    residual: np.ndarray,
    mask: np.ndarray,
    timing: list[np.ndarray],
    columns: list[np.ndarray],
) -> tuple[float, float, np.ndarray]:
    """(RMSE the timing alone leaves, RMSE with ``columns`` fitted jointly with the timing,
    the columns' coefficients there)."""
    best: tuple[float, np.ndarray] = (math.inf, np.zeros(len(columns)))
    for sig in timing:
        coef, res = fit_linear(trace, residual - sig, mask, columns)
        rss = float(np.sum(res[mask] ** 2))
        if rss < best[0]:
            best = (rss, coef)
    joint = math.sqrt(best[0] / int(mask.sum()))
    return _timing_alone(residual, mask, timing), joint, best[1]


def lag_beyond_timing(
    residual: np.ndarray, mask: np.ndarray, timing: list[np.ndarray], rmse_with_lag: float
) -> str | None:
    """Why a fitted lag (alone or with a force effect, leaving ``rmse_with_lag``) is not told
    from the logging's own timing, or ``None``: it must cut what the best sub-resolution lag
    leaves by ``MIN_REDUCTION / 2`` (half the usual bar: the two share their signature's
    shape, so what a longer lag cuts beyond the timing is its length's evidence alone)."""
    alone = _timing_alone(residual, mask, timing)
    if rmse_with_lag > (1.0 - 0.5 * MIN_REDUCTION) * alone:
        return (
            f"a lag under the logging's {LAG_MIN_S:g} s resolution leaves {alone:.3f} km/h, "
            f"this one {rmse_with_lag:.3f}: not told from the logger's own timing"
        )
    return None


def timing_verdict(
    trace: Trace,
    residual: np.ndarray,
    mask: np.ndarray,
    timing: list[np.ndarray],
    steps: list[Step],
) -> str | None:
    """Why force effects (``steps``, one or a pair) do not earn their place against the
    logger's timing (``_against_timing``), or ``None`` when they do."""
    cols = [step_columns(trace, st, residual) for st in steps]
    if any(c is None for c in cols):
        return None
    flat = [x for c in cols for x in c if c is not None]
    alone, joint, coef = _against_timing(trace, residual, mask, timing, flat)
    n = int(mask.sum())
    dbic = bic(joint**2 * n, n, len(flat)) - bic(alone**2 * n, n, 0)
    if joint > (1.0 - MIN_REDUCTION) * alone or dbic > -MIN_DELTA_BIC:
        return (
            f"with the logging's own timing (a lag under {LAG_MIN_S:g} s) fitted alongside, it "
            f"cuts the balance from {alone:.3f} to only {joint:.3f} km/h"
        )
    start = 0
    for st, c in zip(steps, cols, strict=True):
        assert c is not None
        params = params_from(st, coef[start : start + len(c)])
        start += len(c)
        why = negligible(st.category, params, trace) or implausible(st.category, params, trace)
        if why:
            return f"with the logging's own timing fitted alongside: {why}"
    return None

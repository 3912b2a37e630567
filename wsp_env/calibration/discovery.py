"""Effect discovery: which physical effect, missing from the nominal model, explains a residual.

Each candidate effect extends the model of one equation-error channel (``residuals.py``) with
a few parameters. For each candidate the parameters are fitted by least squares on that
channel's samples and scored by the Bayesian information criterion
``BIC = n ln(RSS / n) + k ln(n)``; the best candidate is added only if it lowers the BIC by
more than ``MIN_DELTA_BIC`` *and* cuts the channel's RMSE by at least ``MIN_REDUCTION`` *and*
the channel's RMSE stood above ``NOISE_FACTOR`` times its noise floor. Then the loop repeats
on what is left, until nothing qualifies.

Channels and their candidates (categories of DESIGN §8):

* train-speed balance — ``gradient`` (constant force ``M g theta``), ``running_resistance``
  (``dA + dC V^2``), ``pad_friction`` (brake force x ``(k0 + k1 (V - 100 km/h))``),
  ``unmeasured_brake_force`` (a force following the brake demand), ``pressure_lag`` (the brake
  force follows the logged pressure ``tau`` later), ``sensor`` (ground-speed scale error);
* coasting creep — ``wheel_radius`` (one radius error per axle), ``sensor`` (one scale error for
  the ground speed, seen by every axle alike);
* adhesion fit — ``adhesion_per_axle`` (a friction factor per axle), ``load_transfer`` (bogie
  pitch: leading axles +k a, trailing -k a), ``adhesion_position`` (a friction factor per
  quarter of the stopping distance).

Regressors in the balance channel enter linearly: an extra retarding force ``dF(t) = -c phi(t)``
changes the predicted speed by ``+c/M int phi dt``, so the least-squares coefficient ``c`` of the
regressor ``1/M int phi dt`` gives the force as ``-c phi``.

Pairs of one-parameter force effects (gradient, pad friction, unmeasured brake force) are also
fitted jointly, so that two effects acting together are not absorbed by one two-parameter
effect of another shape; a pair qualifies only if each term earns its place (the pair beats
either term alone by ``MIN_REDUCTION``).

Choice: the channel with the largest relative RMSE cut goes first; on it, candidates whose
remaining error lies within half a noise floor of the best count as equally good, and the one
with the fewest parameters wins — a constant force is a gradient before it is a running
resistance with a spare term (logged samples are strongly correlated, so the BIC's penalty
alone would let a spare parameter through).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from wsp_env.calibration.adhesion_estimate import eq9, estimate_adhesion
from wsp_env.calibration.residuals import (
    MIN_SPEED_KMH,
    _cumtrapz,
    balance_intervals,
    brake_force_N,
    channels,
    masked_cumdiff,
    masked_cumtrapz,
)
from wsp_env.calibration.traces import Trace

G = 9.80665
MIN_DELTA_BIC = 10.0
MIN_REDUCTION = 0.2
NOISE_FACTOR = 2.0
MAX_EFFECTS = 4
UNEXPLAINED_FACTOR = 3.0


@dataclass
class Candidate:
    name: str
    category: str
    channel: str
    n_params: int
    fit: Callable[[Trace, np.ndarray, np.ndarray], tuple[dict[str, float], np.ndarray]]


@dataclass
class Step:
    name: str
    category: str
    channel: str
    parameters: dict[str, float]
    before: float
    after: float
    delta_bic: float

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "category": self.category,
            "parameters": self.parameters,
            "channel": self.channel,
            "before": self.before,
            "after": self.after,
            "delta_bic": self.delta_bic,
        }


@dataclass
class Result:
    errors_before: dict[str, float]
    errors_after: dict[str, float]
    added: list[Step] = field(default_factory=list)
    considered: list[dict[str, Any]] = field(default_factory=list)
    # channels still well above their noise floor once nothing more qualifies: an effect the
    # library does not hold ("other"), reported rather than forced onto a wrong category
    unexplained: list[dict[str, float | str]] = field(default_factory=list)


# ---- linear fits on the balance channel ------------------------------------------------------


def _linear(
    residual: np.ndarray, mask: np.ndarray, regressors: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    X = np.stack([r[mask] for r in regressors], axis=1)
    coef, *_ = np.linalg.lstsq(X, residual[mask], rcond=None)
    return coef, residual - np.stack(regressors, axis=1) @ coef


def _balance_regressor(trace: Trace, force: np.ndarray) -> np.ndarray:
    """Change of the predicted speed (km/h) for an extra retarding force ``force`` (N)."""
    valid = balance_intervals(trace)
    return 3.6 * masked_cumtrapz(trace.time_s, force, valid) / float(trace.vehicle["mass_kg"])


def _fit_gradient(trace, residual, mask):
    mass = float(trace.vehicle["mass_kg"])
    reg = _balance_regressor(trace, np.full(len(trace.time_s), mass * G))
    coef, res = _linear(residual, mask, [reg])
    return {"gradient_permille": -1000.0 * coef[0]}, res


def _fit_resistance(trace, residual, mask):
    v = trace.v_train_kmh / 3.6
    regs = [_balance_regressor(trace, np.ones_like(v)), _balance_regressor(trace, v * v)]
    coef, res = _linear(residual, mask, regs)
    return {"delta_a_N": -coef[0], "delta_c_N_per_mps2": -coef[1]}, res


def _fit_pad_scale(trace, residual, mask):
    brake = brake_force_N(trace).sum(axis=1)
    coef, res = _linear(residual, mask, [_balance_regressor(trace, brake)])
    return {"scale": 1.0 - coef[0]}, res


def _fit_pad(trace, residual, mask):
    brake = brake_force_N(trace).sum(axis=1)
    dv = trace.v_train_kmh / 3.6 - 100.0 / 3.6
    regs = [_balance_regressor(trace, brake), _balance_regressor(trace, brake * dv)]
    coef, res = _linear(residual, mask, regs)
    return {"scale": 1.0 - coef[0], "slope_per_mps": -coef[1]}, res


def _demand_fraction(trace: Trace) -> np.ndarray:
    p_max = float(trace.vehicle.get("brake", {}).get("p_max_bar", 0.0)) or float(
        trace.p_cyl_bar.max()
    )
    if "p_demand_bar" in trace.optional:
        return trace.optional["p_demand_bar"] / p_max
    return trace.p_cyl_bar.max(axis=1) / p_max  # envelope of the cylinders: the demand shape


def _fit_unmeasured(trace, residual, mask):
    coef, res = _linear(residual, mask, [_balance_regressor(trace, _demand_fraction(trace))])
    return {"force_at_full_demand_N": -coef[0]}, res


def _fit_lag(trace, residual, mask):
    """Grid over the lag; the brake force follows the logged pressure ``tau`` later."""
    brake = brake_force_N(trace).sum(axis=1)
    base = _balance_regressor(trace, brake)
    t = trace.time_s
    best = (math.inf, 0.0, residual)
    for tau in np.arange(0.02, 0.61, 0.02):
        lagged = np.interp(t - tau, t, brake, left=0.0)
        # replacing the force by its lagged version changes the prediction by (lagged - brake)
        # a retarding force changed by (lagged - brake) raises the residual by its integral / M
        res = residual + (_balance_regressor(trace, lagged) - base)  # no free gain: the lag alone
        rss = float(np.sum(res[mask] ** 2))
        if rss < best[0]:
            best = (rss, float(tau), res)
    return {"lag_s": best[1]}, best[2]


def _fit_sensor_balance(trace, residual, mask):
    """Ground speed logged as (1 + s) V: the predicted logged speed scales its change by 1 + s.

    In the balance channel this looks like scaling every force; the coasting channel tells the
    two apart (a speed scale error shows as the same apparent creep on every coasting axle), so
    a scale that the coasting data contradicts is rejected (``None``).
    """
    # residual = predicted - measured drop = drop - (1 + s) drop = -s x (true speed drop)
    drop = -masked_cumdiff(trace.v_train_kmh, balance_intervals(trace))
    coef, res = _linear(residual, mask, [drop])
    s = -coef[0]
    coasting = channels(trace)["coasting_creep_pct"]
    if coasting.mask.any():
        observed = coasting.residual[coasting.mask]
        se = observed.std() / math.sqrt(observed.size) + 0.02
        if abs(observed.mean() - 100.0 * s / (1.0 + s)) > 3.0 * se:
            return None
    return {"speed_scale_error": s}, res


def _fit_sensor_lag(trace, residual, mask):
    """Ground speed logged ``tau`` late: the logged speed trails the true one by ``tau a``."""
    measured_drop = -masked_cumdiff(trace.v_train_kmh, balance_intervals(trace))
    predicted_drop = residual + measured_drop  # km/h (residual = predicted - measured drop)
    decel_kmh_s = np.gradient(predicted_drop, trace.time_s)
    # measured drop(t) = true drop(t - tau) ~ true drop(t) - tau a(t): residual ~ tau a(t)
    coef, res = _linear(residual, mask, [decel_kmh_s])
    if coef[0] <= 0.0:  # a lag cannot lead
        return None
    return {"speed_lag_s": float(coef[0])}, res


# one-parameter force effects that can also act together (a gradient *and* weaker pads)
def _pair_terms(trace: Trace) -> dict[str, tuple[np.ndarray, Callable[[float], dict[str, float]]]]:
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
}


# ---- coasting creep ------------------------------------------------------------------------


def _fit_radius(trace, residual, mask):
    res = residual.copy()
    params = {}
    for i in range(residual.shape[1]):
        m = mask[:, i]
        offset = float(residual[m, i].mean()) if m.any() else 0.0
        res[:, i] = residual[:, i] - offset
        # apparent creep 100 (V - v/(1+e)) / V ~ 100 e / (1 + e)
        params[f"axle_{i + 1}_radius_error"] = offset / (100.0 - offset)
    return params, res


def _fit_sensor_coasting(trace, residual, mask):
    offset = float(residual[mask].mean()) if mask.any() else 0.0
    return {"speed_scale_error": offset / 100.0}, residual - offset


# ---- adhesion fit --------------------------------------------------------------------------


def _adhesion_data(trace: Trace):
    axles = estimate_adhesion(trace, min_speed_kmh=MIN_SPEED_KMH)
    brake = brake_force_N(trace)
    decel = -np.gradient(trace.v_train_kmh / 3.6, trace.time_s)
    if "a_train_mps2" in trace.optional:
        decel = trace.optional["a_train_mps2"]
    rows = []
    for i, a in enumerate(axles):
        braked = brake[:, i] > 0.05 * max(brake.max(), 1e-9)
        idx = a.critical[braked[a.critical]]
        rows.append((i, idx, a))
    return rows, decel


N_POSITION_SEGMENTS = 4


def _fit_adhesion(trace, per_axle: bool, load_transfer: bool, position: bool = False):
    """One Eq. 9 law for all axles (+ the chosen extensions), fitted to the critical points."""
    rows, decel = _adhesion_data(trace)
    n_axles = trace.n_axles
    # bogie pitch sign: first axle of each consecutive pair leads
    lead = np.array([1.0 if i % 2 == 0 else -1.0 for i in range(n_axles)])
    x_m = _cumtrapz(trace.time_s, trace.v_train_kmh / 3.6)  # distance run
    edges = np.linspace(0.0, x_m[-1], N_POSITION_SEGMENTS + 1)
    xi = np.concatenate([a.creepage[idx] for _, idx, a in rows])
    dv = np.concatenate([a.sliding_kmh[idx] for _, idx, a in rows])
    force = np.concatenate([a.force_N[idx] for _, idx, a in rows]) / 1e3
    normal = np.concatenate([a.normal_N[idx] for _, idx, a in rows])
    axle = np.concatenate([np.full(idx.size, i) for i, idx, _ in rows])
    acc = np.concatenate([decel[idx] for _, idx, _ in rows])
    x_at = np.concatenate([x_m[idx] for _, idx, _ in rows])
    seg = np.clip(np.searchsorted(edges, x_at) - 1, 0, N_POSITION_SEGMENTS - 1)
    if xi.size < 10:
        return None
    n_ax, n_seg = n_axles - 1, N_POSITION_SEGMENTS - 1

    def model(p: np.ndarray) -> np.ndarray:
        mu0, K, kr = p[:3]
        j = 3
        factor = np.ones(n_axles)
        if per_axle:
            factor[1:] = p[j : j + n_ax]
            j += n_ax
        n = normal.copy()
        if load_transfer:
            n = n + p[j] * 1e3 * lead[axle] * acc
            j += 1
        where = np.ones(N_POSITION_SEGMENTS)
        if position:
            where[1:] = p[j : j + n_seg]
        return eq9(xi, dv, mu0, K, kr) * factor[axle] * where[seg] * n / 1e3

    p0, lo, hi = [0.1, 30.0, 0.02], [0.005, 0.5, 0.0], [1.0, 1e4, 1.0]
    if per_axle:
        p0, lo, hi = p0 + [1.0] * n_ax, lo + [0.3] * n_ax, hi + [3.0] * n_ax
    if load_transfer:
        p0, lo, hi = [*p0, 0.0], [*lo, -50.0], [*hi, 50.0]
    if position:
        p0, lo, hi = p0 + [1.0] * n_seg, lo + [0.2] * n_seg, hi + [5.0] * n_seg
    sol = least_squares(lambda p: model(p) - force, p0, bounds=(lo, hi))
    span = np.asarray(hi) - np.asarray(lo)
    at_bound = (np.abs(sol.x - lo) < 1e-4 * span) | (np.abs(sol.x - hi) < 1e-4 * span)
    at_bound[2] = abs(sol.x[2] - hi[2]) < 1e-4 * span[2]  # K_rozv = 0 is a law, not a bound
    if (per_axle or load_transfer or position) and at_bound.any():
        return None  # a fit that runs to a bound is not identified by these data
    return sol.x, sol.fun


def adhesion_channel_rmse(
    trace: Trace, per_axle: bool = False, load_transfer: bool = False, position: bool = False
):
    out = _fit_adhesion(trace, per_axle, load_transfer, position)
    if out is None:
        return float("nan"), None, 0
    x, res = out
    return float(np.sqrt(np.mean(res**2))), x, res.size


CANDIDATES_BALANCE = [
    Candidate("gradient", "gradient", "train_speed_balance_kmh", 1, _fit_gradient),
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
    Candidate("pressure lag", "pressure_lag", "train_speed_balance_kmh", 1, _fit_lag),
    Candidate("ground-speed scale", "sensor", "train_speed_balance_kmh", 1, _fit_sensor_balance),
    Candidate("ground-speed lag", "sensor", "train_speed_balance_kmh", 1, _fit_sensor_lag),
]
CANDIDATES_COASTING = [
    Candidate("wheel radius per axle", "wheel_radius", "coasting_creep_pct", 4, _fit_radius),
    Candidate("ground-speed scale", "sensor", "coasting_creep_pct", 1, _fit_sensor_coasting),
]


def _noise_floor_kmh(trace: Trace) -> float:
    """Speed-sensor noise from second differences of the logged train speed."""
    d2 = np.diff(trace.v_train_kmh, 2)
    return float(np.median(np.abs(d2)) / 0.6745 / math.sqrt(6.0))


def _channel_of(cand: Any) -> str:
    if isinstance(cand, tuple):
        return "train_speed_balance_kmh"
    if isinstance(cand, str):
        return "adhesion_fit_kN"
    return cand.channel


def _bic(rss: float, n: int, k: int) -> float:
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


def discover(trace: Trace) -> Result:
    """Run the loop on one trace (see the module docstring)."""
    chans = channels(trace)
    before = {k: c.rmse for k, c in chans.items()}
    result = Result(errors_before=before, errors_after=dict(before))
    sampling = chans["train_speed_balance_kmh"].detail.get("sampling_rmse", 0.0)
    floors = {
        "train_speed_balance_kmh": math.hypot(_noise_floor_kmh(trace), sampling),
        "coasting_creep_pct": 100.0
        * _noise_floor_kmh(trace)
        / max(float(np.median(trace.v_train_kmh)), 1.0),
    }
    residual = {k: chans[k].residual.copy() for k in floors}
    masks = {k: chans[k].mask for k in floors}
    adhesion = {"per_axle": False, "load_transfer": False, "position": False}
    adh_rmse, _, _ = adhesion_channel_rmse(trace)
    result.errors_before["adhesion_fit_kN"] = adh_rmse
    result.errors_after["adhesion_fit_kN"] = adh_rmse
    used: set[str] = set()
    x_total = float(_cumtrapz(trace.time_s, trace.v_train_kmh / 3.6)[-1])
    for _ in range(MAX_EFFECTS):
        qualified: list[tuple] = []
        for cands in (CANDIDATES_BALANCE, CANDIDATES_COASTING):
            for cand in cands:
                if cand.category + cand.channel in used:
                    continue
                ch = cand.channel
                res, mask = residual[ch], masks[ch]
                n = int(mask.sum())
                if n < 10:
                    continue
                rss0 = float(np.sum(res[mask] ** 2))
                rmse0 = math.sqrt(rss0 / n)
                if rmse0 < NOISE_FACTOR * floors[ch]:
                    continue
                fitted = cand.fit(trace, res, mask)
                if fitted is None:  # contradicted by another channel
                    continue
                params, new = fitted
                rss1 = float(np.sum(new[mask] ** 2))
                k = cand.n_params if cand.category != "wheel_radius" else trace.n_axles
                dbic = _bic(rss1, n, k) - _bic(rss0, n, 0)
                rmse1 = math.sqrt(rss1 / n)
                row = {"name": cand.name, "category": cand.category, "channel": ch,
                       "before": rmse0, "after": rmse1, "delta_bic": dbic}  # fmt: skip
                result.considered.append(row)
                gain = 1 - rmse1 / rmse0
                if dbic < -MIN_DELTA_BIC and gain >= MIN_REDUCTION:
                    qualified.append((gain, cand, params, new, rmse0, rmse1, dbic, k))
        ch = "train_speed_balance_kmh"
        res, mask = residual[ch], masks[ch]
        n = int(mask.sum())
        if n >= 10 and not any(c + ch in used for c in PAIR_NAMES):
            rss0 = float(np.sum(res[mask] ** 2))
            rmse0 = math.sqrt(rss0 / n)
            if rmse0 >= NOISE_FACTOR * floors[ch]:
                terms = _pair_terms(trace)
                names = list(terms)
                single = {}
                for a in names:
                    _, r1 = _linear(res, mask, [terms[a][0]])
                    single[a] = math.sqrt(float(np.sum(r1[mask] ** 2)) / n)
                for i, a in enumerate(names):
                    for b in names[i + 1 :]:
                        coef, new = _linear(res, mask, [terms[a][0], terms[b][0]])
                        rmse1 = math.sqrt(float(np.sum(new[mask] ** 2)) / n)
                        dbic = _bic(rmse1**2 * n, n, 2) - _bic(rss0, n, 0)
                        gain = 1 - rmse1 / rmse0
                        # each term must earn its place against the other alone
                        earns = rmse1 <= (1 - MIN_REDUCTION) * min(single[a], single[b])
                        row = {"name": f"{a} + {b}", "category": f"{a}+{b}", "channel": ch,
                               "before": rmse0, "after": rmse1, "delta_bic": dbic}  # fmt: skip
                        result.considered.append(row)
                        if dbic < -MIN_DELTA_BIC and gain >= MIN_REDUCTION and earns:
                            params = (terms[a][1](coef[0]), terms[b][1](coef[1]))
                            pair = ((a, params[0], single[a]), (b, params[1], rmse1))
                            qualified.append((gain, pair, None, new, rmse0, rmse1, dbic, 2))
        adhesion_candidates = (
            ("per_axle", "adhesion_per_axle", trace.n_axles - 1),
            ("load_transfer", "load_transfer", 1),
            ("position", "adhesion_position", N_POSITION_SEGMENTS - 1),
        )
        for key, cat, k in adhesion_candidates:
            if adhesion[key] or math.isnan(adh_rmse):
                continue
            trial = dict(adhesion, **{key: True})
            rmse1, x, n = adhesion_channel_rmse(trace, **trial)
            if x is None:  # not identified (a parameter ran to its bound)
                continue
            dbic = _bic(rmse1**2 * n, n, k) - _bic(adh_rmse**2 * n, n, 0)
            gain = 1 - rmse1 / adh_rmse
            row = {"name": cat, "category": cat, "channel": "adhesion_fit_kN",
                   "before": adh_rmse, "after": rmse1, "delta_bic": dbic}  # fmt: skip
            result.considered.append(row)
            if dbic < -MIN_DELTA_BIC and gain >= MIN_REDUCTION:
                params = {"mu0": x[0], "K": x[1], "K_rozv": x[2]}
                extra = list(x[3:])
                axle_f = extra[: trace.n_axles - 1] if trial["per_axle"] else []
                rest = extra[len(axle_f) :]
                pitch = rest[:1] if trial["load_transfer"] else []
                segs = rest[len(pitch) :]
                if key == "per_axle":
                    params.update({f"axle_{i + 2}_factor": v for i, v in enumerate(axle_f)})
                elif key == "load_transfer":
                    params["bogie_pitch_kN_per_mps2"] = pitch[0]
                else:
                    params.update({f"segment_{i + 2}_factor": v for i, v in enumerate(segs)})
                    params["segment_length_m"] = x_total / N_POSITION_SEGMENTS
                qualified.append((gain, key, params, None, adh_rmse, rmse1, dbic, k))
        if not qualified:
            break
        # the channel with the largest relative cut goes first; on it, candidates whose remaining
        # error is within half a noise floor of the best are a tie, broken by fewer parameters
        lead = max(qualified, key=lambda q: q[0])
        channel = _channel_of(lead[1])
        same = [q for q in qualified if _channel_of(q[1]) == channel]
        margin = 0.5 * floors.get(channel, 0.05 * lead[4])
        best_after = min(q[5] for q in same)
        best = min((q for q in same if q[5] <= best_after + margin), key=lambda q: (q[7], q[5]))
        gain, cand, params, new, rmse0, rmse1, dbic, _ = best
        if isinstance(cand, tuple):  # two force effects fitted together on the balance
            ch = "train_speed_balance_kmh"
            residual[ch] = new
            before = rmse0
            for category, p_fit, after in cand:
                used.add(category + ch)
                result.added.append(
                    Step(PAIR_NAMES[category], category, ch, p_fit, before, after, dbic)
                )
                before = after
            result.errors_after[ch] = rmse1
            continue
        if isinstance(cand, str):  # adhesion effect
            adhesion[cand] = True
            adh_rmse = rmse1
            cat = {"per_axle": "adhesion_per_axle", "load_transfer": "load_transfer",
                   "position": "adhesion_position"}[cand]  # fmt: skip
            step = Step(cat, cat, "adhesion_fit_kN", params, rmse0, rmse1, dbic)
            result.errors_after["adhesion_fit_kN"] = rmse1
        else:
            residual[cand.channel] = new
            used.add(cand.category + cand.channel)
            step = Step(cand.name, cand.category, cand.channel, params, rmse0, rmse1, dbic)
            result.errors_after[cand.channel] = rmse1
            if cand.category == "sensor" and cand.channel == "coasting_creep_pct":
                # the same scale error acts on the balance channel: correct it there too
                ch = "train_speed_balance_kmh"
                s = params["speed_scale_error"]
                drop = -masked_cumdiff(trace.v_train_kmh, balance_intervals(trace))
                residual[ch] = residual[ch] + s * drop
                used.add("sensor" + ch)
                m = masks[ch]
                result.errors_after[ch] = float(np.sqrt(np.mean(residual[ch][m] ** 2)))
        result.added.append(step)
    for ch, floor in floors.items():
        m = masks[ch]
        if m.sum() >= 10:
            rmse = float(np.sqrt(np.mean(residual[ch][m] ** 2)))
            if rmse > UNEXPLAINED_FACTOR * max(floor, 1e-9):
                result.unexplained.append({"channel": ch, "rmse": rmse, "noise_floor": floor})
    return result

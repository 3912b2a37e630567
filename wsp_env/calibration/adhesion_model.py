"""The adhesion channel's extended model: one Eq. 9 law for every axle, times the extensions.

The candidate extensions (``discovery``): ``adhesion_per_axle`` (a friction factor per axle,
axle 1 = 1), ``load_transfer`` (bogie pitch: the leading axle of each bogie ``+k a``, the
trailing ``-k a``, on the normal load) and ``adhesion_position`` (a friction factor on the rail
beyond a step position found on a grid, ``fit_adhesion_step``, judged against the law with a
first-order train-speed trend, ``step_null``). ``fit_extension`` fits a trial set of them with
the base law's recovery re-chosen under a step; ``cleaning_explains`` says when per-axle factors
are the rail's cleaning along the train; ``adhesion_params`` names a fit's parameters. All of
them only on a stop whose wheels slid (``ADHESION_MIN_SLIDES``, ``slides_at_limit``).

The loop's side (``discovery``): ``AdhesionModel`` is the adhesion model as the loop extends it
(``start_adhesion_model`` the nominal one), ``adhesion_candidates`` tries each extension not yet
in it (a cut of ``MIN_REDUCTION_ADHESION``: the channel has no noise floor) and
``add_extension`` adds the one chosen.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wsp_env.calibration.adhesion_estimate import (
    CLEANING_MAX,
    RECOVERY_GRID_KW,
    REWEIGHT,
    CensoredPoints,
    CriticalPoints,
    LawFit,
    censored_points,
    cleaning_factor,
    fit_law,
    pooled_points,
    removed_fraction,
)
from wsp_env.calibration.plausibility import implausible
from wsp_env.calibration.residuals import MIN_SPEED_KMH, Channel
from wsp_env.calibration.selection import (
    MIN_DELTA_BIC,
    MIN_REDUCTION,
    Qualified,
    Result,
    Step,
    bic,
)
from wsp_env.calibration.traces import Trace

ADHESION = "adhesion_fit_kN"  # the channel (``residuals.adhesion_fit``)
# candidate step positions: 20 %, 25 %, ... 80 % of the way from the first critical point to the
# last (a step needs room on either side to be told from a trend at the stop's end)
STEP_FRACTIONS = np.linspace(0.2, 0.8, 13)
# and evidence of the rail's available adhesion on either side: at least this share of it on each
# side of a step, and at least STEP_MIN_SLIDES slides in all. Only a wheel at the adhesion limit
# shows the rail's friction — a slide's turning point where the rail is worse, a censored bound
# (a braked wheel rolling) where it is better. A slide is past the creep curve's peak (1-2 % on a
# dry or wet rail, 3-7 % contaminated: SLIDE_MIN_CREEP) and SLIDE_MIN_KMH slower than the train
# and than the fastest axle (below a WSP's first threshold, 2.5-4 km/h, beyond what the ground
# speed's hold between fixes and the noise of the fastest of many axle sensors give a rolling
# wheel); the other critical points are those of a wheel rolling under a rising brake
# force, the creep curve's initial slope, so a stop that never slides (a wet rail) draws its brake
# ramp there, not its rail.
STEP_MIN_SIDE_SHARE = 0.1
STEP_MIN_SLIDES = 8
# Every adhesion extension needs the same evidence of the limit: a stop on which no wheel slid
# (a wet or dry rail under a light brake) shows only the creep curve's initial slope, which
# carries the normal loads, the contact's stiffness and the speed sensors' offsets, not the
# rail's friction; a friction factor per axle fitted there takes a car's body pitch or a
# sensor offset for adhesion (measured on independent clean traces: 6 of the 7 adhesion false
# positives of three held-out sets of 100 were stops without a single slide).
ADHESION_MIN_SLIDES = STEP_MIN_SLIDES
# and enough critical points for the extended law: this many per fitted parameter (law,
# cleaning, trend and extension together); a clean 8-axle trace with 17 points once took a
# load transfer and a friction step (dBIC -14 and -19) from them
ADHESION_POINTS_PER_PARAM = 5
SLIDE_MIN_CREEP = 0.03
SLIDE_MIN_KMH = 2.0
# A rail's adhesion falls with train speed (Curtius-Kniffler: mu = 0.161 + 7.5 / (V + 44), ~20 %
# from 20 to 100 km/h), which Eq. 9 (sliding speed only) lacks. Along a stop the speed falls as
# the position grows, so that trend looks like a friction step to a model without it: a step is
# judged against the law with a first-order train-speed trend ``1 + s (V_mid - V) / 100 km/h``
# (``s`` within +-SPEED_TREND_MAX), the trend staying in the model once a step is added.
SPEED_TREND_MAX = 1.0


# A car's coupled length beyond its outer axles, front and rear together (m): a 4c-axle rake
# whose metadata gives one car's bogie geometry but not the axles' positions is read as cars
# ``bogie_centre_distance_m + bogie_wheelbase_m + CAR_ENDS_M`` long (UIC-Z1: 26.4 m over buffers
# on 19 m bogie centres and 2.56 m wheelbases, 4.8 m; ETR1000: 25.9 m car pitch on 17.5 m and
# 2.7 m, 5.7 m). A few metres per car off is below the step grid's spacing on a stop.
CAR_ENDS_M = 5.2


def axle_offsets_m(trace: Trace) -> np.ndarray:
    """Distance of each axle behind axle 1 (m), in running order: the metadata's
    ``axle_offsets_m`` where it gives them; else from one car's bogie geometry
    (``bogie_centre_distance_m``, ``bogie_wheelbase_m``) for a rake of ``n_axles / 4`` such cars,
    ``CAR_ENDS_M`` between the outer axles of neighbouring cars; else 0 (unknown: every axle
    placed at the front, ``rail_better.stop_position_m`` then reads the front axle)."""
    veh, n = trace.vehicle, trace.n_axles
    listed = veh.get("axle_offsets_m")
    if listed is not None:
        return np.asarray(listed, dtype=float)
    L, b = veh.get("bogie_centre_distance_m"), veh.get("bogie_wheelbase_m")
    if n % 4 == 0 and L and b:
        car = np.array([0.0, b, L, L + b], dtype=float)
        pitch = L + b + CAR_ENDS_M
        return np.concatenate([car + c * pitch for c in range(n // 4)])
    return np.zeros(n)


def fit_adhesion_model(
    trace: Trace,
    per_axle: bool,
    load_transfer: bool,
    step_m: float | None = None,
    pts: CriticalPoints | None = None,
    removed: np.ndarray | None = None,
    law_start: np.ndarray | None = None,
    censored: CensoredPoints | None = None,
    cleaning: bool = False,
    reweight: int = REWEIGHT,
    speed_trend: bool = False,
    monotone: bool = False,
) -> LawFit | None:
    """One Eq. 9 law for all axles' critical points (``pts``, default: the trace's; with the
    base law's recovery when ``removed`` is given, see ``adhesion_estimate.fit_law``), times the
    chosen extensions' factors: a friction factor per axle (axle 1 = 1), a bogie-pitch load
    transfer ``+- k a`` on the leading / trailing axle of each bogie (consecutive pairs), a
    friction factor on the rail beyond ``step_m`` (position of the rail under the axle).
    ``censored``: the rolling wheels' lower bounds on the adhesion (``censored_points``), under
    the same factors. ``cleaning``: the base law's cleaning along the train
    (``adhesion_estimate.cleaning_factor``, its gain the last parameter) stays in the model.
    ``speed_trend``: a first-order train-speed trend of the friction (``SPEED_TREND_MAX``).
    ``monotone``: the per-axle factors constrained to rise along the train (each axle's at
    least the one's ahead: the rail cleaned by the axles ahead, ``cleaning_explains``)."""
    if pts is None:
        pts = pooled_points(trace, MIN_SPEED_KMH)
    if len(pts) < 10:
        return None
    n_ax = trace.n_axles - 1
    start: list[float] = []
    low: list[float] = []
    high: list[float] = []
    if per_axle and monotone:  # increments of the factor from axle to axle, >= 0
        start, low, high = start + [0.0] * n_ax, low + [0.0] * n_ax, high + [3.0] * n_ax
    elif per_axle:
        start, low, high = start + [1.0] * n_ax, low + [0.3] * n_ax, high + [3.0] * n_ax
    if load_transfer:
        start, low, high = [*start, 0.0], [*low, -50.0], [*high, 50.0]
    if step_m is not None:
        start, low, high = [*start, 1.0], [*low, 0.2], [*high, 5.0]
    if speed_trend:
        start, low, high = [*start, 0.0], [*low, -SPEED_TREND_MAX], [*high, SPEED_TREND_MAX]
    if cleaning:
        start, low, high = [*start, 0.1], [*low, 0.0], [*high, CLEANING_MAX]
    offsets = axle_offsets_m(trace)
    v_mid = float(np.median(trace.v_train_kmh[pts.sample]))

    def factors_for(points: Any) -> Callable[[np.ndarray], np.ndarray]:
        """The extensions' force factor at each of ``points`` (critical or censored)."""
        lead = np.where(points.axle % 2 == 0, 1.0, -1.0)
        rail_m = points.position_m - offsets[points.axle]
        beyond = rail_m > (step_m if step_m is not None else np.inf)
        slower = (v_mid - trace.v_train_kmh[points.sample]) / 100.0

        def factor_of(p: np.ndarray) -> np.ndarray:
            j = 0
            out = np.ones(len(points))
            if per_axle:
                f = 1.0 + np.cumsum(p[:n_ax]) if monotone else p[:n_ax]
                out = out * np.concatenate([[1.0], f])[points.axle]
                j = n_ax
            if load_transfer:  # (N + k a) / N
                out = out * (1.0 + p[j] * 1e3 * lead * points.decel_mps2 / points.normal_N)
                j += 1
            if step_m is not None:
                out = np.where(beyond, out * p[j], out)
                j += 1
            if speed_trend:
                out = out * np.maximum(1.0 + p[j] * slower, 0.2)
            if cleaning:
                out = out * clean(p)
            return out

        clean = cleaning_factor(points.axle, trace.n_axles)
        return factor_of

    extended = per_axle or load_transfer or step_m is not None or cleaning or speed_trend
    factors = factors_for(pts) if extended else None
    c_factors = factors_for(censored) if extended and censored is not None else None
    return fit_law(pts, factors, len(start), start, low, high, removed, law_start, censored,
                   c_factors, reweight)  # fmt: skip


def slides_at_limit(trace: Trace, pts: CriticalPoints) -> np.ndarray:
    """Which critical points are slides at the adhesion limit (``SLIDE_MIN_KMH``, ...)."""
    depth = trace.v_axle_kmh.max(axis=1)[pts.sample] - trace.v_axle_kmh[pts.sample, pts.axle]
    if trace.n_axles < 2:  # no other axle to compare with: the ground speed alone
        depth = pts.sliding_kmh
    return (np.minimum(pts.sliding_kmh, depth) >= SLIDE_MIN_KMH) & (pts.creepage >= SLIDE_MIN_CREEP)


def fit_adhesion_step(
    trace: Trace,
    per_axle: bool,
    load_transfer: bool,
    pts: CriticalPoints,
    removed: np.ndarray | None = None,
    law_start: np.ndarray | None = None,
    censored: CensoredPoints | None = None,
    cleaning: bool = False,
    speed_trend: bool = False,
) -> tuple[LawFit | None, float]:
    """The adhesion model with a friction step on the rail, the step's position chosen on a
    grid of the positions with adhesion evidence — critical points and censored bounds, so a
    rail that gets better and stops the slides is seen (best weighted fit) — where each side
    holds ``STEP_MIN_SIDE_SHARE`` of that evidence. The grid is screened without the
    ``speed_trend`` (quick fits); the chosen step is fitted with it."""
    x = pts.position_m
    if x.size < 10:
        return None, float("nan")
    if censored is not None and len(censored):
        x = np.concatenate([x, censored.position_m])
    slides = pts.position_m[slides_at_limit(trace, pts)]
    if slides.size < STEP_MIN_SLIDES:
        return None, float("nan")
    limit = slides if censored is None else np.concatenate([slides, censored.position_m])
    best: tuple[LawFit | None, float] = (None, float("nan"))
    for step_m in x.min() + STEP_FRACTIONS * (x.max() - x.min()):  # screened with one pass
        share = float(np.mean(limit <= step_m))
        if not STEP_MIN_SIDE_SHARE <= share <= 1.0 - STEP_MIN_SIDE_SHARE:
            continue
        fit = fit_adhesion_model(
            trace, per_axle, load_transfer, float(step_m), pts, removed, law_start, censored,
            cleaning, reweight=0,
        )  # fmt: skip
        if fit is not None and (best[0] is None or fit.chi2 < best[0].chi2):
            best = (fit, float(step_m))
    if best[0] is None:
        return best
    final = fit_adhesion_model(
        trace, per_axle, load_transfer, best[1], pts, removed, law_start, censored, cleaning,
        speed_trend=speed_trend,
    )  # fmt: skip
    return final, best[1]


def fit_extension(
    trace: Trace,
    trial: dict[str, bool],
    pts: CriticalPoints,
    removed: np.ndarray | None,
    law_start: np.ndarray | None,
    recovery_grid: dict[tuple[float, float], np.ndarray],
    censored: CensoredPoints | None = None,
) -> tuple[LawFit | None, float, tuple[float, float] | None]:
    """The adhesion model with the extensions in ``trial``; returns the fit, the step position
    (NaN without one) and the recovery's (W_lim, W_max - W_lim) in kW it used (``None``: the
    base law's, or no recovery).

    Where the base law recovers, its W_lim / W_max were chosen on data the extension's effect
    blurred (a step in the rail's friction moves the sliding power at which the slides recover):
    the extended model with a step re-chooses them on the same grid (``RECOVERY_GRID_KW``; no new
    parameter), the step's position held where the base recovery put it."""
    step_m = float("nan")
    clean = bool(trial.get("cleaning")) and not trial["per_axle"]  # per-axle factors replace it
    trend = bool(trial.get("speed_trend"))
    if trial["position"]:
        fit, step_m = fit_adhesion_step(
            trace, trial["per_axle"], trial["load_transfer"], pts, removed, law_start, censored,
            clean, trend,
        )  # fmt: skip
        if fit is None:
            return None, step_m, None
    else:
        fit = fit_adhesion_model(
            trace, trial["per_axle"], trial["load_transfer"], None, pts, removed, law_start,
            censored, clean, speed_trend=trend,
        )  # fmt: skip
    step = None if math.isnan(step_m) else step_m
    best: tuple[LawFit | None, tuple[float, float] | None] = (fit, None)
    # only a step moves where the slides recover (per-axle factors and load transfer scale
    # the force, not the sliding power's threshold): the re-choice is the step's alone
    screened: tuple[float, tuple[float, float] | None] = (math.inf, None)
    for grid, other in recovery_grid.items() if trial["position"] else ():
        if other is removed:
            continue
        alt = fit_adhesion_model(
            trace, trial["per_axle"], trial["load_transfer"], step, pts, other, law_start,
            censored, clean, reweight=0,
        )  # fmt: skip
        if alt is not None and alt.chi2 < screened[0]:
            screened = (alt.chi2, grid)
    if screened[1] is not None:  # the best screened recovery, fitted in full
        alt = fit_adhesion_model(
            trace, trial["per_axle"], trial["load_transfer"], step, pts,
            recovery_grid[screened[1]], law_start, censored, clean, speed_trend=trend,
        )  # fmt: skip
        if alt is not None and (best[0] is None or alt.chi2 < best[0].chi2):
            best = (alt, screened[1])
    return best[0], step_m, best[1]


def step_null(
    trace: Trace,
    adhesion: dict[str, bool],
    pts: CriticalPoints,
    removed: np.ndarray | None,
    law_start: np.ndarray | None,
    censored: CensoredPoints | None,
    step_fit: LawFit,
    step_removed: np.ndarray | None,
    current: tuple[float, float],
) -> tuple[float, float]:
    """(chi2, RMSE) of the model a friction step is judged against: the current one with a
    train-speed trend (``SPEED_TREND_MAX``), fitted from the current law and from the step
    fit's (a step that only lets the law leave a poor local optimum is no step), with the
    base's recovery and with the one the step re-chose; the current model if none does better."""
    best = current
    clean = bool(adhesion.get("cleaning")) and not adhesion["per_axle"]
    starts = [(removed, law_start), (step_removed if step_removed is not None else removed,
                                     step_fit.params[: step_fit.n_law])]  # fmt: skip
    for rem, start in starts:
        if start is not None and len(start) != (3 if rem is None else 4):
            start = None
        fit = fit_adhesion_model(
            trace, adhesion["per_axle"], adhesion["load_transfer"], None, pts, rem, start,
            censored, clean, speed_trend=True,
        )  # fmt: skip
        if fit is not None and fit.chi2 < best[0]:
            best = (fit.chi2, fit.rmse)
    return best


def cleaning_explains(
    trace: Trace,
    adhesion: dict[str, bool],
    pts: CriticalPoints,
    removed: np.ndarray | None,
    law_start: np.ndarray | None,
    censored: CensoredPoints | None,
    rmse_per_axle: float,
) -> str | None:
    """Why per-axle factors are the rail's cleaning along the train, or ``None``: the same
    number of factors constrained to rise from axle to axle (``monotone``) fits within
    ``MIN_REDUCTION`` as well. The axles behind see a rail the ones ahead cleaned (DESIGN §3,
    seed 000 Table 4): a monotone rise is nominal, in whatever shape the contaminant and the
    slides give it; the base law's one-parameter cleaning has one shape only, and held-out
    clean traces (soap, 4 axles) rose 1 / 1.00 / 1.19 / 1.42. One axle off the others is the
    effect (the last axle alone grippier cannot be told from cleaning)."""
    mono = fit_adhesion_model(
        trace, True, adhesion["load_transfer"], None, pts, removed, law_start, censored,
        speed_trend=adhesion["speed_trend"], monotone=True,
    )  # fmt: skip
    if mono is None or rmse_per_axle < (1.0 - MIN_REDUCTION) * mono.rmse:
        return None
    return (
        f"factors rising along the train fit as well ({mono.rmse:.3f} against {rmse_per_axle:.3f}"
        " kN): the rail cleaned by the axles ahead, nominal, not one axle's adhesion"
    )


LAW_KEYS = ("mu0", "K", "K_rozv", "recovery_gain")


def adhesion_params(
    trace: Trace, key: str, trial: dict[str, bool], fit: LawFit, step_m: float
) -> dict[str, float]:
    """The law's and the tried extension's parameters of an extended adhesion fit, by name
    (the fit's vector: the law, per-axle factors, pitch, step factor, speed trend, cleaning)."""
    x = fit.params
    params = {"mu0": x[0], "K": x[1], "K_rozv": x[2]}
    if fit.n_law == 4:
        params["recovery_gain"] = x[3]
    extra = list(x[fit.n_law :])
    axle_f = extra[: trace.n_axles - 1] if trial["per_axle"] else []
    rest = extra[len(axle_f) :]
    pitch = rest[:1] if trial["load_transfer"] else []
    segs = rest[len(pitch) :]
    if key == "per_axle":
        params.update({f"axle_{i + 2}_factor": v for i, v in enumerate(axle_f)})
    elif key == "load_transfer":
        params["bogie_pitch_kN_per_mps2"] = pitch[0]
    else:
        params.update({"step_position_m": step_m, "factor_beyond_step": segs[0]})
    if trial["speed_trend"]:
        last_is_cleaning = trial["cleaning"] and not trial["per_axle"]
        params["speed_trend_per_100kmh"] = segs[-2 if last_is_cleaning else -1]
    return {k: float(v) for k, v in params.items()}


# ---- the loop's adhesion model and its candidate extensions (``discovery``) ------------------

# The adhesion channel has no noise floor to test against (Eq. 9 is a fit to the contact, not
# its law, and residuals are correlated along each WSP cycle), so a structural candidate there
# must remove a third of the error: measured on traces without the effect, the nominal bogie
# pitch and rail cleaning alone give 18-28 %, injected effects 45-68 %.
MIN_REDUCTION_ADHESION = 1.0 / 3.0
# an extension's key in the model and its category
EXTENSION_CATEGORY = {"per_axle": "adhesion_per_axle", "load_transfer": "load_transfer",
                      "position": "adhesion_position"}  # fmt: skip


@dataclass
class AdhesionModel:
    """The adhesion channel's model as the loop extends it, and what its candidates share."""

    extensions: dict[str, bool]  # per_axle, load_transfer, position, cleaning, speed_trend
    points: CriticalPoints  # the pooled critical points, shared by every candidate
    bounds: CensoredPoints  # what rolling wheels prove (issue 11, item 3)
    limit_seen: bool  # enough slides at the adhesion limit (``ADHESION_MIN_SLIDES``)
    rmse: float
    chi2: float
    # the base law's recovery at the critical points; its W_lim / W_max re-chosen under an
    # extension on ``recovery_grid`` (``RECOVERY_GRID_KW``)
    removed: np.ndarray | None
    recovery_grid: dict[tuple[float, float], np.ndarray]
    law_start: np.ndarray
    # the candidates' rows per adhesion model: a round that added a balance or coasting effect
    # leaves them as they were (their fits are the loop's cost)
    rounds: dict[tuple, list[list[Any]]] = field(default_factory=dict)


def start_adhesion_model(
    trace: Trace, chans: dict[str, Channel], health: dict[str, dict[str, Any]], result: Result
) -> AdhesionModel:
    """The nominal adhesion model (the base law, its cleaning and recovery as the adhesion
    channel fitted them, into ``result.adhesion_law``) and the evidence its extensions are tried
    on; notes in ``health`` why they are not tried where no wheel reached the adhesion limit."""
    extensions = {"per_axle": False, "load_transfer": False, "position": False,
                  "cleaning": "cleaning_gain" in chans[ADHESION].detail,
                  "speed_trend": False}  # fmt: skip
    points = pooled_points(trace, MIN_SPEED_KMH)  # shared by every adhesion candidate
    n_slides = int(slides_at_limit(trace, points).sum()) if len(points) else 0
    limit_seen = n_slides >= ADHESION_MIN_SLIDES
    if not limit_seen and health[ADHESION]["usable"]:
        health[ADHESION]["extensions"] = (
            f"adhesion effects not tried: {n_slides} slide(s) at the adhesion limit, "
            f"{ADHESION_MIN_SLIDES} needed (the wheels did not reach the rail's friction)"
        )
    bounds = censored_points(trace, MIN_SPEED_KMH)  # what rolling wheels prove (item 3)
    detail = chans[ADHESION].detail
    result.adhesion_law = {k: v for k, v in detail.items() if k != "chi2"}
    removed = None  # the base law's recovery; its W_lim / W_max re-chosen under an extension
    recovery_grid: dict[tuple[float, float], np.ndarray] = {}
    law_start = np.array([detail.get(k, np.nan) for k in ("mu0", "K", "K_rozv")])
    if "recovery_w_lim_kW" in detail:
        law_start = np.append(law_start, detail["recovery_gain"])
        w_lim = detail["recovery_w_lim_kW"]
        w_span = detail["recovery_w_max_kW"] - w_lim
        recovery_grid = {
            grid: removed_fraction(trace, *grid)[points.sample, points.axle]
            for grid in RECOVERY_GRID_KW
        }
        removed = recovery_grid.get((w_lim, w_span))
        if removed is None:
            removed = removed_fraction(trace, w_lim, w_span)[points.sample, points.axle]
    return AdhesionModel(extensions, points, bounds, limit_seen, chans[ADHESION].rmse,
                         detail.get("chi2", float("nan")), removed, recovery_grid,
                         law_start)  # fmt: skip


def adhesion_candidates(
    trace: Trace, model: AdhesionModel, usable: bool, considered: list[dict[str, Any]]
) -> list[Qualified]:
    """The extensions not yet in ``model``, each tried on it and recorded in ``considered``
    (``usable``: the adhesion channel's health); returns those that qualify."""
    # the adhesion candidates depend on the adhesion model alone: a round that added a
    # balance or coasting effect leaves them as they were (their fits are the loop's cost)
    key = (tuple(sorted(model.extensions.items())), model.chi2, id(model.removed))
    if key not in model.rounds:
        rows: list[list[Any]] = []  # [considered row, qualified entry or None]
        for ext, cat, k in (
            ("per_axle", "adhesion_per_axle", trace.n_axles - 1),
            ("load_transfer", "load_transfer", 1),
            ("position", "adhesion_position", 2),
        ):
            if model.extensions[ext] or math.isnan(model.rmse) or not model.limit_seen:
                continue
            if not usable:
                continue
            row = _try_extension(trace, model, ext, cat, k, considered)
            if row is not None:
                rows.append(row)
        model.rounds[key] = rows
    qualified: list[Qualified] = []
    for row, entry in model.rounds[key]:
        considered.append(dict(row))
        if entry is not None:
            qualified.append(entry)
    return qualified


def _try_extension(
    trace: Trace,
    model: AdhesionModel,
    ext: str,
    cat: str,
    k: int,
    considered: list[dict[str, Any]],
) -> list[Any] | None:
    """One extension ``ext`` (category ``cat``, ``k`` parameters) added to the adhesion model:
    [its considered row, its qualified entry or ``None``]; ``None`` where it is not identified
    (a parameter at its bound) or has too few critical points (then recorded in ``considered``
    directly). It qualifies by the BIC (``MIN_DELTA_BIC``) and a cut of
    ``MIN_REDUCTION_ADHESION``; a step is judged against the law with a train-speed trend
    (``step_null``), which it must also cut by ``MIN_REDUCTION``."""
    trial = dict(model.extensions, **{ext: True})
    if ext == "position":  # a step is judged against a trend in train speed
        trial["speed_trend"] = True
    fit, step_m, trial_recovery = fit_extension(
        trace, trial, model.points, model.removed, model.law_start, model.recovery_grid,
        model.bounds,
    )  # fmt: skip
    if fit is None or fit.at_bound:  # not identified (a parameter ran to its bound)
        return None
    rmse1, x, n = fit.rmse, fit.params, fit.residual_kN.size
    if n < ADHESION_POINTS_PER_PARAM * x.size:  # too few points for the model
        considered.append({
            "name": cat, "category": cat, "channel": ADHESION,
            "before": model.rmse, "after": rmse1, "delta_bic": float("nan"),
            "rejected": f"{n} critical points for {x.size} parameters: "
                        f"{ADHESION_POINTS_PER_PARAM} per parameter needed",
        })  # fmt: skip
        return None
    null_chi2, null_rmse = model.chi2, model.rmse
    if trial["speed_trend"] and not model.extensions["speed_trend"]:
        null_chi2, null_rmse = step_null(
            trace, model.extensions, model.points, model.removed, model.law_start, model.bounds,
            fit, model.recovery_grid.get(trial_recovery) if trial_recovery else None,
            (model.chi2, model.rmse),
        )  # fmt: skip
    # weighted residual sums: n ln(chi2 / n) is the BIC's likelihood term
    dbic = bic(fit.chi2, n, k) - bic(null_chi2, n, 0)
    gain = 1 - rmse1 / model.rmse
    row = {"name": cat, "category": cat, "channel": ADHESION,
           "before": model.rmse, "after": rmse1, "delta_bic": dbic}  # fmt: skip
    # a step must also beat the speed trend alone (BIC above, and MIN_REDUCTION of it)
    beats_trend = 1 - rmse1 / null_rmse >= MIN_REDUCTION
    if null_rmse != model.rmse:
        row["before_with_speed_trend"] = null_rmse
    out: list[Any] = [row, None]
    params = adhesion_params(trace, ext, trial, fit, step_m)
    row["parameters"] = {key: v for key, v in params.items() if key not in LAW_KEYS}
    if dbic < -MIN_DELTA_BIC and gain >= MIN_REDUCTION_ADHESION and beats_trend:
        reason = implausible(cat, params, trace)
        if not reason and ext == "per_axle":
            reason = cleaning_explains(
                trace, model.extensions, model.points, model.removed, model.law_start,
                model.bounds, rmse1,
            )  # fmt: skip
        if reason:
            row["rejected"] = reason
        else:
            out[1] = (gain, ext, params, (fit.chi2, trial_recovery), model.rmse, rmse1, dbic, k)
    return out


def add_extension(
    model: AdhesionModel,
    result: Result,
    ext: str,
    params: dict[str, float],
    new: tuple[float, tuple[float, float] | None],
    rmse0: float,
    rmse1: float,
    dbic: float,
) -> None:
    """An extension chosen by the loop: into ``model`` (a step with its speed trend, and the
    recovery it re-chose, ``new``: the fit's chi2 and that recovery), its step into
    ``result.added`` and the law it was fitted with into ``result.adhesion_law``."""
    model.extensions[ext] = True
    model.extensions["speed_trend"] |= ext == "position"  # the step's null stays in the model
    # an adhesion entry carries its chi2 and its re-chosen recovery (if any) there
    model.rmse, (model.chi2, new_recovery) = rmse1, new
    if new_recovery is not None:
        model.removed = model.recovery_grid[new_recovery]
        result.adhesion_law["recovery_w_lim_kW"] = new_recovery[0]
        result.adhesion_law["recovery_w_max_kW"] = sum(new_recovery)
    cat = EXTENSION_CATEGORY[ext]
    step = Step(cat, cat, ADHESION, params, rmse0, rmse1, dbic)
    result.adhesion_law.update({k: float(params[k]) for k in LAW_KEYS if k in params})
    result.errors_after[ADHESION] = rmse1
    result.added.append(step)

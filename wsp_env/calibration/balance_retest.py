"""The re-test: every balance effect must still earn its place once all are in.

The loop (``discovery``) adds effects one at a time, greedily; an effect added early may be
explained better by one added later, or only have compensated for another. ``retest_balance``
refits every balance effect jointly on the nominal residual and drops, one at a time, the
weakest that no longer earns its place; ``fit_lag_at_joint`` adds the wheels' lag to the balance
effects already in, those refitted with it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wsp_env.calibration.balance_effects import (
    Shape,
    fit_lag_in,
    fit_linear,
    lag_shape,
    lag_signatures,
    params_from,
    shape_params,
    step_columns,
)
from wsp_env.calibration.plausibility import implausible, negligible
from wsp_env.calibration.residuals import anchored, balance_intervals, masked_cumdiff
from wsp_env.calibration.selection import MIN_DELTA_BIC, MIN_REDUCTION, Result, Step, bic
from wsp_env.calibration.traces import Trace


def _balance_base(
    trace: Trace, result: Result, residual0: np.ndarray, mask: np.ndarray
) -> np.ndarray:
    """The nominal balance residual ``residual0`` with a ground-speed scale chosen on the
    coasting channel applied as found (the balance effects are fitted on top of it)."""
    fixed = residual0.copy()
    for st in result.added:
        if st.channel == "coasting_creep_pct" and "speed_scale_error" in st.parameters:
            drop = -masked_cumdiff(trace.v_train_kmh, balance_intervals(trace))
            fixed = fixed + st.parameters["speed_scale_error"] * anchored(drop, trace.time_s, mask)
    return fixed


def fit_lag_at_joint(
    trace: Trace, result: Result, residual0: np.ndarray, mask: np.ndarray, shapes: list[Shape]
) -> tuple[dict[str, float], np.ndarray]:
    """The wheels' lag (the best of ``shapes``, ``balance_effects.wheel_window``) added to the
    balance effects already in, those refitted with it (a force effect added first absorbed
    part of the lag: alone on what it left, the lag would only undo that)."""
    cols = [c for st in result.added if (cc := step_columns(trace, st, residual0)) for c in cc]
    base = _balance_base(trace, result, residual0, mask)
    if not cols:
        return fit_lag_in(trace, base, mask, shapes)
    best: tuple[float, Shape, np.ndarray] = (math.inf, shapes[0], base)
    for shape, sig in zip(shapes, lag_signatures(trace, shapes)[1], strict=True):
        _, new = fit_linear(trace, base - sig, mask, cols)
        rss = float(np.sum(new[mask] ** 2))
        if rss < best[0]:
            best = (rss, shape, new)
    return shape_params(best[1]), best[2]


def retest_balance(
    trace: Trace, result: Result, residual0: np.ndarray, mask: np.ndarray
) -> np.ndarray:
    """Refit every balance effect jointly on the nominal residual; drop, one at a time, the
    weakest that no longer earns its place with all the others in (BIC gain above
    ``MIN_DELTA_BIC`` and ``MIN_REDUCTION / 2`` of the channel's RMSE): an effect added early
    that a later one explains better, or one that only compensated for another. Kept effects
    get their joint parameters and the re-test's BIC gain in ``confidence``; returns the final
    residual."""
    fixed = _balance_base(trace, result, residual0, mask)
    # a lag the wheels measured enters as measured (its signature whole, not a free amplitude
    # a force effect could trade against), and stands on the wheels' evidence
    by_wheels = [st for st in result.added if "wheel_lag_s" in st.confidence]
    for st in by_wheels:
        fixed = fixed - lag_signatures(trace, [lag_shape(st.parameters)])[1][0]
    n = int(mask.sum())
    # effects dropped as weak beside another: re-admitted when that one goes for good (a
    # gradient judged weak beside a resistance that then turns out to propel the train)
    weak: list[tuple[Step, dict[str, Any]]] = []

    def drop_for_good(st: Step, why: str) -> None:
        result.added.remove(st)
        result.dropped.append({**st.as_dict(), "reason": f"re-test: {why}"})
        for back, entry in weak:
            result.added.append(back)
            result.dropped.remove(entry)
        weak.clear()

    while True:
        columns = [
            (st, None if st in by_wheels else step_columns(trace, st, residual0))
            for st in result.added
        ]
        steps = [st for st, c in columns if c is not None]
        if not steps:
            return fixed
        cols = [c for _, c in columns if c is not None]
        k_all = sum(len(c) for c in cols)
        coef, res_full = fit_linear(trace, fixed, mask, [x for c in cols for x in c])
        rss_full = float(np.sum(res_full[mask] ** 2))
        # an effect whose joint value is unphysical was there to compensate for another (a
        # running resistance's constant term propelling the train beside a gradient that the
        # scale correction moved): it goes first, before any is judged weak — else the sound
        # one, sharing its shape, is dropped as weak and the other as implausible
        joint, start = [], 0
        for st, c in zip(steps, cols, strict=True):
            joint.append(params_from(st, coef[start : start + len(c)]))
            start += len(c)
        bad = [(st, why) for st, q in zip(steps, joint, strict=True)
               if (why := implausible(st.category, q, trace))]  # fmt: skip
        if bad:
            drop_for_good(*bad[-1])  # the latest added
            continue
        worst: tuple[float, int] | None = None
        for j, st in enumerate(steps):
            others = [x for i, c in enumerate(cols) if i != j for x in c]
            res_wo = fit_linear(trace, fixed, mask, others)[1] if others else fixed
            rss_wo = float(np.sum(res_wo[mask] ** 2))
            dbic = bic(rss_full, n, k_all) - bic(rss_wo, n, k_all - len(cols[j]))
            cut = 1.0 - math.sqrt(rss_full / max(rss_wo, 1e-300))
            st.confidence["retest_delta_bic"] = dbic
            st.confidence["retest_cut_pct"] = 100.0 * cut
            if dbic > -MIN_DELTA_BIC or cut < 0.5 * MIN_REDUCTION:
                if worst is None or dbic > worst[0]:
                    worst = (dbic, j)
        if worst is None:
            start = 0
            small = None
            for st, c in zip(steps, cols, strict=True):
                st.parameters = params_from(st, coef[start : start + len(c)])
                start += len(c)
                why = negligible(st.category, st.parameters, trace) or implausible(
                    st.category, st.parameters, trace
                )
                small = small or ((st, why) if why else None)
            if small is None:
                return res_full
            drop_for_good(*small)
            continue
        gone = steps[worst[1]]
        result.added.remove(gone)
        entry = {**gone.as_dict(), "reason": (
            f"re-test: with the other effects in, it gains BIC {-worst[0]:.1f} and cuts "
            f"{gone.confidence['retest_cut_pct']:.1f} % (needs {MIN_DELTA_BIC:g} and "
            f"{50 * MIN_REDUCTION:g} %)"
        )}  # fmt: skip
        result.dropped.append(entry)
        weak.append((gone, entry))

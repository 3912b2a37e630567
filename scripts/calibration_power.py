"""Detection power of the calibration loop on traces it was not developed on
(docs/calibration.md, "Calibration on independent traces").

    .venv/bin/python scripts/calibration_power.py [--scenarios 20] [--clean 50] [--pairs 20]
        [--seed 0] [--jobs 2] [--json runs/power.json] [--categories gradient,wheel_radius]
        [--markdown docs/results/calibration_power.md]

Traces come from ``wsp_env/calibration/independent.py``, a simulator that shares no code with
``wsp_env/physics`` (its own vehicle model, friction law, WSP and logger quirks). For every
category of DESIGN §8 a grid of effect magnitudes x ``--scenarios`` random scenarios, plus
``--clean`` traces without any effect and ``--pairs`` traces per pair of effects. Each trace is
written, read back through the project's reader and run through ``discover`` exactly as
``wsp-env calibrate`` does.

Adhesion effects (load transfer, a friction change along the rail, one axle's adhesion) are
drawn on soap, leaves or oil only: on a wet or dry rail the wheels hardly slide and no method
sees the adhesion limit.

Reported per category and magnitude: the detection rate (the category among the added
effects), beside it the rate at which it was chosen *or* named among the chosen effect's
equally good ``alternatives`` (the trace could not tell them apart; never counted as
detected), the median relative parameter error, the median channel cut, the rate of extra
effects; per category the smallest magnitude detected in >= 90 % of scenarios; the
false-positive rate on clean traces (any effect added); per pair the rate at which both were
found. Targets (issue 11) are printed beside the measured figures. For the load transfer and
the friction change along the rail, what their candidates read against the truth whether added
or not; for the friction change also what there was to see on each side of it (the generator's
seconds past the friction curve's peak, ``independent.sliding_around``, and the loop's critical
points at a slide). ``--markdown P`` writes the per-category table, the pairs and the whole
printout there, with the command and the machine above.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import math
import multiprocessing
import os
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from _results_md import fenced, tee_stdout, write_results

# magnitude grid per category (natural units of independent.random_effect) and the target
# magnitude at which >= 90 % must be detected (issue 11)
GRID: dict[str, tuple[list[float], float]] = {
    "gradient": ([2.0, 4.0, 8.0], 4.0),  # permille
    "wheel_radius": ([0.004, 0.008, 0.016], 0.008),  # fraction, one axle
    "pad_friction": ([0.05, 0.10, 0.20], 0.10),  # fraction off nominal
    "unmeasured_brake_force": ([1500.0, 3000.0, 6000.0], 3000.0),  # N
    "running_resistance": ([1.5, 2.0, 3.0], 2.0),  # factor
    "pressure_lag": ([0.1, 0.2, 0.4], 0.2),  # s, a dead time
    "pressure_time_constant": ([0.15, 0.3, 0.6], 0.3),  # s, a first-order lag
    "sensor_scale": ([0.0075, 0.015, 0.03], 0.015),  # fraction
    "sensor_lag": ([0.1, 0.2, 0.4], 0.2),  # s
    "load_transfer": ([1.5, 2.0, 3.0], 2.0),  # factor
    "adhesion_position": ([0.15, 0.30, 0.50], 0.50),  # fractional change of mu (+-)
    # the rail gets better part-way (a factor >= 1.5: the wheels stop sliding there), at a
    # random position; what remains to see is the censored evidence
    "rail_gets_better": ([1.5, 2.0, 3.0], 2.0),  # factor on mu beyond the change
}
# each category's seeds come from its place in this list (``seed_index``), not in ``GRID``: a
# row added later goes at its end and leaves every other row's traces as they were
SEED_ORDER = ["gradient", "wheel_radius", "pad_friction", "unmeasured_brake_force",
              "running_resistance", "pressure_lag", "sensor_scale", "sensor_lag",
              "load_transfer", "adhesion_position", "rail_gets_better",
              "pressure_time_constant"]  # fmt: skip


def seed_index(category: str) -> int:
    """The category's place in ``SEED_ORDER`` (its traces' seeds)."""
    return SEED_ORDER.index(category)


PAIRS = [
    (("pad_friction", 0.15), ("pressure_lag", 0.3)),
    (("gradient", 6.0), ("wheel_radius", 0.012)),
    (("unmeasured_brake_force", 4000.0), ("pressure_lag", 0.3)),
    (("gradient", 6.0), ("sensor_scale", 0.02)),
    (("pressure_lag", 0.15), ("pressure_time_constant", 0.3)),  # both lag shapes at once
]
# the loop's category for each generator category, and the parameter compared
LOOP_CATEGORY = {"sensor_scale": "sensor", "sensor_lag": "sensor",
                 "pressure_time_constant": "pressure_lag",
                 "rail_gets_better": "adhesion_position"}  # fmt: skip
# a lag is found in its shape: the parameter the loop's pressure lag must carry
SHAPE_KEY = {"pressure_lag": "lag_s", "pressure_time_constant": "time_constant_s",
             "sensor_scale": "speed_scale_error", "sensor_lag": "speed_lag_s"}  # fmt: skip
LAG_KEYS = ("lag_s", "time_constant_s")  # a pressure lag's parameters (its shape)


def lag_keys(effects: list[Any]) -> set[str]:
    """The pressure-lag parameters the trace's true effects give (its shape)."""
    return {SHAPE_KEY[e.category] for e in effects
            if LOOP_CATEGORY.get(e.category, e.category) == "pressure_lag"}  # fmt: skip


# Adhesion effects are seen only where the wheels reach the adhesion limit: on a wet or dry rail
# an emergency stop hardly slides, the adhesion channel has no evidence and the effect is
# unobservable by any method. Their scenarios draw a low-adhesion contaminant (the generator's
# soap / leaves / oil, in its own proportions), from a generator of their own so that every
# other draw of the scenario is unchanged.
ADHESION_CATEGORIES = ("load_transfer", "adhesion_position", "adhesion_per_axle",
                       "rail_gets_better")  # fmt: skip
SLIDING_RAILS = (("soap", "leaves", "oil"), (0.45 / 0.7, 0.15 / 0.7, 0.1 / 0.7))
# a friction change is observable where some axle is past the friction curve's peak for this
# long on each side of it (generator truth); the loop has evidence there with this many of its
# critical points at a slide (SLIDE_POINT_KMH or more) on each side
OBSERVABLE_S = 1.0
OBSERVABLE_POINTS = 3
SLIDE_POINT_KMH = 1.0
TARGETS = {"false_positive_max": 0.02, "detection_min": 0.90, "pairs_min": 0.80}
# targets other than detection_min at the target magnitude (issue 25): a friction change along
# the rail at +-50 %, 60 %; load transfer x2 at 80 % on the traces that give the geometry; the
# unmeasured brake force (the choice against pads is declared ambiguous, not forced): 90 % in
# the named set (chosen or an alternative inside the tie margin)
CATEGORY_TARGETS = {"adhesion_position": ("detection_rate", 0.60),
                    "rail_gets_better": ("censored_rate", 0.90),
                    "load_transfer": ("with_geometry_rate", 0.80),
                    "unmeasured_brake_force": ("found_or_named_rate", 0.90)}  # fmt: skip


def target_of(cat: str) -> tuple[str, float]:
    """(the row's rate judged, the rate needed) at the category's target magnitude."""
    return CATEGORY_TARGETS.get(cat, ("detection_rate", TARGETS["detection_min"]))


# clean traces whose demand falls part-way (a driver easing the brake; the generator's
# ``demand_drop_s`` / ``demand_drop_factor``): seeds seed * 1e6 + this + k, apart from every
# category's and pair's
DEMAND_DROP_SEED_OFFSET = 900_000


def demand_drop_draw(seed: int) -> dict[str, float]:
    """When (a fraction of the stop's rough duration, ``V0 / (g mu)``) and to what share of
    itself the demand falls, from a stream of the seed's own."""
    r = np.random.default_rng([seed, 31])
    return {"fraction": float(r.uniform(0.2, 0.6)), "factor": float(r.uniform(0.3, 0.6))}


def with_demand_drop(scenario: Any, drop: dict[str, float]) -> Any:
    """``scenario`` with its demand falling to ``drop["factor"]`` at ``drop["fraction"]`` of the
    stop's rough duration at its contaminated level, ``V0 / (g mu)``."""
    duration_s = scenario.speed_kmh / 3.6 / (9.81 * scenario.mu_contaminated)
    return dataclasses.replace(scenario, demand_drop_s=drop["fraction"] * duration_s,
                               demand_drop_factor=drop["factor"])  # fmt: skip


def sliding_rail(seed: int) -> str:
    """The contaminant an adhesion-effect trace of ``seed`` is drawn on (``SLIDING_RAILS``),
    from its own stream: the scenario's other draws stay those of the seed."""
    names, p = SLIDING_RAILS
    return str(np.random.default_rng([seed, 7]).choice(names, p=p))


def _true_and_found(effect: Any, step: dict[str, Any], trace_meta: dict) -> tuple[float, float]:
    """(true value, found value) of the effect's main parameter, NaN where not comparable."""
    cat, p, q = effect.category, effect.params, step["parameters"]
    if cat == "gradient":
        return p["gradient_permille"], q.get("gradient_permille", math.nan)
    if cat == "wheel_radius":
        return p["radius_error"], q.get(f"axle_{int(p['axle'])}_radius_error", math.nan)
    if cat == "pad_friction":
        return p["scale"], q.get("scale", math.nan)
    if cat == "unmeasured_brake_force":
        return p["force_N"], q.get("force_at_full_demand_N", math.nan)
    if cat == "pressure_lag":
        return p["lag_s"], q.get("lag_s", math.nan)
    if cat == "pressure_time_constant":
        return p["time_constant_s"], q.get("time_constant_s", math.nan)
    if cat == "sensor_scale":
        return p["scale_error"], q.get("speed_scale_error", math.nan)
    if cat == "sensor_lag":
        return p["lag_s"], q.get("speed_lag_s", math.nan)
    if cat == "running_resistance":
        res = trace_meta["vehicle"].get("resistance") or {}
        v = 0.5 * float(trace_meta["initial_speed_kmh"]) / 3.6  # the stop's mean speed
        nominal = res.get("a_N", 0.0) + v * (res.get("b_N_per_mps", 0.0) + v * res.get(
            "c_N_per_mps2", 0.0))  # fmt: skip
        if "factor" in q:  # the metadata's R(V) scaled
            found = (q["factor"] - 1.0) * nominal
        else:
            found = q.get("delta_a_N", math.nan) + q.get("delta_c_N_per_mps2", 0.0) * v * v
        return (p["factor"] - 1.0) * nominal, found
    if cat == "adhesion_position":  # a censored reading (rail_better) is no fit: no error
        return p["factor"], math.nan if q.get("censored") else q.get("factor_beyond_step", math.nan)
    return math.nan, math.nan


def scaled_effect(
    ind: Any, category: str, magnitude: float, rng: np.random.Generator, sc: Any
) -> Any:
    """The generator's effect for a grid magnitude: pad friction and the rail's friction
    change are fractions off 1 here (weaker or stronger, rail worse or better: sign drawn),
    factors in the generator."""
    if category in ("pad_friction", "adhesion_position"):
        sign = 1.0 if rng.random() < 0.5 else -1.0
        return ind.random_effect(category, 1.0 + sign * magnitude, rng, sc)
    if category == "rail_gets_better":  # the generator's friction change, upwards only
        return ind.random_effect("adhesion_position", magnitude, rng, sc)
    return ind.random_effect(category, magnitude, rng, sc)


def _run_one(job: dict[str, Any]) -> dict[str, Any]:
    """Generate one trace, write it, read it back and run the loop (in a worker process)."""
    if multiprocessing.parent_process() is not None:  # a worker: one thread each; never the
        os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # caller's process (its threads run)
    from wsp_env.calibration import independent as ind
    from wsp_env.calibration.discovery import discover
    from wsp_env.calibration.traces import read_trace

    rng = np.random.default_rng(job["seed"])
    scenario = ind.random_scenario(rng, **job.get("overrides", {}))
    if job.get("demand_drop"):
        scenario = with_demand_drop(scenario, job["demand_drop"])
    effects = [scaled_effect(ind, c, m, rng, scenario) for c, m in job["effects"]]
    t0 = time.perf_counter()
    columns, meta = ind.generate(scenario, effects, seed=job["seed"])
    t_gen = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        csv_path, _ = ind.write_trace(Path(tmp) / "t", columns, meta)
        t1 = time.perf_counter()
        try:
            trace = read_trace(csv_path)
            result = discover(trace)
        except Exception as err:  # a crash is a finding, reported, not hidden
            return {**job, "error": f"{type(err).__name__}: {err}", "gen_s": t_gen}
        t_cal = time.perf_counter() - t1
    added = [s.as_dict() for s in result.added]
    rows = []
    for eff in effects:
        want = LOOP_CATEGORY.get(eff.category, eff.category)
        hits = [s for s in added if s["category"] == want]
        any_shape, other_form = bool(hits), False
        if eff.category in SHAPE_KEY:  # scale vs lag, dead time vs time constant: the
            key = SHAPE_KEY[eff.category]  # parameter tells them apart
            # found in another form, with this one declared as equally good
            other_form = any(key in a.get("parameters", {}) for s in hits
                             for a in s.get("alternative_fits", []))  # fmt: skip
            hits = [s for s in hits if key in s["parameters"]]
            if want == "pressure_lag":  # in its shape: exactly the trace's lag parameters (a
                truth = lag_keys(effects)  # dead time read as both shapes is no finding)
                hits = [s for s in hits if set(s["parameters"]) & set(LAG_KEYS) == truth]
        if eff.category == "adhesion_position":  # a change found the wrong way is no finding
            up = eff.params["factor"] > 1.0
            hits = [s for s in hits
                    if (s["parameters"].get("factor_beyond_step", 1.0) > 1.0) == up]  # fmt: skip
        # a choice made inside the tie margin: the effect found while another explains as
        # well, or another chosen while this one is named among its equally good alternatives
        # (the trace could not tell them apart: "named", reported beside the detection rate,
        # never counted in it)
        if hits:
            tied = {c for alt in hits[0]["alternatives"] for c in alt.split("+")} - {want}
        else:
            tied = {s["category"] for s in added
                    if any(want in alt.split("+") for alt in s["alternatives"])}  # fmt: skip
        row = {"category": eff.category, "found": bool(hits),
               "named": bool(hits or tied or other_form),
               "alone": bool(hits) and not hits[0].get("ambiguous", False),
               "category_found": any_shape, "tied_with": sorted(tied),
               "true": math.nan, "value": math.nan, "cut": math.nan}  # fmt: skip
        if hits:
            true, value = _true_and_found(eff, hits[0], meta)
            row.update(true=true, value=value, cut=1.0 - hits[0]["after"] / hits[0]["before"])
        rows.append(row)
    # the adhesion candidates' fits whether added or not (their first round): how often the
    # loop could try them at all, and what they read against the truth
    adhesion_fits = {}
    for cat in ("load_transfer", "adhesion_position"):
        row = next((c for c in result.considered if c["category"] == cat), None)
        if row is not None and "parameters" in row:
            adhesion_fits[cat] = row["parameters"]
    true_pitch = _true_bogie_pitch(scenario, effects)
    step = next((e for e in effects if e.category == "adhesion_position"), None)
    evidence = None if step is None else _step_evidence(ind, scenario, effects, step, job["seed"],
                                                        trace)  # fmt: skip
    expected = {LOOP_CATEGORY.get(e.category, e.category) for e in effects}
    extra = [s["category"] for s in added if s["category"] not in expected]
    return {**job, "effects_found": rows, "added": [s["category"] for s in added],
            "extra": extra, "gen_s": t_gen, "calibrate_s": t_cal,
            "n_axles": scenario.n_axles, "speed_kmh": scenario.speed_kmh,
            "lead_in_s": scenario.lead_in_s, "contaminant": scenario.contaminant,
            "adhesion_fits": adhesion_fits, "true_bogie_pitch_kN_per_mps2": true_pitch,
            "step_evidence": evidence,
            "pivot_in_metadata": scenario.pivot_in_metadata and scenario.geometry_in_metadata,
            "effect_params": [e.params for e in effects]}  # fmt: skip


def _step_evidence(ind: Any, scenario: Any, effects: list[Any], step: Any, seed: int,
                   trace: Any) -> dict[str, float]:  # fmt: skip
    """What a friction change along the rail leaves to be seen, on each side of it: seconds
    during which some axle is past the friction curve's peak (the generator's truth,
    ``independent.sliding_around``), and the loop's critical points at a slide (sliding by
    ``SLIDE_POINT_KMH`` or more: the points that bear on the rail's level, not the creep curve's
    initial slope), placed by the train's distance run since the brake application."""
    from wsp_env.calibration.adhesion_estimate import pooled_points
    from wsp_env.calibration.residuals import MIN_SPEED_KMH

    position = float(step.params["position_m"])
    before_s, after_s = ind.sliding_around(scenario, effects, position, seed=seed)
    run_m = trace.distance_m()
    x_brake = float(np.interp(scenario.lead_in_s, trace.time_s, run_m))
    pts = pooled_points(trace, MIN_SPEED_KMH)
    at_slide = pts.sliding_kmh >= SLIDE_POINT_KMH
    xi = pts.position_m - x_brake
    return {"past_peak_s_before": before_s, "past_peak_s_after": after_s,
            "points_before": int(np.sum(at_slide & (xi < position))),
            "points_after": int(np.sum(at_slide & (xi >= position)))}  # fmt: skip


def _true_bogie_pitch(scenario: Any, effects: list[Any]) -> float:
    """The generator's bogie pitch per axle (kN per m/s^2, the cars' mean), times any load
    transfer factor, less what the metadata declares: what the loop's
    ``bogie_pitch_kN_per_mps2`` measures (a trace that gives the pivot height declares the
    nominal pitch, computed the generator's way by the reader; one without leaves it all)."""
    factor = math.prod(e.params["factor"] for e in effects if e.category == "load_transfer")
    car_mass = 4000.0 * float(np.mean(scenario.car_axle_load_t))
    pitch = car_mass * scenario.bogie_pivot_height_m / (2.0 * scenario.bogie_wheelbase_m)
    declared = pitch if (scenario.pivot_in_metadata and scenario.geometry_in_metadata) else 0.0
    return (factor * pitch - declared) / 1e3


def _jobs(args: argparse.Namespace) -> list[dict[str, Any]]:
    cats = args.categories.split(",") if args.categories else list(GRID)
    jobs = []
    seed = args.seed * 1_000_000
    for k in range(args.clean):
        jobs.append({"kind": "clean", "effects": [], "seed": seed + k})
    for k in range(args.demand_drop):  # clean, but the demand falls part-way: the slides stop
        s = seed + DEMAND_DROP_SEED_OFFSET + k
        jobs.append({"kind": "clean_demand_drop", "effects": [], "seed": s,
                     "overrides": {"contaminant": sliding_rail(s)},
                     "demand_drop": demand_drop_draw(s)})  # fmt: skip
    for cat in cats:
        ci = seed_index(cat)  # a subset draws the full study's seeds
        for mi, mag in enumerate(GRID[cat][0]):
            for k in range(args.scenarios):
                s = seed + 10_000 * (ci + 1) + 1000 * mi + k
                job = {"kind": "single", "category": cat, "magnitude": mag,
                       "effects": [(cat, mag)], "seed": s}  # fmt: skip
                if cat in ADHESION_CATEGORIES:
                    job["overrides"] = {"contaminant": sliding_rail(s)}
                jobs.append(job)
    for pi, pair in enumerate(PAIRS if args.pairs else []):
        for k in range(args.pairs):
            s = seed + 500_000 + 1000 * pi + k
            jobs.append({"kind": "pair", "pair": pi, "effects": list(pair), "seed": s})
    return jobs


def summarise(results: list[dict[str, Any]]) -> dict[str, Any]:
    """The power table (module docstring) from the per-trace results."""
    ok = [r for r in results if "error" not in r]
    clean = [r for r in ok if r["kind"] == "clean"]
    out: dict[str, Any] = {
        "traces": len(results),
        "errors": [
            {k: r.get(k) for k in ("kind", "effects", "seed", "error")}
            for r in results
            if "error" in r
        ],
        "clean": {
            "n": len(clean),
            "false_positive_rate": float(np.mean([bool(r["added"]) for r in clean]))
            if clean
            else math.nan,
            "added": sorted({c for r in clean for c in r["added"]}),
            "bogie_pitch_fit_minus_true": clean_pitch_readings(clean),
        },
        "categories": {},
        "pairs": [],
        "calibrate_s_median": float(np.median([r["calibrate_s"] for r in ok])) if ok else 0.0,
        "calibrate_s_max": float(np.max([r["calibrate_s"] for r in ok])) if ok else 0.0,
        "generate_s_median": float(np.median([r["gen_s"] for r in ok])) if ok else 0.0,
    }
    dropped = [r for r in ok if r["kind"] == "clean_demand_drop"]
    out["clean_demand_drop"] = {
        "n": len(dropped),
        "false_positive_rate": float(np.mean([bool(r["added"]) for r in dropped]))
        if dropped
        else math.nan,
        "added": sorted({c for r in dropped for c in r["added"]}),
    }
    singles = [r for r in ok if r["kind"] == "single"]
    for cat in dict.fromkeys(r["category"] for r in singles):
        rows = []
        for mag in GRID[cat][0]:
            rs = [r for r in singles if r["category"] == cat and r["magnitude"] == mag]
            if not rs:
                continue
            eff = [r["effects_found"][0] for r in rs]
            found = [e for e in eff if e["found"]]
            rel = [
                abs(e["value"] - e["true"]) / abs(e["true"])
                for e in found
                if math.isfinite(e["value"]) and math.isfinite(e["true"]) and e["true"] != 0
            ]
            rows.append({
                "magnitude": mag,
                "n": len(rs),
                "detection_rate": len(found) / len(rs),
                "found_or_named_rate": float(np.mean([e.get("named", e["found"]) for e in eff])),
                "alone_rate": float(np.mean([e.get("alone", e["found"]) for e in eff])),
                "category_rate": float(np.mean([e.get("category_found", e["found"])
                                                for e in eff])),
                "geometry": _by_geometry(rs),
                "with_geometry_rate": _by_geometry(rs).get("with", {}).get("detection_rate",
                                                                              math.nan),
                "tied_rate": float(np.mean([bool(e.get("tied_with")) for e in eff])),
                "tied": int(sum(bool(e.get("tied_with")) for e in eff)),
                "tied_won": int(sum(bool(e.get("tied_with")) and e["found"] for e in eff)),
                "tied_with": dict(collections.Counter(c for e in eff
                                                      for c in e.get("tied_with", []))),
                "param_rel_error_median": float(np.median(rel)) if rel else math.nan,
                "cut_median": float(np.median([e["cut"] for e in found])) if found else math.nan,
                "extra_effect_rate": float(np.mean([bool(r["extra"]) for r in rs])),
                "extra": sorted({c for r in rs for c in r["extra"]}),
                **_on_sliding_rails(rs, lambda r: r["effects_found"][0]["found"]),
            })  # fmt: skip
            if cat == "rail_gets_better":
                rows[-1].update(_censored_rate(rs))
            if cat in ("load_transfer", "adhesion_position"):
                rows[-1].update(_adhesion_readings(cat, rs))
                sliding = [r for r in clean if r.get("contaminant") in SLIDING_RAILS[0]]
                if cat == "load_transfer" and sliding:  # like for like: the effect's rails
                    rows[-1]["pitch_threshold"] = pitch_threshold(sliding, rs)
                    geo = [r for r in sliding if r.get("pivot_in_metadata")]
                    geo_rs = [r for r in rs if r.get("pivot_in_metadata")]
                    if geo and geo_rs:  # the nominal pitch declared: a departure stands alone
                        rows[-1]["pitch_threshold_geometry"] = pitch_threshold(geo, geo_rs)
        detected = [row["magnitude"] for row in rows if row["detection_rate"] >= 0.9]
        target = GRID[cat][1]
        at_target = [row for row in rows if row["magnitude"] == target]
        rate_key, needed = target_of(cat)
        out["categories"][cat] = {
            "rows": rows,
            "smallest_90pct": min(detected) if detected else None,
            "target_magnitude": target,
            "target_met": bool(at_target and at_target[0].get(rate_key, math.nan) >= needed),
            "target_rate": [rate_key, needed],
        }
    pairs = [r for r in ok if r["kind"] == "pair"]
    for pi in sorted({r["pair"] for r in pairs}):
        rs = [r for r in pairs if r["pair"] == pi]
        both = [all(e["found"] for e in r["effects_found"]) for r in rs]
        out["pairs"].append({
            "effects": [list(e) for e in PAIRS[pi]],
            "n": len(rs),
            "both_found_rate": float(np.mean(both)),
            "first_only_rate": float(np.mean([r["effects_found"][0]["found"] and not
                                              r["effects_found"][1]["found"] for r in rs])),
            **_on_sliding_rails(rs, lambda r: all(e["found"] for e in r["effects_found"])),
        })  # fmt: skip
    return out


def _on_sliding_rails(
    rs: list[dict[str, Any]], hit: Callable[[dict[str, Any]], bool]
) -> dict[str, float]:
    """The rate of ``hit`` on the traces drawn on a rail where an emergency stop slides
    (``SLIDING_RAILS``: soap, leaves, oil), where the wheels can name a pressure lag's shape; on
    wet and dry rail they hardly slide and the balance alone cannot tell the shapes apart."""
    sub = [r for r in rs if r.get("contaminant") in SLIDING_RAILS[0]]
    if not sub:
        return {"sliding_n": 0.0, "sliding_rate": math.nan}
    return {"sliding_n": float(len(sub)),
            "sliding_rate": float(np.mean([bool(hit(r)) for r in sub]))}  # fmt: skip


def _censored_rate(rs: list[dict[str, Any]]) -> dict[str, float]:
    """A rail that gets better, on the traces where only censored evidence can show it (issue
    25 item 4): some axle past the friction curve's peak for ``OBSERVABLE_S`` or more before the
    change and for less after it (no slide to fit there; the generator's truth,
    ``step_evidence``); the rate found there."""
    sub = [r for r in rs if r.get("step_evidence")
           and r["step_evidence"]["past_peak_s_before"] >= OBSERVABLE_S
           and r["step_evidence"]["past_peak_s_after"] < OBSERVABLE_S]  # fmt: skip
    return {"censored_n": float(len(sub)),
            "censored_rate": float(np.mean([r["effects_found"][0]["found"] for r in sub]))
            if sub else math.nan}  # fmt: skip


def _pct(rate: float) -> str:
    return "—" if not math.isfinite(rate) else f"{100 * rate:.0f} %"


def _rate(row: dict[str, Any]) -> str:
    """A row's rate on sliding rails as text ("—" where none of its traces is on one)."""
    return _pct(row.get("sliding_rate", math.nan))


def _by_geometry(rs: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Detection on the traces whose metadata gives the bogie pivot height (the full geometry)
    and on those without it."""
    out = {}
    for key, want in (("with", True), ("without", False)):
        sub = [r for r in rs if bool(r.get("pivot_in_metadata")) is want]
        if sub:
            out[key] = {"n": len(sub), "detection_rate": float(np.mean(
                [r["effects_found"][0]["found"] for r in sub]))}  # fmt: skip
    return out


def _adhesion_readings(cat: str, rs: list[dict[str, Any]]) -> dict[str, Any]:
    """How often the adhesion candidate could be fitted at all (enough slides, evidence on
    both sides of a step) and what it read, added or not: the fitted bogie pitch against the
    truth (kN per m/s^2), the fitted factor beyond a step against the truth."""
    key = "bogie_pitch_kN_per_mps2" if cat == "load_transfer" else "factor_beyond_step"
    fits = [r["adhesion_fits"][cat][key] for r in rs if cat in r.get("adhesion_fits", {})]
    if cat == "load_transfer":
        truth = [r["true_bogie_pitch_kN_per_mps2"] for r in rs if cat in r["adhesion_fits"]]
    else:
        truth = [r["effect_params"][0]["factor"] for r in rs if cat in r["adhesion_fits"]]
    err = [abs(f - t) for f, t in zip(fits, truth, strict=True)]
    out = {
        "tried_rate": len(fits) / len(rs),
        "fitted_abs_error_median": float(np.median(err)) if err else math.nan,
    }
    ev = [r["step_evidence"] for r in rs if r.get("step_evidence")]
    if ev:  # a step: is there anything to see on both sides, in truth and for the loop
        out["past_peak_both_sides_rate"] = float(
            np.mean(
                [min(e["past_peak_s_before"], e["past_peak_s_after"]) >= OBSERVABLE_S for e in ev]
            )
        )
        out["points_both_sides_rate"] = float(
            np.mean([min(e["points_before"], e["points_after"]) >= OBSERVABLE_POINTS for e in ev])
        )
        out["points_before_median"] = float(np.median([e["points_before"] for e in ev]))
    return out


def pitch_threshold(clean: list[dict[str, Any]], rs: list[dict[str, Any]]) -> dict[str, Any]:
    """The most a threshold on the fitted bogie pitch could detect: over thresholds that at
    most ``TARGETS['false_positive_max']`` of the clean traces reach (a trace where it could
    not be fitted reaches none), the largest share of ``rs`` reaching it."""

    def pitches(rows: list[dict[str, Any]]) -> np.ndarray:
        return np.array([r["adhesion_fits"]["load_transfer"]["bogie_pitch_kN_per_mps2"]
                         if "load_transfer" in r.get("adhesion_fits", {}) else -np.inf
                         for r in rows])  # fmt: skip

    c, e = pitches(clean), pitches(rs)
    best: dict[str, Any] = {"detection": 0.0, "threshold": math.inf, "clean": len(clean)}
    for th in np.unique(np.concatenate([c[np.isfinite(c)], e[np.isfinite(e)]])):
        if (
            np.mean(c >= th) <= TARGETS["false_positive_max"]
            and np.mean(e >= th) > best["detection"]
        ):
            best.update(detection=float(np.mean(e >= th)), threshold=float(th))
    return best


def clean_pitch_readings(results: list[dict[str, Any]]) -> dict[str, Any]:
    """On clean traces: the fitted bogie pitch less the generator's undeclared one (kN per
    m/s^2), where the loop could fit it: the scatter a load transfer must stand out of; and per
    rail (``by_rail``: n, min, median, max), since a rail the sliding axles clean (soap, leaves)
    may add a leading/trailing pattern of its own that a rail hard to clean (oil) does not."""
    fitted = [
        r
        for r in results
        if r.get("kind") == "clean" and "load_transfer" in r.get("adhesion_fits", {})
    ]
    diff = [r["adhesion_fits"]["load_transfer"]["bogie_pitch_kN_per_mps2"]
            - r["true_bogie_pitch_kN_per_mps2"] for r in fitted]  # fmt: skip
    if not diff:
        return {"n": 0}
    q = np.percentile(diff, [5, 50, 95])
    by_rail: dict[str, dict[str, float]] = {}
    for rail in sorted({r["contaminant"] for r in fitted}):
        d = [x for x, r in zip(diff, fitted, strict=True) if r["contaminant"] == rail]
        by_rail[rail] = {"n": len(d), "min": float(np.min(d)), "median": float(np.median(d)),
                         "max": float(np.max(d))}  # fmt: skip
    return {"n": len(diff), "p5": float(q[0]), "median": float(q[1]), "p95": float(q[2]),
            "by_rail": by_rail}  # fmt: skip


def print_table(summary: dict[str, Any]) -> None:
    c = summary["clean"]
    print(f"clean traces: {c['n']}, false positives {100 * c['false_positive_rate']:.1f} % "
          f"(target <= {100 * TARGETS['false_positive_max']:g} %) {c['added']}")  # fmt: skip
    d = summary.get("clean_demand_drop", {})
    if d.get("n"):
        print(f"clean traces whose demand falls part-way: {d['n']}, false positives "
              f"{100 * d['false_positive_rate']:.1f} % {d['added']}")  # fmt: skip
    pitch = c.get("bogie_pitch_fit_minus_true", {})
    if pitch.get("n"):
        print(f"clean traces' bogie pitch, fitted less the generator's (kN per m/s^2, "
              f"{pitch['n']} fitted): median {pitch['median']:+.1f}, 5-95 % "
              f"{pitch['p5']:+.1f} .. {pitch['p95']:+.1f}")  # fmt: skip
        print("    by rail: " + "; ".join(
            f"{rail} {v['n']}: {v['min']:+.1f} .. {v['max']:+.1f} (median {v['median']:+.1f})"
            for rail, v in pitch.get("by_rail", {}).items()))  # fmt: skip
    print(f"{'category':24s} {'magnitude':>10s} {'n':>4s} {'detect':>7s} {'or alt':>7s} "
          f"{'alone':>6s} {'param err':>9s} {'cut':>6s} {'extra':>6s}")  # fmt: skip
    for cat, info in summary["categories"].items():
        for row in info["rows"]:
            mark = " <- target" if row["magnitude"] == info["target_magnitude"] else ""
            err = 100 * row["param_rel_error_median"]
            print(f"{cat:24s} {row['magnitude']:10.4g} {row['n']:4d} "
                  f"{100 * row['detection_rate']:6.0f}% "
                  f"{100 * row['found_or_named_rate']:6.0f}% "
                  f"{100 * row.get('alone_rate', math.nan):5.0f}% {err:8.0f}% "
                  f"{100 * row['cut_median']:5.0f}% {100 * row['extra_effect_rate']:5.0f}%{mark}"
                  f"{' ' + ','.join(row['extra']) if row['extra'] else ''}")  # fmt: skip
        for row in info["rows"]:
            if cat.startswith("pressure_") and row["category_rate"] != row["detection_rate"]:
                print(f"{'':24s} {row['magnitude']:10.4g}: a pressure lag of any shape "
                      f"{100 * row['category_rate']:.0f} %")  # fmt: skip
            if cat.startswith("pressure_") and row.get("sliding_n"):
                print(f"{'':24s} {row['magnitude']:10.4g}: in its shape on sliding rails "
                      f"{100 * row['sliding_rate']:.0f} % (n {row['sliding_n']:.0f})")  # fmt: skip
            geo = row.get("geometry", {})
            if cat == "load_transfer" and geo:
                print(f"{'':24s} {row['magnitude']:10.4g}: " + "; ".join(
                    f"{k} the pivot height in the metadata {100 * v['detection_rate']:.0f} % "
                    f"(n {v['n']})" for k, v in geo.items()))  # fmt: skip
                thg = row.get("pitch_threshold_geometry")
                if thg:
                    print(f"{'':24s} {'':10s}  with it, a threshold on the fitted departure "
                          f"that <= {100 * TARGETS['false_positive_max']:g} % of the "
                          f"{thg['clean']} clean traces with it reach finds "
                          f"{100 * thg['detection']:.0f} % "
                          f"(at {thg['threshold']:.1f})")  # fmt: skip
            if "tried_rate" in row:
                th = row.get("pitch_threshold")
                at = (f"; a threshold on it that <= {100 * TARGETS['false_positive_max']:g} % "
                      f"of the {th['clean']} clean traces on sliding rails reach finds "
                      f"{100 * th['detection']:.0f} % (at {th['threshold']:.1f})"
                      if th else "")  # fmt: skip
                print(f"{'':24s} {row['magnitude']:10.4g}: fitted at all on "
                      f"{100 * row['tried_rate']:.0f} %, |fitted - true| median "
                      f"{row['fitted_abs_error_median']:.3g}{at}")  # fmt: skip
            if "censored_n" in row:
                rate = row["censored_rate"]
                print(f"{'':24s} {row['magnitude']:10.4g}: past the peak >= {OBSERVABLE_S:g} s "
                      f"before the change, less after (truth) on {row['censored_n']:.0f} of "
                      f"{row['n']}; found there {_pct(rate)}")  # fmt: skip
            if "past_peak_both_sides_rate" in row:
                print(f"{'':24s} {'':10s}  past the curve's peak >= {OBSERVABLE_S:g} s on both "
                      f"sides (truth) {100 * row['past_peak_both_sides_rate']:.0f} %; >= "
                      f"{OBSERVABLE_POINTS} critical points at a slide (>= {SLIDE_POINT_KMH:g} "
                      f"km/h) on both sides "
                      f"{100 * row['points_both_sides_rate']:.0f} % (median before the "
                      f"change {row['points_before_median']:.0f})")  # fmt: skip
        for row in info["rows"]:
            if row["magnitude"] == info["target_magnitude"] and row.get("tied_rate"):
                rivals = ", ".join(
                    f"{c} {n}" for c, n in sorted(row["tied_with"].items(), key=lambda kv: -kv[1])
                )
                print(f"{'':24s} {row['magnitude']:10.4g}: decided inside the tie margin on "
                      f"{100 * row['tied_rate']:.0f} % (won {row['tied_won']} of those "
                      f"{row['tied']}; tied with: {rivals})")  # fmt: skip
        print(f"{'':24s} smallest detected >= 90 %: {info['smallest_90pct']}")
    for p in summary["pairs"]:
        print(f"pair {p['effects']}: both found {100 * p['both_found_rate']:.0f} % "
              f"(first only {100 * p['first_only_rate']:.0f} %), n {p['n']}; on sliding rails "
              f"{_rate(p)} (n {p['sliding_n']:.0f})")  # fmt: skip
    print(f"calibrate per trace: median {summary['calibrate_s_median']:.2f} s, "
          f"max {summary['calibrate_s_max']:.2f} s; generate median "
          f"{summary['generate_s_median']:.2f} s; errors {len(summary['errors'])}")  # fmt: skip


UNITS = {
    "gradient": "permille",
    "wheel_radius": "fraction, one axle",
    "pad_friction": "fraction",
    "unmeasured_brake_force": "N",
    "running_resistance": "factor",
    "pressure_lag": "s, dead time",
    "pressure_time_constant": "s, first order",
    "sensor_scale": "fraction",
    "sensor_lag": "s",
    "load_transfer": "factor",
    "adhesion_position": "fraction of mu",
    "rail_gets_better": "factor on mu",
}


def _met_text(cat: str, info: dict[str, Any]) -> str:
    """'yes' / 'no', naming the rate judged where it is not the detection at 90 %."""
    key, needed = info.get("target_rate", target_of(cat))
    words = {"detection_rate": "detected", "with_geometry_rate": "detected with geometry",
             "found_or_named_rate": "in the named set",
             "censored_rate": "detected where no axle is past the peak for 1 s after the "
                              "change"}  # fmt: skip
    verdict = "yes" if info["target_met"] else "no"
    if (key, needed) == ("detection_rate", TARGETS["detection_min"]):
        return verdict
    return f"{verdict} ({words[key]} >= {100 * needed:.0f} %)"


def markdown_table(summary: dict[str, Any]) -> str:
    """The study as Markdown: per category at its target magnitude, then pairs and clean traces."""
    target = TARGETS["detection_min"]
    lines = [
        f"Per category at its target magnitude (detection target {100 * target:.0f} % unless "
        "*met* says otherwise); *or alt*: "
        "chosen, or named among the chosen effect's equally good `alternatives` (never counted "
        "as detected); *alone*: detected and not declared ambiguous (no alternative inside the "
        "tie margin); *extra*: traces where another effect was added as well. A pressure lag is "
        "detected in its shape: with exactly its parameters (a dead time's `lag_s`, a first-order "
        "lag's `time_constant_s`, both for both).",
        "",
        "| category | target (unit) | n | detected | or alt | alone | smallest at >= 90 % "
        "| parameter error | extra | met |",
        "|---|---|---:|---:|---:|---:|---|---:|---:|---|",
    ]
    for cat, info in summary["categories"].items():
        rows = [r for r in info["rows"] if r["magnitude"] == info["target_magnitude"]]
        if not rows:
            continue
        r = rows[0]
        err = r["param_rel_error_median"]
        err_text = "—" if err is None or not math.isfinite(err) else f"{100 * err:.0f} %"
        smallest = info["smallest_90pct"]
        lines.append(
            f"| {cat} | {info['target_magnitude']:g} ({UNITS.get(cat, '')}) | {r['n']} | "
            f"{100 * r['detection_rate']:.0f} % | {100 * r['found_or_named_rate']:.0f} % | "
            f"{100 * r.get('alone_rate', math.nan):.0f} % | "
            f"{'—' if smallest is None else f'{smallest:g}'} | {err_text} | "
            f"{100 * r['extra_effect_rate']:.0f} % | "
            f"{_met_text(cat, info)} |"
        )
    if summary["pairs"]:
        lines += ["", f"Pairs, both found (target {100 * TARGETS['pairs_min']:.0f} %):", ""]
        lines += [
            f"- {' + '.join(map(str, p['effects']))}: {100 * p['both_found_rate']:.0f} % "
            f"(n {p['n']}; on sliding rails {_rate(p)} of "
            f"{p['sliding_n']:.0f})"
            for p in summary["pairs"]
        ]
    lags = [(cat, r) for cat, info in summary["categories"].items() if cat.startswith("pressure_")
            for r in info["rows"] if r["magnitude"] == info["target_magnitude"]]  # fmt: skip
    if lags:
        lines += ["", "A pressure lag's shape on the traces drawn on sliding rails (soap, leaves, "
                  "oil; on wet and dry rail the wheels hardly slide, and the balance alone cannot "
                  "tell a dead time from a first-order lag: the other shape is then named as an "
                  "equally good alternative): " + "; ".join(
                      f"{cat} {_rate(r)} of {r['sliding_n']:.0f}"
                      for cat, r in lags) + "."]  # fmt: skip
    better = [r for cat, info in summary["categories"].items() if cat == "rail_gets_better"
              for r in info["rows"]]  # fmt: skip
    if better:
        lines += ["", "A rail that gets better, on the traces where only censored evidence can "
                  "show it (some axle past the friction curve's peak for >= "
                  f"{OBSERVABLE_S:g} s before the change and for less after, the generator's "
                  "truth): "
                  + "; ".join(f"x{r['magnitude']:g} {_pct(r['censored_rate'])} of "
                              f"{r['censored_n']:.0f}" for r in better) + "."]  # fmt: skip
    c = summary["clean"]
    d = summary.get("clean_demand_drop", {})
    lines += [
        "",
        f"False positives (any effect added to a clean trace; target <= "
        f"{100 * TARGETS['false_positive_max']:g} %): {100 * c['false_positive_rate']:.1f} % of "
        f"{c['n']}"
        + (
            f"; on {d['n']} clean traces whose demand falls part-way (the slides stop for that "
            f"reason): {100 * d['false_positive_rate']:.1f} %"
            if d.get("n")
            else ""
        )
        + ".",
        "",
        f"Calibration per trace: median {summary['calibrate_s_median']:.2f} s, max "
        f"{summary['calibrate_s_max']:.2f} s; {summary['traces']} traces.",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", type=int, default=20)
    ap.add_argument("--clean", type=int, default=50)
    ap.add_argument("--pairs", type=int, default=20)
    ap.add_argument(
        "--demand-drop",
        type=int,
        default=30,
        help="clean traces whose demand falls part-way (false positives)",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--categories", default="", help="comma-separated subset of the grid")
    ap.add_argument("--json", dest="json_path", default=None)
    ap.add_argument("--markdown", default=None, help="write the tables here (.md)")
    args = ap.parse_args(argv)
    unknown = set(filter(None, args.categories.split(","))) - set(GRID)
    if unknown:
        print(f"--categories: unknown {sorted(unknown)}; known {sorted(GRID)}", file=sys.stderr)
        return 2
    jobs = _jobs(args)
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        results = list(pool.map(_run_one, jobs, chunksize=4))
    summary = summarise(results)
    summary["wall_s"] = time.perf_counter() - t0
    summary["command"] = " ".join(["scripts/calibration_power.py", *(argv or sys.argv[1:])])
    with tee_stdout() as printed:
        print_table(summary)
        print(f"wall time {summary['wall_s']:.0f} s for {len(jobs)} traces")
    if args.markdown:
        body = f"{markdown_table(summary)}\n\nThe whole printout:\n\n{fenced(printed.getvalue())}"
        title = "Calibration: detection power on independent traces"
        write_results(args.markdown, title, body, summary["wall_s"])
        print(f"wrote {args.markdown}")
    if args.json_path:
        path = Path(args.json_path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps({"summary": summary, "results": results}, indent=1,
                                  default=float))  # fmt: skip
        tmp.replace(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

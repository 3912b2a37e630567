"""The benchmark: a sealed test set per vehicle and sensor tier, one score, failures found
(``wsp-env benchmark``; docs/benchmark.md).

**The sealed set** (``sealed_runs``): ``SEALED_RUNS`` (300) stops per vehicle, each a seed of
``SEALED_SEEDS`` and nothing else: the registered id's environment (``envs.tiers``) draws every
condition from its distribution — rail (all six, ``soap_etr1000`` included), pattern and level,
speed 40 km/h to the vehicle's maximum, gradient within +-25 per mille, load tare to laden, pad
friction, emergency or service demand, and the stop's sensor errors. The seeds lie far from any
suite's (``tests/test_benchmark.py`` checks that no seed, case name or adhesion level is shared
with ``tuning``, ``validation``, ``en15595``, ``heldout`` or any other suite). Nothing was tuned or
selected on it; keep it that way (tune on ``tuning``, select on ``validation``).

**The development set** (``STOP_SETS["development"]``, ``wsp-env benchmark --stops
development``): another 300 seeds of the same distribution, shared with neither the sealed set
nor any suite (the same test). Score, diagnose and select on it as often as needed; the sealed
set is for the result of record.

**The score** (``score``): every policy runs the same stops through one code path
(``runner.run_runs``) with the same sensors and the same safety watchdog. Per stop, the default
reward's undiscounted return ``R`` (minus the stop's cost in metres / 100: distance, wheel
damage, locks, air). The tier's classical WSP gains ``G = R_classical - R_none`` over locked
wheels; where it gains at least ``MIN_GAIN`` (0.05: 5 m), a policy's normalised score is
``s = (R_policy - R_none) / G`` — 0 for locked wheels, 1 for the classical WSP — and the policy's
score is their **interquartile mean** with a 95 % percentile-bootstrap interval over stops
(``BOOTSTRAP`` resamples; the IQM as rliable computes it: the mean of the middle half, robust to
the few stops where ``G`` is small). Stops where the classical WSP gains less (dry rail, where it
rightly does nothing) are reported apart: the policy's mean return gain there, in metres.

Beside the score, per policy: the stop ratio to the classical WSP (mean and worst, with the worst
stop's conditions), the pass rate under the damage criteria (``DAMAGE_CRITERIA``: lock, sliding
energy per axle, slide duration; and stopped), sliding energy, longest lock, maximum sliding
speed, air, valve operations per axle, watchdog interventions, the shared reference's error;
the same per scenario family (rail, gradient sign, speed band).

**The upper reference** (``oracle``): per stop, the best of the privileged constant-slip sweep
(``baselines.oracle``) and both frozen classical WSPs, under the same damage criteria; the
report counts how often any other policy beats it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from wsp_env.core.config import VehicleConfig, load_vehicle
from wsp_env.envs.tiers import VERSION, benchmark_env_kwargs, check_tier, env_id
from wsp_env.evaluation.runner import run_runs
from wsp_env.evaluation.suites import Run

SEALED_RUNS = 300
SEALED_SEED_BASE = 7_340_000  # sealed seeds: SEALED_SEED_BASE + i (no suite comes near)
# the stop sets of the benchmark's distribution: name -> (first seed, scenario-name prefix)
STOP_SETS = {"sealed": (SEALED_SEED_BASE, "sealed"), "development": (8_260_000, "dev")}
# kept in ``run_results`` beside each stop's distance and return (``keep_runs``)
RUN_FIGURES = ("sliding_energy_kJ", "air_litres", "max_lock_s", "max_sliding_kmh")
DAMAGE_CRITERIA = {"max_lock_s": 1.0, "max_axle_sliding_energy_pct": 25.0, "max_slide_s": 5.0}
MIN_GAIN = 0.05  # return units (x 100 m): the classical WSP's least gain for a scored stop
BOOTSTRAP = 2000
GRADIENT_LEVEL_PERMILLE = 2.0  # |gradient| below this is "level"
SPEED_BANDS_KMH = (100.0, 160.0)  # <100, 100-160, >=160
# the environment settings a policy may choose (its actions' meaning and what it derives from
# the tier's sensors); the tier fixes every other one
POLICY_KEYS = (
    "action_mode", "residual_scale", "residual_deadband", "valve_group", "slip_target_min_kmh",
    "slip_target_max_kmh", "slip_target_gain_per_kmh", "slip_target_lead_s",
    "slip_target_release", "slip_target_max_creep", "slip_target_drift_correction",
    "slip_target_gain_scale_floor", "slip_target_onset_drift", "slip_target_scale_calibration",
    "slip_target_onset_two_sided", "slip_target_lock_guard", "memory_features",
    "memory_target_mean",
)  # fmt: skip
RESERVED = ("none", "classical", "oracle")  # the score's ends and the upper reference


def sealed_seeds(n: int = SEALED_RUNS, stop_set: str = "sealed") -> list[int]:
    """The seeds of the first ``n`` stops of ``stop_set`` (``STOP_SETS``: the sealed set by
    default)."""
    if stop_set not in STOP_SETS:
        raise ValueError(f"stops: {stop_set!r} is not one of {', '.join(STOP_SETS)}")
    if not 1 <= n <= SEALED_RUNS:
        raise ValueError(f"runs: must be 1-{SEALED_RUNS}, got {n}")
    return [STOP_SETS[stop_set][0] + i for i in range(n)]


def sealed_runs(
    vehicle: VehicleConfig, n: int = SEALED_RUNS, stop_set: str = "sealed"
) -> list[Run]:
    """The first ``n`` stops of ``stop_set`` on ``vehicle``: seeds only (module docstring)."""
    seeds = sealed_seeds(n, stop_set)  # checks the set and the count first
    prefix = STOP_SETS[stop_set][1]
    return [
        Run(f"{prefix}_{i:03d}", seed, {}, dict(DAMAGE_CRITERIA), vehicle)
        for i, seed in enumerate(seeds)
    ]


def stop_set_note(payload: dict[str, Any]) -> str:
    """What a benchmark result's stops are when they are not the whole sealed set (empty when
    they are): for its printout and its report's title."""
    if payload.get("stops", "sealed") != "sealed":
        return f" ({payload['stops']} stops: not the sealed set, not a score of record)"
    return "" if payload["sealed"] else " (the first of the sealed set: not a score of record)"


def iqm(values: np.ndarray, axis: int = -1) -> np.ndarray:
    """Interquartile mean along ``axis``: the mean of the middle half (25 % trimmed at each end,
    as rliable's ``aggregate_iqm``; fractional ends weighted, so any count works)."""
    x = np.sort(np.asarray(values, dtype=float), axis=axis)
    n = x.shape[axis]
    lo, hi = 0.25 * n, 0.75 * n
    idx = np.arange(n) + 0.5  # each value covers [i, i + 1)
    weights = np.clip(np.minimum(idx + 0.5, hi) - np.maximum(idx - 0.5, lo), 0.0, 1.0)
    shape = [1] * x.ndim
    shape[axis] = n
    return (x * weights.reshape(shape)).sum(axis=axis) / weights.sum()


def normalised(
    r_policy: np.ndarray, r_none: np.ndarray, r_classical: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each scored stop's ``(R - R_none) / (R_classical - R_none)`` (the last axis of
    ``r_policy`` runs over stops: one row per policy is fine) and the mask of scored stops
    (where the classical WSP gains at least ``MIN_GAIN``)."""
    gain = r_classical - r_none
    scored = gain >= MIN_GAIN
    return (r_policy[..., scored] - r_none[scored]) / gain[scored], scored


def score(
    r_policy: np.ndarray, r_none: np.ndarray, r_classical: np.ndarray, seed: int = 0
) -> dict[str, Any]:
    """IQM of the per-stop normalised returns with a 95 % percentile-bootstrap interval
    (module docstring); ``None`` fields where no stop is scored."""
    s, scored = normalised(r_policy, r_none, r_classical)
    n = int(scored.sum())
    out: dict[str, Any] = {"score": None, "score_ci95": None, "scored_runs": n}
    if n == 0:
        return out
    rng = np.random.default_rng(seed)
    boot = iqm(s[rng.integers(0, n, (BOOTSTRAP, n))], axis=1)
    out["score"] = float(iqm(s))
    out["score_ci95"] = [float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))]
    out["score_mean"] = float(s.mean())
    out["score_worst"] = float(s.min())
    return out


def paired_difference(
    r_other: np.ndarray, r_base: np.ndarray, r_none: np.ndarray, r_classical: np.ndarray,
    seed: int = 0,
) -> dict[str, Any]:  # fmt: skip
    """``score(other) - score(base)`` on the same stops with a 95 % percentile-bootstrap
    interval that resamples the stops once for both (paired): the spread of the stops, common
    to both, drops out, so the interval is that of the difference, not of either score.
    ``None`` fields where no stop is scored."""
    (s_o, s_b), scored = normalised(np.stack([r_other, r_base]), r_none, r_classical)
    n = int(scored.sum())
    if n == 0:
        return {"difference": None, "difference_ci95": None, "scored_runs": 0}
    idx = np.random.default_rng(seed).integers(0, n, (BOOTSTRAP, n))
    boot = iqm(s_o[idx], axis=1) - iqm(s_b[idx], axis=1)
    return {
        "difference": float(iqm(s_o) - iqm(s_b)),
        "difference_ci95": [float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))],
        "scored_runs": n,
    }


def family(result: dict[str, Any]) -> dict[str, str]:
    """A stop's scenario families: its rail, gradient sign and speed band."""
    c = result["conditions"]
    g = c["gradient_permille"]
    grade = "level" if abs(g) < GRADIENT_LEVEL_PERMILLE else ("uphill" if g > 0 else "downhill")
    v = c["speed_kmh"]
    lo, hi = SPEED_BANDS_KMH
    band = f"<{lo:g} km/h" if v < lo else (f"{lo:g}-{hi:g} km/h" if v < hi else f">={hi:g} km/h")
    return {"rail": c["rail"], "gradient": grade, "speed": band}


def _summary(
    res: list[dict[str, Any]], none: list[dict[str, Any]], cls: list[dict[str, Any]],
    idx: np.ndarray, seed: int,
) -> dict[str, Any]:  # fmt: skip
    """One policy's figures over the stops ``idx`` (module docstring)."""
    pick = [res[i] for i in idx]
    r_p = np.array([r["return"] for r in pick])
    r_n = np.array([none[i]["return"] for i in idx])
    r_c = np.array([cls[i]["return"] for i in idx])
    out = score(r_p, r_n, r_c, seed)
    unscored = (r_c - r_n) < MIN_GAIN
    out["unscored_runs"] = int(unscored.sum())
    out["unscored_return_gain_m"] = (
        float(100.0 * (r_p[unscored] - r_n[unscored]).mean()) if unscored.any() else None
    )
    ratio = np.array(
        [
            r["stopping_distance_m"] / max(cls[i]["stopping_distance_m"], 1e-9)
            for r, i in zip(pick, idx, strict=True)
        ]
    )
    worst = int(np.argmax(ratio))
    n_axles = len(pick[0]["axles"])
    wd = [r["watchdog"]["total"] for r in pick]
    out.update(
        runs=len(pick),
        mean_return=float(r_p.mean()),
        stop_ratio_mean=float(ratio.mean()),
        stop_ratio_worst=float(ratio[worst]),
        worst_run={
            "scenario": pick[worst]["scenario"],
            "seed": pick[worst]["seed"],
            "stopping_distance_m": pick[worst]["stopping_distance_m"],
            "classical_m": cls[idx[worst]]["stopping_distance_m"],
            "conditions": {
                k: pick[worst]["conditions"][k]
                for k in (
                    "rail",
                    "speed_kmh",
                    "mu_contaminated",
                    "gradient_permille",
                    "demand_fraction",
                    "load_factor",
                )
            },
        },
        stopping_distance_m_mean=float(np.mean([r["stopping_distance_m"] for r in pick])),
        stopping_distance_m_max=float(np.max([r["stopping_distance_m"] for r in pick])),
        pass_rate=float(np.mean([r["passed"] for r in pick])),
        stopped_rate=float(np.mean([r["stopped"] for r in pick])),
        sliding_energy_kJ_mean=float(np.mean([r["sliding_energy_kJ"] for r in pick])),
        max_lock_s_mean=float(np.mean([r["max_lock_s"] for r in pick])),
        max_lock_s_max=float(np.max([r["max_lock_s"] for r in pick])),
        max_sliding_kmh_mean=float(np.mean([r["max_sliding_kmh"] for r in pick])),
        max_sliding_kmh_max=float(np.max([r["max_sliding_kmh"] for r in pick])),
        air_litres_mean=float(np.mean([r["air_litres"] for r in pick])),
        valve_operations_per_axle_mean=float(np.mean([r["valve_cycles"] for r in pick]) / n_axles),
        watchdog_interventions=int(sum(wd)),
        watchdog_runs=int(sum(1 for w in wd if w > 0)),
        # stops where the minimum-deceleration override gave way (every axle locked under it)
        watchdog_gave_way_runs=int(sum(r["watchdog"]["gave_way"] for r in pick)),
        reference_error_rms_kmh_mean=float(
            np.mean([r["reference_speed_error_rms_kmh"] for r in pick])
        ),
    )
    return out


def check_policy(policy: Any, vehicle: str, tier: str, control_period_s: float) -> None:
    """Refuse, in one line naming it, a policy the benchmark of ``vehicle`` in ``tier`` cannot
    score as it scores the others: another tier's sensors, privileged observations, another
    control period, another vehicle."""
    from wsp_env.policy import check_sensor_tier

    check_sensor_tier(policy, tier)
    own = getattr(policy, "env_kwargs", None) or {}
    if own.get("privileged"):
        raise ValueError(f"policy {policy.name}: observes privileged state; the benchmark does not")
    period = own.get("control_period_s", control_period_s)
    if period != control_period_s:
        raise ValueError(
            f"policy {policy.name}: runs at a {period} s control period; the benchmark's is "
            f"{control_period_s} s"
        )
    other = getattr(policy, "vehicle", None)
    if isinstance(other, str) and other != vehicle:
        raise ValueError(f"policy {policy.name}: trained for vehicle {other!r}, not {vehicle!r}")


def run_benchmark(
    policies: list[Any],
    vehicle: str = "uic_z1",
    tier: str = "wheels",
    runs: int = SEALED_RUNS,
    progress: Callable[[str], None] | None = None,
    keep_runs: bool = True,
    executor: Any = None,
    stop_set: str = "sealed",
    version: str = VERSION,
) -> dict[str, Any]:
    """Score ``policies`` (``policy.make_policy`` objects) on the sealed set of ``vehicle`` in
    sensor ``tier`` (or another of ``STOP_SETS``: ``development``): ``none`` and the tier's
    classical WSP run too (the score's ends). ``version``: the ids' version (``tiers.VERSIONS``;
    an earlier one reproduces the figures measured under it).
    ``executor``: as ``runner.run_suite``'s (``distributed.RayExecutor``: the stops split
    across workers, the same payload).

    A policy whose sensors are not the tier's (a learned model trained with or without the
    accelerometer) is refused: one line naming it."""
    from wsp_env.baselines.classical import ClassicalWSP
    from wsp_env.baselines.oracle import Oracle
    from wsp_env.policy import NoWSP, make_policy

    check_tier(tier)
    kwargs = benchmark_env_kwargs(vehicle, tier, version)
    veh = load_vehicle(kwargs.pop("vehicle"))
    stops = sealed_runs(veh, runs, stop_set)  # refuses an unknown set or count before any run
    max_time_s = kwargs.pop("max_time_s")
    builtin = {"none": NoWSP, "classical": ClassicalWSP, "oracle": Oracle}
    for p in policies:
        check_policy(p, veh.id, tier, kwargs["control_period_s"])
        if p.name in RESERVED and not isinstance(p, builtin[p.name]):
            raise ValueError(f"policy {p.name}: the name is reserved for the built-in {p.name}")
    names = [p.name for p in policies]
    ends = {"none": make_policy("none"), "classical": make_policy("classical", tier=tier)}
    todo = [ends[n] for n in ("none", "classical") if n not in names] + list(policies)
    results: dict[str, list[dict[str, Any]]] = {}
    for p in todo:
        if progress is not None:
            progress(f"{env_id(vehicle, tier, version)}: {p.name} on {len(stops)} stops")
        res, _ = (run_runs if executor is None else executor.run_runs)(
            veh, stops, p, record="none", max_time_s=max_time_s,
            env_kwargs=kwargs, policy_keys=POLICY_KEYS,
        )  # fmt: skip
        results[p.name] = res
    none, cls = results["none"], results["classical"]
    all_idx = np.arange(len(stops))
    fams = [family(r) for r in none]
    out_policies: dict[str, Any] = {}
    for name in [p.name for p in todo]:
        res = results[name]
        entry = _summary(res, none, cls, all_idx, seed=0)
        by_family: dict[str, Any] = {}
        for key in ("rail", "gradient", "speed"):
            groups: dict[str, list[int]] = {}
            for i, f in enumerate(fams):
                groups.setdefault(f[key], []).append(i)
            by_family[key] = {
                g: _summary(res, none, cls, np.array(ix), seed=0)
                for g, ix in sorted(groups.items())
            }
        entry["families"] = by_family
        out_policies[name] = entry
    oracle = results.get("oracle")
    if oracle is not None:
        beaten = {}
        for name, res in results.items():
            if name == "oracle":
                continue
            beaten[name] = int(sum(
                r["passed"] and r["stopping_distance_m"] < o["stopping_distance_m"] - 0.5
                for r, o in zip(res, oracle, strict=True)
            ))  # fmt: skip
        out_policies["oracle"]["beaten_by"] = beaten
    payload: dict[str, Any] = {
        "benchmark": env_id(vehicle, tier, version),
        "vehicle": vehicle,
        "tier": tier,
        "runs": len(stops),
        "stops": stop_set,
        "sealed": stop_set == "sealed" and len(stops) == SEALED_RUNS,
        "policies": out_policies,
        "score_definition": "IQM over stops of (R - R_none) / (R_classical - R_none), stops "
        f"where the classical WSP gains >= {MIN_GAIN} (x 100 m); 95 % percentile bootstrap",
    }
    if keep_runs:
        payload["run_results"] = {
            name: [
                {k: r[k] for k in ("scenario", "seed", "stopping_distance_m", "return",
                                   "passed", "stopped", "watchdog", "conditions")}
                # the per-stop figures behind the summary's means and maxima (item 6's
                # criteria stop by stop: scripts/ship_criteria.py names the stop of each)
                | {k: r[k] for k in RUN_FIGURES}
                | ({"oracle_variant": r["oracle_variant"]} if "oracle_variant" in r else {})
                for r in res
            ]
            for name, res in results.items()
        }  # fmt: skip
    return payload

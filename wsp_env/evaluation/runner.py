"""Run a scenario suite with a policy — one code path for every policy — and summarise it.

Every run of a suite (case x speed x seed) is one environment of a single batched core: all
runs advance together, each policy sees exactly the same scenarios and seeds, and a run's
metrics are taken the moment it stops (or hits the time limit). ``run_one`` is a one-run suite
on the same path (``wsp-env simulate``, the calibration's synthetic traces, the rig's track
comparison), and ``trace_metadata`` describes such a run as a ``wsp-trace/1`` trace.
"""

from __future__ import annotations

import hashlib
import math
import pickle
import statistics
from collections import OrderedDict
from typing import Any

import numpy as np

from wsp_env.core.braking import BrakingCore, Recorder
from wsp_env.core.config import VehicleConfig, load_rails, load_vehicle
from wsp_env.core.metrics import run_metrics
from wsp_env.core.records import CONTAMINANTS, RunRecord
from wsp_env.core.simulator import VehicleArrays
from wsp_env.envs import make_core
from wsp_env.evaluation.reference import (
    deceleration_distance,
    dry_reference_distances,
    equivalent_build_up_time_s,
    reference_distance,
)
from wsp_env.evaluation.suites import CaseConfig, Run, SuiteConfig, expand

# nothing drawn but the rail's adhesion level and pattern: nominal load, pads and level track
NOMINAL_SCENARIO = {"load_factor": [1.0, 1.0], "pad_factor": [1.0, 1.0],
                    "gradient_permille": [0.0, 0.0]}  # fmt: skip


def _judge(metrics: dict[str, Any], criteria: dict[str, float]) -> dict[str, bool]:
    """One pass flag per criterion the run is held to (``CRITERIA_KEYS``)."""
    limits = {
        "max_extension_pct": ("extension", "extension_pct"),
        "max_deceleration_distance_increase_pct": (
            "deceleration_distance", "deceleration_distance_increase_pct"),
        "max_lock_s": ("lock", "max_lock_s"),
        "max_axle_sliding_energy_kJ": ("sliding_energy", "max_axle_sliding_energy_kJ"),
        "max_axle_sliding_energy_pct": ("sliding_energy", "max_axle_sliding_energy_pct"),
        "max_slide_s": ("slide_duration", "longest_slide_s"),
        "max_air_litres": ("air", "air_litres"),
    }  # fmt: skip
    checks = {}
    for key, limit in criteria.items():
        if key == "min_adhesion_utilisation":
            checks["utilisation"] = bool(metrics["adhesion_utilisation"] >= limit)
        else:
            name, metric = limits[key]
            checks[name] = bool(metrics[metric] <= limit)
    return checks


def run_suite(
    vehicle: str | VehicleConfig,
    suite: SuiteConfig,
    policy: Any,
    record: str = "first_seed",
    progress: bool = False,
    max_time_s: float = 600.0,
    env_kwargs: dict[str, Any] | None = None,
    policy_keys: tuple[str, ...] | None = None,
    executor: Any = None,
) -> tuple[list[dict[str, Any]], dict[tuple[str, int], RunRecord]]:
    """Run every run of ``suite`` with ``policy``; return per-run results and recorded traces.

    ``vehicle`` is the suite's vehicle (a case may name its own). ``record``: ``"first_seed"``
    records speeds and pressures of each scenario's first seed, ``"all"`` every run, ``"none"``
    nothing. ``policy_keys``: as ``run_runs``'. ``executor``: an object with ``run_runs``'s
    signature that runs the runs elsewhere (``distributed.RayExecutor``: split across workers,
    the same results); None runs them here.
    """
    runner = run_runs if executor is None else executor.run_runs
    veh = vehicle if isinstance(vehicle, VehicleConfig) else load_vehicle(vehicle)
    runs = expand(suite, veh)
    groups: dict[int, list[int]] = {}  # runs of one vehicle share one batched core
    vehicles: dict[int, VehicleConfig] = {}
    for i, run in enumerate(runs):
        groups.setdefault(id(run.vehicle), []).append(i)
        vehicles[id(run.vehicle)] = run.vehicle
    results: list[dict[str, Any]] = [{} for _ in runs]
    records: dict[tuple[str, int], RunRecord] = {}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(runs), desc=f"{suite.name}: {policy.name}", unit="run", leave=False)
    for key, ids in groups.items():
        group = [runs[i] for i in ids]
        res, rec = runner(
            vehicles[key], group, policy, record, max_time_s, env_kwargs, bar, policy_keys
        )
        for i, r in zip(ids, res, strict=True):
            results[i] = r
        records.update(rec)
    if bar is not None:
        bar.close()
    return results, records


def run_runs(
    vehicle: VehicleConfig,
    runs: list[Run],
    policy: Any,
    record: str = "none",
    max_time_s: float = 600.0,
    env_kwargs: dict[str, Any] | None = None,
    bar: Any = None,
    policy_keys: tuple[str, ...] | None = None,
) -> tuple[list[dict[str, Any]], dict[tuple[str, int], RunRecord]]:
    """The runs of one vehicle, all environments of one batched core, stepped together (a
    suite's runs, ``run_suite``; the benchmark's sealed set). Each result carries the run's
    metrics, its undiscounted ``return`` under the core's reward, the shared reference's
    error against the train speed and the watchdog's interventions.

    A policy with ``variants`` (the oracle) is a sweep: every variant runs, and per run the one
    ``policy.choose`` picks is kept. ``policy_keys``: the only settings a policy's own
    ``env_kwargs`` may set (the benchmark: action mode, residual, valve grouping; None: any)."""
    variants = getattr(policy, "variants", None)
    if variants is not None:  # a sweep (the oracle): every variant, the best per run
        swept = [
            run_runs(vehicle, runs, v, record, max_time_s, env_kwargs, None, policy_keys)
            for v in variants()
        ]
        results, records = [], {}
        for candidates in zip(*(res for res, _ in swept), strict=True):
            best = policy.choose(list(candidates))
            j = candidates.index(best)
            results.append({**best, "policy": policy.name, "oracle_variant": best["policy"]})
            key = (best["scenario"], best["seed"])
            if key in swept[j][1]:
                records[key] = swept[j][1][key]
        if bar is not None:
            bar.update(len(runs))
        return results, records
    # a trained policy brings the settings its spaces need (action mode, valve grouping, ...)
    own = dict(getattr(policy, "env_kwargs", None) or {})
    if policy_keys is not None:
        own = {k: v for k, v in own.items() if k in policy_keys}
    kwargs = {**(env_kwargs or {}), **own}
    core = make_core(len(runs), vehicle=vehicle, max_time_s=max_time_s, **kwargs)
    for e, run in enumerate(runs):
        core.reset_env(e, run.options, seed=run.seed)
    refs = _references(core, runs, max_time_s)
    policy.bind(core)
    policy.reset(np.arange(len(runs)))
    ref_sq = np.zeros(len(runs))  # integral of (v_ref - V)^2 dt: the shared reference's error
    ref_max = np.zeros(len(runs))
    returns = np.zeros(len(runs))
    first: dict[str, int] = {}
    for e, run in enumerate(runs):
        first.setdefault(run.scenario, e)
    rec_ids = {
        "none": [],
        "all": list(range(len(runs))),
        "first_seed": sorted(first.values()),
    }[record]
    recorder = Recorder(core, rec_ids)
    done = np.zeros(len(runs), dtype=bool)
    results: list[dict[str, Any] | None] = [None] * len(runs)
    sim = core.sim

    def finish(e: int) -> dict[str, Any]:
        duration = max(float(sim.time_s[e]), 1e-9)
        ref_error = (3.6 * math.sqrt(ref_sq[e] / duration), 3.6 * ref_max[e])
        out = _run_result(core, e, runs[e], (*refs[e], ref_error), policy.name)
        out["return"] = float(returns[e])
        out["watchdog"] = core.watchdog_interventions(e)
        return out

    n_steps = math.ceil(max_time_s / sim.control_period_s) + 1
    recorder.snapshot(done)
    for _ in range(n_steps):
        actions = policy.act(core.obs)
        core.step(core.check_actions(actions))
        err = np.where(done, 0.0, core.reference_speed_mps - sim.speed_mps)
        ref_sq += err * err * sim.control_period_s
        ref_max = np.maximum(ref_max, np.abs(err))
        returns += np.where(done, 0.0, core.terms.sum(axis=1))
        recorder.snapshot(done)
        ended = np.flatnonzero(~done & core.ended())
        for e in ended:
            results[e] = finish(e)
            done[e] = True
            core.freeze(e)  # a truncated run stays where it ended
        if bar is not None and ended.size:
            bar.update(ended.size)
        if done.all():
            break
    for e in np.flatnonzero(~done):
        results[e] = finish(e)
    records = {(runs[e].scenario, runs[e].seed): recorder.record(e) for e in rec_ids}
    return [r for r in results if r is not None], records


# What a run's stop is judged against depends on the stop alone, not on the policy: a benchmark
# or evaluation of several policies (and the oracle's variants) runs the same stops again and
# again, so each reference is kept, by the exact inputs that make it (``_references``).
REFERENCE_CACHE_SIZE = 65_536  # available-adhesion references kept (a float and a hash each)
DRY_CACHE_SIZE = 64  # batches of dry-rail references kept
_available_cache: OrderedDict[bytes, float] = OrderedDict()
_dry_cache: OrderedDict[bytes, tuple[float, ...]] = OrderedDict()  # tuples: none can be written


def _remember(cache: OrderedDict, key: bytes, value: Any, size: int) -> None:
    cache[key] = value
    cache.move_to_end(key)
    while len(cache) > size:
        cache.popitem(last=False)


def clear_reference_cache() -> None:
    """Forget every kept reference (``_references``)."""
    _available_cache.clear()
    _dry_cache.clear()


def reference_cache_size() -> tuple[int, int]:
    """How many references are kept: available-adhesion ones (a stop each), dry-rail batches."""
    return len(_available_cache), len(_dry_cache)


def _references(
    core: BrakingCore, runs: list[Run], max_time_s: float
) -> list[tuple[float, float, float, float]]:
    """Per env, what its stop is judged against: the distance the adhesion present allows,
    the same stop on dry rail, the equivalent build-up time and the initial speed. A run
    repeated in the batch (the same seed and options: the same stop, as the fine-tune runs each
    stop once a member) is computed once and shared.

    Each is also kept for the process by the exact inputs that make it: the available-adhesion
    reference by a hash of its env's parameters, rail sections and initial speed (all
    ``reference_distance`` reads), the dry-rail references of a batch by a hash of the pickled
    vehicle, dry setups, rail and steps (all ``dry_reference_distances`` reads); so another
    policy on the same stops reuses them, bit for bit what computing them again gives
    (tested). A batch that cannot be pickled is computed each time."""
    sim = core.sim
    p = core.params
    first: dict[tuple[int, bytes] | int, int] = {}
    rep = [first.setdefault(_run_key(run, e), e) for e, run in enumerate(runs)]
    distinct = sorted(first.values())
    available = {}
    for e in distinct:
        v0 = float(sim.speed_mps[e])
        key = hashlib.sha256(b"".join(
            (p.env_par[e].tobytes(), p.axle_par[e].tobytes(), p.sections[e].tobytes(),
             np.float64(v0).tobytes())
        )).digest()  # fmt: skip
        hit = _available_cache.get(key)
        if hit is None:
            hit = reference_distance(p.env_par, p.axle_par, p.sections, e, v0)
        _remember(_available_cache, key, hit, REFERENCE_CACHE_SIZE)
        available[e] = hit
    dry_rail = core.rails.get("dry") or load_rails()["dry"]
    setups = [sim.setups[e] for e in distinct]
    steps = (sim.dt_s, sim.control_period_s, max_time_s)
    try:
        dry_key = hashlib.sha256(pickle.dumps((core.vehicle, setups, dry_rail, steps))).digest()
    except Exception:  # something in a setup pickle cannot write: computed each time
        dry_key = None
    dry_m = None if dry_key is None else _dry_cache.get(dry_key)
    if dry_m is None:
        dry_m = tuple(dry_reference_distances(core.vehicle, setups, dry_rail, *steps).tolist())
    if dry_key is not None:
        _remember(_dry_cache, dry_key, dry_m, DRY_CACHE_SIZE)
    dry = dict(zip(distinct, dry_m, strict=True))
    t_e = equivalent_build_up_time_s(p.env_par)
    v0 = sim.speed_mps.copy()
    return [(available[rep[e]], dry[rep[e]], t_e[e], v0[e]) for e in range(core.n_envs)]


def _run_key(run: Run, e: int) -> tuple[int, bytes] | int:
    """What makes two runs the same stop: the seed and the options (pickled: every value in
    full; options in another order only miss a share). A run without a whole-number seed or
    with options that cannot be pickled is its own (``e``)."""
    if isinstance(run.seed, bool) or not isinstance(run.seed, (int, np.integer)):
        return e
    try:
        return int(run.seed), pickle.dumps(sorted(run.options.items()))
    except Exception:  # an option pickle cannot write: no sharing
        return e


def _run_result(
    core: Any, e: int, run: Run, refs: tuple[float, float, float, float, Any], policy: str
) -> dict[str, Any]:
    available_m, dry_m, t_e, v0, ref_error = refs
    m = run_metrics(core.sim, e)
    d = m["stopping_distance_m"]
    s_dec = deceleration_distance(d, v0, t_e)
    s_dec_dry = deceleration_distance(dry_m, v0, t_e)
    out = {
        "scenario": run.scenario,
        "seed": run.seed,
        "policy": policy,
        "vehicle": core.vehicle.id,
        "stopping_distance_m": d,
        "reference_distance_m": float(available_m),
        "extension_pct": 100.0 * (d / available_m - 1.0) if available_m > 0 else math.nan,
        "dry_reference_distance_m": float(dry_m),
        "equivalent_build_up_time_s": float(t_e),
        "deceleration_distance_m": float(s_dec),
        "deceleration_distance_increase_pct": (
            100.0 * (s_dec / s_dec_dry - 1.0) if s_dec_dry > 0 else math.nan
        ),
        **m,  # every run metric (stopping time, sliding energy, air, locks, energy balance, axles)
        "conditions": core.describe(e),
    }
    if ref_error is not None:
        out["reference_speed_error_rms_kmh"], out["reference_speed_error_max_kmh"] = ref_error
    out["checks"] = _judge(out, run.criteria)
    out["passed"] = bool(all(out["checks"].values())) and m["stopped"]
    return out


SUMMARY_KEYS = (
    "stopping_distance_m",
    "extension_pct",
    "deceleration_distance_increase_pct",
    "adhesion_utilisation",
    "sliding_energy_kJ",
    "max_axle_sliding_energy_pct",
    "max_sliding_kmh",
    "longest_slide_s",
    "max_lock_s",
    "air_litres",
)


def _stats(values: list[float]) -> dict[str, float]:
    return {
        "mean": statistics.fmean(values),
        "std": statistics.pstdev(values) if len(values) > 1 else 0.0,
        "min": min(values),
        "max": max(values),
    }


def summarise(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Per policy and scenario: mean, std, min, max of the key metrics and the pass count."""
    out: dict[str, Any] = {}
    for policy in sorted({r["policy"] for r in results}):
        mine = [r for r in results if r["policy"] == policy]
        per: dict[str, Any] = {}
        for scenario in dict.fromkeys(r["scenario"] for r in mine):
            runs = [r for r in mine if r["scenario"] == scenario]
            per[scenario] = {k: _stats([r[k] for r in runs]) for k in SUMMARY_KEYS}
            per[scenario]["mean_sliding_kmh"] = statistics.fmean(
                a["mean_sliding_kmh"] for r in runs for a in r["axles"]
            )
            per[scenario]["passed"] = sum(r["passed"] for r in runs)
            per[scenario]["runs"] = len(runs)
        out[policy] = {
            "scenarios": per,
            "overall": {k: _stats([r[k] for r in mine]) for k in SUMMARY_KEYS},
            "passed": sum(r["passed"] for r in mine),
            "runs": len(mine),
        }
    return out


def one_run(
    rail_name: str,
    speed_kmh: float,
    seed: int,
    case: dict[str, Any] | None = None,
    env_kwargs: dict[str, Any] | None = None,
    name: str = "one",
) -> tuple[SuiteConfig, dict[str, Any]]:
    """The one-run suite of a stop from ``speed_kmh`` on rail ``rail_name`` and the environment
    arguments it runs with (``run_one``; the roller rig draws its stop the same way): ``seed``
    draws what ``case`` leaves open, the scenario is nominal (``NOMINAL_SCENARIO``) unless
    ``env_kwargs["scenario"]`` says otherwise."""
    suite = SuiteConfig(
        name=name,
        description="",
        seeds=(seed,),
        cases=(
            CaseConfig(name="run", rail=rail_name, speeds_kmh=(str(speed_kmh),), **(case or {})),
        ),
    )
    kwargs = dict(env_kwargs or {})
    kwargs["scenario"] = {
        "rails": {rail_name: 1.0},
        **NOMINAL_SCENARIO,
        **kwargs.get("scenario", {}),
    }
    return suite, kwargs


def run_one(
    vehicle: str | VehicleConfig,
    rail_name: str,
    speed_kmh: float,
    policy: Any,
    seed: int,
    case: dict[str, Any] | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> tuple[dict[str, Any], RunRecord]:
    """One stop from ``speed_kmh`` on rail ``rail_name`` with ``policy`` (``policy.make_policy``).

    ``seed`` draws what ``case`` (``evaluation.CaseConfig`` fields: ``mu_contaminated``,
    ``pattern``, ``demand``, ...) leaves open; load, pads and gradient are nominal unless
    ``env_kwargs["scenario"]`` says otherwise. Returns the evaluation's run result (metrics,
    ``conditions``) and the record at the control period.
    """
    suite, kwargs = one_run(rail_name, speed_kmh, seed, case, env_kwargs)
    results, records = run_suite(vehicle, suite, policy, record="all", env_kwargs=kwargs)
    return results[0], next(iter(records.values()))


def trace_metadata(
    vehicle: VehicleConfig,
    conditions: dict[str, Any],
    contaminant: str,
    sample_period_s: float,
    test_id: str,
) -> dict[str, Any]:
    """``*.meta.json`` of a simulated run (``conditions``: a run result's, for the initial
    speed and the demand; ``contaminant``: the trace format's name, ``RailConfig.
    contaminant_name``): nominal vehicle data only (docs/trace_format.md)."""
    sim_arrays = VehicleArrays.from_config(vehicle)
    gain, p_th = vehicle.brake.linear_torque()
    veh: dict[str, Any] = {
        "name": vehicle.name,
        "mass_kg": sim_arrays.body_mass_kg + sim_arrays.rest_mass_kg,
        "n_axles": vehicle.n_axles,
        "wheel_radius_m": vehicle.wheel_radius_m,
        "wheelset_inertia_kgm2": vehicle.wheelset_inertia_kgm2,
        "axle_static_load_kN": [round(x / 1e3, 3) for x in sim_arrays.load_ref_N],
        # optional: each axle's distance behind axle 1 (the rail an axle meets, calibration's
        # friction change along the rail)
        "axle_offsets_m": [round(float(x), 3) for x in sim_arrays.offsets_m],
        # optional (docs/trace_format.md): the quasi-static load transfer per axle that the
        # vehicle's documents (its config: pivot and frame heights) give, body and bogie pitch
        # together; calibration reads it when present
        "axle_load_transfer_kN_per_mps2": [
            round(x / 1e3, 4) for x in sim_arrays.transfer_body + sim_arrays.transfer_rest
        ],
        "brake": {
            "p_threshold_bar": p_th,
            "torque_gain_Nm_per_bar": gain,
            "p_max_bar": vehicle.brake.p_max_bar,
        },
        # nominal running resistance (an optional field: documents give it, traces may not)
        "resistance": {
            "a_N": vehicle.resistance.a_N,
            "b_N_per_mps": vehicle.resistance.b_N_per_mps,
            "c_N_per_mps2": vehicle.resistance.c_N_per_mps2,
        },
    }
    if not np.allclose(sim_arrays.brake_gain, gain):
        # optional (docs/trace_format.md): per-axle torque gains where they differ, e.g. motor
        # axles whose ED brake is blended with the friction brake
        veh["brake"]["axle_torque_gain_Nm_per_bar"] = [
            round(float(g), 3) for g in sim_arrays.brake_gain
        ]
    if len(vehicle.cars) == 1:
        car, (b0, b1) = vehicle.cars[0], vehicle.bogies
        veh["cog_height_m"] = car.cog_height_m
        veh["bogie_centre_distance_m"] = b1.position_m - b0.position_m
        veh["bogie_wheelbase_m"] = b0.wheelbase_m
    if contaminant not in CONTAMINANTS:
        raise ValueError(f"contaminant: {contaminant!r} is not one of {', '.join(CONTAMINANTS)}")
    return {
        "format": "wsp-trace/1",
        "test_id": test_id,
        "sample_period_s": sample_period_s,
        "initial_speed_kmh": conditions["speed_kmh"],
        "contaminant": contaminant,
        "brake_type": "emergency" if conditions["demand_fraction"] >= 1.0 else "service",
        "vehicle": veh,
    }

"""Run a scenario suite with a policy — one code path for every policy — and summarise it.

Every run of a suite (case x speed x seed) is one environment of a single batched core: all
runs advance together, each policy sees exactly the same scenarios and seeds, and a run's
metrics are taken the moment it stops (or hits the time limit).
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium.utils import seeding

from wsp_env import env_kernel as K
from wsp_env.config import (
    ConfigError,
    VehicleConfig,
    _configs_root,
    from_dict,
    load_rails,
    load_vehicle,
    read_yaml,
)
from wsp_env.env import OPTION_KEYS, _BrakingCore
from wsp_env.metrics import run_metrics
from wsp_env.physics import layout as L
from wsp_env.reference import (
    deceleration_distance,
    dry_reference_distances,
    equivalent_build_up_time_s,
    reference_distance,
)
from wsp_env.trace_io import RunRecord

# Pass/fail criteria (configurable per suite and case; EN 15595-style defaults, not normative):
# distance against the reference for the adhesion present and against dry rail, and wheel damage
# (lock found by wheel-rotation monitoring, sliding energy per axle, the longest slide) and air.
CRITERIA_KEYS = (
    "max_extension_pct",
    "max_deceleration_distance_increase_pct",
    "min_adhesion_utilisation",
    "max_lock_s",
    "max_axle_sliding_energy_kJ",
    "max_axle_sliding_energy_pct",
    "max_slide_s",
    "max_air_litres",
)
# load cases (body masses x): tare and laden at the ends of the scenario distribution (+-15 %)
LOAD_FACTORS = {"tare": 0.85, "nominal": 1.0, "laden": 1.15}


@dataclass(frozen=True)
class CaseConfig:
    name: str
    rail: str
    speeds_kmh: tuple[str, ...] = field(metadata={"nonempty": True})
    vehicle: str | None = None  # a vehicle id or file; None: the suite run's vehicle
    mu_contaminated: float | None = field(default=None, metadata={"gt": 0.0})
    pattern: str | None = field(
        default=None, metadata={"choices": ("uniform", "step_up", "step_down", "patches")}
    )
    demand: str = field(default="emergency", metadata={"choices": ("emergency", "service")})
    load: str | None = field(default=None, metadata={"choices": tuple(LOAD_FACTORS)})
    load_factor: float | None = field(default=None, metadata={"gt": 0.0})
    gradient_permille: float | None = None
    recovery_basis: str | None = field(
        default=None, metadata={"choices": ("rail_metre", "wheel_metre", "sliding_power")}
    )
    axle_mu_factor: tuple[float, ...] | None = field(default=None, metadata={"gt": 0.0})
    extra_brake_force_N: float | None = field(default=None, metadata={"ge": 0.0})
    sections: tuple[tuple[float, ...], ...] | None = None
    criteria: dict[str, float] = field(default_factory=dict)

    def validate(self, where: str) -> None:
        if self.load is not None and self.load_factor is not None:
            raise ConfigError(f"{where}.load: give load or load_factor, not both")


@dataclass(frozen=True)
class SuiteConfig:
    name: str
    description: str
    seeds: tuple[int, ...] = field(metadata={"nonempty": True})
    cases: tuple[CaseConfig, ...] = field(metadata={"nonempty": True})
    criteria: dict[str, float] = field(default_factory=dict)

    def validate(self, where: str) -> None:
        prefix = f"{where}." if where else ""
        for key in self.criteria:
            if key not in CRITERIA_KEYS:
                raise ConfigError(
                    f"{prefix}criteria.{key}: unknown (one of {', '.join(CRITERIA_KEYS)})"
                )
        for i, case in enumerate(self.cases):
            for key in case.criteria:
                if key not in CRITERIA_KEYS:
                    raise ConfigError(f"{prefix}cases[{i}].criteria.{key}: unknown criterion")
            for s in case.speeds_kmh:
                if s != "max":
                    try:
                        ok = float(s) > 0
                    except ValueError:
                        ok = False
                    if not ok:
                        raise ConfigError(
                            f"{prefix}cases[{i}].speeds_kmh: {s!r} is not a speed or 'max'"
                        )


def load_suite(name_or_path: str) -> SuiteConfig:
    """A suite by name (``quick``, ``en15595``, ``heldout``) or YAML path."""
    p = Path(name_or_path)
    if p.suffix not in (".yaml", ".yml"):
        p = _configs_root() / "scenarios" / f"{name_or_path}.yaml"
        if not p.exists():
            known = sorted(q.stem for q in (_configs_root() / "scenarios").glob("*.yaml"))
            raise ConfigError(f"suite: unknown suite {name_or_path!r} (known: {', '.join(known)})")
    elif not p.exists():
        raise ConfigError(f"{p}: no such file")
    data = read_yaml(p)
    if isinstance(data, dict):  # YAML reads bare numbers in speeds_kmh as numbers
        for case in data.get("cases", []) or []:
            if isinstance(case, dict) and isinstance(case.get("speeds_kmh"), list):
                case["speeds_kmh"] = [str(s) for s in case["speeds_kmh"]]
    try:
        return from_dict(SuiteConfig, data)
    except ConfigError as err:
        raise ConfigError(f"{p}: {err}") from None


@dataclass(frozen=True)
class Run:
    scenario: str
    seed: int
    options: dict[str, Any]
    criteria: dict[str, float]
    vehicle: VehicleConfig


def expand(suite: SuiteConfig, vehicle: VehicleConfig) -> list[Run]:
    """Cases x speeds x seeds, in a fixed order (a case may name its own vehicle)."""
    runs = []
    vehicles: dict[str, VehicleConfig] = {}
    for case in suite.cases:
        veh = vehicle
        if case.vehicle is not None:
            veh = vehicles.setdefault(case.vehicle, load_vehicle(case.vehicle))
        for s in case.speeds_kmh:
            speed = veh.max_speed_kmh if s == "max" else float(s)
            name = f"{case.name}_{round(speed)}"
            options: dict[str, Any] = {"rail": case.rail, "speed_kmh": speed, "demand": case.demand}
            if case.load is not None:
                options["load_factor"] = LOAD_FACTORS[case.load]
            for key in (
                "mu_contaminated", "pattern", "load_factor", "gradient_permille",
                "recovery_basis", "axle_mu_factor", "extra_brake_force_N", "sections",
            ):  # fmt: skip
                value = getattr(case, key)
                if value is not None:
                    options[key] = value
            assert set(options) <= set(OPTION_KEYS)
            criteria = {**suite.criteria, **case.criteria}
            runs.extend(Run(name, seed, options, criteria, veh) for seed in suite.seeds)
    return runs


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
) -> tuple[list[dict[str, Any]], dict[tuple[str, int], RunRecord]]:
    """Run every run of ``suite`` with ``policy``; return per-run results and recorded traces.

    ``vehicle`` is the suite's vehicle (a case may name its own). ``record``: ``"first_seed"``
    records speeds and pressures of each scenario's first seed, ``"all"`` every run, ``"none"``
    nothing.
    """
    variants = getattr(policy, "variants", None)
    if variants is not None:  # a sweep (the oracle): every variant, the best per run
        swept = [
            run_suite(vehicle, suite, v, record, progress, max_time_s, env_kwargs)
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
        return results, records
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
        res, rec = _run_group(vehicles[key], group, policy, record, max_time_s, env_kwargs, bar)
        for i, r in zip(ids, res, strict=True):
            results[i] = r
        records.update(rec)
    if bar is not None:
        bar.close()
    return results, records


def _run_group(
    vehicle: VehicleConfig,
    runs: list[Run],
    policy: Any,
    record: str,
    max_time_s: float,
    env_kwargs: dict[str, Any] | None,
    bar: Any,
) -> tuple[list[dict[str, Any]], dict[tuple[str, int], RunRecord]]:
    """The runs of one vehicle, all environments of one batched core, stepped together."""
    # a trained policy brings the settings its spaces need (action mode, valve grouping, ...)
    kwargs = {**(env_kwargs or {}), **getattr(policy, "env_kwargs", {})}
    core = _BrakingCore(len(runs), vehicle=vehicle, max_time_s=max_time_s, **kwargs)
    sim = core.sim
    available = np.zeros(len(runs))
    for e, run in enumerate(runs):
        core.rngs[e] = seeding.np_random(run.seed)[0]
        core.reset_env(e, run.options)
        available[e] = reference_distance(
            sim.env_par, sim.axle_par, sim.sections, e, sim.speed_mps[e]
        )
    dry_rail = core.rails.get("dry") or load_rails()["dry"]
    dry = dry_reference_distances(
        core.vehicle, list(sim.setups), dry_rail, sim.dt_s, sim.control_period_s, max_time_s
    )
    t_e = equivalent_build_up_time_s(sim.env_par)
    v0 = sim.speed_mps.copy()
    policy.bind(core)
    policy.reset(np.arange(len(runs)))
    estimates = getattr(policy, "reference_speed", None)
    ref_sq = np.zeros(len(runs))  # integral of (v_ref - V)^2 dt, for policies that estimate one
    ref_max = np.zeros(len(runs))
    first = {}
    for e, run in enumerate(runs):
        first.setdefault(run.scenario, e)
    rec_ids = {
        "none": [],
        "all": list(range(len(runs))),
        "first_seed": sorted(first.values()),
    }[record]
    rows: dict[int, list[np.ndarray]] = {e: [] for e in rec_ids}

    def snapshot() -> None:
        demand = sim.demand_bar()
        for e in rec_ids:
            if not done[e]:
                head = [sim.time_s[e], sim.speed_mps[e], demand[e], core.wsp[e, K.W_VREF]]
                head.append(sim.env_state[e, L.ES_DECEL])
                rows[e].append(np.concatenate([head, sim.wheel_speed_mps[e], sim.pressure_bar[e]]))

    done = np.zeros(len(runs), dtype=bool)
    results: list[dict[str, Any] | None] = [None] * len(runs)

    def finish(e: int) -> dict[str, Any]:
        ref_error = None
        if estimates is not None:
            duration = max(float(sim.time_s[e]), 1e-9)
            ref_error = (3.6 * math.sqrt(ref_sq[e] / duration), 3.6 * ref_max[e])
        refs = (available[e], dry[e], t_e[e], v0[e], ref_error)
        return _run_result(core, e, runs[e], refs, policy.name)

    n_steps = math.ceil(max_time_s / sim.control_period_s) + 1
    snapshot()
    for _ in range(n_steps):
        actions = policy.act(core.obs)
        if estimates is not None:
            err = np.where(done, 0.0, np.asarray(estimates(), dtype=float) - sim.speed_mps)
            ref_sq += err * err * sim.control_period_s
            ref_max = np.maximum(ref_max, np.abs(err))
        core.step(core.check_actions(actions))
        snapshot()
        ended = np.flatnonzero(
            ~done & (core.flags[:, K.F_TERMINATED] | core.flags[:, K.F_TRUNCATED]).astype(bool)
        )
        for e in ended:
            results[e] = finish(e)
            done[e] = True
            sim.env_state[e, L.ES_STOPPED] = 1.0  # freeze a truncated run
        if bar is not None and ended.size:
            bar.update(ended.size)
        if done.all():
            break
    for e in np.flatnonzero(~done):
        results[e] = finish(e)
    n = core.n_axles
    records = {}
    for e in rec_ids:
        a = np.asarray(rows[e])
        keep = np.concatenate([[True], np.diff(a[:, 0]) > 1e-9])
        a = a[keep]
        p = a[:, 5 + n : 5 + 2 * n]
        records[(runs[e].scenario, runs[e].seed)] = RunRecord(
            time_s=a[:, 0],
            v_train_kmh=3.6 * a[:, 1],
            v_axle_kmh=3.6 * a[:, 5 : 5 + n],
            p_cyl_bar=p,
            p_demand_bar=a[:, 2],
            a_train_mps2=a[:, 4],
            v_ref_kmh=3.6 * a[:, 3],
            wsp_active=p < a[:, 2:3] - 0.05,
        )
    return [r for r in results if r is not None], records


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


def with_option(suite: SuiteConfig, **changes: Any) -> SuiteConfig:
    """A copy of ``suite`` with every case changed (e.g. ``mu_contaminated``)."""
    cases = tuple(dataclasses.replace(c, **changes) for c in suite.cases)
    return dataclasses.replace(suite, cases=cases)

"""Policies on fresh stops of one rail from the benchmark's distribution, for rates its 300-stop
sets cannot resolve (a watchdog stop on 1 % of the leaves stops is 0-2 of a set's ~74).

The stops are those whose rail is ``--rail`` among the seeds ``FRESH_SEED_BASE + i``,
``i < --draw`` (9,800,000 + i: no sealed, development, fine-tune pool or suite stop), drawn
with the benchmark's scenario, sensors and watchdog of ``--vehicle`` and ``--tier``
(``benchmark_env_kwargs``), every policy on the same stops through the benchmark's runner. Per
policy: the stops with a watchdog intervention, the longest lock and its stop, the stops not
stopped in the time limit, and the mean return, air and sliding energy a stop; with
``classical`` among the policies, each other's mean and worst per-stop ratio of stopping
distance to it. ``--policy`` is ``classical`` (the tier's
frozen classical WSP), ``target:X`` (a constant X km/h target on the slip-target loop of the
tier, the environment's default loop), ``target:X:drift`` (the same with the loop's drift
correction, ``wheels+accel`` only; ``target:X:drift:onset`` with its onset reading of the
accelerometer's offset, ``target:X:drift:onset2`` with that reading two-sided),
``target:X[:drift]:GxF`` (with the loop's gain G per km/h
scaled by the pressure held, never below F of it: ``target:2:drift:0.8x0.25``), then
``:creepC`` or ``:creepC@F`` for the loop's creep cap C (a fraction of the reference speed)
with its floor F km/h (2 by default; ``target:2:creep0.02@0.5`` asks for 2 km/h above 100 km/h,
2 % of the reference speed below, never under 0.5 km/h: a creep schedule), each with
``:cal`` for the loop's wheel-scale calibration (either tier: ``target:2:cal``,
``target:2:drift:onset:cal``) and ``:guard`` last for its lock guard
(``target:1:drift:onset2:cal:guard``), or anything
``wsp-env benchmark --policy`` takes (a model file, a shipped policy's name). ``--json`` keeps
every run (written whole or not at all). ``--watchdog-floor A`` runs every policy under a
minimum-deceleration supervision floor of A m/s^2 instead of the benchmark's (a probe of the
supervision, not the benchmark: the header says so).

    .venv/bin/python scripts/fresh_stops.py --rail leaves --draw 1200 \\
        --policy runs/train/bc_st_cap2_s1/student.zip --policy target:2 --policy classical \\
        --json runs/s17/leaves.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from wsp_env.baselines.slip_target import (
    DEFAULT_MAX_CREEP,
    MAX_CREEP_FLOOR_KMH,
    SlipTargetLoop,
    SlipTargetPolicy,
    parse_pressure_gain,
)
from wsp_env.core.config import check_number, load_vehicle
from wsp_env.core.sensors import WatchdogConfig
from wsp_env.envs import make_core
from wsp_env.envs.tiers import TIERS, VERSION, benchmark_env_kwargs
from wsp_env.evaluation.benchmark import DAMAGE_CRITERIA, POLICY_KEYS
from wsp_env.evaluation.runner import run_runs
from wsp_env.evaluation.suites import Run
from wsp_env.policy import make_policy

FRESH_SEED_BASE = 9_800_000  # above the fine-tune pool's 9,510,000 + i, i < 100,000
MAX_DRAW = 100_000
WATCHDOG_FIELDS = {f.name: f for f in dataclasses.fields(WatchdogConfig)}


def benchmark_setup(vehicle: str, tier: str) -> tuple[Any, float, dict[str, Any]]:
    """The benchmark's vehicle, time limit and other environment settings for ``tier``."""
    kw = benchmark_env_kwargs(vehicle, tier, VERSION)
    return load_vehicle(kw.pop("vehicle")), kw.pop("max_time_s"), kw


def rail_seeds(vehicle: str, tier: str, rail: str, draw: int) -> list[int]:
    """The seeds among ``FRESH_SEED_BASE + i``, ``i < draw``, whose stop is on ``rail``: each
    stop's scenario drawn as the runner draws it, without running it."""
    veh, max_time_s, kw = benchmark_setup(vehicle, tier)
    seeds = [FRESH_SEED_BASE + i for i in range(draw)]
    core = make_core(len(seeds), vehicle=veh, max_time_s=max_time_s, **kw)
    found = []
    for e, seed in enumerate(seeds):
        core.reset_env(e, {}, seed=seed)
        if core.sim.setups[e].rail_name == rail:
            found.append(seed)
    return found


def parse_creep(text: str, where: str) -> tuple[float, float]:
    """``creepC`` or ``creepC@F`` as the loop's ``(max_creep, creep_floor_kmh)`` (the floor 2
    km/h without ``@F``), checked as the loop checks them; else a one-line ``ValueError``
    beginning with ``where``."""
    cap, at, floor = text.removeprefix("creep").partition("@")
    try:
        creep = check_number(cap, "slip_target_max_creep")
        creep_floor = check_number(floor, "creep_floor_kmh") if at else MAX_CREEP_FLOOR_KMH
        SlipTargetLoop(max_creep=creep, creep_floor_kmh=creep_floor)  # the loop's own checks
    except ValueError as err:
        raise ValueError(f"{where}: creepC[@F], the loop's cap and floor ({err})") from None
    if creep == 0.0 and at:
        raise ValueError(f"{where}: creep0 is no cap, so a floor means nothing")
    return creep, creep_floor


def build_policy(spec: str, tier: str) -> Any:
    """``target:X`` as a constant target on the tier's default loop, ``target:X:drift`` with
    the loop's drift correction, ``target:X[:drift]:GxF`` with its gain G per km/h scaled by
    the pressure held, never below F of it (``slip_target.parse_pressure_gain``),
    ``:creepC[@F]`` with the creep cap C and its floor F km/h (``parse_creep``), ``:cal``
    with the wheel-scale calibration, ``:guard`` last with the lock guard; anything else
    as ``wsp-env benchmark --policy`` builds it."""
    if spec.startswith("target:"):
        value, _, option = spec.removeprefix("target:").partition(":")
        items = option.split(":") if option else []
        guard = items[-1:] == ["guard"]
        items = items[:-1] if guard else items
        cal = items[-1:] == ["cal"]
        items = items[:-1] if cal else items
        creep, creep_floor = DEFAULT_MAX_CREEP, MAX_CREEP_FLOOR_KMH
        if items and items[-1].startswith("creep"):
            creep, creep_floor = parse_creep(items.pop(), f"--policy {spec}")
        drift = items[:1] == ["drift"]
        rest = items[1:] if drift else items
        onset = drift and rest[:1] in (["onset"], ["onset2"])
        two_sided = onset and rest[0] == "onset2"
        rest = rest[1:] if onset else rest
        if len(rest) > 1 or (rest and "x" not in rest[0]):
            raise ValueError(
                f"--policy {spec}: "
                "target:X[:drift[:onset|:onset2]][:GAINxFLOOR][:creepC[@F]][:cal][:guard]"
            )
        gain, floor = parse_pressure_gain(rest[0] if rest else "off", f"--policy {spec}")
        if drift and tier != "wheels+accel":
            raise ValueError(f"--policy {spec}: the drift correction needs --tier wheels+accel")
        try:
            kmh = float(value)
        except ValueError:
            raise ValueError(f"--policy {spec}: target:X needs a number of km/h") from None
        if not 0.0 <= kmh <= 30.0:
            raise ValueError(f"--policy {spec}: a target in [0, 30] km/h")
        # the bound core's tier's loop
        loop = SlipTargetLoop(drift_correction=drift, gain_per_kmh=gain, gain_scale_floor=floor,
                              onset_drift=onset, scale_calibration=cal,
                              onset_two_sided=two_sided, max_creep=creep,
                              creep_floor_kmh=creep_floor, lock_guard=guard)  # fmt: skip
        return SlipTargetPolicy(kmh, loop)
    return make_policy(spec, tier=tier)


def run(
    vehicle: str, tier: str, seeds: list[int], specs: list[str],
    watchdog_floor: float | None = None,
) -> dict[str, list[dict]]:  # fmt: skip
    """Every policy on the stops of ``seeds``: each policy's run results, keyed by its spec."""
    veh, max_time_s, kw = benchmark_setup(vehicle, tier)
    if watchdog_floor is not None:  # a probe of the supervision, not the benchmark's
        kw = {**kw, "watchdog": {**(kw["watchdog"] or {}), "min_decel_mps2": watchdog_floor}}
    runs = [Run(f"fresh_{s}", s, {}, dict(DAMAGE_CRITERIA), veh) for s in seeds]
    out = {}
    for spec in specs:
        policy = build_policy(spec, tier)
        res, _ = run_runs(veh, runs, policy, max_time_s=max_time_s, env_kwargs=kw,
                          policy_keys=POLICY_KEYS)  # fmt: skip
        out[spec] = res
    return out


def summary(results: list[dict], classical: list[dict] | None = None) -> dict[str, Any]:
    """A policy's watchdog stops, longest lock (and its stop), stops not stopped, and its mean
    return, air and sliding energy a stop (what the score and item 6 weigh beside the
    distance); with the classical WSP's runs of the same stops, the mean and worst per-stop
    ratio of stopping distance to it (and the worst's stop)."""
    longest = max(results, key=lambda r: r["max_lock_s"])
    ratios = {}
    if classical is not None:
        ratio = np.array([r["stopping_distance_m"] for r in results]) / np.array(
            [c["stopping_distance_m"] for c in classical]
        )
        worst = int(np.argmax(ratio))
        ratios = {
            "stop_ratio_mean": float(ratio.mean()),
            "stop_ratio_worst": float(ratio[worst]),
            "stop_ratio_worst_stop": results[worst]["scenario"],
        }
    return {
        "stops": len(results),
        "watchdog_stops": [r["scenario"] for r in results if r["watchdog"]["total"] > 0],
        "longest_lock_s": float(longest["max_lock_s"]),
        "longest_lock_stop": longest["scenario"],
        "not_stopped": [r["scenario"] for r in results if not r["stopped"]],
        "return_mean": float(np.mean([r["return"] for r in results])),
        "air_litres_mean": float(np.mean([r["air_litres"] for r in results])),
        "sliding_energy_kJ_mean": float(np.mean([r["sliding_energy_kJ"] for r in results])),
        **ratios,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rail", required=True, help="the rail of the stops kept")
    ap.add_argument("--draw", type=int, default=1200, help="seeds drawn (default 1200)")
    ap.add_argument("--policy", action="append", required=True, help="repeatable")
    ap.add_argument("--vehicle", default="uic_z1")
    ap.add_argument("--tier", default="wheels+accel", choices=list(TIERS))
    ap.add_argument("--json", dest="json_path", help="write every run here")
    ap.add_argument(
        "--watchdog-floor",
        type=float,
        default=None,
        help="the supervision's floor, m/s^2 (0: no supervision; a probe; default: the "
        "benchmark's)",
    )
    args = ap.parse_args(argv)
    try:
        if not 1 <= args.draw <= MAX_DRAW:
            raise ValueError(f"--draw: must be 1-{MAX_DRAW}, got {args.draw}")
        rails = benchmark_setup(args.vehicle, args.tier)[2]["scenario"]["rails"]
        if args.rail not in rails:
            raise ValueError(f"--rail: {args.rail!r} is not one of {', '.join(rails)}")
        for spec in args.policy:  # every policy checked before any stop runs
            build_policy(spec, args.tier)
        if args.watchdog_floor is not None:  # the watchdog's own bounds, before any stop
            bounds = WATCHDOG_FIELDS["min_decel_mps2"].metadata
            check_number(args.watchdog_floor, "--watchdog-floor", **bounds)
        seeds = rail_seeds(args.vehicle, args.tier, args.rail, args.draw)
        if not seeds:
            raise ValueError(f"--draw: no {args.rail} stop among {args.draw} seeds")
        results = run(args.vehicle, args.tier, seeds, args.policy, args.watchdog_floor)
    except (OSError, ValueError, KeyError) as err:
        msg = str(err) if isinstance(err, ValueError) else f"{type(err).__name__}: {err}"
        print(f"fresh_stops: {msg}", file=sys.stderr)
        return 2
    last = FRESH_SEED_BASE + args.draw - 1
    print(f"{len(seeds)} {args.rail} stops among seeds {FRESH_SEED_BASE}-{last} "
          f"({args.vehicle}, {args.tier}, {VERSION})")  # fmt: skip
    if args.watchdog_floor is not None:
        off = " (no supervision)" if args.watchdog_floor == 0.0 else ""
        print(f"supervision floor {args.watchdog_floor:g} m/s^2{off}: a probe, not the benchmark's")
    classical = results.get("classical")
    sums = {spec: summary(res, classical) for spec, res in results.items()}
    for spec, s in sums.items():
        wd = s["watchdog_stops"]
        ratio = (f", stop / classical: mean {s['stop_ratio_mean']:.4f}, worst "
                 f"{s['stop_ratio_worst']:.3f} ({s['stop_ratio_worst_stop']})"
                 if classical is not None and spec != "classical" else "")  # fmt: skip
        print(f"{spec}: watchdog on {len(wd)} ({', '.join(wd[:8])}{' ...' if len(wd) > 8 else ''}"
              f"), longest lock {s['longest_lock_s']:.2f} s ({s['longest_lock_stop']}), "
              f"not stopped {len(s['not_stopped'])}{ratio}; a stop: return "
              f"{s['return_mean']:.3f}, air {s['air_litres_mean']:.0f} l, sliding energy "
              f"{s['sliding_energy_kJ_mean']:.0f} kJ")  # fmt: skip
    if args.json_path:
        path = Path(args.json_path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        payload = {
            "vehicle": args.vehicle, "tier": args.tier, "version": VERSION, "rail": args.rail,
            "seeds": seeds, "summary": sums, "run_results": results,
            "watchdog_floor_mps2": args.watchdog_floor,
        }  # fmt: skip
        tmp.write_text(json.dumps(payload, indent=1, default=float), encoding="utf-8")
        os.replace(tmp, path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""A table of constant slip targets by rail for ``oracle_target_rail`` (the imitation teacher,
``pretrain.teacher_targets_kmh``), chosen on development stops under issue 23 item 6's limits.

Reads benchmark files of ``scripts/slip_target_benchmark.py --stops development --json F`` (the
constant targets ``slip_target_<x>kmh`` beside the classical WSP; several files of the same
stops are merged) and, for each rail, keeps the targets that on that rail's stops

1. bring no watchdog intervention,
2. lock no axle longer than the classical WSP's longest lock over all the stops,
3. make no stop more than ``--worst`` (1.10) times the classical WSP's,

and picks the one with the best mean return. Where no target passes all three, the last limit
is dropped first (then the second, then the first), and the line says so. Prints each rail's
candidates, then **the teacher with that table**, composed stop by stop from those runs (each
of its stops is its rail's constant target: ``oracle_target_rail`` runs bit for bit as that,
``tests/test_imitation.py``): its benchmark score with the 95 % interval and item 6's criteria
(``ship_criteria.py``) on these stops; then **each stop's best target after the fact** (by
return, and by the shortest stop): what no teacher that holds one of these targets a stop can
beat, however it picks it (by return: none returns more on any stop, so none scores higher; by
distance: none has a lower mean of the per-stop ratios to the classical WSP's stop), with its
score, worst stop and longest lock; then the table as YAML for a config. Never reads the
sealed set (refuses a file of it); the files must be of one vehicle and tier, each target in one.
Reads only the targets named ``slip_target_<x>kmh``: the environment's default loop when the
file was made (gated and capped since 2026-11-27; a file made before the gate named its ungated
runs so, one made between the gate and the creep cap its uncapped runs; a loop other than the
default is named in the policy's name, ``slip_target_<x>kmh_always``, ``..._creep0``, and
skipped; ``--loop drift`` reads the targets of the loop with the drift correction,
``slip_target_<x>kmh_drift``, instead, and skips the default loop's; ``--loop drift-pgain``
that loop's with the gain scaled by the pressure held, ``..._drift_pgain0.8x0.25``;
``--loop drift-onset`` with its onset reading, ``..._drift_onset``; ``--loop
drift-onset-cal`` with the wheel-scale calibration too, ``..._drift_onset_cal``, and
``--loop cap0.05-drift-onset-cal`` that loop under a 5 % creep cap). Files
whose loops ran on different classical thresholds (``slip_target_loop``: the tier's since
2026-11-27, ``WSPConfig()``'s defaults before) are not merged.

    .venv/bin/python scripts/choose_rail_targets.py runs/s14/regiolis_targets_dev.json \\
        [runs/s14/more_targets_dev.json] [--worst 1.10]
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
from ship_criteria import criteria

from wsp_env.evaluation.benchmark import score

# the loops ``--loop`` reads, by the suffix their runs' names carry (``slip_target.loop_suffix``)
LOOPS = {
    "default": "",
    "drift": "_drift",
    # the drift correction with the gain scaled by the pressure held (0.8 per km/h, floor 0.25)
    "drift-pgain": "_drift_pgain0.8x0.25",
    # the drift correction with its onset reading of the accelerometer's offset
    "drift-onset": "_drift_onset",
    # and the wheel-scale calibration
    "drift-onset-cal": "_drift_onset_cal",
    # that loop under a 5 % creep cap (``--max-creep 0.05``)
    "cap0.05-drift-onset-cal": "_creep0.05_drift_onset_cal",
}


def target_pattern(loop: str = "default") -> re.Pattern[str]:
    """The names of one loop's constant targets (``LOOPS``), the km/h as the first group."""
    return re.compile(rf"^slip_target_(\d+(?:\.\d+)?)kmh{re.escape(LOOPS[loop])}$")


def by_stop(rows: list[dict]) -> dict[tuple, dict]:
    return {(r["scenario"], int(r["seed"])): r for r in rows}


def loop_thresholds(data: dict[str, Any]) -> str:
    """Which classical thresholds the file's loop ran on (``slip_target_benchmark.py
    --thresholds``; a file without the record was made before it: ``WSPConfig()``'s
    defaults)."""
    return (data.get("slip_target_loop") or {}).get("thresholds", "default")


def load(
    paths: list[str], loop: str = "default"
) -> tuple[dict[str, Any], dict[float, dict[tuple, dict]]]:
    """The first file's content (its classical WSP's and locked wheels' runs, its summary) and
    each constant target's runs of ``loop`` (``LOOPS``), keyed by (scenario, seed)."""
    pattern = target_pattern(loop)
    first: dict[str, Any] = {}
    targets: dict[float, dict[tuple, dict]] = {}
    for path in paths:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
        if not isinstance(data, dict) or "run_results" not in data:
            raise ValueError(f"{path}: not a benchmark file kept with its runs (--json)")
        if data.get("stops") != "development":
            raise ValueError(f"{path}: stops {data.get('stops')!r}, not development")
        runs = data["run_results"]
        if not runs.get("classical") or not runs.get("none"):
            raise ValueError(f"{path}: no classical or no locked-wheel (none) runs")
        base = by_stop(runs["classical"])
        if first:
            for field in ("vehicle", "tier"):
                if data.get(field) != first.get(field):
                    raise ValueError(f"{path}: {field} {data.get(field)!r}, not "
                                     f"{first.get(field)!r} as {paths[0]}")  # fmt: skip
            if loop_thresholds(data) != loop_thresholds(first):
                raise ValueError(f"{path}: the loop on {loop_thresholds(data)} thresholds, not on "
                                 f"{loop_thresholds(first)} as {paths[0]}")  # fmt: skip
            if set(base) != set(by_stop(first["run_results"]["classical"])):
                raise ValueError(f"{path}: not the same stops as {paths[0]}")
        else:
            first = data
        for name, rows in runs.items():
            m = pattern.match(name)
            if not m:
                continue
            if float(m.group(1)) in targets:
                raise ValueError(f"{path}: {name} is in an earlier file too")
            keyed = by_stop(rows)
            if set(keyed) != set(base):
                raise ValueError(f"{path}: {name} did not run every stop of the classical WSP")
            targets[float(m.group(1))] = keyed
    if not targets:
        raise ValueError(f"no slip_target_<x>kmh{LOOPS[loop]} policy in the files")
    return first, targets


def teacher(first: dict[str, Any], targets: dict, table: dict[str, float]) -> dict[str, Any]:
    """The teacher with ``table``, stop by stop from the constant targets' runs: its score
    (``benchmark.score``) and item 6's criteria rows (``ship_criteria.criteria``)."""
    runs = first["run_results"]
    keys = sorted(by_stop(runs["classical"]))
    base, none = by_stop(runs["classical"]), by_stop(runs["none"])
    mine = [targets[table[base[k]["conditions"]["rail"]]][k] for k in keys]
    ret = np.array([r["return"] for r in mine])
    result = score(ret, np.array([none[k]["return"] for k in keys]),
                   np.array([base[k]["return"] for k in keys]))  # fmt: skip
    summary = {"sliding_energy_kJ_mean": float(np.mean([r["sliding_energy_kJ"] for r in mine])),
               "air_litres_mean": float(np.mean([r["air_litres"] for r in mine])),
               "max_lock_s_max": float(max(r["max_lock_s"] for r in mine)),
               "max_sliding_kmh_max": float(max(r["max_sliding_kmh"] for r in mine))}  # fmt: skip
    data = {"policies": {"classical": first["policies"]["classical"], "teacher": summary},
            "run_results": {"classical": runs["classical"], "teacher": mine}}  # fmt: skip
    return {**result, "criteria": criteria(data, "teacher")}


def hindsight(first: dict[str, Any], targets: dict, by: str) -> dict[str, Any]:
    """Each stop's best constant target after the fact (``by``: ``"return"``, the highest, or
    ``"distance"``, the shortest stop): its benchmark score with the 95 % interval, the mean
    and worst of its per-stop ratios to the classical WSP's stop, its longest lock, and how
    many stops each target won."""
    kmh = sorted(targets)
    classical = by_stop(first["run_results"]["classical"])
    none = by_stop(first["run_results"]["none"])
    ratios, locks, returns, wins = [], [], [], dict.fromkeys(kmh, 0)
    for k, base in classical.items():
        rows = [targets[t][k] for t in kmh]
        if by == "return":
            i = int(np.argmax([r["return"] for r in rows]))
        else:
            i = int(np.argmin([r["stopping_distance_m"] for r in rows]))
        wins[kmh[i]] += 1
        returns.append(rows[i]["return"])
        ratios.append(rows[i]["stopping_distance_m"] / base["stopping_distance_m"])
        locks.append(rows[i]["max_lock_s"])
    keys = list(classical)
    result = score(np.array(returns), np.array([none[k]["return"] for k in keys]),
                   np.array([classical[k]["return"] for k in keys]))  # fmt: skip
    return {"score": result["score"], "score_ci95": result["score_ci95"],
            "mean_ratio": float(np.mean(ratios)), "worst_ratio": float(np.max(ratios)),
            "longest_lock_s": float(max(locks)), "wins": wins}  # fmt: skip


def choose(classical: dict, targets: dict, worst_limit: float) -> dict[str, dict[str, Any]]:
    """Per rail: every target's figures and the choice (module docstring); ``classical``: the
    classical WSP's runs keyed by (scenario, seed)."""
    lock_limit = max(r["max_lock_s"] for r in classical.values())
    rails = sorted({r["conditions"]["rail"] for r in classical.values()})
    out: dict[str, dict[str, Any]] = {}
    for rail in rails:
        keys = [k for k, r in classical.items() if r["conditions"]["rail"] == rail]
        rows = []
        for kmh, runs in sorted(targets.items()):
            mine = [runs[k] for k in keys]
            ratio = np.array([m["stopping_distance_m"] / classical[k]["stopping_distance_m"]
                              for m, k in zip(mine, keys, strict=True)])  # fmt: skip
            rows.append({
                "kmh": kmh,
                "mean_return": float(np.mean([m["return"] for m in mine])),
                "mean_ratio": float(ratio.mean()),
                "worst_ratio": float(ratio.max()),
                "watchdog_stops": int(sum(m["watchdog"]["total"] > 0 for m in mine)),
                "longest_lock_s": float(max(m["max_lock_s"] for m in mine)),
            })  # fmt: skip
        limits = [
            ("no watchdog stop", lambda r: r["watchdog_stops"] == 0),
            (f"longest lock <= {lock_limit:.2f} s", lambda r: r["longest_lock_s"] <= lock_limit),
            (f"worst stop <= {worst_limit:.2f}", lambda r: r["worst_ratio"] <= worst_limit),
        ]
        for n in (3, 2, 1, 0):
            ok = [r for r in rows if all(test(r) for _, test in limits[:n])]
            if ok:
                best = max(ok, key=lambda r: r["mean_return"])
                dropped = [name for name, _ in limits[n:]]
                break
        out[rail] = {"stops": len(keys), "rows": rows, "choice": best["kmh"], "dropped": dropped}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("benchmark_json", nargs="+", help="development-stop benchmark files")
    ap.add_argument("--worst", type=float, default=1.10, help="worst stop / classical limit")
    ap.add_argument("--loop", choices=tuple(LOOPS), default="default",
                    help="whose constant targets: the default loop's, the drift-corrected "
                         "loop's (slip_target_<x>kmh_drift) or that loop's with the gain "
                         "scaled by the pressure held (..._drift_pgain0.8x0.25) or with its "
                         "onset reading (..._drift_onset), and the wheel-scale calibration "
                         "(..._drift_onset_cal)")  # fmt: skip
    args = ap.parse_args(argv)
    try:
        first, targets = load(args.benchmark_json, args.loop)
        table = choose(by_stop(first["run_results"]["classical"]), targets, args.worst)
        taught = teacher(first, targets, {rail: info["choice"] for rail, info in table.items()})
    except (OSError, ValueError, KeyError, TypeError) as err:
        msg = str(err) if isinstance(err, ValueError) else f"{type(err).__name__}: {err}"
        print(f"choose_rail_targets: {msg}", file=sys.stderr)
        return 2
    for rail, info in table.items():
        print(f"{rail} ({info['stops']} stops)")
        for r in info["rows"]:
            mark = "<-" if r["kmh"] == info["choice"] else "  "
            print(f"  {mark} {r['kmh']:5.2f} km/h  return {r['mean_return']:8.2f}  "
                  f"stop/classical {r['mean_ratio']:.3f} (worst {r['worst_ratio']:.2f})  "
                  f"watchdog {r['watchdog_stops']:2d}  longest lock "
                  f"{r['longest_lock_s']:.2f} s")  # fmt: skip
        if info["dropped"]:
            print(f"     no target meets every limit: dropped {', '.join(info['dropped'])}")
    lo, hi = taught["score_ci95"] or (float("nan"), float("nan"))
    print(f"the teacher with this table on these stops: score {taught['score']:.4f} "
          f"({lo:.4f}-{hi:.4f}); item 6's criteria:")  # fmt: skip
    for r in taught["criteria"]:
        value = "-" if r["value"] is None else f"{r['value']:.4g}"
        mark = "holds" if r["holds"] else "FAILS"
        print(f"  {mark:5s}  {r['criterion']}: {value} against {r['limit']:.4g}")
    held = sum(r["holds"] for r in taught["criteria"])
    print(f"  {held} of {len(taught['criteria'])} criteria hold")
    print("each stop's best target after the fact (no one-target-a-stop teacher beats it):")
    for by in ("return", "distance"):
        h = hindsight(first, targets, by)
        wins = ", ".join(f"{t:g}: {n}" for t, n in h["wins"].items())
        lo, hi = h["score_ci95"] or (float("nan"), float("nan"))
        print(f"  by {by}: score {h['score']:.4f} ({lo:.4f}-{hi:.4f}), "
              f"mean stop / classical (mean of ratios) {h['mean_ratio']:.3f}, worst "
              f"{h['worst_ratio']:.3f}, longest lock {h['longest_lock_s']:.2f} s; stops won "
              f"(km/h: stops) {wins}")  # fmt: skip
    print("teacher_targets_kmh:")
    for rail, info in table.items():
        print(f"  {rail}: {info['choice']:g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

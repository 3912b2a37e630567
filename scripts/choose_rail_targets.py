"""A table of constant slip targets by rail for ``oracle_target_rail`` (the imitation teacher,
``pretrain.teacher_targets_kmh``), chosen on development stops under issue 23 item 6's limits.

Reads benchmark files of ``scripts/slip_target_benchmark.py --stops development --json F`` (the
constant targets ``slip_target_<x>kmh`` beside the classical WSP; several files of the same
stops are merged) and, for each rail, keeps the targets that on that rail's stops

1. bring no watchdog intervention,
2. lock no axle longer than the classical WSP's longest lock over all the stops,
3. make no stop more than ``--worst`` (1.10) times the classical WSP's,

and picks the one with the best mean return. Where no target passes all three, the last limit
is dropped first (then the second), and the line says so. Prints each rail's candidates and the
table as YAML for a config; never reads the sealed set (refuses a file of it).

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

TARGET = re.compile(r"^slip_target_(\d+(?:\.\d+)?)kmh$")


def load(paths: list[str]) -> tuple[dict[tuple, dict], dict[float, dict[tuple, dict]]]:
    """The classical WSP's runs and each constant target's, keyed by (scenario, seed)."""
    classical: dict[tuple, dict] = {}
    targets: dict[float, dict[tuple, dict]] = {}
    for path in paths:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
        if not isinstance(data, dict) or "run_results" not in data:
            raise ValueError(f"{path}: not a benchmark file kept with its runs (--json)")
        if data.get("stops") != "development":
            raise ValueError(f"{path}: stops {data.get('stops')!r}, not development")
        runs = data["run_results"]
        base = {(r["scenario"], int(r["seed"])): r for r in runs.get("classical", [])}
        if not base:
            raise ValueError(f"{path}: no classical runs")
        if classical and set(base) != set(classical):
            raise ValueError(f"{path}: not the same stops as {paths[0]}")
        classical = classical or base
        for name, rows in runs.items():
            m = TARGET.match(name)
            if m:
                targets[float(m.group(1))] = {(r["scenario"], int(r["seed"])): r for r in rows}
    if not targets:
        raise ValueError("no slip_target_<x>kmh policy in the files")
    return classical, targets


def choose(classical: dict, targets: dict, worst_limit: float) -> dict[str, dict[str, Any]]:
    """Per rail: every target's figures and the choice (module docstring)."""
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
    args = ap.parse_args(argv)
    try:
        classical, targets = load(args.benchmark_json)
    except (OSError, ValueError, KeyError, TypeError) as err:
        msg = str(err) if isinstance(err, ValueError) else f"{type(err).__name__}: {err}"
        print(f"choose_rail_targets: {msg}", file=sys.stderr)
        return 2
    table = choose(classical, targets, args.worst)
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
    print("teacher_targets_kmh:")
    for rail, info in table.items():
        print(f"  {rail}: {info['choice']:g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

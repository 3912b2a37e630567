"""Two policies stop by stop on the same stops (sealed or development): on how many one returns
less than the other, the median and mean return change per rail (metres: the return is minus
the stop's cost in units of 100 m), and how much of the summed change its (up to) five largest
gains carry, or losses where the sum is a loss (a mean moved by a few stops is not a typical
stop's); where the base file holds the locked-wheel and classical runs, the difference of the
two scores with a paired bootstrap interval (``benchmark.paired_difference``). Reads the JSON
of ``wsp-env benchmark --json`` (which keeps every run) or of
``scripts/slip_target_benchmark.py --json``; the two files must hold the same stops.

    .venv/bin/python scripts/compare_stops.py runs/exp/bench_const425.json slip_target_4.25kmh \\
        runs/exp/bench_st_lowstd.json st_lowstd/model
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np


def runs_of(path: str, policy: str) -> tuple[dict[tuple[str, int], dict], tuple[Any, Any]]:
    """``policy``'s runs in the benchmark JSON at ``path`` by (scenario, seed), and the file's
    (vehicle, tier): the sealed stops' names and seeds are the same for every vehicle."""
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    runs = data.get("run_results", {})
    if not runs.get(policy):
        raise SystemExit(f"{path}: no runs of policy {policy!r} (has: {', '.join(runs) or 'none'})")
    return {(r["scenario"], int(r["seed"])): r for r in runs[policy]}, (
        data.get("vehicle"), data.get("tier"))  # fmt: skip


def _ends(path: str, keys: list[tuple[str, int]]) -> tuple[np.ndarray, np.ndarray] | None:
    """The locked-wheel and classical returns on ``keys`` from the benchmark JSON at ``path``
    (the score's ends), or None where the file lacks them."""
    runs = json.loads(Path(path).read_text(encoding="utf-8")).get("run_results", {})
    ends = []
    for name in ("none", "classical"):
        by_key = {(r["scenario"], int(r["seed"])): r["return"] for r in runs.get(name) or []}
        if not all(k in by_key for k in keys):
            return None
        ends.append(np.array([by_key[k] for k in keys]))
    return ends[0], ends[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("base_json")
    ap.add_argument("base_policy")
    ap.add_argument("other_json")
    ap.add_argument("other_policy")
    args = ap.parse_args(argv)
    base, where = runs_of(args.base_json, args.base_policy)
    other, other_where = runs_of(args.other_json, args.other_policy)
    if where != other_where:
        print(f"the two files are of different vehicles or tiers: {where} and {other_where}",
              file=sys.stderr)  # fmt: skip
        return 2
    if base.keys() != other.keys():
        print("the two files hold different stops", file=sys.stderr)
        return 2
    keys = sorted(base)
    diff = np.array([other[k]["return"] - base[k]["return"] for k in keys])
    print(
        f"{args.other_policy} against {args.base_policy} on {len(keys)} stops: returns less "
        f"on {100 * np.mean(diff < 0):.0f} %, more on {100 * np.mean(diff > 0):.0f} %; "
        f"median change {100 * np.median(diff):+.1f} m, mean {100 * diff.mean():+.1f} m"
    )
    total = diff.sum()
    side = "gains" if total > 0 else "losses"
    top = np.sort(diff[diff > 0])[::-1][:5] if total > 0 else np.sort(diff[diff < 0])[:5]
    if total != 0 and top.size:
        print(
            f"  the largest {side} (the {top.size} most: "
            f"{', '.join(f'{100 * t:+.0f}' for t in top)} m) carry "
            f"{100 * top.sum() / total:.0f} % of the summed change"
        )
    ends = _ends(args.base_json, keys)
    if ends is not None:
        from wsp_env.evaluation.benchmark import paired_difference

        r_o = np.array([other[k]["return"] for k in keys])
        r_b = np.array([base[k]["return"] for k in keys])
        d = paired_difference(r_o, r_b, *ends)
        if d["difference"] is not None:
            lo, hi = d["difference_ci95"]
            print(
                f"  score difference, paired over the {d['scored_runs']} scored stops: "
                f"{d['difference']:+.4f} (95 % {lo:+.4f} to {hi:+.4f})"
            )
    by_rail: dict[str, list[float]] = {}
    for k, d in zip(keys, diff, strict=True):
        by_rail.setdefault(str(other[k]["conditions"].get("rail")), []).append(float(d))
    for rail, ds in sorted(by_rail.items()):
        print(
            f"  {rail:14s} n {len(ds):3d}  median {100 * np.median(ds):+7.1f} m  "
            f"mean {100 * np.mean(ds):+8.1f} m  less on {100 * np.mean(np.array(ds) < 0):3.0f} %"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

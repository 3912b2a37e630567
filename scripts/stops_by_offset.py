"""A policy's stops against the classical WSP's, grouped by the accelerometer's offset on each
stop: its bias less g times the gradient (a specific-force sensor reads the gradient's
``g sin(theta)`` as well; ``wsp_env.core.sensors``), in m/s^2. A negative offset reads less
deceleration than the train makes, so the aided reference speed runs above the train
(docs/training_log.md, "The third run"). Leaves stops are left out (their tails come from the
rail, not the reference). Reads ``wsp-env benchmark --json``; ``--json F`` writes the rows.

    .venv/bin/python scripts/stops_by_offset.py runs/s9/sealed_es.json bc_st_s1/student
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

import numpy as np

G_MPS2 = 9.81
EDGES = (-np.inf, -0.3, -0.15, 0.0, 0.15, np.inf)
WORST = 1.10  # issue 23 item 6: no stop more than 10 % longer than the classical WSP's


def rows(data: dict, policy: str) -> list[dict]:
    """One row a band of offsets: stops, mean stop ratio, stops over ``WORST``."""
    runs = data.get("run_results") or {}
    if not runs.get(policy) or not runs.get("classical"):
        raise ValueError(f"no runs of {policy!r} and 'classical' (has: {', '.join(runs)})")
    base = {(r["scenario"], int(r["seed"])): r for r in runs["classical"]}
    out_ratio, offset = [], []
    for r in runs[policy]:
        b = base.get((r["scenario"], int(r["seed"])))
        if b is None:
            raise ValueError(f"{r['scenario']}: no classical run on this stop")
        if not b["stopping_distance_m"] > 0:
            raise ValueError(
                f"{r['scenario']}: stopping_distance_m: the classical WSP's is not > 0"
            )
        c = b["conditions"]
        if c["rail"] == "leaves":
            continue
        bias = c["sensors"].get("accelerometer_bias_mps2")
        if bias is None:
            raise ValueError(f"{r['scenario']}: no accelerometer on this tier's stops")
        out_ratio.append(r["stopping_distance_m"] / b["stopping_distance_m"])
        offset.append(bias - G_MPS2 * c["gradient_permille"] / 1000.0)
    ratio, off = np.array(out_ratio), np.array(offset)
    table = []
    for lo, hi in itertools.pairwise(EDGES):
        k = (off >= lo) & (off < hi)
        table.append({"offset_from": float(lo), "offset_to": float(hi), "stops": int(k.sum()),
                      "stop_ratio_mean": float(ratio[k].mean()) if k.any() else None,
                      "stops_over_1_10": int((ratio[k] > WORST).sum())})  # fmt: skip
    return table


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("benchmark_json")
    ap.add_argument("policy")
    ap.add_argument("--json", dest="json_path", default=None)
    args = ap.parse_args(argv)
    try:
        table = rows(json.loads(Path(args.benchmark_json).read_text(encoding="utf-8")), args.policy)
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        print(f"{args.benchmark_json}: {err}", file=sys.stderr)
        return 2
    print(f"{args.policy}: stops off leaves by the accelerometer's offset (bias - g x gradient)")
    print("| offset [m/s^2] | stops | stop / classical, mean | stops > 1.10x |")
    print("|---|---|---|---|")
    for r in table:
        band = f"{r['offset_from']:+.2f} to {r['offset_to']:+.2f}".replace("inf", "∞")
        mean = "-" if r["stop_ratio_mean"] is None else f"{r['stop_ratio_mean']:.3f}"
        print(f"| {band} | {r['stops']} | {mean} | {r['stops_over_1_10']} |")
    if args.json_path:
        try:
            Path(args.json_path).write_text(json.dumps(table, indent=1))
        except OSError as err:
            print(f"--json: {args.json_path}: {err.strerror}", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())

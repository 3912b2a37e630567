"""The benchmark's tables for the README: the scores of `wsp-env benchmark` on uic_z1 in both
sensor tiers, and the stops outside the old training range re-run through `wsp-env simulate`.

    .venv/bin/wsp-env benchmark --policy none --policy classical --policy oracle \\
        --tier wheels --json runs/bench/wheels.json
    .venv/bin/wsp-env benchmark --policy classical --policy oracle --policy ppo_bc_uic_z1 \\
        --policy bc_slip_target_accel_uic_z1 --tier wheels+accel --json runs/bench/accel.json
    .venv/bin/python scripts/benchmark_results.py --wheels runs/bench/wheels.json \\
        --accel runs/bench/accel.json --markdown docs/results/benchmark.md

The first two commands produce the scores (each ~5-10 min on 2 cores: the oracle is twelve
controllers); this script lays them out and runs the simulate rows itself (``wsp-env
simulate``'s own code path, in process: seed 3301, every policy of the tier).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path
from typing import Any

from _results_md import write_results

from wsp_env.cli import main as wsp_env

# (label, rail, speed, gradient per mille, accelerometer bias or None): the table
CASES = (
    ("leaves 100 km/h, gradient -20 per mille", "leaves", 100, -20.0, None),
    ("leaves 100 km/h, gradient -10 per mille", "leaves", 100, -10.0, None),
    ("soap 140 km/h, gradient +20 per mille (uphill)", "soap", 140, 20.0, None),
    ("leaves 100 km/h, accelerometer bias +0.3 m/s^2", "leaves", 100, 0.0, 0.3),
    ("dry 120 km/h, accelerometer bias -0.3 m/s^2", "dry", 120, 0.0, -0.3),
)
# (column, policy, with the accelerometer)
COLUMNS = (
    ("none", "none", False),
    ("classical (wheels)", "classical", False),
    ("classical (wheels+accel)", "classical", True),
    ("ppo_bc_uic_z1 (wheels+accel)", "ppo_bc_uic_z1", True),
    ("bc_slip_target_accel_uic_z1 (wheels+accel)", "bc_slip_target_accel_uic_z1", True),
    ("oracle", "oracle", False),
)
SEED = 3301


def simulate(rail: str, speed: float, grade: float, bias: float | None, policy: str,
             accel: bool) -> dict[str, Any]:  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "r.json"
        argv = [
            "simulate",
            "--policy",
            policy,
            "--rail",
            rail,
            "--speed-kmh",
            str(speed),
            "--seed",
            str(SEED),
            "--gradient-permille",
            str(grade),
            "--json",
            str(out),
        ]
        if accel:
            argv.append("--accelerometer")
        if bias is not None:
            argv += ["--accelerometer-bias-mps2", str(bias)]
        assert wsp_env(argv) == 0, argv
        return json.loads(out.read_text())


def score_table(payload: dict[str, Any]) -> str:
    lines = [
        f"**{payload['benchmark']}** ({payload['runs']} stops of the sealed set):",
        "",
        "| policy | score (IQM) | 95 % interval | mean normalised score | stop / classical: mean "
        "| worst | pass rate | watchdog interventions (stops; the override gave way) "
        "| reference error RMS [km/h] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, p in payload["policies"].items():
        ci = "{:.3f}-{:.3f}".format(*p["score_ci95"])
        lines.append(
            f"| {name} | {p['score']:.3f} | {ci} | {p['score_mean']:.2f} | "
            f"{p['stop_ratio_mean']:.3f} | "
            f"{p['stop_ratio_worst']:.2f} | {100 * p['pass_rate']:.0f} % | "
            f"{p['watchdog_interventions']} ({p['watchdog_runs']}; "
            f"{p.get('watchdog_gave_way_runs', '-')}) | "
            f"{p['reference_error_rms_kmh_mean']:.2f} |"
        )
    oracle = payload["policies"].get("oracle", {}).get("beaten_by")
    if oracle:
        lines += ["", "Stops on which a policy beat the oracle (shorter, damage criteria met): "
                  + ", ".join(f"{k} {v}" for k, v in oracle.items()) + "."]  # fmt: skip
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--wheels", type=Path, required=True, help="benchmark JSON, tier wheels")
    ap.add_argument("--accel", type=Path, required=True, help="benchmark JSON, wheels+accel")
    ap.add_argument("--markdown", type=Path, default=None)
    args = ap.parse_args()
    start = time.perf_counter()
    wheels = json.loads(args.wheels.read_text())
    accel = json.loads(args.accel.read_text())
    for path, payload in ((args.wheels, wheels), (args.accel, accel)):
        if payload.get("stops", "sealed") != "sealed":  # the results page is the sealed set's
            raise SystemExit(f"{path}: {payload['stops']} stops, not the sealed set's results")
    rows = ["| case (seed 3301) | " + " | ".join(c for c, _, _ in COLUMNS) + " |",
            "|---|" + "---|" * len(COLUMNS)]  # fmt: skip
    for label, rail, speed, grade, bias in CASES:
        cells = []
        for _, policy, acc in COLUMNS:
            if bias is not None and not acc and policy != "none" and policy != "oracle":
                cells.append("-")  # a bias needs an accelerometer
                continue
            r = simulate(rail, speed, grade, bias, policy, acc or bias is not None)
            wd = r["watchdog"]["total"] if "watchdog" in r else 0
            cells.append(f"{r['stopping_distance_m']:,.0f} m" + (f" (wd {wd})" if wd else ""))
        rows.append(f"| {label} | " + " | ".join(cells) + " |")
        print(rows[-1], flush=True)
    body = "\n\n".join([
        score_table(wheels), score_table(accel),
        "Stops outside the old training range, through `wsp-env simulate` (seed 3301; `wd N`: "
        "the safety watchdog intervened N times; the bias rows run with the accelerometer for "
        "every policy, the oracle reads the true state and ignores it):",
        "\n".join(rows),
    ])  # fmt: skip
    print(body)
    if args.markdown:
        write_results(args.markdown, "Benchmark: scores on the sealed set, stops outside the "
                      "training range", body, time.perf_counter() - start)  # fmt: skip


if __name__ == "__main__":
    main()

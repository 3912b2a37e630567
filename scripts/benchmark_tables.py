"""The benchmark tables: `none`, `classical` and `oracle` on en15595 and heldout.

    .venv/bin/python scripts/benchmark_tables.py [--suite en15595 --suite heldout] [--json P]
        [--markdown docs/results/benchmark_tables.md]

Every policy runs through `evaluation.run_suite` (one code path, the same scenarios and seeds);
per scenario the table gives mean ± standard deviation over the seeds of the stopping distance,
the deceleration-distance increase over the dry-rail stop (EN 15595's headline figure), the
sliding energy, the largest sliding speed, the longest lock and the air, and the runs that pass
the suite's criteria. `--markdown P` writes the tables with the command and the machine above
them (the docs quote `docs/results/benchmark_tables.md`).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from _results_md import write_results

from wsp_env.evaluation import load_suite, run_suite
from wsp_env.policy import make_policy

POLICIES = ("none", "classical", "oracle")
COLUMNS = (
    ("stopping_distance_m", "stop [m]", 0),
    ("deceleration_distance_increase_pct", "vs dry [%]", 0),
    ("sliding_energy_kJ", "sliding energy [kJ]", 0),
    ("max_sliding_kmh", "max sliding [km/h]", 0),
    ("max_lock_s", "lock [s]", 1),
    ("air_litres", "air [l]", 0),
)


def _cell(values: list[float], digits: int) -> str:
    mean = statistics.fmean(values)
    spread = statistics.pstdev(values) if len(values) > 1 else 0.0
    return f"{mean:.{digits}f} ± {spread:.{digits}f}"


def table(suite_name: str) -> tuple[str, list[dict]]:
    suite = load_suite(suite_name)
    results = {p: run_suite("uic_z1", suite, make_policy(p), record="none")[0] for p in POLICIES}
    scenarios = list(dict.fromkeys(r["scenario"] for r in results["none"]))
    head = "| scenario | policy | " + " | ".join(c[1] for c in COLUMNS) + " | passed |"
    lines = [head, "|" + "---|" * (len(COLUMNS) + 3)]
    for sc in scenarios:
        for p in POLICIES:
            runs = [r for r in results[p] if r["scenario"] == sc]
            cells = " | ".join(_cell([r[k] for r in runs], d) for k, _, d in COLUMNS)
            passed = sum(r["passed"] for r in runs)
            lines.append(f"| {sc} | {p} | {cells} | {passed}/{len(runs)} |")
    total = " · ".join(
        f"`{p}` {sum(r['passed'] for r in results[p])}/{len(results[p])} passed, stop "
        f"{statistics.fmean(r['stopping_distance_m'] for r in results[p]):.0f} m"
        for p in POLICIES
    )
    lines += ["", f"Overall (mean over all runs): {total}"]
    return "\n".join(lines), [r for p in POLICIES for r in results[p]]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", action="append", default=None)
    ap.add_argument("--json", type=Path, default=None, help="also write every run here")
    ap.add_argument("--markdown", type=Path, default=None, help="write the tables here (.md)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    runs = {}
    sections = []
    for name in args.suite or ["en15595", "heldout"]:
        text, runs[name] = table(name)
        print(f"### {name}\n\n{text}\n", flush=True)
        n = len(runs[name]) // len(POLICIES)
        sections.append(f"## `{name}` ({n} runs per policy)\n\n{text}\n")
    if args.markdown is not None:
        intro = (
            "Every policy through `evaluation.run_suite` (the same scenarios and seeds); uic_z1 "
            "unless the scenario names another vehicle; mean ± standard deviation over the "
            "suite's seeds; *vs dry*: the deceleration-distance increase over the same stop on "
            "dry rail (EN 15595's headline figure); lock: the longest; passed: runs meeting the "
            "suite's criteria.\n\n"
        )
        body = intro + "\n".join(sections)
        title = "Benchmark: `none`, `classical`, `oracle`"
        write_results(args.markdown, title, body, time.perf_counter() - t0)
        print(f"wrote {args.markdown}")
    if args.json is not None:
        from wsp_env.files import write_json

        write_json(args.json, {"runs": runs})
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

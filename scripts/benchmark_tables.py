"""The README's benchmark tables: `none`, `classical` and `oracle` on en15595 and heldout.

    .venv/bin/python scripts/benchmark_tables.py [--suite en15595 --suite heldout] [--json P]

Every policy runs through `evaluation.run_suite` (one code path, the same scenarios and seeds);
per scenario the table gives mean ± standard deviation over the seeds of the stopping distance,
the deceleration-distance increase over the dry-rail stop (EN 15595's headline figure), the
sliding energy, the largest sliding speed, the longest lock and the air, and the runs that pass
the suite's criteria. About 3 minutes for en15595 and 1 for heldout on a 2-core machine.
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

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
    args = ap.parse_args()
    runs = {}
    for name in args.suite or ["en15595", "heldout"]:
        text, runs[name] = table(name)
        print(f"### {name}\n\n{text}\n", flush=True)
    if args.json is not None:
        from wsp_env.files import write_json

        write_json(args.json, {"runs": runs})
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

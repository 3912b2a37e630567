"""What keeping each stop's references saves (``evaluation.runner._references``): the same jobs
with the cache off (size 0: every run computes its references, as before 2026-12-07) and on,
alternating in one process, medians and their ratio. The jobs run several policies on the same
stops: the oracle on the ``quick`` suite (its variants each run every stop) and ``wsp-env
validate``'s locked-wheel check (``none`` and the classical WSP on every soap and leaves run of
two suites). The results are checked equal both ways.

    .venv/bin/python scripts/reference_cache_timing.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

from wsp_env.evaluation import load_suite, run_suite, runner
from wsp_env.policy import make_policy
from wsp_env.validation.checks import locked_vs_wsp_check


def _oracle_quick() -> str:
    results, _ = run_suite("uic_z1", load_suite("quick"), make_policy("oracle"), record="none")
    return json.dumps(results, sort_keys=True)


def _locked_check() -> str:
    return json.dumps(locked_vs_wsp_check(), sort_keys=True)


JOBS = {"oracle on quick": _oracle_quick, "validate's locked-wheel check": _locked_check}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    sizes = {"off": (0, 0), "on": (runner.REFERENCE_CACHE_SIZE, runner.DRY_CACHE_SIZE)}
    _oracle_quick()  # compile and load everything once, outside the timings
    for name, job in JOBS.items():
        times: dict[str, list[float]] = {"off": [], "on": []}
        outputs: dict[str, set[str]] = {"off": set(), "on": set()}
        for _ in range(args.repeats):
            for mode, (size, dry_size) in sizes.items():
                runner.REFERENCE_CACHE_SIZE, runner.DRY_CACHE_SIZE = size, dry_size
                runner.clear_reference_cache()  # each job starts cold: only its own reuse counts
                t0 = time.perf_counter()
                outputs[mode].add(job())
                times[mode].append(time.perf_counter() - t0)
        same = outputs["off"] == outputs["on"] and len(outputs["on"]) == 1
        off, on = statistics.median(times["off"]), statistics.median(times["on"])
        print(f"{name}: cache off {off:.2f} s, on {on:.2f} s (medians of {args.repeats}), "
              f"on/off {on / off:.2f}; results identical: {same}")  # fmt: skip
        if not same:
            return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

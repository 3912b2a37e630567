"""The speed-up of an evaluation split across Ray workers (``wsp-env benchmark --workers N``)
against one process, and that every split gives the one-process payload.

    .venv/bin/python scripts/eval_scaling.py --json runs/bench/accel.json \\
        --markdown docs/results/eval_scaling.md

Runs ``wsp-env benchmark --policy classical --policy oracle --policy ppo_bc_uic_z1 --tier
wheels+accel`` (the README's accel benchmark: 300 sealed stops, the oracle twelve controllers)
as a user would, in a fresh process each: one process (the compiled step in parallel over the
cores), then ``--workers 1`` and ``--workers N`` for each N of ``--workers`` (each worker one
core, one Ray task per worker), timing the whole command (Ray's start included). The one-process
payload is written to ``--json`` (what ``benchmark_results.py`` lays out).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _results_md import write_results

BENCH = ["benchmark", "--policy", "classical", "--policy", "oracle", "--policy",
         "ppo_bc_uic_z1", "--tier", "wheels+accel", "--no-progress"]  # fmt: skip


def _run(extra: list[str], out: Path) -> float:
    exe = Path(sys.executable).with_name("wsp-env")
    t0 = time.perf_counter()
    subprocess.run([str(exe), *BENCH, *extra, "--json", str(out)], check=True,
                   stdout=subprocess.DEVNULL)  # fmt: skip
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", required=True, help="the one-process benchmark payload")
    ap.add_argument("--markdown", default=None)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args()
    started = time.perf_counter()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        one = Path(tmp) / "one.json"
        base = _run([], one)
        payload = json.loads(one.read_text())
        rows.append(("one process (kernel parallel over the cores)", base, True))
        for n in args.workers:
            path = Path(tmp) / f"w{n}.json"
            wall = _run(["--workers", str(n)], path)
            rows.append((f"`--workers {n}`", wall, json.loads(path.read_text()) == payload))
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(one.read_text())
    lines = ["| run | wall [s] | speed-up vs one process | vs `--workers 1` | payload = one "
             "process's |", "|---|---|---|---|---|"]  # fmt: skip
    w1 = next((w for label, w, _ in rows if label == "`--workers 1`"), None)
    for label, wall, same in rows:
        vs1 = "—" if w1 is None else f"{w1 / wall:.2f}"
        lines.append(f"| {label} | {wall:.0f} | {base / wall:.2f} | {vs1} | "
                     f"{'yes' if same else 'NO'} |")  # fmt: skip
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        body = (f"`wsp-env {' '.join(BENCH)}`: 300 sealed stops x (none, classical, the oracle's "
                f"12 controllers, ppo_bc_uic_z1).\n\n{text}\n")  # fmt: skip
        write_results(Path(args.markdown), "Evaluation split across Ray workers", body,
                      time.perf_counter() - started)  # fmt: skip
    if not all(same for _, _, same in rows):
        sys.exit("a split payload differs from the one-process payload")


if __name__ == "__main__":
    main()

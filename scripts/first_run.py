"""How long a newcomer's first commands take, numba compiling on an empty cache.

    .venv/bin/python scripts/first_run.py [--tree DIR] [--markdown docs/results/first_run.md]

The package is laid out as a wheel installs it (``check_imports.stage``: ``baselines/``,
``agents/`` and ``configs/`` inside ``wsp_env``) in a fresh temp folder, so no compiled kernel
is cached, and the commands below run there one after the other in new processes, as a first
session would: a stop without WSP, a stop with the classical WSP, the quick suite with the
shipped learned policy beside the classical WSP, and the quick throughput benchmark (which
steps the kernel's parallel path as well). Then the same commands again, warm. ``--tree``
measures another checkout (e.g. an older commit) with this machine's interpreter.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from check_imports import stage

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = (
    ("simulate",),
    ("simulate", "--policy", "classical"),
    ("evaluate", "--policy", "ppo_bc_uic_z1", "--policy", "classical", "--suite", "quick",
     "--no-progress"),
    ("bench", "--quick"),  # the kernel's parallel path too (evaluation's from 64 environments)
)  # fmt: skip


def timings(tree: Path) -> list[tuple[str, float, float]]:
    """Per command: wall seconds cold (empty cache) and warm (its second run)."""
    with tempfile.TemporaryDirectory(prefix="wsp-first-run-") as tmp:
        stage(tree, Path(tmp))
        shutil.copytree(tree / "configs", Path(tmp) / "wsp_env" / "configs")
        env = {**os.environ, "PYTHONPATH": tmp}
        rows = []
        for cold_pass in (True, False):
            for i, cmd in enumerate(COMMANDS):
                t0 = time.perf_counter()
                subprocess.run(
                    [sys.executable, "-m", "wsp_env.cli", *cmd], cwd=tmp, env=env, check=True,
                    capture_output=True,
                )  # fmt: skip
                took = time.perf_counter() - t0
                if cold_pass:
                    rows.append((f"wsp-env {' '.join(cmd)}", took, 0.0))
                else:
                    rows[i] = (rows[i][0], rows[i][1], took)
        return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", type=Path, default=ROOT, help="the checkout to measure (this one)")
    ap.add_argument("--markdown", type=Path, default=None, help="write the table here (.md)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = timings(args.tree.resolve())
    lines = ["| command | first run, empty cache [s] | again, cached [s] |", "|---|---|---|"]
    lines += [f"| `{cmd}` | {cold:.1f} | {warm:.1f} |" for cmd, cold, warm in rows]
    total = sum(r[1] for r in rows)
    lines.append(f"| all {len(rows)} | {total:.1f} | {sum(r[2] for r in rows):.1f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.markdown:
        from _results_md import write_results

        write_results(args.markdown, "First run", text, time.perf_counter() - t0)
    return 0


if __name__ == "__main__":
    sys.exit(main())

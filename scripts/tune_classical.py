"""Random search of the classical WSP thresholds on the en15595 suite (never on heldout).

    .venv/bin/python scripts/tune_classical.py [--n 40]      # ~3 minutes

Objective: mean extension over the reference distance across all runs, plus 20 points per
second of the longest lock beyond 1 s (a WSP that locks wheels is not acceptable however
short it stops). Prints the best configurations; the chosen one goes to
configs/wsp/classical.yaml by hand, with the figures in the commit message.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from wsp_env.baselines.classical import ClassicalWSP, load_wsp_config
from wsp_env.evaluation import load_suite, run_suite


def objective(results) -> float:
    ext = np.mean([r["extension_pct"] for r in results])
    lock = max(r["max_lock_s"] for r in results)
    return float(ext + 20.0 * max(0.0, lock - 1.0))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=40)
    ap.add_argument("--suite", default="en15595")
    args = ap.parse_args()
    suite = load_suite(args.suite)
    base = load_wsp_config()
    rng = np.random.default_rng(1)
    rows = [(objective(run_suite("uic_z1", suite, ClassicalWSP(base), record="none")[0]), base)]
    print(f"current defaults: objective {rows[0][0]:.2f}")
    for _ in range(args.n):
        cfg = dataclasses.replace(
            base,
            slip_rel=rng.uniform(0.05, 0.3),
            slip_abs_kmh=rng.uniform(1.5, 6.0),
            release_ratio=rng.uniform(0.3, 0.95),
            decel_vent_mps2=rng.uniform(2.0, 8.0),
            accel_hold_mps2=rng.uniform(0.3, 3.0),
            ref_decel_active_mps2=rng.uniform(0.4, 1.0),
            periodic_release_interval_s=rng.uniform(2.0, 6.0),
            ref_adapt_margin=rng.uniform(1.0, 1.5),
        )
        rows.append(
            (objective(run_suite("uic_z1", suite, ClassicalWSP(cfg), record="none")[0]), cfg)
        )
    rows.sort(key=lambda r: r[0])
    for value, cfg in rows[:5]:
        changed = {
            k: round(v, 3) for k, v in dataclasses.asdict(cfg).items() if v != getattr(base, k)
        }
        print(f"objective {value:.2f}: {changed}")


if __name__ == "__main__":
    main()

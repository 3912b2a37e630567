"""Fit the E402B anti-skid device's thresholds to seed 002's traction test (Tables 9-10), the
device only: the adhesion (Table 8), load transfer, cleaning and recovery are not touched.

    .venv/bin/python scripts/seed002_traction_fit.py --n 200 --seed 0 \
        [--write configs/antiskid/e402b_seed002.yaml]

Seed 002 gives no anti-skid thresholds (its logic follows the E402B documentation, its ref.
[11]); as for the braking test's WSP (scripts/seed002_reproduction.py) they are searched here
within ranges a traction engineer would accept, by seeded random search. Score: each axle's
mean sliding against the mean of tests T1 and T2 (Table 9), plus a penalty for leaving the
envelope widened by 0.5 km/h, for axle 4 not being the least sliding and for a 20 s distance
outside Table 10's T2-T1 span. About 0.2 s per candidate on one core.

Findings. At Table 8's level under axle 1 with the braking tables' recovery reading
(``--n 150 --seed 0``, 2026-11-23): no setting brings axles 2 and 3 near Table 9 (best -1.73 /
-0.19 / -0.29 / -0.17 km/h): the sliding-power recovery holds them at ~0.3 km/h of slip. With
the readings of ``wsp_env/rig/traction.py`` (axle 1 at R_1 mu_c = 0.0846, Eqs. 9-10 as written:
``--mu-contaminated 0.0846 --recovery-basis wheel_metre``) ``--n 80 --seed 2`` finds
-2.46 / -0.57 / -0.94 / -0.26 km/h and 168.0 m, inside every envelope; that search wrote
``configs/antiskid/e402b_seed002.yaml``.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from wsp_env.baselines.antiskid import AntiSkid, AntiSkidConfig
from wsp_env.rig.traction import DURATION_S, MU_C, run_traction, seed002_rail
from wsp_env.validation.targets import TABLE9_KMH, TABLE9_WIDEN_KMH, TABLE10_M

RANGES = {
    "slip_abs_kmh": (0.5, 4.0),
    "slip_rel": (0.0, 0.1),
    "accel_slip_mps2": (0.5, 3.0),
    "release_ratio": (0.3, 0.9),
    "reduce_per_s": (0.5, 5.0),
    "min_factor": (0.2, 0.8),
    "hold_s": (0.0, 1.0),
    "restore_per_s": (0.1, 1.0),
}


def score(
    cfg: AntiSkidConfig, mu_contaminated: float = MU_C, rail: Any = None
) -> tuple[float, dict]:
    run = run_traction(
        antiskid=AntiSkid(cfg), duration_s=DURATION_S, mu_contaminated=mu_contaminated, rail=rail
    )
    slide = np.array(run.summary["mean_sliding_kmh"])
    target = TABLE9_KMH.mean(axis=0)
    lo = TABLE9_KMH.min(axis=0) - TABLE9_WIDEN_KMH
    hi = TABLE9_KMH.max(axis=0) + TABLE9_WIDEN_KMH
    outside = np.maximum(lo - slide, 0.0) + np.maximum(slide - hi, 0.0)
    d = run.summary["distance_m"]
    s = float(np.abs(slide - target).sum() + 5.0 * outside.sum())
    s += 0.0 if np.argmin(np.abs(slide)) == 3 else 2.0
    s += 0.25 * max(TABLE10_M[0] - d, d - TABLE10_M[1], 0.0)
    return s, {"slide": slide.round(2).tolist(), "distance_m": round(d, 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--write", default=None)
    ap.add_argument("--mu-contaminated", type=float, default=MU_C,
                    help="the soap level under axle 1 (default Table 8's mu_c)")  # fmt: skip
    ap.add_argument("--recovery-basis", default=None,
                    help="the recovery's power basis (default the soap rail's)")  # fmt: skip
    args = ap.parse_args()
    rail = seed002_rail()
    if args.recovery_basis:
        recovery = dataclasses.replace(rail.recovery, basis=args.recovery_basis)
        rail = dataclasses.replace(rail, recovery=recovery)
    rng = np.random.default_rng(args.seed)
    best = (score(AntiSkidConfig(), args.mu_contaminated, rail)[0], AntiSkidConfig(), None)
    print(f"default: score {best[0]:.3f}")
    for i in range(args.n):
        fields = {k: float(rng.uniform(*r)) for k, r in RANGES.items()}
        cfg = AntiSkidConfig(**fields)
        s, info = score(cfg, args.mu_contaminated, rail)
        if s < best[0]:
            best = (s, cfg, info)
            print(f"{i}: score {s:.3f} {info}")
    s, cfg, info = best
    print(f"best: score {s:.3f} {info}")
    if args.write:
        lines = [
            "# The E402B anti-skid device of seed 002's traction test (Tables 9-10). The seed",
            "# gives no thresholds: the ones marked 'fitted' were found by",
            f"#   .venv/bin/python scripts/seed002_traction_fit.py --n {args.n} --seed "
            f"{args.seed} --mu-contaminated {args.mu_contaminated} "
            f"--recovery-basis {args.recovery_basis} --write {args.write}",
            f"# (best of {args.n} draws: score {s:.3f}, {info}).",
        ]
        for k, v in dataclasses.asdict(cfg).items():
            tag = "   # fitted" if k in RANGES else ""
            lines.append(f"{k}: {round(v, 4)}{tag}")
        Path(args.write).write_text("\n".join(lines) + "\n")
        print(f"wrote {args.write}")


if __name__ == "__main__":
    main()

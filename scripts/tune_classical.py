"""Tune the classical WSP's thresholds on the `tuning` suite, then freeze them.

    .venv/bin/python scripts/tune_classical.py --n 80 --refine 40 --write configs/wsp/classical.yaml

A seeded random search over the thresholds (ranges below: values a WSP engineer would accept),
then a local refinement around the best (one threshold at a time, x0.8 / x1.25). Objective: the
mean ratio stop / available-adhesion reference distance over the contaminated runs of the
`tuning` suite (configs/scenarios/tuning.yaml, which shares no level, case or seed with en15595
or heldout), plus 1 for every run that breaks one of its criteria (wheel damage: lock, sliding
energy per axle, slide duration; on dry and wet rail any air at all) and for every soap or
leaves run it does not stop at least ``LOCK_MARGIN`` shorter than with locked wheels (no WSP)
— a WSP that damages wheels, brakes falsely or loses to locking is not acceptable however
short it stops elsewhere.

``--write`` saves the best thresholds with the command, budget and result in the header: from
then on that file is the frozen baseline every learned controller is compared with.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import sys
import time
from pathlib import Path

import numpy as np

from wsp_env.baselines.classical import ClassicalWSP, WSPConfig, load_wsp_config
from wsp_env.envs.tiers import TIER_SENSORS, TIERS
from wsp_env.evaluation import load_suite, run_suite
from wsp_env.policy import NoWSP

# (low, high) of each tuned threshold; the rest keep their WSPConfig defaults
RANGES = {
    "slip_abs_kmh": (1.5, 6.0),
    "slip_rel": (0.04, 0.25),
    "release_ratio": (0.2, 0.9),
    "decel_vent_mps2": (2.0, 8.0),
    "accel_hold_mps2": (0.5, 4.0),
    "reapply_fast_fraction": (0.0, 0.95),
    "reapply_fill_s": (0.02, 0.3),
    "reapply_hold_s": (0.0, 0.5),
    "periodic_release_interval_s": (1.5, 6.0),
    "periodic_release_max_s": (1.0, 4.0),
}
DRY_RAILS = ("dry", "wet")
LOCKING_RAILS = ("soap", "leaves")  # where locked wheels must lose (DESIGN §3)
LOCK_MARGIN = 0.03


ENV_KWARGS: dict = {}  # the sensor tier's settings (--tier), set in main


def tier_kwargs(tier: str) -> dict:
    """The environment settings of sensor ``tier``: its sensors as the benchmark ids fix them
    (``wsp_env.envs.tiers``), so that a classical WSP is tuned on the sensors it is judged with."""
    return {
        "accelerometer": tier == "wheels+accel",
        "sensors": dataclasses.asdict(TIER_SENSORS[tier]),
    }


def locked_stops(suite) -> list[float]:
    """Every run's stop with locked wheels (no WSP): the bar the WSP must clear."""
    results, _ = run_suite("uic_z1", suite, NoWSP(), record="none", env_kwargs=ENV_KWARGS)
    return [r["stopping_distance_m"] for r in results]


def evaluate(cfg: WSPConfig, suite, locked: list[float]) -> tuple[float, dict[str, float]]:
    """Objective of one set of thresholds (module docstring) and its parts."""
    results, _ = run_suite("uic_z1", suite, ClassicalWSP(cfg), record="none", env_kwargs=ENV_KWARGS)
    ratios = [
        r["stopping_distance_m"] / r["reference_distance_m"]
        for r in results
        if r["conditions"]["rail"] not in DRY_RAILS
    ]
    failed = sum(not r["passed"] for r in results)
    lost = sum(
        r["conditions"]["rail"] in LOCKING_RAILS
        and r["stopping_distance_m"] > (1.0 - LOCK_MARGIN) * none_m
        for r, none_m in zip(results, locked, strict=True)
    )
    ratio = float(np.mean(ratios))
    parts = {"mean_stop_ratio": ratio, "failed_runs": failed, "not_beating_locked": lost}
    return ratio + failed + lost, parts


def _draw(rng: np.random.Generator, base: WSPConfig) -> WSPConfig:
    return dataclasses.replace(base, **{k: float(rng.uniform(*r)) for k, r in RANGES.items()})


def _header(args: argparse.Namespace, best: tuple, n_runs: int, wall_s: float) -> str:
    value, parts, _ = best
    return (
        "# Classical WSP thresholds: FROZEN baseline (every learned controller is compared with\n"
        "# these). Tuned on the `tuning` suite (configs/scenarios/tuning.yaml; no level, case or\n"
        "# seed shared with en15595 or heldout) by\n"
        f"#   .venv/bin/python scripts/tune_classical.py --n {args.n} --refine {args.refine} "
        f"--seed {args.seed} --tier {args.tier} --start {args.start}\n"
        f"# (sensor tier {args.tier}: the sensors of wsp_env/envs/tiers.py TIER_SENSORS)\n"
        f"# budget: {n_runs} candidate settings ({wall_s / 60:.0f} min on a 2-core machine, "
        f"{datetime.date.today().isoformat()});\n"
        f"# result: mean stop / available-adhesion reference {parts['mean_stop_ratio']:.3f} "
        f"over the contaminated runs,\n# {parts['failed_runs']} runs breaking a criterion, "
        f"{parts['not_beating_locked']} not {100 * LOCK_MARGIN:.0f} % shorter than locked wheels "
        f"(objective {value:.3f}).\n# See baselines/classical.py for each threshold.\n"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=80, help="random draws")
    ap.add_argument("--refine", type=int, default=40, help="local refinement steps")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--suite", default="tuning")
    ap.add_argument("--write", type=Path, help="save the best thresholds to this YAML file")
    ap.add_argument(
        "--tier", choices=TIERS, default="wheels",
        help="sensor tier: its sensors and, as the start, its frozen thresholds (wheels)",
    )  # fmt: skip
    ap.add_argument(
        "--start", choices=("defaults", "frozen"), default="defaults",
        help="start from WSPConfig's defaults or from the tier's frozen file (defaults)",
    )  # fmt: skip
    args = ap.parse_args()
    ENV_KWARGS.update(tier_kwargs(args.tier))
    if args.suite in ("en15595", "heldout"):
        sys.exit(f"--suite: {args.suite} judges the WSP; tune on `tuning`")
    suite = load_suite(args.suite)
    rng = np.random.default_rng(args.seed)
    start = time.perf_counter()
    base = WSPConfig() if args.start == "defaults" else load_wsp_config(tier="wheels")
    locked = locked_stops(suite)
    rows = [(*evaluate(base, suite, locked), base)]
    print(f"defaults: objective {rows[0][0]:.3f} {rows[0][1]}", flush=True)
    for i in range(args.n):
        cfg = _draw(rng, base)
        rows.append((*evaluate(cfg, suite, locked), cfg))
        best = min(rows, key=lambda r: r[0])
        print(f"draw {i + 1}/{args.n}: {rows[-1][0]:.3f} (best {best[0]:.3f})", flush=True)
    best = min(rows, key=lambda r: r[0])
    names = list(RANGES)
    for i in range(args.refine):
        name = names[i % len(names)]
        factor = (0.8, 1.25)[int(rng.integers(2))]
        lo, hi = RANGES[name]
        value = float(np.clip(getattr(best[2], name) * factor, lo, hi))
        cfg = dataclasses.replace(best[2], **{name: value})
        row = (*evaluate(cfg, suite, locked), cfg)
        rows.append(row)
        if row[0] < best[0]:
            best = row
        print(f"refine {i + 1}/{args.refine}: {name} -> {value:.3g}: {row[0]:.3f} "
              f"(best {best[0]:.3f})", flush=True)  # fmt: skip
    wall = time.perf_counter() - start
    print(f"best: objective {best[0]:.3f} {best[1]}")
    fields = dataclasses.asdict(best[2])
    body = "".join(f"{k}: {round(v, 4)}\n" for k, v in fields.items())
    print(body)
    if args.write:
        args.write.write_text(_header(args, best, len(rows), wall) + body)
        print(f"wrote {args.write}")


if __name__ == "__main__":
    main()

"""What the censored evidence can tell of a rail that gets better part-way (issue 25, item 4):
on traces of the independent generator, the used adhesion of braked wheels rolling with the
train beyond the last slide, against the adhesion the slides showed, on clean traces and on
the power study's ``rail_gets_better`` traces (docs/calibration.md, "The misses").

Per trace: the slide points (``adhesion_model.slides_at_limit``: past the curve's peak and
sliding), the censored bounds (``adhesion_estimate.censored_points``: the rail carried at least
the force a braked, calm, rolling wheel transmitted), both placed on the rail under their axle
(``adhesion_model.axle_offsets_m``). Beyond the last slide's rail position, each bound over its
axle's median slide-point adhesion is ``r``; the trace's statistic is the median ``r`` there. A
rail that got better and stopped the slides should read high; the script prints how high clean
rails read (wheels stop sliding as the demand or the speed falls, a rolling wheel uses the
friction curve's peak where a sliding one sits on its falling side) and, over thresholds on the
statistic that at most ``--fp`` of the clean traces reach, the largest share of the
rail-gets-better traces over one.

    .venv/bin/python scripts/rail_better_null.py [--seed 0] [--clean 100] [--scenarios 20]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibration_power as cp

CLEAN_SEED_OFFSET = 910_000  # clean sliding-rail traces: seed * 1e6 + this + k
MIN_BOUNDS = 3  # bounds beyond the last slide for a statistic


def run_job(job: dict[str, Any]) -> dict[str, Any]:
    if multiprocessing.parent_process() is not None:
        os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    from wsp_env.calibration import independent as ind
    from wsp_env.calibration.adhesion_estimate import censored_points, pooled_points
    from wsp_env.calibration.adhesion_model import axle_offsets_m, slides_at_limit
    from wsp_env.calibration.residuals import MIN_SPEED_KMH
    from wsp_env.calibration.traces import read_trace

    rng = np.random.default_rng(job["seed"])
    scenario = ind.random_scenario(rng, contaminant=cp.sliding_rail(job["seed"]))
    effects = [cp.scaled_effect(ind, c, m, rng, scenario) for c, m in job["effects"]]
    columns, meta = ind.generate(scenario, effects, seed=job["seed"])
    with tempfile.TemporaryDirectory() as tmp:
        csv_path, _ = ind.write_trace(Path(tmp) / "t", columns, meta)
        trace = read_trace(csv_path)
    pts = pooled_points(trace, MIN_SPEED_KMH)
    cen = censored_points(trace, MIN_SPEED_KMH)
    slides = slides_at_limit(trace, pts)
    out = {**job, "slides": int(slides.sum()), "bounds": len(cen), "statistic": None}
    if not slides.any() or not len(cen):
        return out
    off = axle_offsets_m(trace)
    last = float(np.max(pts.position_m[slides] - off[pts.axle[slides]]))
    mu = pts.mu[slides]
    axles = pts.axle[slides]
    level = {int(a): float(np.median(mu[axles == a])) for a in np.unique(axles)}
    beyond = (cen.position_m - off[cen.axle]) > last
    if beyond.sum() < MIN_BOUNDS:
        return out
    ref = np.array([level.get(int(a), float(np.median(mu))) for a in cen.axle[beyond]])
    r = cen.force_N[beyond] / cen.normal_N[beyond] / ref
    out.update(statistic=float(np.median(r)), beyond=int(beyond.sum()))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clean", type=int, default=100)
    ap.add_argument("--scenarios", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--fp", type=float, default=0.02)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args(argv)
    base = args.seed * 1_000_000
    ci = cp.seed_index("rail_gets_better")
    jobs = [{"kind": "clean", "effects": [], "seed": base + CLEAN_SEED_OFFSET + k}
            for k in range(args.clean)]  # fmt: skip
    for mi, mag in enumerate(cp.GRID["rail_gets_better"][0]):  # the power study's seeds
        jobs += [{"kind": f"better x{mag:g}", "effects": [("rail_gets_better", mag)],
                  "seed": base + 10_000 * (ci + 1) + 1000 * mi + k}
                 for k in range(args.scenarios)]  # fmt: skip
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        rows = list(pool.map(run_job, jobs))
    kinds = list(dict.fromkeys(r["kind"] for r in rows))
    stat = {k: np.array([r["statistic"] if r["statistic"] is not None else -np.inf
                         for r in rows if r["kind"] == k]) for k in kinds}  # fmt: skip
    for k in kinds:
        s = stat[k][np.isfinite(stat[k])]
        q = np.percentile(s, [50, 90, 98]) if s.size else [np.nan] * 3
        print(f"{k:>11s}: {stat[k].size} traces, {s.size} with {MIN_BOUNDS}+ bounds beyond the "
              f"last slide; median r there: median {q[0]:.2f}, 90th pct {q[1]:.2f}, 98th "
              f"{q[2]:.2f}")  # fmt: skip
    clean = stat["clean"]
    for k in kinds[1:]:
        best = (0.0, np.inf)
        for th in np.unique(np.concatenate([clean[np.isfinite(clean)], stat[k]])):
            if np.mean(clean >= th) <= args.fp and np.mean(stat[k] >= th) > best[0]:
                best = (float(np.mean(stat[k] >= th)), float(th))
        print(f"{k:>11s}: a threshold that <= {100 * args.fp:g} % of the clean traces reach "
              f"finds {100 * best[0]:.0f} % (at r >= {best[1]:.2f})")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

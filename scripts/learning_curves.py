"""The pure-RL learning curves (issue 23 item 5): each training run's fixed-seed curve
(``curve.json``: the current policy, deterministic, on the same first ``curve_runs`` stops of
the ``validation`` suite every ``curve_every_timesteps``; docs/training.md, "The run") as the
benchmark's score against the steps trained, one panel per group of runs (an algorithm and its
options over its seeds: the seeds' mean, their range shaded; each panel its own scale), beside
the classical WSP (1) and the group's score at step 0.

    .venv/bin/python scripts/learning_curves.py \\
        --group "PPO, valve fractions=runs/train/repeat4_s0,runs/train/repeat4_s1" \\
        --group "PPO, slip target=runs/train/slip_target,..." [--out docs/learning_curves.png]

Prints per group the seeds' score at step 0, at the best point and at the last point. The curve
is 8 stops of ``validation``, not the benchmark's stops: it shows where training goes, the sealed
set says where it ends.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np


def read_curve(run: Path) -> tuple[np.ndarray, np.ndarray]:
    """Steps and scores of a run's ``curve.json``; one line naming the file on a problem."""
    path = run / "curve.json"
    try:
        rows = json.loads(path.read_text(encoding="utf-8"))["history"]
        steps = np.array([int(r["timesteps"]) for r in rows])
        scores = np.array([float(r["score"]) for r in rows])
    except FileNotFoundError:
        raise SystemExit(f"{path}: no such file (a run of wsp-env train with a curve)") from None
    except (ValueError, KeyError, TypeError) as err:
        raise SystemExit(f"{path}: not a learning curve ({type(err).__name__}: {err})") from None
    if not len(rows):
        raise SystemExit(f"{path}: the curve has no point")
    if np.any(np.diff(steps) <= 0):
        raise SystemExit(f"{path}: the curve's steps do not increase")
    return steps, scores


def parse_group(text: str) -> tuple[str, list[Path]]:
    label, sep, runs = text.partition("=")
    if not sep or not label.strip() or not runs.strip():
        raise SystemExit(f"--group {text!r}: expected 'LABEL=RUN_DIR[,RUN_DIR...]'")
    return label.strip(), [Path(r.strip()) for r in runs.split(",") if r.strip()]


def summarise(curves: list[tuple[np.ndarray, np.ndarray]]) -> dict[str, Any]:
    """The seeds' curves on the steps they share (each seed's point at or before each step);
    every curve must start at the same step (``wsp-env train`` takes its first point at 0)."""
    firsts = {int(s[0]) for s, _ in curves}
    if len(firsts) > 1:
        raise SystemExit(f"the group's curves start at different steps: {sorted(firsts)}")
    last = min(int(s[-1]) for s, _ in curves)
    grid = np.unique(np.concatenate([s[s <= last] for s, _ in curves]))
    values = np.array([[sc[np.searchsorted(s, g, side="right") - 1] for g in grid]
                       for s, sc in curves])  # fmt: skip
    return {"steps": grid, "values": values}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--group", action="append", required=True, help="LABEL=RUN[,RUN...]")
    ap.add_argument("--out", default="docs/learning_curves.png")
    args = ap.parse_args(argv)
    groups = [parse_group(g) for g in args.group]
    data = []
    for label, runs in groups:
        s = summarise([read_curve(r) for r in runs])
        v = s["values"]
        best = v.max(axis=1)
        print(
            f"{label}: {len(runs)} seeds, to {s['steps'][-1]:,} steps; score at step 0 "
            f"{v[:, 0].mean():.3f}, best point {best.mean():.3f} "
            f"({best.min():.3f}-{best.max():.3f}), last {v[:, -1].mean():.3f} "
            f"({v[:, -1].min():.3f}-{v[:, -1].max():.3f})"
        )
        data.append((label, s))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = min(3, len(data))
    rows = -(-len(data) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.3 * rows), squeeze=False)
    for ax in axes.flat[len(data) :]:
        ax.set_visible(False)
    for ax, (label, s) in zip(axes.flat, data, strict=False):
        x = s["steps"] / 1e6
        v = s["values"]
        ax.fill_between(x, v.min(axis=0), v.max(axis=0), alpha=0.25, step="post")
        ax.step(x, v.mean(axis=0), where="post", label=f"mean of {v.shape[0]} seeds")
        ax.axhline(1.0, color="k", lw=0.8, ls="--", label="classical WSP")
        ax.axhline(v[:, 0].mean(), color="tab:green", lw=0.8, ls=":", label="step 0")
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("steps trained [M]")
        ax.grid(alpha=0.3)
        ax.set_ylabel("score (curve's 8 validation stops)", fontsize=8)
    axes[0][0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"wrote {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

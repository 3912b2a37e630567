"""The learning curve of an evolution-strategies fine-tune (``wsp-env finetune``): per
generation, the current weights' score less the start's on that generation's fresh training
stops, and the share of those stops on which the current weights return more, each with a
moving mean.

    .venv/bin/python scripts/es_curve.py runs/train/es_st_s1 --png docs/es_curve.png
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def moving_mean(x: np.ndarray, k: int) -> np.ndarray:
    """The mean of each value and the up to ``k - 1`` before it."""
    c = np.cumsum(np.insert(x, 0, 0.0))
    i = np.arange(1, len(x) + 1)
    lo = np.maximum(i - k, 0)
    return (c[i] - c[lo]) / (i - lo)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", nargs="+", help="fine-tune folders (each with history.json)")
    ap.add_argument("--png", required=True, help="the figure to write")
    ap.add_argument("--window", type=int, default=10, help="generations in the moving mean")
    args = ap.parse_args(argv)
    if args.window < 1:
        print("es_curve: --window: must be >= 1", file=sys.stderr)
        return 2
    runs = []
    for folder in args.run:
        path = Path(folder) / "history.json"
        try:
            rows = json.loads(path.read_text())
        except (OSError, ValueError) as err:
            print(f"es_curve: {path}: {err}", file=sys.stderr)
            return 2
        if not rows:
            print(f"es_curve: {path}: no generation yet", file=sys.stderr)
            return 2
        runs.append((Path(folder).name, rows))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for name, rows in runs:
        g = np.array([r["generation"] for r in rows])
        gain = np.array([r["score_gain"] for r in rows])
        better = np.array([r["stops_better"] for r in rows])
        for ax, y in ((axes[0], gain), (axes[1], better)):
            (line,) = ax.plot(g, y, ".", alpha=0.35)
            ax.plot(g, moving_mean(y, args.window), "-", color=line.get_color(), label=name)
    axes[0].axhline(0.0, color="k", lw=0.8)
    axes[0].set_ylabel("score less the start's")
    axes[1].axhline(0.5, color="k", lw=0.8)
    axes[1].set_ylabel("share of stops returning more")
    for ax in axes:
        ax.set_xlabel("generation")
        ax.legend(fontsize=8)
    title = "fine-tune, fresh training stops each generation (dots; line: mean of"
    fig.suptitle(f"{title} {args.window})", fontsize=9)
    fig.tight_layout()
    out = Path(args.png)
    tmp = out.with_name(out.stem + ".tmp.png")
    fig.savefig(tmp, dpi=110)
    tmp.replace(out)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

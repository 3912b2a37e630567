"""How well the training's per-stop weight (``training.stop_weight``) tracks the score's own
scale: on a benchmark JSON with ``none`` and ``classical`` runs (``wsp-env benchmark --stops
development --json F``), the classical WSP's gain ``G = R_classical - R_none`` of each scored
stop (``G >= MIN_GAIN``) against ``d_est``, the braking distance the weight is computed from
(``stop_weight.braking_distance_m``). Prints the correlation of their logarithms and
the quartile spread (75th / 25th percentile) of ``G`` and of ``G / d_est``: the flatter the
latter, the closer the weighted mean return is to the mean of the score's normalised returns.

    .venv/bin/python scripts/stop_weight_fit.py runs/s4/dev_students.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from wsp_env.evaluation.benchmark import MIN_GAIN
from wsp_env.training.stop_weight import StopWeightConfig, braking_distance_m


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bench_json")
    args = ap.parse_args(argv)
    data = json.loads(Path(args.bench_json).read_text(encoding="utf-8"))
    runs = data.get("run_results", {})
    for name in ("none", "classical"):
        if not runs.get(name):
            raise SystemExit(f"{args.bench_json}: no runs of policy {name!r}")
    cfg = StopWeightConfig()
    gain, dist = [], []
    for c, n in zip(runs["classical"], runs["none"], strict=True):
        if (c["scenario"], c["seed"]) != (n["scenario"], n["seed"]):
            raise SystemExit(f"{args.bench_json}: runs of none and classical not in one order")
        g = c["return"] - n["return"]
        if g >= MIN_GAIN:
            gain.append(g)
            dist.append(braking_distance_m(c["conditions"], cfg))
    g, d = np.array(gain), np.array(dist)

    def spread(x: np.ndarray) -> float:
        return float(np.percentile(x, 75) / np.percentile(x, 25))

    r = float(np.corrcoef(np.log(g), np.log(d))[0, 1])
    print(f"{len(g)} scored stops; corr(log G, log d_est) {r:.2f}; quartile spread of G "
          f"{spread(g):.1f}x, of G / d_est {spread(g / d):.1f}x")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())

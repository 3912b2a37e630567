"""How the sliding wheels read a pressure lag's shape (``calibration/wheel_lag.py``) on
independent traces (``calibration/independent.py``, which shares no code with the loop): for
each stop, a 0.2 s dead time, a 0.3 s first-order lag and both at once (0.15 s then 0.3 s) in the
same scenario on a sliding rail, the shape the wheels name, its parameters and the slide
episodes it rests on; then the counts. With ``--discover`` also what the calibration loop adds.
The default seeds 1011-1033 (soap, leaves, oil) are the ones ``wheel_lag``'s rules were checked
on (not the power study's).

    .venv/bin/python scripts/lag_shapes.py [--discover]              # ~45 s (~100 s)
    .venv/bin/python scripts/lag_shapes.py --power runs/power.json   # the study's pair traces
    .venv/bin/python scripts/lag_shapes.py --power runs/power.json --dry-rails   # ~30 s

``--dry-rails``: the study's lag traces on a wet or dry rail (no wheel slides, so the balance
alone decides), each shape's balance RMSE after the loop's fit against the channel's noise floor
(from the added step's cut and its cut over the floor): how far apart the balance puts the
shapes, in noise floors, where the tie margin is half of one.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibration_power as cp

SETS = ((range(1011, 1017), "soap"), (range(1017, 1024), "leaves"), (range(1024, 1028), "oil"),
        (range(1028, 1034), "soap"))  # fmt: skip
LAGS = {"dead_time": [("pressure_lag", 0.2)], "first_order": [("pressure_time_constant", 0.3)],
        "both": [("pressure_lag", 0.15), ("pressure_time_constant", 0.3)]}  # fmt: skip


def read(seed: int, effects: list[tuple[str, float]], overrides: dict[str, Any]) -> Any:
    """The independent trace of ``seed`` with ``effects``, written and read back."""
    from wsp_env.calibration import independent as ind
    from wsp_env.calibration.traces import read_trace

    rng = np.random.default_rng(seed)
    scenario = ind.random_scenario(rng, **overrides)
    effs = [cp.scaled_effect(ind, c, m, rng, scenario) for c, m in effects]
    columns, meta = ind.generate(scenario, effs, seed=seed)
    with tempfile.TemporaryDirectory() as tmp:
        csv_path, _ = ind.write_trace(Path(tmp) / "t", columns, meta)
        return read_trace(csv_path)


def one(seed: int, effects: list[tuple[str, float]], overrides: dict[str, Any],
        loop: bool) -> dict[str, Any]:  # fmt: skip
    from wsp_env.calibration.discovery import discover
    from wsp_env.calibration.wheel_lag import wheel_lag

    trace = read(seed, effects, overrides)
    wheels = wheel_lag(trace)
    row: dict[str, Any] = {"seed": seed, "shape": None if wheels is None else wheels.shape,
                           "params": {} if wheels is None else wheels.params,
                           "episodes": 0 if wheels is None else wheels.episodes}  # fmt: skip
    if loop:
        lag = [s for s in discover(trace).added if s.category == "pressure_lag"]
        row["loop"] = sorted(lag[0].parameters) if lag else []
    return row


def dry_rails(results: list[dict[str, Any]]) -> int:
    """Each lag trace of a study on a wet or dry rail: the balance RMSE after the chosen lag and
    after each other shape the loop named inside the tie margin, in noise floors."""
    from wsp_env.calibration.discovery import discover

    lag_cats = {"pressure_lag", "pressure_time_constant"}
    spans: list[float] = []
    for r in results:
        cats = {e[0] for e in r["effects"]}
        if not cats & lag_cats or cats - lag_cats or r["contaminant"] not in ("wet", "dry"):
            continue
        steps = [s for s in discover(read(r["seed"], r["effects"], r.get("overrides", {}))).added
                 if s.category == "pressure_lag"]  # fmt: skip
        if not steps:
            print(f"seed {r['seed']:7d} {r['contaminant']:4s} {r['effects']}: no lag added")
            continue
        s = steps[0]
        cut, over = s.confidence["cut_pct"] / 100.0, s.confidence["cut_over_noise_floor"]
        floor = (s.after / (1.0 - cut) - s.after) / over  # km/h
        forms = {s.name: s.after} | {a["name"]: a["after"] for a in s.alternative_fits
                                     if a["effect"] == "pressure_lag"}  # fmt: skip
        span = (max(forms.values()) - min(forms.values())) / floor
        spans.append(span)
        shown = ", ".join(f"{n} {(v - s.after) / floor:+.3f}" for n, v in forms.items())
        print(
            f"seed {r['seed']:7d} {r['contaminant']:4s} {r['effects']}: floor {floor:.3f} km/h, "
            f"after the chosen {s.after / floor:.2f} floors; the shapes, against it: {shown}"
        )
    if spans:
        print(
            f"{len(spans)} traces: the shapes' balance fits lie within {max(spans):.3f} noise "
            f"floors of each other (median {np.median(spans):.3f}); the tie margin is 0.5"
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--discover", action="store_true", help="also run the calibration loop")
    ap.add_argument("--power", help="a power study's JSON: its both-shapes pair traces instead")
    ap.add_argument("--dry-rails", action="store_true",
                    help="with --power: the lag traces on wet or dry rail, the shapes' balance "
                    "fits in noise floors")  # fmt: skip
    args = ap.parse_args(argv)
    if args.dry_rails and not args.power:
        ap.error("--dry-rails needs --power (a power study's JSON)")
    if args.power and args.dry_rails:
        return dry_rails(json.loads(Path(args.power).read_text(encoding="utf-8"))["results"])
    if args.power:
        results = json.loads(Path(args.power).read_text(encoding="utf-8"))["results"]
        pair = [
            r
            for r in results
            if r["kind"] == "pair"
            and [e[0] for e in r["effects"]] == ["pressure_lag", "pressure_time_constant"]
        ]
        for r in pair:  # fmt: skip
            row = one(r["seed"], r["effects"], r.get("overrides", {}), False)
            both = all(e["found"] for e in r["effects_found"])
            print(f"seed {r['seed']:7d} {r['contaminant']:7s} wheels {row['shape']!s:12s} "
                  f"episodes {row['episodes']:3d}  found as both: {both}")  # fmt: skip
        return 0
    counts: collections.Counter[tuple[str, str]] = collections.Counter()
    loop_both: collections.Counter[str] = collections.Counter()
    for seeds, rail in SETS:
        for seed in seeds:
            for truth, effects in LAGS.items():
                row = one(seed, effects, {"contaminant": rail}, args.discover)
                counts[truth, str(row["shape"])] += 1
                extra = f"  loop: {row['loop']}" if args.discover else ""
                if args.discover and row["loop"] == ["lag_s", "time_constant_s"]:
                    loop_both[truth] += 1
                params = {k: round(v, 3) for k, v in row["params"].items()}
                print(f"seed {seed} {rail:7s} {truth:12s} wheels {row['shape']!s:12s} "
                      f"{params} episodes {row['episodes']}{extra}", flush=True)  # fmt: skip
    for truth in LAGS:
        read_as = ", ".join(f"{s} {n}" for (t, s), n in sorted(counts.items()) if t == truth)
        both = f"; the loop added both parameters on {loop_both[truth]}" if args.discover else ""
        print(f"{truth}: read as {read_as}{both}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

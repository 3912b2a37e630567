"""Issue 23 item 6's criteria for a shipped policy, checked on one benchmark file against the
tier's classical WSP, criterion by criterion, with what each compares:

- **mean stop**: the mean stopping distance at least 10 % shorter than the classical WSP's,
  under both readings: the ratio of the two means (carried by the long leaves stops), and the
  mean of the per-stop ratios (every stop weighed alike); both must be <= 0.90;
- **sliding energy, air**: the mean a stop no more than the classical WSP's;
- **longest lock, maximum sliding speed**: the largest over the stops no more than the
  classical WSP's;
- **worst stop**: no stop more than 10 % longer than the classical WSP's on it;
- **watchdog**: no stop on which the safety watchdog intervened;
- **soap, soap_etr1000**: the mean stopping distance shorter than the classical WSP's on each
  rail's stops taken alone (the gain shown separately).

Reads the JSON of ``wsp-env benchmark --json`` (every run is kept there); exits 0 when every
criterion holds, 1 when one fails, 2 on a bad file.

    .venv/bin/python scripts/ship_criteria.py runs/s10/sealed.json es_cap_s1/model [--json F]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

STOP_GAIN = 0.90  # mean stopping distance at most 0.90 x the classical WSP's
WORST_STOP = 1.10  # no stop more than 1.10 x the classical WSP's
RAILS = ("soap", "soap_etr1000")
SUMMARY_KEYS = (
    ("sliding energy a stop [kJ]", "sliding_energy_kJ_mean"),
    ("air a stop [l]", "air_litres_mean"),
    ("longest lock [s]", "max_lock_s_max"),
    ("maximum sliding speed [km/h]", "max_sliding_kmh_max"),
)


def criteria(data: dict[str, Any], policy: str, classical: str = "classical") -> list[dict]:
    """Each criterion's row: name, the policy's value, the classical WSP's (or the limit), and
    whether it holds. ``data`` is a benchmark JSON's content."""
    runs = data.get("run_results") or {}
    summary = data.get("policies") or {}
    for name in (policy, classical):
        if not runs.get(name) or name not in summary:
            have = ", ".join(runs) or "none"
            raise ValueError(f"no runs of policy {name!r} (has: {have})")
    base = {(r["scenario"], int(r["seed"])): r for r in runs[classical]}
    mine = {(r["scenario"], int(r["seed"])): r for r in runs[policy]}
    if set(base) != set(mine):
        raise ValueError(f"{policy!r} and {classical!r} ran different stops")
    keys = sorted(base)
    d_base = np.array([base[k]["stopping_distance_m"] for k in keys], dtype=float)
    d_mine = np.array([mine[k]["stopping_distance_m"] for k in keys], dtype=float)
    if not (np.isfinite(d_base).all() and (d_base > 0).all() and np.isfinite(d_mine).all()):
        raise ValueError("stopping_distance_m: a missing, non-finite or zero distance")
    ratio = d_mine / d_base
    rail = np.array([base[k]["conditions"]["rail"] for k in keys])
    rows = [
        _row("mean stop / classical (ratio of means)", d_mine.mean() / d_base.mean(),
             STOP_GAIN),
        _row("mean stop / classical (mean of ratios)", ratio.mean(), STOP_GAIN),
    ]  # fmt: skip
    for label, key in SUMMARY_KEYS:
        rows.append(_row(label, summary[policy][key], summary[classical][key],
                         _where_max(key, mine, keys, summary[classical][key])))  # fmt: skip
    worst = int(np.argmax(ratio))
    over = int((ratio > WORST_STOP).sum())
    rows.append(_row("worst stop / classical", ratio[worst], WORST_STOP,
                     f"{keys[worst][0]}; {over} stops over"))  # fmt: skip
    wd = [k for k in keys if mine[k]["watchdog"]["total"] > 0]
    named = ", ".join(f"{k[0]} ({mine[k]['conditions']['rail']})" for k in wd[:4])
    rows.append(_row("stops with a watchdog intervention", len(wd), 0,
                     named + (" ..." if len(wd) > 4 else "")))  # fmt: skip
    for name in RAILS:
        on = rail == name
        if not on.any():
            rows.append({"criterion": f"{name}: mean stop / classical", "value": None,
                         "limit": 1.0, "holds": False, "note": "no stop on this rail"})  # fmt: skip
            continue
        rows.append(_row(f"{name}: mean stop / classical", d_mine[on].mean() / d_base[on].mean(),
                         1.0, f"{int(on.sum())} stops", strict=True))  # fmt: skip
    return rows


def _where_max(key: str, mine: dict, keys: list, limit: float) -> str:
    """For a largest-over-stops criterion: the stop that sets the policy's largest value and
    how many of its stops exceed the classical WSP's largest, where the file keeps each stop's
    figure (benchmark files written since 2026-11-27 do: ``benchmark.RUN_FIGURES``); else ""."""
    field = key.removesuffix("_max")
    if not key.endswith("_max") or any(field not in mine[k] for k in keys):
        return ""
    values = np.array([mine[k][field] for k in keys], dtype=float)
    top = keys[int(np.argmax(values))]
    over = int((values > limit).sum())
    return f"largest on {top[0]} ({mine[top]['conditions']['rail']}); {over} stops over"


def _row(name: str, value: float, limit: float, note: str = "", strict: bool = False) -> dict:
    holds = value < limit if strict else value <= limit
    return {"criterion": name, "value": float(value), "limit": float(limit),
            "holds": bool(holds), "note": note}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("benchmark_json", help="a `wsp-env benchmark --json` file")
    ap.add_argument("policy", help="the policy's name in it")
    ap.add_argument("--json", dest="json_path", default=None, help="write the rows here")
    args = ap.parse_args(argv)
    try:
        data = json.loads(Path(args.benchmark_json).read_text(encoding="utf-8"))
        if not isinstance(data, dict):
            raise ValueError("not a benchmark file")
        rows = criteria(data, args.policy)
    except (OSError, ValueError, KeyError, TypeError) as err:
        msg = str(err) if isinstance(err, ValueError) else f"{type(err).__name__}: {err}"
        print(f"{args.benchmark_json}: {msg}", file=sys.stderr)
        return 2
    print(f"{data.get('benchmark', '?')} ({data.get('stops', '?')} stops, {data.get('runs')} runs):"
          f" {args.policy} against the classical WSP")  # fmt: skip
    for r in rows:
        value = "-" if r["value"] is None else f"{r['value']:.4g}"
        mark = "holds" if r["holds"] else "FAILS"
        note = f"  ({r['note']})" if r["note"] else ""
        print(f"  {mark:5s}  {r['criterion']}: {value} against {r['limit']:.4g}{note}")
    failed = [r["criterion"] for r in rows if not r["holds"]]
    print(f"{len(rows) - len(failed)} of {len(rows)} criteria hold")
    if args.json_path:
        try:
            Path(args.json_path).write_text(json.dumps({"policy": args.policy, "rows": rows}))
        except OSError as err:
            print(f"--json: {args.json_path}: {err.strerror}", file=sys.stderr)
            return 2
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

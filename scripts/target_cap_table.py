"""``choose_rail_targets.py`` over (target, creep cap) pairs: the constant targets of
``scripts/slip_target_benchmark.py --max-creep C`` runs (policies ``slip_target_<x>kmh`` for
the default cap 0.2, ``slip_target_<x>kmh_creep<c>`` for another; other loops skipped), each
pair a candidate. Prints per rail the pair chosen by ``choose_rail_targets.choose``'s rule and
the four best by mean return, the teacher of that table (score, item 6's criteria held), and
each stop's best pair after the fact by return and by distance: how much a cap chosen per rail
beside the target could add to the one-target-a-stop family.

    .venv/bin/python scripts/target_cap_table.py runs/s16/uic_tier_dev.json \\
        runs/s17/uic_caps_lo_dev.json runs/s17/uic_caps_hi_dev.json runs/s16/uic_tier_nocap_dev.json
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import choose_rail_targets as crt

from wsp_env.baselines.slip_target import DEFAULT_MAX_CREEP

NAME = re.compile(r"^slip_target_(\d+(?:\.\d+)?)kmh(?:_creep(\d*\.?\d+))?$")


def load_pairs(paths: list[str]) -> tuple[dict, dict[float, dict], dict[float, tuple]]:
    """The first file's content, each pair's runs keyed by (scenario, seed) under an index key
    (``choose_rail_targets`` keys its candidates by a float), and each key's (km/h, cap)."""
    first: dict = {}
    targets: dict[float, dict] = {}
    label: dict[float, tuple[float, float]] = {}
    for path in paths:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
        if data.get("stops") != "development":
            raise ValueError(f"{path}: stops {data.get('stops')!r}, not development")
        if first and crt.loop_thresholds(data) != crt.loop_thresholds(first):
            raise ValueError(f"{path}: the loop on other thresholds than {paths[0]}")
        first = first or data
        for name, rows in data["run_results"].items():
            m = NAME.match(name)
            if not m:
                continue
            pair = (float(m.group(1)), float(m.group(2)) if m.group(2) else DEFAULT_MAX_CREEP)
            if pair in label.values():
                raise ValueError(f"{path}: {name} is in an earlier file too")
            key = float(len(label))
            label[key] = pair
            targets[key] = crt.by_stop(rows)
    if not targets:
        raise ValueError("no slip_target_<x>kmh policy in the files")
    return first, targets, label


def main(argv: list[str] | None = None) -> int:
    paths = sys.argv[1:] if argv is None else argv
    try:
        if not paths:
            raise ValueError("give development-stop files of slip_target_benchmark.py")
        first, targets, label = load_pairs(paths)
        table = crt.choose(crt.by_stop(first["run_results"]["classical"]), targets, 1.10)
        taught = crt.teacher(first, targets, {r: info["choice"] for r, info in table.items()})
    except (OSError, ValueError, KeyError) as err:
        msg = str(err) if isinstance(err, ValueError) else f"{type(err).__name__}: {err}"
        print(f"target_cap_table: {msg}", file=sys.stderr)
        return 2
    for rail, info in table.items():
        kmh, cap = label[info["choice"]]
        print(f"{rail}: {kmh:g} km/h at cap {cap:g}")
        for r in sorted(info["rows"], key=lambda r: -r["mean_return"])[:4]:
            k, c = label[r["kmh"]]
            print(f"    {k:5.2f} km/h cap {c:4.2f}  return {r['mean_return']:8.2f}  "
                  f"stop/classical {r['mean_ratio']:.3f} (worst {r['worst_ratio']:.2f})  "
                  f"watchdog {r['watchdog_stops']:2d}  longest lock "
                  f"{r['longest_lock_s']:.2f} s")  # fmt: skip
    lo, hi = taught["score_ci95"] or (float("nan"), float("nan"))
    held = sum(r["holds"] for r in taught["criteria"])
    ratio = next(r["value"] for r in taught["criteria"] if "mean of ratios" in r["criterion"])
    print(f"the teacher of this table: score {taught['score']:.4f} ({lo:.4f}-{hi:.4f}), "
          f"mean of ratios {ratio:.3f}, {held} of {len(taught['criteria'])} of item 6's "
          "criteria")  # fmt: skip
    for by in ("return", "distance"):
        h = crt.hindsight(first, targets, by)
        lo, hi = h["score_ci95"] or (float("nan"), float("nan"))
        print(f"each stop's best pair by {by}: score {h['score']:.4f} ({lo:.4f}-{hi:.4f}), "
              f"mean of ratios {h['mean_ratio']:.3f}, worst {h['worst_ratio']:.3f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())

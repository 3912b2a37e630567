"""The learned-controller results: a learned policy against the frozen classical WSP (and
`none`, `oracle`) on `heldout`, plus a check on random scenarios nobody chose.

    .venv/bin/python scripts/learned_tables.py [--policy ppo_bc_uic_z1] [--random 60]
        [--json runs/learned_tables.json] [--markdown docs/results/learned_tables.md]

Every policy runs through `evaluation.run_suite` (one code path, the same scenarios and seeds).
Per `heldout` scenario: mean and 95 % interval of the mean over the seeds (Student t, 3 seeds:
mean +- 4.30 s / sqrt(3)). Then the acceptance of issue 10 against the classical WSP, on the
means over all runs: stop at least 5 % shorter; no more sliding energy, air, lock or maximum
sliding speed (the worst run's lock and sliding speed); no scenario family (a `heldout` case,
all its speeds and seeds) more than 5 % longer.

`--random N`: N scenarios drawn by a seeded generator (seed 20261123, never a training or
suite seed) from every rail of `configs/rails.yaml` (level uniform in the rail's range, its
patterns), 40 km/h to the vehicle's maximum, loads 0.85-1.15, emergency or service demand,
gradients +-5 permille; learned against classical, per contaminant.

`--markdown P` writes the tables with the command and the machine above them (the docs quote
`docs/results/learned_tables.md`).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np
from _results_md import write_results
from scipy import stats

from wsp_env.core.config import from_dict, load_rails, load_vehicle
from wsp_env.evaluation import SuiteConfig, load_suite, run_suite
from wsp_env.policy import make_policy

COLUMNS = (
    ("stopping_distance_m", "stop [m]", 0),
    ("sliding_energy_kJ", "sliding energy [kJ]", 0),
    ("max_sliding_kmh", "max sliding [km/h]", 1),
    ("max_lock_s", "lock [s]", 2),
    ("air_litres", "air [l]", 0),
)
RANDOM_SEED = 20261123


def _ci(values: list[float]) -> tuple[float, float]:
    """Mean and the half-width of its 95 % Student-t interval."""
    mean = statistics.fmean(values)
    if len(values) < 2:
        return mean, 0.0
    half = stats.t.ppf(0.975, len(values) - 1) * statistics.stdev(values) / len(values) ** 0.5
    return mean, float(half)


def _family(scenario: str) -> str:
    head, _, tail = scenario.rpartition("_")
    return head if tail.isdigit() else scenario


def heldout_table(policies: list[str], learned: str) -> tuple[str, dict[str, Any]]:
    suite = load_suite("heldout")
    results = {p: run_suite("uic_z1", suite, make_policy(p), record="none")[0] for p in policies}
    names = {p: results[p][0]["policy"] for p in policies}
    scenarios = list(dict.fromkeys(r["scenario"] for r in results["classical"]))
    head = "| scenario | policy | " + " | ".join(c[1] for c in COLUMNS) + " | passed |"
    lines = [head, "|" + "---|" * (len(COLUMNS) + 3)]
    for sc in scenarios:
        for p in policies:
            runs = [r for r in results[p] if r["scenario"] == sc]
            cells = []
            for key, _, digits in COLUMNS:
                mean, half = _ci([r[key] for r in runs])
                cells.append(f"{mean:.{digits}f} ± {half:.{digits}f}")
            passed = sum(r["passed"] for r in runs)
            lines.append(f"| {sc} | {names[p]} | {' | '.join(cells)} | {passed}/{len(runs)} |")
    overall = {}
    for p in policies:
        rs = results[p]
        overall[p] = {
            "runs": len(rs),
            "passed": sum(r["passed"] for r in rs),
            "stop_m": _ci([r["stopping_distance_m"] for r in rs]),
            "sliding_energy_kJ": statistics.fmean(r["sliding_energy_kJ"] for r in rs),
            "air_litres": statistics.fmean(r["air_litres"] for r in rs),
            "max_lock_s": max(r["max_lock_s"] for r in rs),
            "max_sliding_kmh": max(r["max_sliding_kmh"] for r in rs),
        }
    lines += [
        "",
        "| policy | passed | mean stop [m] (95 % interval) | sliding energy [kJ] | "
        "air [l] | worst lock [s] | worst sliding [km/h] |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in policies:
        o = overall[p]
        lines.append(
            f"| {names[p]} | {o['passed']}/{o['runs']} | {o['stop_m'][0]:.0f} ± "
            f"{o['stop_m'][1]:.0f} | {o['sliding_energy_kJ']:.0f} | {o['air_litres']:.0f} | "
            f"{o['max_lock_s']:.2f} | {o['max_sliding_kmh']:.1f} |"
        )
    acceptance = _acceptance(results["classical"], results[learned])
    lines += ["", "Acceptance against the classical WSP:"]
    lines += [
        f"- {k}: {v['text']} — {'met' if v['met'] else 'NOT met'}" for k, v in acceptance.items()
    ]
    data = {
        "overall": overall,
        "acceptance": acceptance,
        "runs": [r for p in policies for r in results[p]],
    }
    return "\n".join(lines), data


def _acceptance(classical: list[dict], learned: list[dict]) -> dict[str, Any]:
    def mean(rs: list[dict], k: str) -> float:
        return statistics.fmean(r[k] for r in rs)

    out: dict[str, Any] = {}
    ratio = mean(learned, "stopping_distance_m") / mean(classical, "stopping_distance_m")
    out["mean stop"] = {
        "met": ratio <= 0.95,
        "value": ratio,
        "text": f"{100 * (ratio - 1):+.1f} % (target <= -5 %)",
    }
    for key, label, worst in (
        ("sliding_energy_kJ", "sliding energy", False),
        ("air_litres", "air", False),
        ("max_lock_s", "lock", True),
        ("max_sliding_kmh", "maximum sliding speed", True),
    ):
        a = max(r[key] for r in classical) if worst else mean(classical, key)
        b = max(r[key] for r in learned) if worst else mean(learned, key)
        what = "worst run" if worst else "mean"
        out[label] = {
            "met": b <= a + 1e-9,
            "value": [b, a],
            "text": f"{what} {b:.2f} against {a:.2f}",
        }
    families = {}
    for fam in dict.fromkeys(_family(r["scenario"]) for r in classical):
        c = [r["stopping_distance_m"] for r in classical if _family(r["scenario"]) == fam]
        lr = [r["stopping_distance_m"] for r in learned if _family(r["scenario"]) == fam]
        families[fam] = statistics.fmean(lr) / statistics.fmean(c)
    worst_fam = max(families, key=families.get)
    out["worst family"] = {
        "met": families[worst_fam] <= 1.05,
        "value": families,
        "text": f"{worst_fam} {100 * (families[worst_fam] - 1):+.1f} % (limit +5 %); "
        + ", ".join(f"{k} {100 * (v - 1):+.1f} %" for k, v in families.items()),
    }
    return out


def random_suite(n: int, vehicle: str = "uic_z1") -> SuiteConfig:
    """``n`` scenarios drawn over every rail, level, pattern, speed, load, demand, gradient."""
    rng = np.random.default_rng(RANDOM_SEED)
    rails = load_rails()
    v_max = load_vehicle(vehicle).max_speed_kmh
    cases = []
    for i in range(n):
        name = list(rails)[int(rng.integers(len(rails)))]
        rail = rails[name]
        lo, hi = rail.mu_contaminated_range
        patterns = list(rail.patterns)
        weights = np.array([rail.patterns[p] for p in patterns], dtype=float)
        pattern = patterns[int(rng.choice(len(patterns), p=weights / weights.sum()))]
        cases.append(
            {
                "name": f"r{i:03d}_{name}",
                "rail": name,
                "mu_contaminated": float(rng.uniform(lo, hi)),
                "pattern": pattern,
                "speeds_kmh": [f"{rng.uniform(40.0, v_max):.1f}"],
                "load_factor": float(rng.uniform(0.85, 1.15)),
                "demand": "emergency" if rng.uniform() < 0.7 else "service",
                "gradient_permille": float(rng.uniform(-5.0, 5.0)),
            }
        )
    return from_dict(
        SuiteConfig,
        {
            "name": "random",
            "description": "random draws",
            "seeds": [RANDOM_SEED % 100000],
            "cases": cases,
        },
    )


def random_table(learned: str, n: int) -> tuple[str, dict[str, Any]]:
    suite = random_suite(n)
    res = {
        p: run_suite("uic_z1", suite, make_policy(p), record="none")[0]
        for p in ("classical", learned)
    }
    lines = [
        "| rail | scenarios | learned / classical stop: mean (min–max) | learned shorter | "
        "sliding energy [kJ] learned / classical | air [l] learned / classical |",
        "|---|---|---|---|---|---|",
    ]
    by_rail: dict[str, list[int]] = {}
    for i, r in enumerate(res["classical"]):
        by_rail.setdefault(r["conditions"]["rail"], []).append(i)
    by_rail["all"] = list(range(len(res["classical"])))
    summary = {}
    for rail, idx in by_rail.items():
        c = [res["classical"][i] for i in idx]
        lr = [res[learned][i] for i in idx]
        ratios = [
            b["stopping_distance_m"] / a["stopping_distance_m"] for a, b in zip(c, lr, strict=True)
        ]
        shorter = sum(x < 1.0 for x in ratios)
        se = (
            statistics.fmean(r["sliding_energy_kJ"] for r in lr),
            statistics.fmean(r["sliding_energy_kJ"] for r in c),
        )
        air = (
            statistics.fmean(r["air_litres"] for r in lr),
            statistics.fmean(r["air_litres"] for r in c),
        )
        summary[rail] = {
            "n": len(idx),
            "ratio_mean": statistics.fmean(ratios),
            "ratio_min": min(ratios),
            "ratio_max": max(ratios),
            "shorter": shorter,
            "sliding_energy_kJ": se,
            "air_litres": air,
        }
        lines.append(
            f"| {rail} | {len(idx)} | {statistics.fmean(ratios):.3f} ({min(ratios):.3f}–"
            f"{max(ratios):.3f}) | {shorter}/{len(idx)} | {se[0]:.0f} / {se[1]:.0f} | "
            f"{air[0]:.0f} / {air[1]:.0f} |"
        )
    return "\n".join(lines), {"summary": summary}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default="ppo_bc_uic_z1", help="learned policy (name/path)")
    ap.add_argument("--random", type=int, default=60, help="random scenarios (0: none)")
    ap.add_argument("--json", default=None, help="write every result here")
    ap.add_argument("--markdown", default=None, help="write the tables here (.md)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    text, data = heldout_table(["none", "classical", "oracle", args.policy], args.policy)
    print(text)
    sections = [
        "## `heldout`\n\nEvery policy through `evaluation.run_suite` (the same scenarios and "
        "seeds); uic_z1; mean ± half-width of the 95 % Student-t interval of the mean over the "
        "suite's 3 seeds. Then the means over all runs, and the acceptance against the classical "
        f"WSP.\n\n{text}\n"
    ]
    if args.random:
        rtext, rdata = random_table(args.policy, args.random)
        print(f"\nRandom scenarios ({args.random}, seed {RANDOM_SEED}):\n")
        print(rtext)
        data["random"] = rdata
        sections.append(
            f"## {args.random} random scenarios\n\nDrawn by a seeded generator (seed "
            f"{RANDOM_SEED}, never a training or suite seed) over every rail of "
            "`configs/rails.yaml`, its levels and patterns, 40 km/h to the vehicle's maximum, "
            "loads 0.85-1.15, emergency or service demand, gradients ±5 ‰; "
            f"`{args.policy}` against `classical`, per rail.\n\n{rtext}\n"
        )
    if args.markdown:
        title = f"Learned (`{args.policy}`) against classical"
        write_results(args.markdown, title, "\n".join(sections), time.perf_counter() - t0)
        print(f"wrote {args.markdown}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(data, indent=1, default=float))


if __name__ == "__main__":
    main()

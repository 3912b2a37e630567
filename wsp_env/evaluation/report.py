"""Markdown + PNG report of a suite evaluation (``wsp-env evaluate --report DIR``).

The report is built in a temporary folder next to ``DIR`` and moved into place at the end, so
an interrupted run never leaves a half-written report.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from wsp_env.core.records import RunRecord
from wsp_env.evaluation.benchmark import stop_set_note
from wsp_env.evaluation.plotting import plot_run
from wsp_env.files import replace_dir_atomically


def _fmt(stats: dict[str, float], digits: int = 1) -> str:
    return f"{stats['mean']:.{digits}f} ± {stats['std']:.{digits}f}"


def _bar_figure(
    path: Path, title: str, ylabel: str, groups: list[str], series: dict[str, Any]
) -> None:
    fig = Figure(figsize=(max(6.0, 0.9 * len(groups) + 2), 4.2), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    width = 0.8 / max(len(series), 1)
    x = np.arange(len(groups))
    for i, (name, (means, stds)) in enumerate(series.items()):
        ax.bar(
            x + (i - (len(series) - 1) / 2) * width, means, width, yerr=stds, capsize=3, label=name
        )
    ax.set_xticks(x)
    ax.set_xticklabels(groups, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(axis="y", alpha=0.4)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)


def write_report(
    directory: str | Path,
    suite: Any,
    vehicle: str,
    results: list[dict[str, Any]],
    summary: dict[str, Any],
    records: dict[str, dict[tuple[str, int], RunRecord]],
) -> Path:
    """Write ``report.md`` and ``plots/*.png`` into ``directory`` (replacing an old report)."""
    target = replace_dir_atomically(
        directory, lambda tmp: _build(tmp, suite, vehicle, results, summary, records)
    )
    return target / "report.md"


def _build(out: Path, suite: Any, vehicle: str, results, summary, records) -> None:
    plots = out / "plots"
    plots.mkdir()
    policies = list(summary)
    scenarios = list(dict.fromkeys(r["scenario"] for r in results))
    lines = [
        f"# WSP evaluation: suite `{suite.name}` on `{vehicle}`",
        "",
        suite.description,
        "",
        f"Policies: {', '.join(f'`{p}`' for p in policies)}. Seeds per scenario: "
        f"{len(suite.seeds)} ({', '.join(map(str, suite.seeds))}), identical for every policy.",
        "",
        "Reference distance: the stop an ideal controller would make using all the adhesion the "
        "rail as laid offers under each axle (no cleaning, no recovery), within the brake demand. "
        "Extension = stop / reference - 1 (negative when sliding cleaned the rail or recovered "
        "adhesion). Utilisation = the friction the axles used while braking over the most their "
        "creep curves offered there (recovered level included; at most 1). "
        "Pass/fail criteria are configurable EN 15595-style checks, "
        "not normative values: " + (", ".join(f"{k} {v:g}" for k, v in suite.criteria.items()) or "none") + ".",
        "",
        "## Overall",
        "",
        "| policy | runs passed | stopping distance [m] | extension [%] | utilisation | sliding energy [kJ] | air [l] | longest lock [s] |",
        "|---|---|---|---|---|---|---|---|",
    ]  # fmt: skip
    for p in policies:
        o = summary[p]["overall"]
        lines.append(
            f"| {p} | {summary[p]['passed']}/{summary[p]['runs']} | {_fmt(o['stopping_distance_m'])} | "
            f"{_fmt(o['extension_pct'])} | {_fmt(o['adhesion_utilisation'], 2)} | "
            f"{_fmt(o['sliding_energy_kJ'], 0)} | {_fmt(o['air_litres'], 0)} | {_fmt(o['max_lock_s'], 2)} |"
        )
    for sc in scenarios:
        lines += [
            "",
            f"## {sc}",
            "",
            "| policy | passed | stop [m] | reference [m] | extension [%] | utilisation | mean sliding [km/h] | sliding energy [kJ] | air [l] | longest lock [s] |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]  # fmt: skip
        for p in policies:
            s = summary[p]["scenarios"].get(sc)
            if s is None:
                continue
            ref = np.mean(
                [
                    r["reference_distance_m"]
                    for r in results
                    if r["scenario"] == sc and r["policy"] == p
                ]
            )
            lines.append(
                f"| {p} | {s['passed']}/{s['runs']} | {_fmt(s['stopping_distance_m'])} | {ref:.1f} | "
                f"{_fmt(s['extension_pct'])} | {_fmt(s['adhesion_utilisation'], 2)} | "
                f"{s['mean_sliding_kmh']:.1f} | {_fmt(s['sliding_energy_kJ'], 0)} | "
                f"{_fmt(s['air_litres'], 0)} | {_fmt(s['max_lock_s'], 2)} |"
            )
        for p in policies:
            for (scenario, seed), rec in records.get(p, {}).items():
                if scenario != sc:
                    continue
                name = f"{p}_{sc}_seed{seed}.png"
                plot_run(rec, plots / name, title=f"{vehicle} {sc} seed {seed}: {p}")
                lines += ["", f"![{p} {sc}](plots/{name})"]
        axle_series = {}
        for p in policies:
            runs = [r for r in results if r["scenario"] == sc and r["policy"] == p]
            if runs:
                per_axle = np.array([[a["mean_sliding_kmh"] for a in r["axles"]] for r in runs])
                axle_series[p] = (per_axle.mean(axis=0), per_axle.std(axis=0))
        if axle_series:
            n = len(next(iter(axle_series.values()))[0])
            name = f"sliding_{sc}.png"
            _bar_figure(plots / name, f"{sc}: mean sliding per axle (seed 002 Eq. 23)", "km/h",
                        [f"axle {i + 1}" for i in range(n)], axle_series)  # fmt: skip
            lines += ["", f"![sliding per axle](plots/{name})"]
    if len(policies) > 1:
        series = {}
        for p in policies:
            sc_stats = summary[p]["scenarios"]
            series[p] = (
                [sc_stats[s]["stopping_distance_m"]["mean"] for s in scenarios],
                [sc_stats[s]["stopping_distance_m"]["std"] for s in scenarios],
            )
        _bar_figure(
            plots / "comparison.png", "stopping distance by scenario", "m", scenarios, series
        )
        lines += ["", "## Side by side", "", "![comparison](plots/comparison.png)"]
    (out / "report.md").write_text("\n".join(lines) + "\n")


def benchmark_markdown(payload: dict[str, Any]) -> str:
    """The benchmark's tables (``wsp-env benchmark``'s JSON) as markdown: one row per policy,
    then per scenario family the score and the worst stop ratio."""
    lines = [
        f"# {payload['benchmark']}: {payload['runs']} stops" + stop_set_note(payload),
        "",
        f"Score: {payload['score_definition']}.",
        "",
        "| policy | score (IQM) | 95 % interval | scored stops | stop / classical, mean | "
        "worst | pass rate | sliding energy, kJ | longest lock, s (max) | air, l | valve ops "
        "per axle | watchdog (stops; gave way) | reference error RMS, km/h |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, p in payload["policies"].items():
        sc = "-" if p["score"] is None else f"{p['score']:.3f}"
        ci = "-" if p["score_ci95"] is None else "{:.3f} - {:.3f}".format(*p["score_ci95"])
        lines.append(
            f"| {name} | {sc} | {ci} | {p['scored_runs']} | {p['stop_ratio_mean']:.3f} | "
            f"{p['stop_ratio_worst']:.2f} | {100 * p['pass_rate']:.0f} % | "
            f"{p['sliding_energy_kJ_mean']:.0f} | {p['max_lock_s_max']:.1f} | "
            f"{p['air_litres_mean']:.0f} | {p['valve_operations_per_axle_mean']:.1f} | "
            f"{p['watchdog_interventions']} ({p['watchdog_runs']}; "
            f"{p.get('watchdog_gave_way_runs', '-')}) | "
            f"{p['reference_error_rms_kmh_mean']:.2f} |"
        )
    oracle = payload["policies"].get("oracle", {}).get("beaten_by")
    if oracle:
        beats = ", ".join(f"{k} {v}" for k, v in oracle.items())
        lines += ["", f"Stops on which a policy beat the oracle (shorter, damage criteria met): "
                  f"{beats}."]  # fmt: skip
    for key, title in (("rail", "rail"), ("gradient", "gradient"), ("speed", "initial speed")):
        groups = next(iter(payload["policies"].values()))["families"][key]
        lines += ["", f"## By {title}", "",
                  "| policy | " + " | ".join(f"{g} (n={groups[g]['runs']})" for g in groups)
                  + " |", "|---|" + "---|" * len(groups)]  # fmt: skip
        for name, p in payload["policies"].items():
            cells = []
            for g in groups:
                f = p["families"][key][g]
                sc = "-" if f["score"] is None else f"{f['score']:.2f}"
                cells.append(f"{sc} / {f['stop_ratio_worst']:.2f}")
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines.append("")
        lines.append("Cells: score (IQM) / worst stop ratio to the classical WSP.")
    for name, p in payload["policies"].items():
        w = p["worst_run"]
        lines.append(
            f"\nWorst stop of {name}: {w['scenario']} (seed {w['seed']}), "
            f"{w['stopping_distance_m']:.0f} m against the classical WSP's "
            f"{w['classical_m']:.0f} m; {w['conditions']}."
        )
    return "\n".join(lines) + "\n"


def write_benchmark_report(out_dir: Path, payload: dict[str, Any]) -> None:
    """``report.md`` of a benchmark run into ``out_dir`` (a reserved temporary folder)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "report.md").write_text(benchmark_markdown(payload))

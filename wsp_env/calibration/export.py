"""Calibration outputs: a config the environment loads, and a Markdown/PNG report.

``export_config(PATH, ...)`` writes two files:

* ``PATH`` — a rail table (the ``configs/rails.yaml`` schema) with one entry, ``calibrated``:
  the seed 000 Eq. 9 law fitted to the trace's critical points;
* ``PATH.options.yaml`` — the ``reset`` options the discovered effects translate into
  (gradient, pad friction, per-axle adhesion, non-wheel brake force).

Used as::

    env = gymnasium.make("WSPBraking-v0", rails_config=PATH,
                         scenario={"rails": {"calibrated": 1.0}})
    env.reset(options={"rail": "calibrated", **yaml.safe_load(open(PATH + ".options.yaml"))})
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from wsp_env.calibration.adhesion_estimate import eq9, estimate_adhesion, fit_polach
from wsp_env.calibration.discovery import Result
from wsp_env.calibration.residuals import channels
from wsp_env.calibration.traces import Trace
from wsp_env.trace_io import replace_dir_atomically, write_atomically


def scenario_options(result: Result) -> dict[str, Any]:
    """Environment ``reset`` options implied by the added effects."""
    opts: dict[str, Any] = {}
    for step in result.added:
        p = step.parameters
        if step.category == "gradient":
            opts["gradient_permille"] = float(p["gradient_permille"])
        elif step.category == "pad_friction" and "scale" in p:
            opts["pad_factor"] = float(p["scale"])
        elif step.category == "unmeasured_brake_force":
            opts["extra_brake_force_N"] = max(0.0, float(p["force_at_full_demand_N"]))
        elif step.category == "adhesion_per_axle":
            n = sum(1 for k in p if k.startswith("axle_") and k.endswith("_factor"))
            factors = [1.0] + [float(p[f"axle_{i}_factor"]) for i in range(2, n + 2)]
            top = max(factors)
            opts["axle_mu_factor"] = [f / top for f in factors]
    return opts


def export_config(path: str | Path, trace: Trace, result: Result) -> tuple[Path, Path]:
    """Write ``PATH`` (rail table) and ``PATH.options.yaml`` (reset options)."""
    target = Path(path)
    fits = [fit_polach(a) for a in estimate_adhesion(trace)]
    ok = [f for f in fits if np.isfinite(f.mu0)]
    if not ok:
        raise ValueError(f"{trace.path}: too few critical points to fit an adhesion law")
    mu0 = float(np.median([f.mu0 for f in ok]))
    if "axle_mu_factor" in scenario_options(result):  # the law of the best axle
        mu0 = float(max(f.mu0 for f in ok))
    rail = {
        "calibrated": {
            "law": "polach_simple",
            "law_params": {
                "K": float(np.median([f.K for f in ok])),
                "K_rozv_per_kmh": float(np.median([f.K_rozv for f in ok])),
            },
            "mu_clean": max(0.2, mu0),
            "mu_contaminated": mu0,
            "mu_contaminated_range": [mu0, mu0],
            "contamination": 1.0,
            "clean_energy_J_per_m": float("inf"),
        }
    }
    header = (
        f"# Calibrated from {trace.path} by wsp-env calibrate (seed 000 Eq. 9 fitted to the\n"
        f"# critical points; median over {len(ok)} axles). Scenario options: "
        f"{target.name}.options.yaml\n"
    )
    text = header + yaml.safe_dump(rail, sort_keys=False)
    opts_path = target.with_name(target.name + ".options.yaml")
    opts_text = yaml.safe_dump(scenario_options(result), sort_keys=True)
    target.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(target, lambda fh: fh.write(text))
    write_atomically(opts_path, lambda fh: fh.write(opts_text))
    return target, opts_path


def write_report(directory: str | Path, trace: Trace, result: Result) -> Path:
    """``report.md`` + plots: errors before/after, added effects, residuals, adhesion curves."""
    target = replace_dir_atomically(directory, lambda tmp: _build(tmp, trace, result))
    return target / "report.md"


def _build(out: Path, trace: Trace, result: Result) -> None:
    lines = [
        f"# Calibration of `{trace.path.name}`",
        "",
        f"{trace.meta.get('test_id', '')} — {trace.n_axles} axles, "
        f"{trace.time_s[-1] - trace.time_s[0]:.1f} s, contaminant {trace.meta.get('contaminant')}.",
        "",
        "| channel | before | after |",
        "|---|---|---|",
    ]
    for key, before in result.errors_before.items():
        lines.append(f"| {key} | {before:.3f} | {result.errors_after[key]:.3f} |")
    lines += ["", "## Added effects", ""]
    if not result.added:
        lines.append("Nothing to add: the model explains the data within its noise floors.")
    for s in result.added:
        params = ", ".join(f"{k} = {v:.4g}" for k, v in s.parameters.items())
        lines.append(
            f"- **{s.category}** on `{s.channel}`: {s.before:.3f} → {s.after:.3f} "
            f"(ΔBIC {s.delta_bic:.0f}); {params}"
        )
    if trace.notes:
        lines += ["", "Reading notes: " + "; ".join(trace.notes)]
    # residual plot (balance channel, nominal model)
    ch = channels(trace)["train_speed_balance_kmh"]
    fig = Figure(figsize=(8, 3.5), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.plot(trace.time_s, np.where(ch.mask, ch.residual, np.nan), label="nominal model")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("predicted - measured speed drop [km/h]")
    ax.set_title("train-speed balance residual")
    ax.grid(alpha=0.4)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "balance_residual.png")
    # adhesion curves per axle (seed 000 Figs. 5-8)
    axles = estimate_adhesion(trace)
    fig = Figure(figsize=(8, 4.5), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    table = [
        "",
        "## Eq. 9 fit per axle (seed 000 Table 4 layout)",
        "",
        "| axle | mu0 | K | K_rozv [1/(km/h)] | points | rmse |",
        "|---|---|---|---|---|---|",
    ]
    xi = np.linspace(0.0, 0.4, 100)
    v_ref = float(np.median(trace.v_train_kmh))
    for i, a in enumerate(axles):
        f = fit_polach(a)
        line = ax.plot(a.creepage, a.mu, ".", alpha=0.5, label=f"axle {i + 1}")[0]
        if np.isfinite(f.mu0):
            ax.plot(xi, eq9(xi, xi * v_ref, f.mu0, f.K, f.K_rozv), color=line.get_color())
        table.append(
            f"| {i + 1} | {f.mu0:.4f} | {f.K:.2f} | {f.K_rozv:.4f} | {f.n_points} | {f.rmse:.4f} |"
        )
    ax.set_xlabel("creepage")
    ax.set_ylabel("adhesion coefficient")
    ax.set_title(f"critical points and Eq. 9 fits (curves at {v_ref:.0f} km/h)")
    ax.grid(alpha=0.4)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "adhesion_curves.png")
    lines += table
    lines += [
        "",
        "![balance residual](balance_residual.png)",
        "",
        "![adhesion curves](adhesion_curves.png)",
    ]
    (out / "report.md").write_text("\n".join(lines) + "\n")

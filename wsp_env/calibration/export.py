"""Calibration outputs: a config the environment loads, and a Markdown/PNG report.

``export_config(PATH, ...)`` writes two files:

* ``PATH`` — a rail table (the ``configs/rails.yaml`` schema) with one entry, ``calibrated``:
  the seed 000 Eq. 9 law fitted to the trace's critical points (with seed 002 recovery when
  the data call for it);
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

from wsp_env.calibration.adhesion_estimate import (
    RECOVERY_TAU_S,
    RECOVERY_ZETA,
    cleaning_factor,
    eq9,
    estimate_adhesion,
    fit_polach,
)
from wsp_env.calibration.discovery import Result
from wsp_env.calibration.residuals import channels
from wsp_env.calibration.traces import Trace
from wsp_env.files import replace_dir_atomically, write_atomically


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
    gain = result.adhesion_law.get("cleaning_gain")
    if gain is not None and "axle_mu_factor" not in opts and result.n_axles > 1:
        # the base law's cleaning along the train, as the env's per-axle factors
        factors = list(cleaning_factor(np.arange(result.n_axles), result.n_axles)([gain]))
        opts["axle_mu_factor"] = [float(f / max(factors)) for f in factors]
    return opts


def ambiguity_comments(result: Result) -> str:
    """YAML comments recording, for each effect the trace did not decide, the alternatives the
    options were not built from (comments: ``reset`` reads the options unchanged)."""
    lines = []
    for st in result.added:
        if not st.ambiguous:
            continue
        chosen = ", ".join(f"{k} {v:.4g}" for k, v in st.parameters.items())
        lines.append(f"# ambiguous: built from {st.category} ({chosen}); as well explained by:")
        for a in st.alternative_fits:
            flat: dict[str, float] = {}
            for k, v in a["parameters"].items():  # a pair's: per category
                if isinstance(v, dict):
                    flat.update({f"{k}.{kk}": vv for kk, vv in v.items()})
                else:
                    flat[k] = v
            params = ", ".join(f"{k} {v:.4g}" for k, v in flat.items())
            lines.append(f"#   {a['effect']} ({params}; dBIC {a['delta_bic']:.0f})")
        lines.append(f"#   to separate them: {st.separate_by}")
    return "".join(line + "\n" for line in lines)


def export_config(
    path: str | Path, trace: Trace, result: Result, name: str | None = None
) -> tuple[Path, Path]:
    """Write ``PATH`` (rail table) and ``PATH.options.yaml`` (reset options); ``name``: the
    table's file name as its header names it (default: ``PATH``'s; a temp path's final name).

    The rail is the calibrated adhesion law (``Result.adhesion_law``: the pooled Eq. 9 fit, with
    the last adhesion effect's joint refit) as a ``polach_simple`` rail, its level that of the
    grippiest axle when per-axle factors are exported (they are normalised to it; the base
    law's cleaning along the train is exported as such factors too), and seed
    002's recovery on the sliding-power basis when the base law has it.
    """
    target = Path(path)
    law = result.adhesion_law
    if not np.isfinite(law.get("mu0", np.nan)):
        raise ValueError(f"{trace.path}: too few critical points to fit an adhesion law")
    opts = scenario_options(result)
    mu0 = float(law["mu0"])
    if "axle_mu_factor" in opts:  # factors normalised to the grippiest axle
        mu0 = float(mu0 / opts["axle_mu_factor"][0])  # axle 1 carries the law's own level
    rail: dict[str, Any] = {
        "law": "polach_simple",
        "law_params": {"K": float(law["K"]), "K_rozv_per_kmh": float(law["K_rozv"])},
        "mu_clean": max(0.2, mu0),
        "mu_contaminated": mu0,
        "mu_contaminated_range": [mu0, mu0],
        "contamination": 1.0,
        "clean_energy_J_per_m": float("inf"),
    }
    if "recovery_w_lim_kW" in law:
        rail["recovery"] = {
            "w_lim": 1e3 * float(law["recovery_w_lim_kW"]),
            "w_max": 1e3 * float(law["recovery_w_max_kW"]),
            "gain": float(law["recovery_gain"]),
            "tau_s": RECOVERY_TAU_S,
            "zeta": RECOVERY_ZETA,
            "basis": "sliding_power",
        }
    rail = {"calibrated": rail}
    header = (
        f"# Calibrated from {trace.path} by wsp-env calibrate (seed 000 Eq. 9 fitted to all\n"
        f"# axles' critical points{', with recovery' if 'recovery' in rail['calibrated'] else ''}"
        f"). Scenario options: {name or target.name}.options.yaml\n"
    )
    text = header + yaml.safe_dump(rail, sort_keys=False)
    opts_path = target.with_name(target.name + ".options.yaml")
    opts_text = ambiguity_comments(result) + yaml.safe_dump(opts, sort_keys=True)
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

"""Markdown + PNG report of ``wsp-env validate`` (``--report DIR``), built atomically."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from wsp_env.evaluation.plotting import plot_run
from wsp_env.files import replace_dir_atomically


def write_validation_report(directory: str | Path, result: dict[str, Any]) -> Path:
    """Write ``report.md`` and ``plots/*.png`` into ``directory`` (replacing an old report)."""
    target = replace_dir_atomically(directory, lambda tmp: _build(tmp, result))
    return target / "report.md"


def _flag(ok: bool) -> str:
    return "**pass**" if ok else "**FAIL**"


def _seed000_figure(path: Path, check: dict[str, Any]) -> None:
    from wsp_env.calibration.adhesion_estimate import eq9

    fig = Figure(figsize=(10, 7), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2, sharex=True, sharey=True).ravel()
    xi = np.linspace(0.0, 0.3, 200)
    for i, (ax, pts, fit) in enumerate(zip(axes, check["_points"], check["_fits"], strict=True)):
        ax.scatter(pts.creepage, pts.mu, s=8, color="C0", alpha=0.6, label="critical points")
        speed = np.median(pts.sliding_kmh / np.maximum(pts.creepage, 1e-6))  # typical km/h
        if np.isfinite(fit.mu0):
            ax.plot(xi, eq9(xi, xi * speed, fit.mu0, fit.K, fit.K_rozv), color="C3",
                    label=f"Eq. 9 fit: mu0 {fit.mu0:.3f}, K_rozv {fit.K_rozv:.4f}")  # fmt: skip
        t4 = check["table4"]
        ax.plot(xi, eq9(xi, xi * speed, t4["mu0"][i], t4["K"][i], t4["K_rozv"][i]),
                color="0.4", ls="--", label="Table 4")  # fmt: skip
        ax.set_title(f"axle {i + 1}")
        ax.grid(alpha=0.4)
        ax.legend(fontsize=7)
    for ax in axes[2:]:
        ax.set_xlabel("creepage")
    for ax in axes[::2]:
        ax.set_ylabel("adhesion coefficient")
    fig.suptitle("Seed 000 Fig. 5 / Table 4 through our estimator: ETR 1000, soap, 150 km/h")
    fig.savefig(path)


def _locked_figure(path: Path, rows: list[dict[str, Any]]) -> list[str]:
    names = list(dict.fromkeys(f"{r['suite']}:{r['scenario']}" for r in rows))
    none = [np.mean([r["none_m"] for r in rows if f"{r['suite']}:{r['scenario']}" == n])
            for n in names]  # fmt: skip
    wsp = [np.mean([r["classical_m"] for r in rows if f"{r['suite']}:{r['scenario']}" == n])
           for n in names]  # fmt: skip
    fig = Figure(figsize=(max(7.0, 0.6 * len(names) + 2), 4.5), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    x = np.arange(len(names))
    ax.bar(x - 0.2, none, 0.4, label="none (wheels lock)", color="C3")
    ax.bar(x + 0.2, wsp, 0.4, label="classical WSP", color="C0")
    ax.set_xticks(x)
    ax.set_xticklabels(names, rotation=40, ha="right", fontsize=7)
    ax.set_ylabel("stopping distance [m] (mean of seeds)")
    ax.set_title("Locked wheels lose: soap and leaves runs of en15595 and heldout")
    ax.grid(axis="y", alpha=0.4)
    ax.legend()
    fig.savefig(path)
    return names


def _build(out: Path, result: dict[str, Any]) -> None:
    plots = out / "plots"
    plots.mkdir()
    s2, s0 = result["seed002"], result["seed000"]
    locked, dry = result["locked_vs_wsp"], result["dry_quiet"]
    lines = [
        "# Physics fidelity checks (`wsp-env validate`)",
        "",
        "Each check is a premise the adhesion model must hold together with the others "
        "(docs/physics.md; docs/validation.md says how each is judged).",
        "",
        f"## Seed 002 braking test (Tables 6-7, Table 5 fixed): {_flag(s2['passed'])}",
        "",
        f"Stop {s2['stopping_distance_m']:.1f} m (Table 7: 725 m ± 5 %); without WSP "
        f"{s2['none_stopping_distance_m']:.1f} m ({s2['none_margin_pct']:+.1f} %).",
        "",
        "| axle | mean sliding [km/h] | Table 6 (B1 / B2) | std [km/h] |",
        "|---|---|---|---|",
    ]
    from wsp_env.validation.targets import TABLE6

    for i, (m, sd) in enumerate(zip(s2["mean_sliding_kmh"], s2["std_sliding_kmh"], strict=True)):
        lines.append(f"| {i + 1} | {m:.2f} | {TABLE6[0, i]:.2f} / {TABLE6[1, i]:.2f} | {sd:.2f} |")
    plot_run(s2["_record"], plots / "seed002.png", title="Seed 002 braking test (cf. Fig. 15)")
    lines += ["", "![seed 002](plots/seed002.png)", ""]
    lines += [
        f"## Seed 000 Table 4 through our estimator: {_flag(s0['passed'])}",
        "",
        f"mu0 within 15 %: {s0['mu0_within_15pct']}; rising from the front bogie to the rear one: "
        f"{s0['mu0_rising_between_bogies']}; "
        f"K_rozv within a factor 2: {s0['K_rozv_within_factor_2']}.",
        "",
        "| axle | mu0 (Table 4) | K (Table 4) | K_rozv (Table 4) | points |",
        "|---|---|---|---|---|",
    ]
    t4 = s0["table4"]
    for i in range(4):
        lines.append(
            f"| {i + 1} | {s0['mu0'][i]:.4f} ({t4['mu0'][i]:.4f}) | {s0['K'][i]:.1f} "
            f"({t4['K'][i]:.2f}) | {s0['K_rozv'][i]:.4f} ({t4['K_rozv'][i]:.4f}) | "
            f"{s0['n_points'][i]} |"
        )
    _seed000_figure(plots / "seed000.png", s0)
    lines += ["", "![seed 000](plots/seed000.png)", ""]
    lines += [
        f"## Locked wheels lose (en15595 and heldout, soap and leaves): {_flag(locked['passed'])}",
        "",
        "| suite | scenario | seed | none [m] | classical [m] | none / classical | longest lock "
        "without WSP [s] | sliding energy none / classical [kJ] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in locked["runs"]:
        ratio = f"{r['none_m'] / r['classical_m']:.3f}" if r["judged"] else "n/a (no lock)"
        lines.append(
            f"| {r['suite']} | {r['scenario']} | {r['seed']} | {r['none_m']:.0f} | "
            f"{r['classical_m']:.0f} | {ratio} | {r['none_max_lock_s']:.1f} | "
            f"{r['none_sliding_energy_kJ']:.0f} / {r['classical_sliding_energy_kJ']:.0f} |"
        )
    _locked_figure(plots / "locked_vs_wsp.png", locked["runs"])
    lines += ["", "![locked vs WSP](plots/locked_vs_wsp.png)", ""]
    lines += [
        f"## Quiet on good adhesion: {_flag(dry['passed'])}",
        "",
        "| scenario | none [m] | classical [m] | classical air [l] |",
        "|---|---|---|---|",
    ]
    for r in dry["runs"]:
        lines.append(
            f"| {r['scenario']} | {r['none_m']:.1f} | {r['classical_m']:.1f} | "
            f"{r['classical_air_l']:.1f} |"
        )
    rig = result["rig"]
    lines += [
        "",
        f"## Seed 002's test on the roller rig (HIL, §3, §5.2.2): {_flag(rig['passed'])}",
        "",
        f"Rig {rig['rig_stopping_distance_m']:.1f} m, track alone "
        f"{rig['track_stopping_distance_m']:.1f} m ({rig['rig_vs_track_pct']:+.2f} %, limit "
        "1 %); e_omega RMS under 0.5 km/h on every axle.",
        "",
        "| axle | e_omega RMS / max [km/h] | e_C RMS / max [N m] | mean sliding rig / track "
        "[km/h] |",
        "|---|---|---|---|",
    ]
    for i in range(len(rig["e_omega_rms_kmh"])):
        lines.append(
            f"| {i + 1} | {rig['e_omega_rms_kmh'][i]:.3f} / {rig['e_omega_max_kmh'][i]:.3f} | "
            f"{rig['e_C_rms_Nm'][i]:.0f} / {rig['e_C_max_Nm'][i]:.0f} | "
            f"{rig['mean_sliding_kmh'][i]:.2f} / {rig['track_mean_sliding_kmh'][i]:.2f} |"
        )
    from wsp_env.rig.roller_rig import plot_rig

    plot_rig(rig["_result"], str(plots / "rig.png"))
    lines += ["", "![rig](plots/rig.png)", ""]
    tr = result["seed002_traction"]
    open_note = "" if tr["in_overall_verdict"] else " (open: not yet in the overall verdict)"
    lines += [
        "",
        f"## Seed 002 traction test (Tables 9-10): {_flag(tr['passed'])}{open_note}",
        "",
        f"E402B from 5 km/h, 12,300 N m per axle, {tr['duration_s']:g} s: "
        f"{tr['distance_m']:.1f} m (Table 10: 159.64-225.57 m; at 18 / 22 s "
        f"{tr['distance_at_18_22_s_m'][0]:.1f} / {tr['distance_at_18_22_s_m'][1]:.1f} m).",
        "",
        "| axle | mean sliding [km/h] | Table 9 T1 / T2 | envelope (+-0.5) | std [km/h] |",
        "|---|---|---|---|---|",
    ]
    from wsp_env.rig.traction import plot_traction
    from wsp_env.validation.targets import TABLE9_KMH

    lo, hi = tr["table9_envelope_kmh"]
    for i, m in enumerate(tr["mean_sliding_kmh"]):
        lines.append(
            f"| {i + 1} | {m:.2f} | {TABLE9_KMH[0, i]:.2f} / {TABLE9_KMH[1, i]:.2f} | "
            f"{lo[i]:.2f} to {hi[i]:.2f} | {tr['std_sliding_kmh'][i]:.2f} |"
        )
    from wsp_env.rig.traction import TractionRun

    plot_traction(TractionRun(summary={}, record=tr["_record"]), str(plots / "traction.png"))
    lines += ["", "![traction](plots/traction.png)", ""]
    (out / "report.md").write_text("\n".join(lines) + "\n")

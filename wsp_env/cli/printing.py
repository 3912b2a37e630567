"""What each ``wsp-env`` subcommand prints from its result (the JSON ``--json`` writes): one
function per command, ``PRINTERS`` by command name."""

from __future__ import annotations

from typing import Any


def print_simulate(result: dict[str, Any]) -> None:
    print(
        f"{result['vehicle']} on {result['rail']} (mu {result['mu_contaminated']:.3f}), "
        f"policy {result['policy']}: stop {result['stopping_distance_m']:.1f} m in "
        f"{result['stopping_time_s']:.1f} s, air {result['air_litres']:.1f} l, "
        f"longest lock {result['max_lock_s']:.1f} s"
    )
    for i, a in enumerate(result["axles"], start=1):
        print(
            f"  axle {i}: sliding {a['mean_sliding_kmh']:5.2f} "
            f"+- {a['std_sliding_kmh']:5.2f} km/h, "
            f"adhesion used {a['mean_adhesion_used']:.3f}, sliding energy "
            f"{a['sliding_energy_kJ']:.0f} kJ"
        )
    for p in result["outputs"]:
        print(f"  wrote {p}")


def print_evaluate(result: dict[str, Any]) -> None:
    print(f"suite {result['suite']} on {result['vehicle']}:")
    for name, s in result["summary"].items():
        o = s["overall"]
        stop = o["stopping_distance_m"]
        print(
            f"  {name:10s} passed {s['passed']}/{s['runs']}  stop {stop['mean']:.0f} m "
            f"(+-{stop['std']:.0f}), extension {o['extension_pct']['mean']:+.1f} %, "
            f"utilisation {o['adhesion_utilisation']['mean']:.2f}, sliding energy "
            f"{o['sliding_energy_kJ']['mean']:.0f} kJ, air {o['air_litres']['mean']:.0f} l, "
            f"longest lock {o['max_lock_s']['max']:.1f} s"
        )
    if result.get("report"):
        print(f"  wrote {result['report']}")


def print_calibrate(result: dict[str, Any]) -> None:
    print(f"calibration of {result['trace']}:")
    for note in result.get("notes", []):
        print(f"  read: {note}")
    for key, before in result["errors_before"].items():
        print(f"  {key:26s} {before:8.3f} -> {result['errors_after'][key]:8.3f}")
    if not result["added_effects"] and not result["unexplained"]:
        print("  nothing to add: the model explains the data")
    elif not result["added_effects"]:
        print("  nothing in the effect library explains the data (below)")
    for e in result["added_effects"]:
        params = ", ".join(f"{k} {v:.4g}" for k, v in e["parameters"].items())
        change = f"{e['before']:.3f} -> {e['after']:.3f}"
        print(f"  added {e['category']} on {e['channel']}: {change} ({params})")
        if e.get("ambiguous"):
            print("    ambiguous: the trace does not decide; as well explained by")
            for a in e.get("alternative_fits") or []:
                ap = "; ".join(
                    f"{k} {v:.4g}"
                    if not isinstance(v, dict)
                    else f"{k}: " + ", ".join(f"{kk} {vv:.4g}" for kk, vv in v.items())
                    for k, v in a["parameters"].items()
                )
                print(f"      {a['effect']} ({ap}; dBIC {a['delta_bic']:.0f}, "
                      f"{a['after']:.3f} left)")  # fmt: skip
            print(f"    to separate them: {e['separate_by']}")
    for d in result.get("dropped_effects", []):
        print(f"  dropped {d['category']}: {d['reason']}")
    for name, h in result.get("channels", {}).items():
        if not h["usable"]:
            print(f"  channel {name} not used: {h['reason']}")
        elif h.get("extensions"):
            print(f"  channel {name}: {h['extensions']}")
    for u in result["unexplained"]:
        print(
            f"  unexplained: {u['channel']} still {u['rmse']:.3f} "
            f"(noise floor {u['noise_floor']:.3f}) - an effect outside the library"
        )
    for p in result["outputs"]:
        print(f"  wrote {p}")


def print_bench(result: dict[str, Any]) -> None:
    if "wsp_env_steps_per_s" in result:  # --train
        from wsp_env.training.bench import format_train_bench

        print(format_train_bench(result))
        return
    from wsp_env.evaluation.bench import format_bench

    print(format_bench(result))


def print_train(result: dict[str, Any]) -> None:
    best, cl = result["best_validation"], result["classical_validation"]
    print(
        f"{result['algo']}: {result['total_timesteps']:,} steps, {result['wall_time_s']:.0f} s "
        f"({result['env_steps_per_s']:,.0f} env-steps/s this call)"
    )
    print(
        f"best on {result['validation_suite']} at {best['timesteps']:,} steps: "
        f"{best['passed']}/{best['runs']} passed, "
        f"mean stop {best['mean_stopping_distance_m']:.0f} m "
        f"(classical WSP {cl['passed']}/{cl['runs']}, {cl['mean_stopping_distance_m']:.0f} m)"
    )
    print(f"  wrote {result['model_path']}")


def print_finetune(result: dict[str, Any]) -> None:
    last = result.get("last")
    print(
        f"evolution strategies: {result['generations']} generations, {result['wall_time_s']:.0f} s "
        f"({result['wall_time_s_this_call']:.0f} s this call), {result['parameters']} parameters"
    )
    if last is not None:
        print(
            f"last generation: score {last['score_current']:.4f} against the start's "
            f"{last['score_start']:.4f} on its {result['settings']['stops']} training stops"
        )
    print(f"  wrote {result['model_path']}")


def print_validate(result: dict[str, Any]) -> None:
    s2, s0, dry = result["seed002"], result["seed000"], result["dry_quiet"]
    slides = ", ".join(f"{x:.1f}" for x in s2["mean_sliding_kmh"])
    print(
        f"seed002   {'pass' if s2['passed'] else 'FAIL'}  stop {s2['stopping_distance_m']:.1f} m "
        f"(725 m), mean sliding [{slides}] km/h, none {s2['none_margin_pct']:+.1f} %"
    )
    mu0 = ", ".join(f"{x:.4f}" for x in s0["mu0"])
    kr = ", ".join(f"{x:.4f}" for x in s0["K_rozv"])
    print(f"seed000   {'pass' if s0['passed'] else 'FAIL'}  mu0 [{mu0}], K_rozv [{kr}]")
    runs = [r for r in result["locked_vs_wsp"] if r["judged"]]
    worst = min(runs, key=lambda r: r["none_m"] / r["classical_m"])
    print(
        f"locked    {'pass' if result['locked_vs_wsp_passed'] else 'FAIL'}  {len(runs)} runs "
        f"with locked wheels, none / classical from {worst['none_m'] / worst['classical_m']:.3f} "
        f"({worst['scenario']} seed {worst['seed']})"
    )
    print(
        f"dry quiet {'pass' if dry['passed'] else 'FAIL'}  none {dry['none_m']:.1f} m, classical "
        f"{dry['classical_m']:.1f} m, air {dry['classical_air_l']:.1f} l"
    )
    rig = result["rig"]
    e_w = ", ".join(f"{x:.3f}" for x in rig["e_omega_rms_kmh"])
    print(
        f"rig       {'pass' if rig['passed'] else 'FAIL'}  seed 002 test on the rig "
        f"{rig['rig_stopping_distance_m']:.1f} m, track {rig['track_stopping_distance_m']:.1f} m "
        f"({rig['rig_vs_track_pct']:+.2f} %), e_omega RMS [{e_w}] km/h"
    )
    tr = result["seed002_traction"]
    slide = ", ".join(f"{x:.2f}" for x in tr["mean_sliding_kmh"])
    note = "" if tr["in_overall_verdict"] else " (open: not in the overall verdict yet)"
    print(
        f"traction  {'pass' if tr['passed'] else 'FAIL'}  seed 002 E402B start: mean sliding "
        f"[{slide}] km/h (Table 9 +-0.5 inside: {tr['mean_sliding_inside']}, axle 4 least: "
        f"{tr['axle4_least_sliding']}), {tr['distance_m']:.1f} m in {tr['duration_s']:g} s "
        f"(Table 10 159.6-225.6 m){note}"
    )
    if result.get("report"):
        print(f"wrote {result['report']}")


def print_rig(result: dict[str, Any]) -> None:
    def row(values: list[float], fmt: str) -> str:
        return " ".join(format(v, fmt) for v in values)

    print(
        f"{result['policy']} on the rig, {result['vehicle']}, {result['rail']} from "
        f"{result['speed_kmh']:g} km/h: stop {result['rig_stopping_distance_m']:.1f} m on the "
        f"rig, {result['track_stopping_distance_m']:.1f} m on the track alone "
        f"({result['rig_vs_track_pct']:+.2f} %)"
    )
    print(f"  e_omega RMS [km/h]  {row(result['e_omega_rms_kmh'], '.3f')}")
    print(f"  e_omega max [km/h]  {row(result['e_omega_max_kmh'], '.3f')}")
    print(f"  e_C RMS [N m]       {row(result['e_C_rms_Nm'], '.0f')}")
    print(f"  mean sliding [km/h] {row(result['mean_sliding_kmh'], '.2f')} (rig), "
          f"{row(result['track_mean_sliding_kmh'], '.2f')} (track)")  # fmt: skip
    print(
        f"  {result['rig_stopping_time_s']:.1f} s of braking in {result['wall_time_s']:.1f} s "
        f"wall ({result['real_time_factor']:.2g}x real time, any compilation included)"
    )


def print_traction(result: dict[str, Any]) -> None:
    slide = " ".join(f"{x:.2f}" for x in result["mean_sliding_kmh"])
    print(
        f"{result['vehicle']} from {result['speed_kmh']:g} km/h, {result['torque_Nm']:g} N m per "
        f"axle, {'with' if result['antiskid'] else 'without'} anti-skid: "
        f"{result['distance_m']:.1f} m in {result['duration_s']:.1f} s, "
        f"{result['final_speed_kmh']:.1f} km/h; mean sliding [{slide}] km/h"
    )
    if result.get("reached_max_speed"):
        print("  stopped early: the train reached the vehicle's maximum speed")


def print_export(result: dict[str, Any]) -> None:
    print(
        f"wrote {result['onnx']} ({result['inputs']} inputs, frame stack "
        f"{result['frame_stack']}); ONNX Runtime, one decision: median "
        f"{result['latency_median_us']:.0f} us, p99 {result['latency_p99_us']:.0f} us "
        "(the WSP cycle is 20,000 us)"
    )


def print_benchmark(result: dict[str, Any]) -> None:
    from wsp_env.evaluation.benchmark import stop_set_note

    print(f"{result['benchmark']}: {result['runs']} stops{stop_set_note(result)}")
    print(f"{'policy':<24} {'score':>6} {'95% interval':>15} {'stop/cls':>8} {'worst':>6} "
          f"{'pass':>5} {'watchdog':>8}")  # fmt: skip
    for name, p in result["policies"].items():
        sc = "-" if p["score"] is None else f"{p['score']:.3f}"
        ci = "-" if p["score_ci95"] is None else "{:.3f}-{:.3f}".format(*p["score_ci95"])
        print(f"{name:<24} {sc:>6} {ci:>15} {p['stop_ratio_mean']:>8.3f} "
              f"{p['stop_ratio_worst']:>6.2f} {100 * p['pass_rate']:>4.0f}% "
              f"{p['watchdog_interventions']:>8d}")  # fmt: skip


def print_sweep(result: dict[str, Any]) -> None:
    print(f"sweep {result['sweep']}: {len(result['trials'])} trials in "
          f"{result['wall_time_s']:.0f} s (metric {result['metric']})")  # fmt: skip
    for s in result["summary"]:
        ci = s["metric_ci95"]
        mean = "-" if s["metric_mean"] is None else f"{s['metric_mean']:.3f}"
        interval = "" if ci is None else f" (95 % {ci[0]:.3f}-{ci[1]:.3f})"
        print(f"  {s['overrides'] or '(base)'}: {mean}{interval} over seeds {s['seeds']}")
    best = result.get("best")
    if best is not None:
        print(f"best: trial {best['trial']} {best['overrides']} seed {best['seed']}: "
              f"{best['metric']:.3f}; config {result.get('best_config')}")  # fmt: skip


PRINTERS = {
    "sweep": print_sweep,
    "benchmark": print_benchmark,
    "simulate": print_simulate,
    "evaluate": print_evaluate,
    "calibrate": print_calibrate,
    "bench": print_bench,
    "train": print_train,
    "finetune": print_finetune,
    "validate": print_validate,
    "export-policy": print_export,
    "rig": print_rig,
    "traction": print_traction,
}

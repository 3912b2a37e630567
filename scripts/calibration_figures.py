"""Print the calibration loop's measured figures that the tests do not assert — the figures
docs/calibration.md quotes on the adhesion channel.

    .venv/bin/python scripts/calibration_figures.py [--markdown docs/results/calibration_figures.md]

``--markdown P`` also writes the printed figures there, with the command and the machine above.

1. Force at the critical points against the simulator's own adhesion force (Eq. 9 rail, no
   recovery or cleaning, no sensor noise), next to the per-sample estimate with a
   Savitzky–Golay wheel deceleration that the critical points replace.
2. The adhesion channel's floor on traces without an injected effect, and the largest cut any
   adhesion candidate reaches there (the 1/3 bar of ``adhesion_model.MIN_REDUCTION_ADHESION``).
3. Injected effects (a gradient; adhesion effects on soap, where the floor is higher, and on
   oil): the effect named first, its parameters and the cut of its channel.
4. Polach parameter recovery: seed 000 Table 4's law on the ETR 1000 (no recovery or
   cleaning), pooled fit of all axles and per axle, at several sensor settings.
5. Closing the loop: the exported rail and options, run with the same WSP from the trace's
   speed, against the measured stopping distance (after the generator's 3 s coasting).
6. Runtime of ``wsp-env calibrate --json --report --export`` on a ~60 s, 4-axle, 10 Hz trace
   (median of 3, in-process: without the interpreter's start-up and imports).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import math
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from _results_md import fenced, tee_stdout, write_results
from scipy.signal import savgol_filter

from wsp_env.calibration.adhesion_estimate import estimate_adhesion, fit_polach
from wsp_env.calibration.discovery import discover, fit_adhesion_model
from wsp_env.calibration.synthetic import simulate_trace
from wsp_env.calibration.traces import read_trace
from wsp_env.cli import main as cli_main
from wsp_env.core.config import RecoveryConfig, load_rail
from wsp_env.evaluation.runner import run_one
from wsp_env.evaluation.trace_writer import SensorModel
from wsp_env.policy import make_policy

NOISY = SensorModel(sample_period_s=0.1, speed_noise_kmh=0.1, pressure_noise_bar=0.01)


def force_estimate(directory: Path) -> None:
    rail = dataclasses.replace(
        load_rail("oil"),
        law_params={"K": 30.0, "K_rozv_per_kmh": 0.03},
        clean_energy_J_per_m=math.inf,
        pass_removal=0.0,
    )
    print("1. adhesion force estimate vs the simulator's force (uic_z1, 120 km/h, Eq. 9 rail)")
    for period in (0.1, 0.02):
        sensors = SensorModel(sample_period_s=period)
        csv_path, _, _, truth = simulate_trace(
            directory / f"force_{period}",
            rail,
            120.0,
            sensors=sensors,
            mu_contaminated=0.08,
            pattern="uniform",
            return_record=True,
        )
        t_true, f_true = truth.time_s, truth.f_adhesion_N
        trace = read_trace(csv_path)
        t = trace.time_s
        errors, errors_sg = [], []
        veh = trace.vehicle
        r, inertia = float(veh["wheel_radius_m"]), float(veh["wheelset_inertia_kgm2"])
        gain = float(veh["brake"]["torque_gain_Nm_per_bar"])
        p_th = float(veh["brake"]["p_threshold_bar"])
        for pts in estimate_adhesion(trace, min_speed_kmh=10.0):
            i = int(pts.axle[0]) if len(pts) else 0
            truth = np.interp(t[pts.sample], t_true, f_true[:, i])
            errors.append(pts.force_N - truth)
            # the per-sample estimate: wheelset equation with a 0.5 s Savitzky–Golay derivative
            wheel = trace.v_axle_kmh[:, i] / 3.6
            win = max(5, round(0.5 / period) | 1)
            acc = savgol_filter(wheel, win, polyorder=2, deriv=1, delta=period)
            torque = gain * np.maximum(0.0, trace.p_cyl_bar[:, i] - p_th)
            braked = (torque > 0.05 * gain) & (trace.v_train_kmh > 10.0)
            sg = (torque + inertia * acc / r) / r
            errors_sg.append(sg[braked] - np.interp(t[braked], t_true, f_true[:, i]))
        rms = float(np.sqrt(np.mean(np.concatenate(errors) ** 2))) / 1e3
        rms_sg = [float(np.sqrt(np.mean(e**2))) / 1e3 for e in errors_sg]
        print(
            f"   {1 / period:.0f} Hz: critical points {rms:.3f} kN rms "
            f"({sum(e.size for e in errors)} points); per-sample Savitzky–Golay "
            f"{min(rms_sg):.2f}-{max(rms_sg):.2f} kN rms per axle"
        )


def _discover(directory: Path, name: str, rail, seed=0, speed=120.0, **effect):
    effect.setdefault("mu_contaminated", 0.08)
    csv_path, _, _ = simulate_trace(
        directory / name, rail, speed, sensors=NOISY, seed=seed, pattern="uniform", **effect
    )
    return discover(read_trace(csv_path))


def _adhesion_cuts(result) -> dict[str, float]:
    return {
        row["name"]: 1.0 - row["after"] / row["before"]
        for row in result.considered
        if row["channel"] == "adhesion_fit_kN"
    }


def floors(directory: Path) -> None:
    soap = load_rail("soap")
    uncleaned = dataclasses.replace(soap, clean_energy_J_per_m=math.inf, pass_removal=0.0)
    print("2. adhesion channel without an injected effect (10 Hz, 0.1 km/h noise)")
    cases = [
        ("soap, no cleaning", uncleaned, 0, 120.0),
        ("soap, no cleaning", uncleaned, 1, 100.0),
        ("soap, no cleaning", uncleaned, 2, 140.0),
        ("soap with cleaning", soap, 0, 120.0),
        ("soap with cleaning", soap, 2, 140.0),
        ("oil", load_rail("oil"), 0, 120.0),
    ]
    for label, rail, seed, speed in cases:
        mu = 0.06 if label == "oil" else 0.08
        res = _discover(directory, "floor", rail, seed, speed, mu_contaminated=mu)
        cuts = _adhesion_cuts(res)
        best = max(cuts, key=cuts.get) if cuts else "-"
        print(
            f"   {label:19s} seed {seed} {speed:5.0f} km/h: floor "
            f"{res.errors_before['adhesion_fit_kN']:.2f} kN; best candidate {best} "
            f"{100 * cuts.get(best, 0.0):.0f} %; added {[s.category for s in res.added]}"
        )
    print("3. injected effects: the first effect added, its parameters and its channel's cut")
    step = ((0.0, 500.0, 0.667), (500.0, 5000.0, 1.0))  # mu ~0.107 to 500 m, then 0.06
    ratios = {"axle_mu_factor": (0.6, 0.75, 0.9, 1.0)}
    one_off = (1.0, 1.0, 0.6, 1.0)
    oil = load_rail("oil")
    injected = (
        ("soap, gradient -15 permille", uncleaned, {"gradient_permille": -15.0}),
        ("soap, R_i 0.6/0.75/0.9/1", uncleaned, ratios),
        ("soap, axle 2 x0.6", uncleaned, {"axle_mu_factor": (1.0, 0.6, 1.0, 1.0)}),
        ("soap, friction step at 500 m", uncleaned, {"sections": step, "mu_contaminated": 0.06}),
        ("oil, R_i 0.6/0.75/0.9/1", oil, {**ratios, "mu_contaminated": 0.06}),
        ("oil, axle 3 x0.6", oil, {"axle_mu_factor": one_off, "mu_contaminated": 0.06}),
        ("oil, CoG/pivot heights x4", oil, {"height_scale": 4.0, "mu_contaminated": 0.06}),
        ("oil, friction step at 500 m", oil, {"sections": step, "mu_contaminated": 0.06}),
    )
    for label, rail, effect in injected:
        res = _discover(directory, "effect", rail, **effect)
        if not res.added:
            gain = res.adhesion_law.get("cleaning_gain")
            law = f" (base law's cleaning gain {gain:.3f})" if gain is not None else ""
            print(f"   {label:30s}: nothing added{law}")
            continue
        first = res.added[0]
        shown = {k: round(float(v), 3) for k, v in first.parameters.items()}
        print(
            f"   {label:30s}: {first.category} on {first.channel} {first.before:.3f} -> "
            f"{first.after:.3f} ({100 * (1 - first.after / first.before):.0f} % cut) {shown}"
        )


def parameter_recovery(directory: Path) -> None:
    truth = np.array([0.1497, 30.0, 0.0291])  # mu0, K, K_rozv: seed 000 Table 4, axle 1
    rail = dataclasses.replace(
        load_rail("soap_etr1000"),
        recovery=RecoveryConfig(w_lim=math.inf, w_max=math.inf),
        clean_energy_J_per_m=math.inf,
        pass_removal=0.0,
    )
    print("4. Polach parameters recovered (relative error of mu0, K, K_rozv; ETR 1000, 150 km/h)")
    for period, noise in ((0.02, 0.0), (0.1, 0.0), (0.1, 0.03), (0.1, 0.1)):
        sensors = SensorModel(
            sample_period_s=period, speed_noise_kmh=noise, pressure_noise_bar=0.01 if noise else 0.0
        )
        csv_path, _, _ = simulate_trace(
            directory / "polach", rail, 150.0, sensors=sensors, mu_contaminated=truth[0],
            pattern="uniform",
        )  # fmt: skip
        trace = read_trace(csv_path)
        fit = fit_adhesion_model(trace, per_axle=False, load_transfer=False)
        pooled = fit.params[:3] / truth - 1 if fit is not None else np.full(3, np.nan)
        pitch = fit_adhesion_model(trace, per_axle=False, load_transfer=True).params[3]
        axles = [fit_polach(p) for p in estimate_adhesion(trace)]
        worst = np.nanmax(
            [np.abs(np.array([f.mu0, f.K, f.K_rozv]) / truth - 1) for f in axles], axis=0
        )
        print(
            f"   {1 / period:.0f} Hz, noise {noise} km/h: all axles pooled "
            f"{np.round(100 * pooled, 1)} % (a bogie-pitch term beyond the declared transfer "
            f"fits {pitch:.1f} kN per m/s^2); "
            f"single axles at most {np.round(100 * worst, 1)} %"
        )


def closed_loop(directory: Path) -> None:
    soap = load_rail("soap")
    uncleaned = dataclasses.replace(soap, clean_energy_J_per_m=math.inf, pass_removal=0.0)
    print("5. calibrated config re-simulated (classical WSP) against the measured stop")
    cases = (
        ("soap, -10 permille, R_i 0.6-1", uncleaned,
         {"gradient_permille": -10.0, "axle_mu_factor": (0.6, 0.75, 0.9, 1.0)}),
        ("soap, seed 1, 100 km/h", uncleaned, {"seed": 1, "speed": 100.0}),
        ("soap with cleaning", soap, {}),
        ("oil", load_rail("oil"), {"mu_contaminated": 0.06}),
    )  # fmt: skip
    for label, rail, effect in cases:
        effect = dict(effect)
        seed, speed = effect.pop("seed", 0), effect.pop("speed", 120.0)
        effect.setdefault("mu_contaminated", 0.08)
        csv_path, _, _ = simulate_trace(
            directory / "loop", rail, speed, sensors=NOISY, seed=seed, pattern="uniform", **effect
        )
        rails = directory / "loop.yaml"
        with contextlib.redirect_stdout(io.StringIO()):
            cli_main(["calibrate", str(csv_path), "--export", str(rails)])
        options = yaml.safe_load(rails.with_name("loop.yaml.options.yaml").read_text())
        trace = read_trace(csv_path)
        run_m = trace.distance_m()
        measured = run_m[-1] - float(np.interp(3.0, trace.time_s, run_m))
        run, _ = run_one(
            "uic_z1", "calibrated", float(trace.v_train_kmh[0]), make_policy("classical"), 0,
            options, {"rails_config": str(rails)},
        )  # fmt: skip
        sim = run["stopping_distance_m"]
        print(f"   {label:30s}: measured {measured:6.1f} m, calibrated {sim:6.1f} m "
              f"({100 * (sim / measured - 1):+.1f} %)")  # fmt: skip


def runtime(directory: Path) -> None:
    csv_path, _, _ = simulate_trace(
        directory / "runtime", load_rail("soap"), 160.0, sensors=NOISY, mu_contaminated=0.08,
        pattern="uniform", gradient_permille=-10.0,
    )  # fmt: skip
    trace = read_trace(csv_path)
    args = ["calibrate", str(csv_path), "--json", str(directory / "cal.json")]
    args += ["--report", str(directory / "report"), "--export", str(directory / "cal.yaml")]
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        with contextlib.redirect_stdout(io.StringIO()):
            cli_main(args)
        times.append(time.perf_counter() - t0)
    print(
        f"6. calibrate with report and export, {trace.time_s[-1]:.0f} s / {trace.n_axles} axles / "
        f"{len(trace.time_s)} samples: {statistics.median(times):.2f} s (median of 3)"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", type=Path, default=None, help="also write the figures here")
    args = ap.parse_args()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp, tee_stdout() as printed:
        directory = Path(tmp)
        force_estimate(directory)
        floors(directory)
        parameter_recovery(directory)
        closed_loop(directory)
        runtime(directory)
    if args.markdown is not None:
        title = "Calibration loop: measured figures"
        write_results(args.markdown, title, fenced(printed.getvalue()), time.perf_counter() - t0)
        print(f"wrote {args.markdown}")


if __name__ == "__main__":
    main()

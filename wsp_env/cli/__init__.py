"""``wsp-env`` command line: one subcommand per job, each with ``--json PATH``.

User mistakes (bad config, argument, file) end with one line on stderr naming the file, field
or argument, and exit status 2 — never a traceback, never a half-written output file.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from wsp_env.cli.printing import PRINTERS
from wsp_env.core.braking import SUBSTEP_MIN_S
from wsp_env.core.config import ConfigError, check_option, from_dict, load_rail, load_vehicle
from wsp_env.files import Outputs, write_json
from wsp_env.physics.jit_cache import compiled


class UserError(Exception):
    """A mistake in the user's input; its message is printed as one line."""


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (the usage is one ``--help`` away)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _vehicle_for_speed(vehicle_id: str, speed_kmh: float) -> Any:
    """The vehicle, refusing an initial speed above its maximum (one line)."""
    vehicle = load_vehicle(vehicle_id)
    check_option("speed_kmh", speed_kmh, vehicle, where="--speed-kmh")
    return vehicle


def _fixed_rail(args: argparse.Namespace) -> dict[str, Any]:
    """The case fields --pattern and --mu-contaminated fix (the seed draws the rest)."""
    out: dict[str, Any] = {}
    if args.pattern is not None:
        out["pattern"] = args.pattern
    if args.mu_contaminated is not None:
        out["mu_contaminated"] = args.mu_contaminated
    return out


def _bounded(low: float, high: float, low_open: bool = False) -> Any:
    """An argparse type: a finite number in ``[low, high]`` (``(low, high]`` if ``low_open``)."""

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        above = v > low if low_open else v >= low
        if not (np.isfinite(v) and above and v <= high):
            if np.isinf(high):
                span = f"a finite number {'>' if low_open else '>='} {low:g}"
            else:
                span = f"in {'(' if low_open else '['}{low:g}, {high:g}]"
            raise argparse.ArgumentTypeError(f"must be {span}, got {text!r}")
        return v

    return parse


_positive = _bounded(0.0, np.inf, low_open=True)
_nonneg = _bounded(0.0, np.inf)


def _seed(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if not 0 <= v < 2**63:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 0, got {text!r}")
    return v


def _reserve(
    args: argparse.Namespace, attr: str, option: str, kind: str = "file", suffixes: tuple = ()
) -> Path | None:
    """The temp path to write ``args.<attr>``'s output to, checked now (``files.Outputs``)."""
    path = getattr(args, attr)
    return None if path is None else args.outputs.reserve(path, option, kind, suffixes)


# the arguments that name outputs; any other argument naming an existing file is an input
OUTPUT_ARGS = ("json_path", "plot", "trace", "report", "export", "onnx", "out", "resume")


def _meta_of(csv_path: str) -> str:
    """A trace's metadata file (``NAME.meta.json`` beside ``NAME.csv``)."""
    p = Path(csv_path)
    name = p.name[: -len(".csv")] if p.name.endswith(".csv") else p.stem
    return str(p.with_name(f"{name}.meta.json"))


def _option(name: str) -> Any:
    """An argparse type checking an environment option against the environment's own bounds
    (``core.config.OPTION_SPECS``: one table for options, configs and the command line)."""

    def parse(text: str) -> Any:
        try:
            return check_option(name, text, where="")
        except ConfigError as err:
            raise argparse.ArgumentTypeError(str(err).removeprefix(": ")) from None

    return parse


_LEVEL = _option("mu_contaminated")


def _policies(names: list[str], wsp_config: str | None, tier: str = "wheels") -> list[Any]:
    """The policies named on the command line, each once under a name of its own (two model
    files that call themselves alike are told apart by their paths); ``--wsp-config`` only
    where a classical WSP reads it; ``classical`` is the frozen classical WSP of ``tier``."""
    from wsp_env.policy import make_policy

    if wsp_config is not None and "classical" not in names:
        raise UserError("--wsp-config: only the classical WSP reads it (add --policy classical)")
    if len(set(names)) < len(names):
        raise UserError("--policy: the same policy is named twice")
    policies = []
    for name in names:
        try:
            policies.append(
                make_policy(name, wsp_config if name == "classical" else None, tier=tier)
            )
        except FileNotFoundError as err:
            raise UserError(f"--policy: {err}") from None
        except IsADirectoryError:
            raise UserError(f"--policy: {name} is a folder, not a model file") from None
    counts: dict[str, int] = {}
    for pol in policies:  # results and report files are keyed by policy name: keep them apart
        counts[pol.name] = counts.get(pol.name, 0) + 1
        if counts[pol.name] > 1:
            pol.name = f"{pol.name}-{counts[pol.name]}"
    return policies


# ---- simulate -------------------------------------------------------------------------------


def _add_simulate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="run one braking stop and report stopping distance, sliding, air",
        description="One braking stop. The seed draws the rail's adhesion level and pattern "
        "from that contaminant's distribution (configs/rails.yaml); --mu-contaminated and "
        "--pattern fix them.",
    )
    p.add_argument("--vehicle", default="uic_z1", help="vehicle id or YAML path (uic_z1)")
    p.add_argument("--speed-kmh", type=_positive, default=120.0, help="initial speed (120)")
    p.add_argument(
        "--rail", default="soap", help="a rail of the rail table (configs/rails.yaml: dry, wet, "
        "soap, oil, leaves, ...; or --rails-config) (soap)"
    )  # fmt: skip
    p.add_argument("--rails-config", default=None, help="rail-condition table (YAML)")
    p.add_argument(
        "--policy",
        default="none",
        help="none (full demand, no WSP), classical, oracle, a shipped policy's name "
        "(agents/pretrained) or a trained model file (none); model files are pickles: "
        "load only files you trust",
    )
    p.add_argument(
        "--wsp-config", default=None, help="classical WSP parameters (YAML; --policy classical)"
    )
    p.add_argument("--seed", type=_seed, default=0, help="draws adhesion level and pattern (0)")
    p.add_argument("--mu-contaminated", type=_LEVEL, default=None, help="fix the level (0.001-1)")
    p.add_argument(
        "--pattern", choices=("uniform", "step_up", "step_down", "patches"), default=None
    )
    p.add_argument("--demand", choices=("emergency", "service"), default="emergency")
    p.add_argument(
        "--gradient-permille", type=_option("gradient_permille"), default=0.0,
        help="track gradient, per mille, > 0 uphill (0; within +-100)",
    )  # fmt: skip
    p.add_argument(
        "--accelerometer", action="store_true",
        help="sensor tier wheels+accel: a body accelerometer aids the reference and is "
        "observed; --policy classical is then the accelerometer-aided classical WSP",
    )  # fmt: skip
    p.add_argument(
        "--accelerometer-bias-mps2", type=_option("accelerometer_bias_mps2"), default=None,
        help="the accelerometer's bias, exactly (m/s^2, > 0 reads more deceleration; "
        "default 0; needs an accelerometer)",
    )  # fmt: skip
    p.add_argument(
        "--wheel-speed-noise-kmh", type=_option("wheel_speed_noise_kmh"), default=None,
        help="standard deviation of each wheel-speed reading (km/h; default 0: exact)",
    )  # fmt: skip
    p.add_argument("--json", dest="json_path", default=None, help="write the result here")
    p.add_argument("--plot", default=None, help="write a PNG of speeds and pressures")
    p.add_argument("--trace", default=None, help="write a wsp-trace/1 trace STEM.csv + .json")
    p.add_argument(
        "--sample-period-s", type=_bounded(1e-3, 10.0), default=0.1,
        help="trace logger period (0.1; 0.001-10)",
    )  # fmt: skip
    p.add_argument(
        "--speed-noise-kmh", type=_bounded(0.0, 50.0), default=0.1, help="trace sensor noise"
    )
    p.add_argument(
        "--pressure-noise-bar", type=_bounded(0.0, 10.0), default=0.01, help="trace sensor noise"
    )
    p.add_argument(
        "--dt-s", type=_positive, default=1e-3,
        help="physics substep (0.001; 1e-5 to the 0.02 s control period, dividing it)",
    )  # fmt: skip
    p.set_defaults(func=cmd_simulate)


def cmd_simulate(args: argparse.Namespace) -> dict[str, Any]:
    from wsp_env.evaluation.runner import run_one, trace_metadata
    from wsp_env.evaluation.trace_writer import SensorModel, sample_run, stem_path, write_trace

    vehicle = _vehicle_for_speed(args.vehicle, args.speed_kmh)
    control_period_s = 0.02  # the environment's default BCU cycle
    if args.dt_s < SUBSTEP_MIN_S or args.dt_s > control_period_s:
        raise UserError(
            f"--dt-s: must be in [{SUBSTEP_MIN_S:g}, {control_period_s}], got {args.dt_s:g}"
        )
    if abs(round(control_period_s / args.dt_s) * args.dt_s - control_period_s) > 1e-9:
        raise UserError(
            f"--dt-s: must divide the {control_period_s} s control period, got {args.dt_s:g}"
        )
    rail = load_rail(args.rail, args.rails_config)  # a bad table or rail fails here, named
    from wsp_env.baselines.classical import accelerometer_tier

    tier = accelerometer_tier(bool(args.accelerometer))
    (policy,) = _policies([args.policy], args.wsp_config, tier)
    from wsp_env.policy import check_sensor_tier, sensor_tier

    if args.accelerometer:
        try:
            check_sensor_tier(policy, tier)
        except ValueError as err:
            raise UserError(f"--accelerometer: {err}") from None
    accelerometer = args.accelerometer or sensor_tier(policy) == "wheels+accel"
    if args.accelerometer_bias_mps2 is not None and not accelerometer:
        raise UserError(
            "--accelerometer-bias-mps2: there is no accelerometer (add --accelerometer)"
        )
    plot_tmp = _reserve(args, "plot", "--plot")
    trace_tmp = None
    if args.trace:
        args.trace = str(stem_path(args.trace))  # STEM, STEM.csv and STEM.meta.json name one
        trace_tmp = _reserve(args, "trace", "--trace", "stem")
    case: dict[str, Any] = {
        "demand": args.demand, "gradient_permille": args.gradient_permille, **_fixed_rail(args),
        "accelerometer_bias_mps2": (
            args.accelerometer_bias_mps2 if args.accelerometer_bias_mps2 is not None
            else 0.0 if accelerometer else None
        ),
        "wheel_speed_noise_kmh": args.wheel_speed_noise_kmh,
    }  # fmt: skip
    case = {k: v for k, v in case.items() if v is not None}
    env_kwargs = {"substep_s": args.dt_s, "rails_config": args.rails_config,
                  "accelerometer": accelerometer}  # fmt: skip
    run, record = run_one(vehicle, args.rail, args.speed_kmh, policy, args.seed, case, env_kwargs)
    conditions = run["conditions"]
    result = {
        "vehicle": vehicle.id,
        "rail": args.rail,
        "policy": policy.name,
        "tier": accelerometer_tier(bool(accelerometer)),
        "seed": args.seed,
        "mu_contaminated": conditions["mu_contaminated"],
        "pattern_sections": conditions["sections"],
        "gradient_permille": conditions["gradient_permille"],
        "sensors": conditions["sensors"],
        **{k: v for k, v in run.items() if k not in ("scenario", "seed", "policy", "conditions")},
    }
    outputs = []
    if plot_tmp is not None:
        from wsp_env.evaluation.plotting import plot_run

        title = f"{vehicle.name}, {args.speed_kmh:g} km/h, {args.rail}, policy {policy.name}"
        plot_run(record, plot_tmp, title=title)
        outputs.append(args.plot)
    if trace_tmp is not None:
        sensors = SensorModel(
            sample_period_s=args.sample_period_s,
            speed_noise_kmh=args.speed_noise_kmh,
            pressure_noise_bar=args.pressure_noise_bar,
        )
        columns = sample_run(record, sensors, np.random.default_rng([args.seed, 1]))
        meta = trace_metadata(
            vehicle,
            conditions,
            rail.contaminant_name(args.rail),
            args.sample_period_s,
            f"simulated {vehicle.id} {args.rail} {args.speed_kmh:g} km/h seed {args.seed}",
        )
        write_trace(trace_tmp, columns, meta)
        outputs.extend([f"{args.trace}.csv", f"{args.trace}.meta.json"])
    result["outputs"] = [str(p) for p in outputs]
    return result


# ---- evaluate -------------------------------------------------------------------------------


def _add_evaluate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "evaluate",
        help="run a scenario suite with one or more policies; JSON and Markdown report",
        description="Runs every scenario x speed x seed of a suite with each policy (same "
        "scenarios and seeds for all, one code path). Policies: classical, none, oracle, or a "
        "trained model file.",
    )
    p.add_argument(
        "--policy",
        action="append",
        required=True,
        help="classical | none | oracle | a shipped policy's name | PATH.zip (repeat to "
        "compare); model files are pickles: load only files you trust",
    )
    p.add_argument("--suite", default="quick", help="quick | en15595 | heldout | PATH.yaml")
    p.add_argument("--vehicle", default="uic_z1", help="vehicle id or YAML path (uic_z1)")
    p.add_argument("--wsp-config", default=None, help="thresholds of the classical WSP (YAML)")
    p.add_argument(
        "--tier", choices=("wheels", "wheels+accel"), default=None,
        help="run with a sensor tier's sensors (its benchmark id's errors; wheels+accel: an "
        "accelerometer), --policy classical being that tier's classical WSP (default: ideal "
        "wheel-speed sensors, the wheels classical WSP, a learned policy's own sensors)",
    )  # fmt: skip
    p.add_argument("--json", dest="json_path", default=None, help="write the result here")
    p.add_argument("--report", default=None, help="write report.md and plots into this folder")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    _add_worker_args(p)
    p.set_defaults(func=cmd_evaluate)


def _add_worker_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=int, default=None,
                   help="split the stops across N worker processes through Ray (local; "
                   "needs the sweep extra); the result is the one-process result, run for "
                   "run")  # fmt: skip
    p.add_argument("--address", default=None,
                   help="attach to a running Ray cluster (auto or HOST:PORT; see `wsp-env sweep "
                   "--help`) and split the stops across its CPUs (or --workers N)")  # fmt: skip


@contextlib.contextmanager
def _executor(args: argparse.Namespace) -> Iterator[Any]:
    """None (run here), or a Ray executor for --workers / --address for the ``with``."""
    if args.workers is None and args.address is None:
        yield None
        return
    if args.workers is not None and not 1 <= args.workers <= 4096:
        raise UserError(f"--workers: must be 1-4096, got {args.workers}")
    from wsp_env.evaluation.distributed import RayExecutor, ray_session

    with ray_session(args.address, args.workers) as ray:
        n = args.workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        yield RayExecutor(ray, n)


def cmd_evaluate(args: argparse.Namespace) -> dict[str, Any]:
    from wsp_env.evaluation import expand, load_suite, run_suite, summarise

    suite = load_suite(args.suite)
    expand(suite, load_vehicle(args.vehicle))  # fail early: the vehicle, the suite's speeds
    policies = _policies(args.policy, args.wsp_config, args.tier or "wheels")
    env_kwargs, policy_keys = None, None
    if args.tier is not None:
        import dataclasses

        from wsp_env.envs.tiers import TIER_SENSORS
        from wsp_env.policy import check_sensor_tier

        accel = args.tier == "wheels+accel"
        for pol in policies:
            try:
                check_sensor_tier(pol, args.tier)
            except ValueError as err:
                raise UserError(f"--tier: {err}") from None
        env_kwargs = {"accelerometer": accel,
                      "sensors": dataclasses.asdict(TIER_SENSORS[args.tier])}  # fmt: skip
        # the tier decides the sensors; a learned policy keeps its spaces' own settings
        from wsp_env.evaluation.benchmark import POLICY_KEYS

        policy_keys = (*POLICY_KEYS, "privileged", "control_period_s")
    report_tmp = _reserve(args, "report", "--report", "dir")
    results, records = [], {}
    with _executor(args) as executor:
        for pol in policies:
            res, rec = run_suite(
                args.vehicle, suite, pol, record="first_seed" if args.report else "none",
                progress=not args.no_progress and sys.stderr.isatty(), env_kwargs=env_kwargs,
                policy_keys=policy_keys, executor=executor,
            )  # fmt: skip
            results.extend(res)
            records[pol.name] = rec
    summary = summarise(results)
    payload = {
        "suite": suite.name,
        "vehicle": args.vehicle,
        "tier": args.tier,
        "policies": [p.name for p in policies],
        "runs": results,
        "summary": summary,
    }
    if report_tmp is not None:
        from wsp_env.evaluation.report import write_report

        write_report(report_tmp, suite, args.vehicle, results, summary, records)
        payload["report"] = args.report
    return payload


# ---- benchmark ------------------------------------------------------------------------------


def _add_benchmark(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "benchmark",
        help="score controllers on the sealed test set of a vehicle and sensor tier",
        description="Runs the sealed set (300 fixed-seed stops per vehicle drawn from the "
        "real world's range: every rail, gradients +-25 per mille, sensor errors, loads, "
        "demands, speeds to the maximum) of a registered id (WSPBraking-UICZ1-v3, "
        "WSPBraking-UICZ1-Accel-v3, ...) with every policy and the tier's classical WSP and "
        "none: score 0 = locked wheels, 1 = the tier's classical WSP (IQM, 95 %% bootstrap "
        "interval), stop ratio mean and worst, pass rate, damage, air, valve operations, "
        "watchdog interventions, per scenario family. See docs/benchmark.md.",
    )
    p.add_argument(
        "--policy", action="append", required=True,
        help="classical | none | oracle | a shipped policy's name | PATH.zip | "
        "module:callable (repeat to compare); model files are pickles and modules run code: "
        "load only what you trust",
    )  # fmt: skip
    p.add_argument("--tier", choices=("wheels", "wheels+accel"), default="wheels",
                   help="sensor tier (wheels)")  # fmt: skip
    p.add_argument("--vehicle", default="uic_z1", help="a vehicle with a benchmark id (uic_z1)")
    p.add_argument(
        "--runs", type=int, default=None,
        help="only the first N stops of the set (a quick look; the score of record uses all 300 "
        "of the sealed set)",
    )  # fmt: skip
    p.add_argument(
        "--stops", choices=("sealed", "development"), default="sealed",
        help="sealed: the test set (the result of record); development: 300 other stops of the "
        "same distribution, to compare and select on (default: sealed)",
    )  # fmt: skip
    p.add_argument(
        "--version", choices=("v1", "v2", "v3"), default="v3",
        help="the ids' version: v3 (default, the current one); v2 reproduces the figures "
        "measured under -v2 (the estimator's spin-up test on one reading, no accelerometer "
        "offset learned), v1 those measured under -v1 (besides, the watchdog's override "
        "standing until standstill)",
    )  # fmt: skip
    p.add_argument("--json", dest="json_path", default=None, help="write the result here")
    p.add_argument("--report", default=None, help="write report.md into this folder")
    p.add_argument("--no-progress", action="store_true", help="no progress lines")
    _add_worker_args(p)
    p.set_defaults(func=cmd_benchmark)


def cmd_benchmark(args: argparse.Namespace) -> dict[str, Any]:
    from wsp_env import BENCHMARK_VEHICLES
    from wsp_env.evaluation.benchmark import SEALED_RUNS, run_benchmark

    if args.vehicle not in BENCHMARK_VEHICLES:
        raise UserError(
            f"--vehicle: {args.vehicle!r} has no benchmark id (one of "
            f"{', '.join(BENCHMARK_VEHICLES)})"
        )
    runs = SEALED_RUNS if args.runs is None else args.runs
    if not 1 <= runs <= SEALED_RUNS:
        raise UserError(f"--runs: must be 1-{SEALED_RUNS}, got {args.runs}")
    policies = _policies(args.policy, None, args.tier)
    report_tmp = _reserve(args, "report", "--report", "dir")

    def progress(line: str) -> None:
        if not args.no_progress:
            print(line, file=sys.stderr, flush=True)

    with _executor(args) as executor:
        payload = run_benchmark(
            policies, args.vehicle, args.tier, runs, progress, executor=executor,
            stop_set=args.stops, version=args.version,
        )  # fmt: skip
    if report_tmp is not None:
        from wsp_env.evaluation.report import write_benchmark_report

        write_benchmark_report(report_tmp, payload)
        payload["report"] = args.report
    return payload


# ---- calibrate ------------------------------------------------------------------------------


def _add_calibrate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "calibrate",
        help="explain a measured trace: residual channels, effect discovery, error before/after",
        description="Reads TRACE.csv (+ TRACE.meta.json next to it, wsp-trace/1), computes the "
        "train-speed balance, adhesion fit and coasting creep residuals, and adds the physical "
        "effects (BIC-scored) that explain them; --report writes a report with plots, --export "
        "a rail table the environment loads. Format: docs/trace_format.md (installed as "
        "wsp_env/docs/trace_format.md).",
    )
    p.add_argument("trace_csv", metavar="trace", help="the trace CSV (metadata found next to it)")
    p.add_argument("--json", dest="json_path", default=None, help="write the result here")
    p.add_argument("--report", default=None, help="write report.md and plots into this folder")
    p.add_argument(
        "--export", default=None, help="write a rail table (+ .options.yaml) the env loads"
    )
    p.set_defaults(func=cmd_calibrate)


def cmd_calibrate(args: argparse.Namespace) -> dict[str, Any]:
    from wsp_env.calibration.discovery import discover
    from wsp_env.calibration.traces import TraceError, read_trace

    export_tmp = _reserve(args, "export", "--export", suffixes=(".options.yaml",))
    report_tmp = _reserve(args, "report", "--report", "dir")
    try:
        trace = read_trace(args.trace_csv)
    except TraceError as err:
        raise UserError(str(err)) from None
    result = discover(trace)
    payload = {
        "trace": str(args.trace_csv),
        "errors_before": result.errors_before,
        "errors_after": result.errors_after,
        "added_effects": [s.as_dict() for s in result.added],
        "unexplained": result.unexplained,
        "dropped_effects": result.dropped,
        "channels": result.channel_health,
        "adhesion_law": result.adhesion_law,
        "wheel_lag": result.wheel_lag,
        "candidates": result.considered,
        "notes": trace.notes,
        "outputs": [],
    }
    from wsp_env.calibration.export import export_config, write_report

    if export_tmp is not None:
        export_config(export_tmp, trace, result, name=Path(args.export).name)
        payload["outputs"].extend([args.export, f"{args.export}.options.yaml"])
    if report_tmp is not None:
        write_report(report_tmp, trace, result)
        payload["outputs"].append(args.report)
    return payload


# ---- bench ----------------------------------------------------------------------------------


def _add_bench(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench",
        help="environment throughput (single, 1024-env vector, 256 x 32-axle) vs CartPole",
        description="Measures steps per second of WSPBraking-v0 (single env through "
        "gymnasium.make; native vector env) and of CartPole-v1 in the same run; medians.",
    )
    p.add_argument("--json", dest="json_path", default=None, help="write the result here")
    p.add_argument("--repeats", type=int, default=5, help="timed runs per figure (5; 1-100)")
    p.add_argument("--quick", action="store_true", help="tiny counts (smoke test)")
    p.add_argument("--train", action="store_true",
                   help="training throughput instead: PPO env-steps/s including updates for a "
                   "training config, beside SB3 PPO on CartPole-v1 with the same settings "
                   "(docs/training.md, Threads)")  # fmt: skip
    p.add_argument("--config", default=None,
                   help="with --train: the training config (a path or built-in name; "
                   "ppo_uic_z1)")  # fmt: skip
    p.add_argument(
        "--rollouts",
        type=int,
        default=4,
        help="with --train: rollouts (and updates) per timed run (4; 1-100)",
    )
    p.add_argument("--busy", type=int, default=0,
                   help="with --train: busy-looping processes beside the measurement, as on a "
                   "shared machine (0; 0-64)")  # fmt: skip
    p.set_defaults(func=cmd_bench)


def cmd_bench(args: argparse.Namespace) -> dict[str, Any]:
    if not 1 <= args.repeats <= 100:
        raise UserError(f"--repeats: must be 1-100, got {args.repeats}")
    if not args.train:
        for flag, value, default in (("--config", args.config, None),
                                     ("--rollouts", args.rollouts, 4),
                                     ("--busy", args.busy, 0)):  # fmt: skip
            if value != default:
                raise UserError(f"{flag}: only with --train")
        from wsp_env.evaluation.bench import run_bench

        return run_bench(quick=args.quick, repeats=args.repeats)
    if not 1 <= args.rollouts <= 100:
        raise UserError(f"--rollouts: must be 1-100, got {args.rollouts}")
    if not 0 <= args.busy <= 64:
        raise UserError(f"--busy: must be 0-64, got {args.busy}")
    from wsp_env.policy import require_extras

    require_extras("bench --train needs", "rl")
    from wsp_env.training.bench import DEFAULT_CONFIG, run_train_bench

    return run_train_bench(args.config or DEFAULT_CONFIG, rollouts=args.rollouts,
                           repeats=args.repeats, busy=args.busy, quick=args.quick)  # fmt: skip


# ---- train ----------------------------------------------------------------------------------


SWEEP_EPILOG = """\
a cluster: start Ray's head on one machine and attach the others (same Python environment,
the same project files where the trials read them):
  head$    ray start --head --port 6379
  worker$  ray start --address HEAD_HOST:6379
  head$    wsp-env sweep --config configs/sweeps/NAME.yaml --out runs/sweeps/NAME --address auto
Without --address Ray starts in this process on this machine's cores and stops at the end.
A killed sweep goes on with: wsp-env sweep --out DIR --resume (finished trials are not rerun;
unfinished ones resume from their last checkpoint). See docs/sweeps.md."""


def _add_sweep(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sweep",
        help="many training runs as one job on Ray Tune: a grid (configs, options, seeds) or "
        "an Optuna search with pruning; local or on a cluster",
        description="Runs every trial of a sweep file (configs/sweeps/NAME.yaml: a base "
        "training config and a grid or a search space) as a `wsp-env train` run in DIR/trials/, "
        "in chunks, each reporting its fixed-seed learning curve; writes results.json, "
        "results.md (a table, the grid over seeds with 95 % intervals) and best.yaml.",
        epilog=SWEEP_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--config", default=None, help="the sweep file (configs/sweeps/NAME.yaml)")
    p.add_argument("--out", required=True, help="the sweep folder (new or empty; or --resume)")
    p.add_argument("--address", default=None,
                   help="attach to a running Ray cluster (auto or HOST:PORT); default: Ray "
                   "started here")  # fmt: skip
    p.add_argument("--resume", action="store_true",
                   help="continue the sweep in --out (its own sweep.yaml)")  # fmt: skip
    p.add_argument("--json", dest="json_path", default=None, help="write the result here")
    p.set_defaults(func=cmd_sweep)


def cmd_sweep(args: argparse.Namespace) -> dict[str, Any]:
    from wsp_env.policy import require_extras

    require_extras("sweep needs", "rl", "sweep")
    from wsp_env.sweep.run import run_sweep

    return run_sweep(args.config, args.out, address=args.address, resume=args.resume)


def _add_train(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "train",
        help="train a learned WSP controller (stable-baselines3) from a YAML config",
        description="Train PPO / SAC / TD3 / A2C on WSPBraking-v0's native vector env, with "
        "periodic validation against the frozen classical WSP, best-model selection and "
        "checkpoints; --resume continues a run bit for bit. See docs/training.md.",
    )
    p.add_argument("--config", default=None, help="configs/train/NAME.yaml (or a built-in NAME)")
    p.add_argument("--out", default=None, help="run folder (new or empty; default: --resume's)")
    p.add_argument("--seed", type=_seed, default=None, help="override the config's seed")
    p.add_argument("--resume", default=None, help="continue the run in this folder")
    p.add_argument(
        "--total-timesteps", type=int, default=None, help="the run's total (default: config's)"
    )
    p.add_argument(
        "--chunk-timesteps", type=int, default=None,
        help="stop after about this many steps with a checkpoint (go on with --resume)",
    )  # fmt: skip
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", dest="json_path", default=None, help="write the result here")
    p.set_defaults(func=cmd_train)


def cmd_train(args: argparse.Namespace) -> dict[str, Any]:
    from wsp_env.training.train import train

    if args.config is None and args.resume is None:
        raise UserError("--config: required unless --resume")
    out = args.out or args.resume
    if out is None:
        raise UserError("--out: required")
    if args.total_timesteps is not None and args.total_timesteps < 1:
        raise UserError("--total-timesteps: must be >= 1")
    if args.chunk_timesteps is not None and args.chunk_timesteps < 1:
        raise UserError("--chunk-timesteps: must be >= 1")
    if args.config is not None and args.resume is not None:
        raise UserError("--config: a resumed run keeps its own config.yaml (drop --config)")
    if args.seed is not None and args.resume is not None:
        raise UserError("--seed: a resumed run keeps its own seed")
    return train(
        args.config, out, seed=args.seed, resume=args.resume,
        total_timesteps=args.total_timesteps, progress=not args.no_progress,
        chunk_timesteps=args.chunk_timesteps,
    )  # fmt: skip


def _add_finetune(sub: argparse._SubParsersAction) -> None:
    from wsp_env.training.es import ESSettings

    d = ESSettings(start="")
    p = sub.add_parser(
        "finetune",
        help="fine-tune a trained policy on the benchmark's own score (evolution strategies)",
        description="Evolution strategies on the actor's last layers: antithetic perturbations "
        "run the same training stops (never sealed or development ones), each scored as the "
        "benchmark scores; --resume continues bit for bit. See docs/training.md.",
    )
    p.add_argument("start", nargs="?", default=None, help="the model file to start from")
    p.add_argument("--out", default=None, help="run folder (default: --resume's)")
    p.add_argument("--resume", default=None, help="continue the fine-tune in this folder")
    p.add_argument("--generations", type=int, required=True, help="generations to run now")
    for flag, kind, what in (
        ("--pairs", int, "antithetic pairs a generation"),
        ("--stops", int, "training stops a generation"),
        ("--pool", int, "training stops to draw from"),
        ("--sigma", _positive, "perturbation scale"),
        ("--learning-rate", _positive, "Adam's step"),
        ("--layers", int, "the actor's last layers that move"),
        ("--seed", _seed, "the draws' seed"),
        ("--average", float, "decay of the written weights' running average (0: last step's)"),
        ("--guard", float, "a member losing more than this on any stop ranks last (0: off)"),
        (
            "--ratio-cap",
            float,
            "the fitness loses the mean excess of its stops' distance over this times the "
            "classical WSP's (0: off)",
        ),
        ("--ratio-weight", float, "that excess' weight, in the score's units"),
        (
            "--watchdog-weight",
            float,
            "the fitness loses this times the share of its stops with a watchdog intervention",
        ),
        (
            "--unscored",
            int,
            "unscored (dry) stops a generation, in that excess and the watchdog share only",
        ),
    ):
        name = flag[2:].replace("-", "_")
        p.add_argument(flag, type=kind, default=None,
                       help=f"{what} (default {getattr(d, name)})")  # fmt: skip
    p.add_argument("--no-progress", action="store_true", help="no line per generation")
    p.add_argument("--json", dest="json_path", default=None, help="write the result here")
    p.set_defaults(func=cmd_finetune)


FINETUNE_SETTINGS = ("pairs", "stops", "pool", "sigma", "learning_rate", "layers", "seed",
                     "average", "guard", "ratio_cap", "ratio_weight", "watchdog_weight",
                     "unscored")  # fmt: skip


def cmd_finetune(args: argparse.Namespace) -> dict[str, Any]:
    from wsp_env.training.es import ESSettings, finetune

    if args.generations < 0:
        raise UserError("--generations: must be >= 0")
    given = {k: getattr(args, k) for k in FINETUNE_SETTINGS if getattr(args, k) is not None}
    if args.resume is not None:
        if args.start is not None:
            raise UserError("start: a resumed fine-tune keeps its own start (drop it)")
        if args.out is not None and Path(args.out) != Path(args.resume):
            raise UserError("--out: a resumed fine-tune writes to its own folder (drop --out)")
        if given:
            flag = "--" + next(iter(given)).replace("_", "-")
            raise UserError(f"{flag}: a resumed fine-tune keeps its own settings (drop it)")
        out, settings = args.resume, None
    else:
        if args.start is None:
            raise UserError("start: the model file to fine-tune is required unless --resume")
        if args.out is None:
            raise UserError("--out: required")
        out = args.out
        settings = ESSettings(start=args.start, **given)

    def progress(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    return finetune(
        args.start, out, args.generations, settings, resume=args.resume is not None,
        progress=None if args.no_progress else progress,
    )  # fmt: skip


# ---- validate -------------------------------------------------------------------------------


def _add_validate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate",
        help="run the physics' fidelity checks against the seeds (exit 1 if one fails)",
        description="Seed 002 Tables 6-7, seed 000 Table 4 through the adhesion estimator, "
        "locked wheels against the classical WSP on soap and leaves, and silence on dry rail. "
        "Exit status 1 when a check fails.",
    )
    p.add_argument("--json", dest="json_path", default=None, help="write the result here")
    p.add_argument("--report", default=None, help="write report.md and plots into this folder")
    p.set_defaults(func=cmd_validate)


def cmd_validate(args: argparse.Namespace) -> dict[str, Any]:
    from wsp_env.validation.checks import run_validation

    report_tmp = _reserve(args, "report", "--report", "dir")
    result = run_validation(report_tmp)
    if report_tmp is not None:
        result["report"] = args.report
    return result


# ---- entry point ----------------------------------------------------------------------------


# ---- rig ------------------------------------------------------------------------------------


def _add_rig(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "rig",
        help="a braking test on the virtual roller rig (HIL, seed 002), against the track alone",
        description="Runs a WSP (any policy evaluate runs) on a physical vehicle standing on a "
        "full-scale roller rig whose rollers make its wheels feel the virtual track's degraded "
        "adhesion (seed 002 §3: rig, estimator Eqs. 20-21, sliding-mode controller Eqs. 16-19), "
        "and the same policy and scenario on the virtual track alone. See docs/rig.md.",
    )
    p.add_argument("--vehicle", default="uic_z1", help="vehicle id or YAML path (uic_z1)")
    p.add_argument(
        "--policy", default="classical",
        help="classical | none | oracle | a shipped policy's name | PATH.zip (classical); model "
        "files are pickles: load only files you trust",
    )  # fmt: skip
    p.add_argument("--rail", default="soap", help="a rail of configs/rails.yaml (soap)")
    p.add_argument("--speed-kmh", type=_positive, default=120.0, help="initial speed (120)")
    p.add_argument("--mu-contaminated", type=_LEVEL, default=None, help="fix the level (0.001-1)")
    p.add_argument(
        "--pattern", choices=("uniform", "step_up", "step_down", "patches"), default=None
    )
    p.add_argument("--seed", type=_seed, default=0, help="draws what the case leaves open (0)")
    p.add_argument("--rig-config", default=None, help="rig parameters (YAML, RigConfig fields)")
    p.add_argument("--omega-noise-kmh", type=_nonneg, default=None, help="roller speed noise")
    p.add_argument("--json", dest="json_path", default=None, help="write the result here")
    p.add_argument("--plot", default=None, help="write seed 002 Figs. 18-22 style plots (PNG)")
    p.set_defaults(func=cmd_rig)


def cmd_rig(args: argparse.Namespace) -> dict[str, Any]:
    from wsp_env.core.config import read_yaml
    from wsp_env.rig.roller_rig import RigConfig, plot_rig, rig_test

    vehicle = _vehicle_for_speed(args.vehicle, args.speed_kmh)
    load_rail(args.rail, None)  # an unknown rail fails here, named
    rig_fields = (read_yaml(Path(args.rig_config)) or {}) if args.rig_config else {}
    if args.omega_noise_kmh is not None:
        rig_fields = {**rig_fields, "omega_noise_kmh": args.omega_noise_kmh}
    where = args.rig_config or "--omega-noise-kmh"
    try:
        rig = from_dict(RigConfig, rig_fields, "")
    except ConfigError as err:
        raise ConfigError(f"{where}: {err}") from None
    (policy,) = _policies([args.policy], None)
    plot_tmp = _reserve(args, "plot", "--plot")
    case = _fixed_rail(args)
    result = rig_test(vehicle, policy, args.rail, args.speed_kmh, args.seed, case, rig)
    if plot_tmp is not None:
        plot_rig(result, str(plot_tmp))
    return result.summary


# ---- traction -------------------------------------------------------------------------------


def _add_traction(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "traction",
        help="a start on a contaminated rail with the anti-skid device (seed 002 traction test)",
        description="The traction phase (seed 002 §3.1.4, §5.3): the driver's torque per axle, "
        "modulated by the anti-skid device, on soap at Table 8's levels; defaults are the "
        "E402B test of Table 3. See docs/traction.md.",
    )
    p.add_argument("--vehicle", default="e402b", help="vehicle id or YAML path (e402b)")
    p.add_argument("--speed-kmh", type=_positive, default=5.0, help="initial speed (5)")
    p.add_argument(
        "--torque-nm", type=_bounded(0.0, 1e6, low_open=True), default=12300.0,
        help="per axle (12300)",
    )  # fmt: skip
    p.add_argument(
        "--duration-s", type=_bounded(0.0, 3600.0, low_open=True), default=20.0,
        help="test duration (20; at most 3600)",
    )  # fmt: skip
    p.add_argument(
        "--mu-contaminated", type=_LEVEL, default=None,
        help="soap level under axle 1 (default 0.0846: Table 8's 0.09 x R_1, traction.py)",
    )  # fmt: skip
    p.add_argument(
        "--antiskid-config", default=None,
        help="anti-skid thresholds (YAML; default configs/antiskid/e402b_seed002.yaml)",
    )  # fmt: skip
    p.add_argument("--no-antiskid", action="store_true", help="the full torque throughout")
    p.add_argument("--json", dest="json_path", default=None, help="write the result here")
    p.add_argument("--plot", default=None, help="write a PNG of speeds, torques, adhesion")
    p.set_defaults(func=cmd_traction)


def cmd_traction(args: argparse.Namespace) -> dict[str, Any]:
    from wsp_env.baselines.antiskid import AntiSkid, AntiSkidConfig
    from wsp_env.core.config import read_yaml
    from wsp_env.rig.traction import MU_HEAD, plot_traction, run_traction

    vehicle = _vehicle_for_speed(args.vehicle, args.speed_kmh)
    plot_tmp = _reserve(args, "plot", "--plot")
    antiskid = None
    if args.antiskid_config:
        fields = read_yaml(Path(args.antiskid_config)) or {}  # a missing file: named there
        try:
            cfg = from_dict(AntiSkidConfig, fields, "")
        except ConfigError as err:
            raise ConfigError(f"{args.antiskid_config}: {err}") from None
        antiskid = AntiSkid(cfg)
    run = run_traction(
        vehicle, args.torque_nm, args.speed_kmh, args.duration_s,
        mu_contaminated=args.mu_contaminated or MU_HEAD, antiskid=antiskid,
        no_antiskid=args.no_antiskid,
    )  # fmt: skip
    if plot_tmp is not None:
        plot_traction(run, str(plot_tmp))
    return run.summary


# ---- export-policy ----------------------------------------------------------------------------


def _add_export(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export-policy",
        help="export a trained PPO/A2C policy to ONNX, normalisation folded in",
        description="Write the deterministic actor of a trained model (normalisation folded "
        "in) as ONNX for an embedded WSP, and measure ONNX Runtime's per-decision latency. "
        "Model files are pickles: load only files you trust. See docs/training.md.",
    )
    p.add_argument("model", help="a model file written by `wsp-env train` (.zip), or a shipped "
                   "policy's name")  # fmt: skip
    p.add_argument("--onnx", required=True, help="output path (.onnx)")
    p.add_argument("--json", dest="json_path", default=None, help="write the result here")
    p.set_defaults(func=cmd_export)


def cmd_export(args: argparse.Namespace) -> dict[str, Any]:
    from wsp_env.training.export import export_onnx

    if not args.onnx.endswith(".onnx"):
        raise UserError(f"--onnx: {args.onnx} should end in .onnx")
    onnx_tmp = _reserve(args, "onnx", "--onnx")
    result = export_onnx(args.model, onnx_tmp)
    result["onnx"] = args.onnx
    return result


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="wsp-env", description="Wheel slide protection braking: simulate, evaluate, train."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    _add_simulate(sub)
    _add_evaluate(sub)
    _add_benchmark(sub)
    _add_calibrate(sub)
    _add_bench(sub)
    _add_train(sub)
    _add_finetune(sub)
    _add_sweep(sub)
    _add_validate(sub)
    _add_export(sub)
    _add_rig(sub)
    _add_traction(sub)
    return parser


# the commands that step the physics, and what a first run of one says while numba compiles
# (measured: docs/physics.md, "First run")
COMPILING = ("simulate", "evaluate", "benchmark", "train", "validate", "rig", "traction",
             "bench", "sweep", "finetune")  # fmt: skip
COMPILE_NOTICE = (
    "wsp-env: compiling the physics kernels (once per install and version; 15-30 s on 2 cores) ..."
)


def stderr_is_terminal() -> bool:
    """Someone watches stderr (a terminal): say what a long silence is. Logs and pipes get only
    the command's own lines (errors stay one line)."""
    return sys.stderr.isatty()


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command in COMPILING and stderr_is_terminal() and not compiled():
        print(COMPILE_NOTICE, file=sys.stderr, flush=True)
    try:
        with Outputs() as outputs:  # every output checked first, all written at the end or none
            args.outputs = outputs
            read = [v for k, v in vars(args).items() if k not in OUTPUT_ARGS
                    and isinstance(v, str) and Path(v).is_file()]  # fmt: skip
            outputs.inputs(*read, *(_meta_of(v) for v in read if v.endswith(".csv")))
            json_tmp = _reserve(args, "json_path", "--json") if "json_path" in args else None
            result = args.func(args)
            if json_tmp is not None:
                write_json(json_tmp, result)
            outputs.commit()
    except (ConfigError, UserError, ValueError, OSError) as err:
        message = outputs.explain(str(err))  # a producer's error names the output, not its temp
        print(f"wsp-env {args.command}: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C: the outputs were removed on the way out (Outputs)
        said = "nothing written"
        if args.command == "finetune":  # its run folder keeps every generation done
            said = f"the generations done are in {args.resume or args.out} (--resume it)"
        print(f"wsp-env {args.command}: interrupted; {said}", file=sys.stderr)
        return 130
    try:
        PRINTERS[args.command](result)
        sys.stdout.flush()
    except BrokenPipeError:  # `wsp-env simulate | head -1`: the reader has had enough
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # as a process that SIGPIPE ended (128 + 13); the outputs are written
    if args.command == "validate" and not result["passed"]:
        return 1  # a fidelity check failed (the result and report are written)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Constant slip targets on the benchmark's sealed set: what the slip-target inner loop alone
gives, the baseline a policy trained in ``action_mode="slip_target"`` must beat (issue 23).

Each ``--target`` is a ``baselines.slip_target.SlipTargetPolicy`` (every valve asks for that
measured sliding speed, tracked every 20 ms by the same ``SlipTargetLoop`` the environment's
mode uses, on the same thresholds: the tier's frozen classical WSP's), scored through
``evaluation.benchmark.run_benchmark`` like any other controller: the same stops, sensors,
watchdog and score. ``--thresholds default`` runs the loop on ``WSPConfig()``'s defaults
instead, as this script did before 2026-11-27 (every constant-target figure measured with it
until then: the wheels tier's 2.0 m/s^2 recovery hold and 3 s release interval where the
``wheels+accel`` tier's are 3.27 m/s^2 and 4.6 s); the file records which
(``slip_target_loop``), and ``choose_rail_targets.py`` does not merge files of different loops.

    .venv/bin/python scripts/slip_target_benchmark.py --tier wheels+accel --target 4.25 \\
        [--target 2 --target 6] [--runs 300] [--stops development] [--vehicle regiolis] \\
        [--json runs/bench/slip_constant.json] [--rail-teacher] [--release always] \\
        [--max-creep 0 --max-creep 0.2] [--drift-correction on [--onset-drift on]] \\
        [--pressure-gain 0.8x0.25] [--scale-calibration on] [--onset-two-sided on] \\
        [--teacher-table configs/train/ppo_bc_slip_target_cal_accel_uic_z1.yaml]

``--rail-teacher`` adds ``baselines.oracle.SlipTargetOracle``: the privileged teacher of the
imitation start (``oracle_target_rail``: each stop's constant target picked by its rail, which
the sensors do not measure), through the same loop; ``--teacher-table CONFIG`` (implies it)
gives it a training config's table (``pretrain.teacher_targets_kmh``, with its creep
schedules, ``pretrain.teacher_creep``) instead of ``oracle.RAIL_TARGETS_KMH``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from wsp_env import BENCHMARK_VEHICLES
from wsp_env.baselines.classical import WSPConfig, load_wsp_config
from wsp_env.baselines.oracle import SlipTargetOracle, SlipTargetTeacher
from wsp_env.baselines.slip_target import (
    DEFAULT_MAX_CREEP,
    DEFAULT_RELEASE,
    RELEASE_GATES,
    SlipTargetLoop,
    SlipTargetPolicy,
    loop_suffix,
    parse_pressure_gain,
)
from wsp_env.cli.printing import print_benchmark
from wsp_env.evaluation.benchmark import SEALED_RUNS, STOP_SETS, run_benchmark
from wsp_env.training.config import config_teacher_creep, config_teacher_table


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tier", default="wheels+accel", choices=("wheels", "wheels+accel"))
    ap.add_argument("--vehicle", default="uic_z1", choices=tuple(BENCHMARK_VEHICLES))
    ap.add_argument("--target", type=float, action="append", help="km/h, repeatable")
    ap.add_argument("--runs", type=int, default=SEALED_RUNS)
    ap.add_argument("--stops", choices=tuple(STOP_SETS), default="sealed")
    ap.add_argument("--json", dest="json_path", default=None)
    ap.add_argument(
        "--rail-teacher",
        action="store_true",
        help="also the privileged oracle_target_rail (one target a stop by its rail)",
    )
    ap.add_argument(
        "--release",
        action="append",
        choices=RELEASE_GATES,
        help="the loop's periodic-release gate (repeatable: each target under each; default "
        "working)",
    )
    ap.add_argument(
        "--max-creep",
        type=float,
        action="append",
        help="the loop's cap on each target, a fraction of the reference speed (0: none; "
        f"repeatable; default {DEFAULT_MAX_CREEP})",
    )
    ap.add_argument(
        "--drift-correction",
        action="append",
        choices=("off", "on"),
        help="the loop's correction of the aided reference's drift (wheels+accel only; "
        "repeatable: each target under each; default off)",
    )
    ap.add_argument(
        "--onset-drift",
        action="append",
        choices=("off", "on"),
        help="the drift-corrected loop's reading of the accelerometer's offset at the stop's "
        "onset (needs --drift-correction on; repeatable; default off)",
    )
    ap.add_argument(
        "--scale-calibration",
        action="append",
        choices=("off", "on"),
        help="the loop's calibration of the wheel-speed sensors' scales at the stop's onset "
        "(either tier; repeatable: each target under each; default off)",
    )
    ap.add_argument(
        "--onset-two-sided",
        action="append",
        choices=("off", "on"),
        help="the onset reading's other sense too (needs --onset-drift on; repeatable; "
        "default off)",
    )
    ap.add_argument(
        "--teacher-table",
        help="a training config whose pretrain.teacher_targets_kmh (and teacher_creep) the "
        "rail teacher asks for (implies --rail-teacher)",
    )
    ap.add_argument(
        "--pressure-gain",
        action="append",
        help="the loop's gain: off (a fixed 0.2 per km/h) or GxF, G per km/h times the pressure "
        "held over the demand, never below F of it (e.g. 0.8x0.25; repeatable: each target "
        "under each; default off)",
    )
    ap.add_argument(
        "--thresholds",
        choices=("tier", "default"),
        default="tier",
        help="the loop's classical thresholds: the tier's frozen file (the environment's mode) "
        "or WSPConfig()'s defaults (this script before 2026-11-27)",
    )
    args = ap.parse_args(argv)
    # with --teacher-table alone, only the teacher runs
    targets = args.target or ([] if args.teacher_table else [4.25])
    if any(not 0.0 <= t <= 30.0 for t in targets):
        print("--target: a sliding speed in [0, 30] km/h", file=sys.stderr)
        return 2
    caps = args.max_creep or [DEFAULT_MAX_CREEP]
    if any(not 0.0 <= c <= 1.0 for c in caps):
        print("--max-creep: a fraction of the reference speed in [0, 1]", file=sys.stderr)
        return 2
    drifts = [d == "on" for d in args.drift_correction or ["off"]]
    onsets = [o == "on" for o in args.onset_drift or ["off"]]
    if any(onsets) and not all(drifts):
        print("--onset-drift on: needs --drift-correction on (only)", file=sys.stderr)
        return 2
    cals = [c == "on" for c in args.scale_calibration or ["off"]]
    sides = [c == "on" for c in args.onset_two_sided or ["off"]]
    if any(sides) and not all(onsets):
        print("--onset-two-sided on: needs --onset-drift on (only)", file=sys.stderr)
        return 2
    table, creep, creep_floor_kmh = None, {}, 0.5
    if args.teacher_table:
        try:
            table = config_teacher_table(args.teacher_table)
            creep, creep_floor_kmh = config_teacher_creep(args.teacher_table)
        except ValueError as err:
            print(f"--teacher-table {err}", file=sys.stderr)
            return 2
    if any(drifts) and args.tier != "wheels+accel":
        print("--drift-correction on: needs --tier wheels+accel", file=sys.stderr)
        return 2
    try:
        gains = [
            parse_pressure_gain(g, f"--pressure-gain {g}") for g in args.pressure_gain or ["off"]
        ]
    except ValueError as err:
        print(err, file=sys.stderr)
        return 2
    loops = [
        {"release": g, "max_creep": c, "drift_correction": d, "onset_drift": o,
         "gain_per_kmh": gain, "gain_scale_floor": floor, "scale_calibration": cal,
         "onset_two_sided": side}
        for g in args.release or [DEFAULT_RELEASE]
        for c in caps
        for d in drifts
        for o in onsets
        for gain, floor in gains
        for cal in cals
        for side in sides
    ]  # fmt: skip
    wsp = load_wsp_config(tier=args.tier) if args.thresholds == "tier" else WSPConfig()
    policies: list = [
        SlipTargetPolicy(t, SlipTargetLoop(wsp, **kw)) for kw in loops for t in targets
    ]
    if args.rail_teacher or table is not None:  # under each loop too (named where it is not
        # the default)
        for kw in loops:
            own = None if table is None else SlipTargetTeacher(table, creep, creep_floor_kmh)
            teacher = SlipTargetOracle(own)
            teacher.loop = SlipTargetLoop(wsp, **kw)
            teacher.name += loop_suffix(teacher.loop)
            policies.append(teacher)
    result = run_benchmark(policies, vehicle=args.vehicle, tier=args.tier, runs=args.runs,
                           stop_set=args.stops, keep_runs=args.json_path is not None,
                           progress=lambda m: print(m, file=sys.stderr))  # fmt: skip
    # which loop made the runs (choose_rail_targets.py refuses to merge files of two)
    result["slip_target_loop"] = {"thresholds": args.thresholds}
    print_benchmark(result)
    if args.json_path:
        path = Path(args.json_path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

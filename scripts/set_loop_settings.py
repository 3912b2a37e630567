"""A copy of a slip-target model file with its loop's later settings set: the periodic
release's gate (``--release``: ``slip_target_release``, ``working`` or ``always``), the creep
cap (``--max-creep``: ``slip_target_max_creep``, 0-1, 0 no cap), the drift correction
(``--drift-correction on|off``: ``slip_target_drift_correction``, an accelerometer model's; and
``--onset-drift on|off``, its onset reading, ``slip_target_onset_drift``, and
``--onset-two-sided on|off``, that reading's other sense, ``slip_target_onset_two_sided``), the
wheel-scale
calibration (``--scale-calibration on|off``: ``slip_target_scale_calibration``), the lock
guard (``--lock-guard on|off``: ``slip_target_lock_guard``) and
the gain (``--pressure-gain off|GxF``: ``slip_target_gain_per_kmh`` and
``slip_target_gain_scale_floor``, off the fixed 0.2 per km/h, GxF G per km/h times the pressure
held over the demand, never below F of it; docs/environment.md), so that a
policy trained before a setting existed (which loads with the loop it was made with:
``policy.LEGACY_LOOP_SETTINGS``) can be scored with today's loop, or the other way round. The
copy takes its observation statistics (``STEM.vecnormalize.pkl``) along; nothing else of the
model changes.

    .venv/bin/python scripts/set_loop_settings.py runs/train/bc_st_v3_s1/student.zip \\
        runs/s16/uic_v3_capped/student.zip --release working --max-creep 0.2
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from wsp_env.baselines.slip_target import RELEASE_GATES, check_max_creep, parse_pressure_gain
from wsp_env.policy import model_metadata, write_model_metadata


def _write(pairs: list[tuple[Path, Path]], meta: dict) -> None:
    """Each (source, copy) written beside its name first (the model's metadata set), then moved
    in, the model file last: a failure leaves no part behind and no model without its
    statistics."""
    parts = [dst.with_name(dst.name + ".part") for _, dst in pairs]
    folder = pairs[0][1].parent
    made = not folder.exists()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for (src, _), part in zip(pairs, parts, strict=True):
            shutil.copy(src, part)
        write_model_metadata(parts[-1], meta)
        for (_, dst), part in zip(pairs, parts, strict=True):
            part.replace(dst)
    finally:
        for part in parts:
            part.unlink(missing_ok=True)
        if made and not any(folder.iterdir()):
            folder.rmdir()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", type=Path, help="a slip-target model file (.zip)")
    ap.add_argument("out", type=Path, help="the copy to write (.zip)")
    ap.add_argument("--release", choices=RELEASE_GATES, help="the periodic release's gate")
    ap.add_argument("--max-creep", help="the cap on the target, a fraction of the reference speed")
    ap.add_argument(
        "--drift-correction",
        choices=("on", "off"),
        help="the loop's correction of the aided reference's drift (accelerometer models)",
    )
    ap.add_argument(
        "--onset-drift",
        choices=("on", "off"),
        help="the drift-corrected loop's onset reading of the accelerometer's offset",
    )
    ap.add_argument(
        "--onset-two-sided",
        choices=("on", "off"),
        help="the onset reading's other sense too (a reading of too much deceleration)",
    )
    ap.add_argument(
        "--scale-calibration",
        choices=("on", "off"),
        help="the loop's calibration of the wheel-speed sensors' scales at the stop's onset",
    )
    ap.add_argument(
        "--lock-guard",
        choices=("on", "off"),
        help="the loop's cap on its requests at low speed on a low-adhesion stop",
    )
    ap.add_argument(
        "--pressure-gain",
        help="the loop's gain: off (a fixed 0.2 per km/h) or GxF (G per km/h times the pressure "
        "held over the demand, never below F of it, e.g. 0.8x0.25)",
    )
    args = ap.parse_args(argv)
    try:
        settings: dict = {}
        if args.release is not None:
            settings["slip_target_release"] = args.release
        if args.max_creep is not None:
            try:
                value = float(args.max_creep)
            except ValueError:
                raise ValueError(f"--max-creep: a number, got {args.max_creep!r}") from None
            settings["slip_target_max_creep"] = check_max_creep(value)
        if args.drift_correction is not None:
            settings["slip_target_drift_correction"] = args.drift_correction == "on"
        if args.onset_drift is not None:
            settings["slip_target_onset_drift"] = args.onset_drift == "on"
        if args.scale_calibration is not None:
            settings["slip_target_scale_calibration"] = args.scale_calibration == "on"
        if args.onset_two_sided is not None:
            settings["slip_target_onset_two_sided"] = args.onset_two_sided == "on"
        if args.lock_guard is not None:
            settings["slip_target_lock_guard"] = args.lock_guard == "on"
        if args.pressure_gain is not None:
            gain, floor = parse_pressure_gain(
                args.pressure_gain, f"--pressure-gain {args.pressure_gain}"
            )
            settings["slip_target_gain_per_kmh"] = gain
            settings["slip_target_gain_scale_floor"] = floor
        if not settings:
            raise ValueError(
                "nothing to set: give --release, --max-creep, --drift-correction, "
                "--onset-drift, --onset-two-sided, --scale-calibration, --lock-guard and/or "
                "--pressure-gain"
            )
        if args.out.suffix != ".zip":
            raise ValueError(f"{args.out}: the copy must be a .zip model file")
        if args.out.resolve() == args.model.resolve():
            raise ValueError(f"{args.out}: the model itself; write the copy elsewhere")
        meta = model_metadata(args.model)
        mode = meta["env_kwargs"].get("action_mode", "continuous")
        if mode != "slip_target":
            raise ValueError(f"{args.model}: not a slip-target model (action_mode {mode!r})")
        kw_after = {**meta["env_kwargs"], **settings}
        if kw_after.get("slip_target_onset_drift") and not kw_after.get(
            "slip_target_drift_correction"
        ):
            raise ValueError(
                f"{args.model}: the onset reading needs the drift correction "
                "(--drift-correction on)"
            )
        if kw_after.get("slip_target_onset_two_sided") and not kw_after.get(
            "slip_target_onset_drift"
        ):
            raise ValueError(
                f"{args.model}: the two-sided onset reading needs the onset reading "
                "(--onset-drift on)"
            )
        if settings.get("slip_target_drift_correction") and not meta["env_kwargs"].get(
            "accelerometer"
        ):
            raise ValueError(
                f"{args.model}: trained without the accelerometer; the drift correction needs it"
            )
        norm = args.model.with_suffix(".vecnormalize.pkl")
        if meta.get("obs_normalization") and not norm.exists():
            raise ValueError(f"{args.model}: trained on normalised observations, {norm} missing")
        meta["env_kwargs"].update(settings)
        meta["name"] = f"{args.out.parent.name}/{args.out.stem}"
        # the model file and, where the model has one, its observation statistics
        pairs = [(args.model, args.out)]
        if norm.exists():
            pairs.insert(0, (norm, args.out.with_suffix(".vecnormalize.pkl")))
        for path in (args.out, args.out.with_suffix(".vecnormalize.pkl")):
            if path.exists():
                raise ValueError(f"{path}: exists; not overwriting")
        _write(pairs, meta)
    except (OSError, ValueError) as err:
        print(f"set_loop_settings: {err}", file=sys.stderr)
        return 2
    print(f"{args.out}: " + ", ".join(f"{k} {v}" for k, v in settings.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())

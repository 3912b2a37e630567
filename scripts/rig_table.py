"""Braking tests on the virtual roller rig against the virtual track alone: one table.

    .venv/bin/python scripts/rig_table.py [--markdown docs/results/rig_table.md]

Each row is what ``wsp-env rig`` runs (``rig.roller_rig.rig_test``: the rig, then the same
policy and scenario on the track, ``runner.run_one``) for one policy, rail and rig setting,
uic_z1, seed 0: the stops, the speed error ``e_ω`` (RMS over the stop and largest, over the
axles), the torque estimation error ``e_C`` (RMS, over the axles), each axle's mean sliding on the
rig and on the track, and the rig's speed against real time. ``--markdown P`` writes the table
with the command and the machine above it.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from _results_md import write_results

from wsp_env.policy import make_policy
from wsp_env.rig.roller_rig import rig_test

SOAP = {"mu_contaminated": 0.08, "pattern": "uniform"}
# (label, policy, rail, speed km/h, fixed case fields, rig fields); the equivalent command:
# wsp-env rig --policy P --rail R --speed-kmh V [--mu-contaminated M --pattern uniform]
#     [--omega-noise-kmh N] [--rig-config YAML with derivative_cutoff_hz]
TESTS = (
    ("classical, soap 0.08, 120 km/h", "classical", "soap", 120.0, SOAP, {}),
    ("the same, roller-speed noise 0.1 km/h", "classical", "soap", 120.0, SOAP,
     {"omega_noise_kmh": 0.1}),
    ("the same, noise 0.1 km/h, differentiator 25 Hz", "classical", "soap", 120.0, SOAP,
     {"omega_noise_kmh": 0.1, "derivative_cutoff_hz": 25.0}),
    ("none (wheels lock), soap 0.08, 120 km/h", "none", "soap", 120.0, SOAP, {}),
    ("none, dry, 120 km/h", "none", "dry", 120.0, {"pattern": "uniform"}, {}),
    ("ppo_bc_uic_z1 (shipped), soap 0.08, 120 km/h", "ppo_bc_uic_z1", "soap", 120.0, SOAP, {}),
    ("ppo_bc_uic_z1, leaves 0.04, 90 km/h", "ppo_bc_uic_z1", "leaves", 90.0,
     {"mu_contaminated": 0.04, "pattern": "uniform"}, {}),
)  # fmt: skip


def _span(values: list[float], fmt: str) -> str:
    lo, hi = format(min(values), fmt), format(max(values), fmt)
    return lo if lo == hi else f"{lo}–{hi}"


def _slides(values: list[float]) -> str:
    return ", ".join(f"{v:.2f}" for v in values)


def table() -> str:
    lines = [
        "| test | rig stop | track stop | e_ω RMS / max [km/h] | e_C RMS [N m] | mean sliding "
        "axles 1-4 on the rig [km/h] | on the track [km/h] | rig speed |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for label, policy, rail, speed, case, rig in TESTS:
        s = rig_test("uic_z1", make_policy(policy), rail, speed, 0, dict(case), rig).summary
        lines.append(
            f"| {label} | {s['rig_stopping_distance_m']:.1f} m | "
            f"{s['track_stopping_distance_m']:.1f} m ({s['rig_vs_track_pct']:+.2f} %) | "
            f"{_span(s['e_omega_rms_kmh'], '.3f')} / {_span(s['e_omega_max_kmh'], '.2f')} | "
            f"{_span(s['e_C_rms_Nm'], '.0f')} | {_slides(s['mean_sliding_kmh'])} | "
            f"{_slides(s['track_mean_sliding_kmh'])} | {s['real_time_factor']:.0f}× real time |"
        )
        print(lines[-1], flush=True)
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", type=Path, default=None, help="write the table here (.md)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    text = table()
    if args.markdown is not None:
        intro = (
            "uic_z1, seed 0; track: the same policy and scenario on the virtual track alone "
            "(`runner.run_one`). Spans are over the four axles.\n\n"
        )
        title = "Roller rig against the track"
        write_results(args.markdown, title, intro + text, time.perf_counter() - t0)
        print(f"wrote {args.markdown}")


if __name__ == "__main__":
    main()

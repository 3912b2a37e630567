"""The fidelity checks of `wsp-env validate` as one table: check, target, measured, pass.

    .venv/bin/python scripts/validation_table.py [--json runs/validate.json]
        [--markdown docs/results/validation.md]

Runs the same checks as `wsp-env validate` (``wsp_env.validation.checks.run_validation``; the
targets and tolerances are ``wsp_env.validation.targets``, docs/validation.md says why) and
prints the table; ``--markdown P`` writes it with the command and the machine above it.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
from _results_md import write_results

from wsp_env.files import write_json
from wsp_env.validation import targets as T
from wsp_env.validation.checks import run_validation


def _join(values: Any, fmt: str) -> str:
    return " / ".join(format(float(v), fmt) for v in values)


def _yes(ok: bool) -> str:
    return "yes" if ok else "**no**"


def rows(r: dict[str, Any]) -> list[tuple[str, str, str, str]]:
    """(check, target, measured, pass) per line of the table."""
    s2, s0, dry, rig, tr = (r[k] for k in ("seed002", "seed000", "dry_quiet", "rig",
                                           "seed002_traction"))  # fmt: skip
    table6 = T.TABLE6.mean(axis=0)
    judged = [x for x in r["locked_vs_wsp"] if x["judged"]]
    ratios = [x["none_m"] / x["classical_m"] for x in judged]
    closest = judged[int(np.argmin(ratios))]
    t4 = T.TABLE4
    lo, hi = T.TABLE10_M
    low, high = np.asarray(tr["table9_envelope_kmh"])
    envelope = ", ".join(f"{a:.2f}…{b:.2f}" for a, b in zip(low, high, strict=True))
    return [
        (
            "seed 002 braking test (Table 5 fixed): stop",
            f"{T.TABLE7_M:.0f} m ± {100 * T.SEED002_STOP_TOL:.0f} % (Table 7)",
            f"{s2['stopping_distance_m']:.1f} m",
            _yes(s2["passed"]),
        ),
        (
            "seed 002: mean sliding, axles 1-4",
            f"Table 6 ± {T.SEED002_SLIDE_TOL_KMH:g} km/h: {_join(table6, '.2f')}",
            f"{_join(s2['mean_sliding_kmh'], '.2f')} km/h",
            "",
        ),
        (
            "seed 002: the same stop without WSP",
            f">= {100 * T.SEED002_LOCK_MARGIN:.0f} % longer",
            f"{s2['none_stopping_distance_m']:.1f} m ({s2['none_margin_pct']:+.1f} %)",
            "",
        ),
        (
            "seed 000 Table 4 through our estimator (ETR 1000, soap, 150 km/h, classical WSP, "
            "10 Hz trace): mu0, axles 1-4",
            f"within {100 * T.SEED000_MU0_TOL:.0f} % of {_join(t4['mu0'], '.4f')}; rear bogie "
            "above front",
            _join(s0["mu0"], ".4f"),
            _yes(s0["passed"]),
        ),
        (
            "seed 000: K_rozv, axles 1-4 [per km/h]",
            f"within ×{T.SEED000_KROZV_FACTOR:g} of {min(t4['K_rozv']):.3f}-"
            f"{max(t4['K_rozv']):.3f}",
            _join(s0["K_rozv"], ".4f"),
            "",
        ),
        (
            "seed 000: K (reported, not judged)",
            f"{t4['K'][0]:.1f} (a bound of the seed's fit)",
            _join(s0["K"], ".1f"),
            "",
        ),
        (
            "locked wheels lose: soap and leaves runs of `en15595` and `heldout`",
            "`none` longer than `classical` in every run",
            f"{len(judged)} runs, none / classical {min(ratios):.3f}-{max(ratios):.3f} (closest: "
            f"{closest['scenario']} seed {closest['seed']})",
            _yes(r["locked_vs_wsp_passed"]),
        ),
        (
            f"dry quiet ({dry['scenario']})",
            f"no air, within {100 * T.DRY_QUIET_TOL:.0f} % of `none`",
            f"{dry['classical_m']:.1f} m vs {dry['none_m']:.1f} m, {dry['classical_air_l']:.1f} l",
            _yes(dry["passed"]),
        ),
        (
            "rig: seed 002's braking test on the roller rig against the track alone",
            f"within {100 * T.RIG_STOP_TOL:.0f} %; e_ω RMS < {T.RIG_E_OMEGA_RMS_KMH:g} km/h "
            "every axle",
            f"{rig['rig_stopping_distance_m']:.1f} m vs {rig['track_stopping_distance_m']:.1f} m "
            f"({rig['rig_vs_track_pct']:+.2f} %); e_ω RMS {min(rig['e_omega_rms_kmh']):.3f}-"
            f"{max(rig['e_omega_rms_kmh']):.3f} km/h",
            _yes(rig["passed"]),
        ),
        (
            "traction: seed 002's E402B start, mean sliding axles 1-4 and distance"
            + ("" if tr.get("in_overall_verdict", True) else " (not in the overall verdict)"),
            f"inside Table 9's T1-T2 ± {T.TABLE9_WIDEN_KMH:g} km/h "
            f"({envelope}); axle 4 least; "
            f"{tr['duration_s']:g} s distance within Table 10's {lo:.1f}-{hi:.1f} m",
            f"{_join(tr['mean_sliding_kmh'], '.2f')} km/h; "
            f"{'axle 4 least' if tr['axle4_least_sliding'] else 'axle 4 not least'}; "
            f"{tr['distance_m']:.1f} m",
            _yes(tr["passed"]),
        ),
    ]


def markdown(r: dict[str, Any]) -> str:
    lines = ["| check | target | measured | pass |", "|---|---|---|---|"]
    lines += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows(r)]
    lines += ["", f"Overall: {'pass' if r['passed'] else 'FAIL'}."]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, default=None, help="also write the checks' result here")
    ap.add_argument("--markdown", type=Path, default=None, help="write the table here (.md)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    result = run_validation()
    text = markdown(result)
    print(text)
    if args.json is not None:
        write_json(args.json, result)
    if args.markdown is not None:
        title = "Physics fidelity checks (`wsp-env validate`)"
        write_results(args.markdown, title, text, time.perf_counter() - t0)
        print(f"wrote {args.markdown}")


if __name__ == "__main__":
    main()

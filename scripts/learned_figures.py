"""Where the shipped policy's gain comes from: one `heldout` soap stop and one leaves stop,
classical WSP against the learned policy, same scenario and seed (the evaluation's code path).

    .venv/bin/python scripts/learned_figures.py [--policy ppo_bc_uic_z1] \
        [--out docs/learned_vs_classical.png] [--markdown docs/results/learned_figures.md]

Prints per run and policy the stop, each axle's mean sliding (seed 002 Eq. 23), the time any
axle slides deeper than 10 km/h, the sliding energy and the air; the figure shows the axle
speeds against the train speed and the cylinder pressures against the demand. ``--markdown P``
also writes the printed figures there, with the command and the machine above.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
from _results_md import printed_results

from wsp_env.evaluation import load_suite, run_suite
from wsp_env.policy import make_policy

RUNS = (("soap_mid", 140.0), ("leaves_patches", 90.0))
SEED = 1000


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default="ppo_bc_uic_z1")
    ap.add_argument("--out", default="docs/learned_vs_classical.png")
    ap.add_argument("--markdown", default=None, help="also write the printed figures here")
    args = ap.parse_args()
    title = f"Where `{args.policy}`'s gain comes from"
    printed_results(args.markdown, title, lambda: figures(args))


def figures(args: argparse.Namespace) -> None:
    heldout = load_suite("heldout")
    cases = tuple(
        dataclasses.replace(c, speeds_kmh=(f"{v:g}",))
        for name, v in RUNS
        for c in heldout.cases
        if c.name == name
    )
    suite = dataclasses.replace(heldout, seeds=(SEED,), cases=cases)
    out = {}
    for p in ("classical", args.policy):
        results, records = run_suite("uic_z1", suite, make_policy(p), record="all")
        out[p] = (results, records)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 4, figsize=(18, 8))
    for col in range(len(RUNS)):
        for row, p in enumerate(("classical", args.policy)):
            results, records = out[p]
            res = results[col]
            rec = records[(res["scenario"], SEED)]
            deep = np.any(rec.v_train_kmh[:, None] - rec.v_axle_kmh > 10.0, axis=1)
            dt = float(np.median(np.diff(rec.time_s)))
            slides = " / ".join(f"{a['mean_sliding_kmh']:.1f}" for a in res["axles"])
            print(f"{res['scenario']} seed {SEED} {res['policy']:>24s}: stop "
                  f"{res['stopping_distance_m']:.0f} m, mean sliding {slides} km/h, deeper than "
                  f"10 km/h {deep.sum() * dt:.1f} s, sliding energy {res['sliding_energy_kJ']:.0f} "
                  f"kJ, air {res['air_litres']:.0f} l")  # fmt: skip
            a = ax[row, 2 * col]
            a.plot(rec.time_s, rec.v_train_kmh, "k", lw=1.2, label="train")
            for i in range(rec.v_axle_kmh.shape[1]):
                a.plot(rec.time_s, rec.v_axle_kmh[:, i], lw=0.7, label=f"axle {i + 1}")
            a.set(title=f"{res['scenario']}: {res['policy']} ({res['stopping_distance_m']:.0f} m)",
                  ylabel="speed [km/h]")  # fmt: skip
            a.legend(fontsize=7)
            b = ax[row, 2 * col + 1]
            b.plot(rec.time_s, rec.p_demand_bar, "k--", lw=0.8, label="demand")
            for i in range(rec.p_cyl_bar.shape[1]):
                b.plot(rec.time_s, rec.p_cyl_bar[:, i], lw=0.7, label=f"axle {i + 1}")
            b.set(title="cylinder pressures", ylabel="bar")
            b.legend(fontsize=7)
    for a in ax[1]:
        a.set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(args.out, dpi=80)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

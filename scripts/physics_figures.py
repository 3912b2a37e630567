"""Print the physics core's measured figures (accuracy and speed) — docs/physics.md's numbers.

    .venv/bin/python scripts/physics_figures.py [--markdown docs/results/physics_figures.md]

Speed figures are medians over repeated runs on this machine. ``--markdown P`` also writes the
printed figures there, with the command and the machine above.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from pathlib import Path

import numpy as np
from _results_md import printed_results

from wsp_env.core.config import load_rail, load_vehicle
from wsp_env.core.metrics import run_metrics
from wsp_env.core.simulator import RunSetup, TrainSim

KMH = 1 / 3.6


def stop(vehicle, rail, speed=120.0, dt=1e-3, n_envs=1, cmd_fn=None):
    sim = TrainSim(vehicle, n_envs=n_envs, dt_s=dt)
    for e in range(n_envs):
        sim.configure(e, RunSetup(speed, load_rail(rail) if isinstance(rail, str) else rail))
    sim.reset()
    n = 0
    t0 = time.perf_counter()
    while not sim.stopped.all():
        sim.step(None if cmd_fn is None else cmd_fn(n))
        n += 1
    return sim, time.perf_counter() - t0, n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", type=Path, default=None, help="also write the figures here")
    args = ap.parse_args()
    printed_results(args.markdown, "Physics core: accuracy and speed", figures)


def figures() -> None:
    veh = load_vehicle("uic_z1")
    inst = dataclasses.replace(
        veh,
        brake=dataclasses.replace(
            veh.brake,
            fill_tau_s=0.0,
            fill_rate_bar_per_s=1e9,
            demand_delay_s=0.0,
            demand_rise_s=0.0,
            valve_dead_time_s=0.0,
        ),
        resistance=dataclasses.replace(veh.resistance, a_N=0.0, b_N_per_mps=0.0, c_N_per_mps2=0.0),
    )
    sim, _, _ = stop(inst, "dry")
    gain, p_th = inst.brake.linear_torque()
    m = sim.arrays.body_mass_kg + sim.arrays.rest_mass_kg
    a = 4 * gain * (inst.brake.p_max_bar - p_th) / 0.46 / (m + 4 * 160 / 0.46**2)
    ref = (120 * KMH) ** 2 / (2 * a)
    print(
        f"dry rigid-body stop: {sim.position_m[0]:.2f} m vs analytic {ref:.2f} m "
        f"({(sim.position_m[0] / ref - 1) * 100:+.3f}%)"
    )
    rng = np.random.default_rng(3)
    cmds = rng.uniform(0, 1, size=(20000, 1, 4)) ** 0.3
    for rail in ("soap", "leaves", "oil"):
        sim, _, _ = stop(veh, rail, 140.0, cmd_fn=lambda n: cmds[n])
        err = run_metrics(sim)["energy_balance_rel_error"]
        print(f"energy balance, {rail}, random valve commands: relative residual {err:.1e}")

    def pulse(n):
        c = np.ones((1, 4))
        if (n * 0.02) % 1.2 < 0.3:
            c[0, (int(n * 0.02 / 1.2) % 2) :: 2] = 0.0
        return c

    for rail, fn, label in (
        ("soap", None, "no WSP"),
        ("soap", pulse, "pulsed valves"),
        ("leaves", pulse, "pulsed valves"),
    ):
        d = [stop(veh, rail, dt=dt, cmd_fn=fn)[0].position_m[0] for dt in (1e-3, 5e-5)]
        print(
            f"convergence {rail} ({label}): 1 ms {d[0]:.2f} m vs 0.05 ms {d[1]:.2f} m "
            f"({(d[0] / d[1] - 1) * 100:+.3f}%)"
        )
    stop(veh, "soap")
    singles = [stop(veh, "soap") for _ in range(7)]
    wall = statistics.median(s[1] for s in singles)
    t_sim = singles[0][0].time_s[0]
    print(
        f"one 120 km/h emergency stop (uic_z1, soap, no WSP, 1 ms substeps): {wall * 1e3:.1f} ms "
        f"wall for {t_sim:.1f} s simulated = {t_sim / wall:.0f}x real time (median of 7)"
    )
    stop(veh, "soap", n_envs=1024)
    batch = statistics.median(stop(veh, "soap", n_envs=1024)[1] for _ in range(3))
    print(
        f"1024 such stops in one batch: {batch:.2f} s wall = {1024 * wall / batch:.1f}x faster "
        f"than 1024 single stops ({1024 * wall:.1f} s) (median of 3)"
    )


if __name__ == "__main__":
    main()

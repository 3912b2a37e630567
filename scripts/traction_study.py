"""The traction test's soap curve and sliding under variants of the rail (docs/traction.md).

    .venv/bin/python scripts/traction_study.py      # a few seconds

Prints the soap curve's peak (creep, slip, mu) at Table 8's level on the E402B's axle 2 at 10, 30
and 60 km/h (``physics.adhesion.peak_adhesion`` on the test's state), and the test's mean sliding
per axle as modelled, without rail cleaning, and with a lower clean-rail level.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from wsp_env.core.config import load_vehicle
from wsp_env.core.simulator import RunSetup, TrainSim
from wsp_env.physics import layout as L
from wsp_env.physics.adhesion import peak_adhesion
from wsp_env.physics.rail import recovered_level
from wsp_env.rig.traction import MU_C, TORQUE_NM, run_traction, seed002_rail


def main() -> None:
    veh = load_vehicle("e402b")
    sim = TrainSim(veh, 1)
    sim.configure(0, RunSetup(speed_kmh=20.0, rail=seed002_rail(), mu_contaminated=MU_C))
    sim.reset([0])
    sim.env_par[0, L.EP_EXT_TORQUE] = 1.0
    sim.axle_state[0, :, L.AS_EXT_TORQUE] = TORQUE_NM
    sim.step()
    ep, k = sim.env_par, 1
    k_n = sim.axle_state[0, k, L.AS_STIFF]
    level = sim.axle_state[0, k, L.AS_MU_LEVEL]
    demand = TORQUE_NM / veh.wheel_radius_m / sim.axle_par[0, k, L.AP_N_STATIC]
    print(f"torque asks mu {demand:.4f} of the static axle load")
    for v_kmh in (10.0, 30.0, 60.0):
        xi, mu = peak_adhesion(
            int(ep[0, L.EP_LAW]), level, recovered_level(ep, 0, level, 1.0), 0.0, k_n,
            1.0 / k_n, v_kmh / 3.6, ep[0, L.EP_LP0], ep[0, L.EP_LP1], ep[0, L.EP_LP2],
            ep[0, L.EP_LP3],
        )  # fmt: skip
        slip = xi * v_kmh
        print(f"{v_kmh:4.0f} km/h: peak at creep {xi:.4f} ({slip:.2f} km/h of slip), mu {mu:.4f}")
    base = seed002_rail()
    variants = {
        "as modelled": base,
        "no cleaning": dataclasses.replace(
            base, clean_energy_J_per_m=float("inf"), pass_removal=0.0
        ),
        "mu_clean 0.12": dataclasses.replace(base, mu_clean=0.12),
    }
    for name, rail in variants.items():
        r = run_traction(rail=rail).summary
        slide = " / ".join(f"{x:.2f}" for x in np.asarray(r["mean_sliding_kmh"]))
        print(f"{name:14s} {r['distance_m']:.1f} m, mean sliding {slide} km/h")


if __name__ == "__main__":
    main()

"""Stopping distance against the physics substep: 1, 2 and 4 ms vs a 0.1 ms reference.

.venv/bin/python scripts/substep_study.py [--markdown docs/results/substep_study.md]

``--markdown P`` also writes the printed figures there, with the command and the machine above.
"""

from __future__ import annotations

import argparse

import numpy as np
from _results_md import printed_results

from wsp_env.core.config import load_rail, load_vehicle
from wsp_env.core.simulator import RunSetup, TrainSim


def pulse(n: int) -> np.ndarray:
    """A crude WSP: vent alternate axles for 0.3 s every 1.2 s."""
    c = np.ones((1, 4))
    if (n * 0.02) % 1.2 < 0.3:
        c[0, (int(n * 0.02 / 1.2) % 2) :: 2] = 0.0
    return c


def stop_distance(rail: str, dt: float, cmd) -> float:
    sim = TrainSim(load_vehicle("uic_z1"), 1, dt_s=dt)
    sim.configure(0, RunSetup(120.0, load_rail(rail)))
    sim.reset()
    n = 0
    while not sim.stopped[0]:
        sim.step(None if cmd is None else cmd(n))
        n += 1
    return float(sim.position_m[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", default=None, help="also write the figures here")
    args = ap.parse_args()
    printed_results(args.markdown, "Stopping distance against the physics substep", study)


def study() -> None:
    rand = np.random.default_rng(5).uniform(0, 1, size=(20000, 1, 4)) ** 0.5
    cases = [("soap", None, "no WSP"), ("soap", pulse, "pulsed"), ("leaves", pulse, "pulsed"),
             ("wet", pulse, "pulsed"), ("soap", lambda n: rand[n], "random"),
             ("oil", lambda n: rand[n], "random")]  # fmt: skip
    for rail, cmd, label in cases:
        ref = stop_distance(rail, 1e-4, cmd)
        cells = [f"{rail:7s} {label:7s} 0.1 ms {ref:8.2f} m"]
        for dt in (1e-3, 2e-3, 4e-3):
            d = stop_distance(rail, dt, cmd)
            cells.append(f"{dt * 1e3:.0f} ms {100 * (d / ref - 1):+.3f}%")
        print("  ".join(cells))


if __name__ == "__main__":
    main()

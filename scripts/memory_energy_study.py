"""The memory features' sliding-energy estimate against each axle's true sliding energy.

.venv/bin/python scripts/memory_energy_study.py [--markdown docs/results/memory_energy_study.md]

Soap 0.05, 0.06, 0.07 and 0.08 at 60, 120 and 160 km/h, four seeds each, under three
controllers (the classical WSP; a constant 4 km/h slip target; locked wheels, ``none``) and two
sensor sets (the environment's default ideal sensors; the benchmark's wheel-sensor tier, noise,
0.02 km/h resolution and +-0.5 % scale errors, ``envs.tiers.TIER_SENSORS``): the ratio of the
estimate at each stop's end (``BrakingCore.memory_energy_J``, unclipped) to the axle's true
sliding energy (``info["metrics"]["axles"][i]["sliding_energy_kJ"]``), least-greatest (median)
over the 48 stops' axles. Beside the environment's estimate (``env``), two variants computed
here period by period from the same readings, to see whether they would pay: ``inertia``
subtracts the wheelset's inertial term from the force at the rail (``F_i - J a_i / r^2``,
``a_i`` the measured wheel deceleration, floored at 0), ``band`` counts only the measured slip
above ``2 e v_ref``, the largest slip the sensors' scale errors ``+-e`` make of wheels that all
roll at the train's speed (0 with ideal sensors), and ``both``. The script checks that its
own ``env`` column is the environment's estimate.

``--markdown P`` also writes the printed figures there, with the command and the machine above.
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import Any

import numpy as np
from _results_md import printed_results

from wsp_env.envs import make_core
from wsp_env.envs.tiers import TIER_SENSORS
from wsp_env.physics import layout as L
from wsp_env.physics.brake import PAD_FACTOR_MIN
from wsp_env.policy import make_policy

SEEDS = (0, 1, 2, 3)
SPEEDS_KMH = (60.0, 120.0, 160.0)
MUS = (0.05, 0.06, 0.07, 0.08)
VARIANTS = ("env", "inertia", "band", "both")


def ratios(controller: str, sensors: dict[str, Any] | None) -> dict[str, list[float]]:
    """Every axle's estimate / true sliding energy, per variant, over the stops."""
    out: dict[str, list[float]] = {v: [] for v in VARIANTS}
    n = len(SEEDS)
    kw: dict[str, Any] = {"memory_features": True, "sensors": sensors}
    if controller == "target 4 km/h":
        kw["action_mode"] = "slip_target"
    for speed in SPEEDS_KMH:
        for mu in MUS:
            core = make_core(n, **kw)
            opts = {"rail": "soap", "mu_contaminated": mu, "speed_kmh": speed}
            for e, seed in enumerate(SEEDS):
                core.reset_env(e, {**opts, "pattern": "uniform"}, seed=seed)
            policy = None
            if controller in ("classical", "none"):
                policy = make_policy(controller)
                policy.bind(core)
                policy.reset(np.arange(n))
            # the default 0.5-8 km/h range: 4 km/h
            action = np.full((n, core.n_valves), 2.0 * 3.5 / 7.5 - 1.0)
            for row in _stops(core, policy, action):
                for v in VARIANTS:
                    out[v].extend(row[v].tolist())
    return out


def _stops(core: Any, policy: Any, action: np.ndarray) -> list[dict[str, np.ndarray]]:
    """Step every stop to its end (held there), the variants accumulated period by period."""
    sim, dt, n = core.sim, core.sim.control_period_s, core.n_envs
    scale_error = core.sensors.wheel_speed_scale_error
    est = {v: np.zeros((n, core.n_axles)) for v in VARIANTS}
    live = np.ones(n, dtype=bool)
    result: list[dict[str, np.ndarray]] = [{} for _ in range(n)]
    prev_wheel = core.measured_wheel_speed_mps.copy()
    while live.any():
        a = policy.act(core.obs) if policy is not None else action
        core.step(core.check_actions(a))
        v_ref = core.reference_speed_mps
        wheel = core.measured_wheel_speed_mps
        slip = v_ref[:, None] - wheel
        env_par, axle_par = sim.env_par, sim.axle_par
        pad = np.maximum(
            PAD_FACTOR_MIN, 1.0 + env_par[:, L.EP_PAD_SLOPE] * (v_ref - env_par[:, L.EP_PAD_VREF])
        )
        radius = axle_par[:, :, L.AP_RADIUS]
        pressure = sim.axle_state[:, :, L.AS_P]
        force = (
            axle_par[:, :, L.AP_BRAKE_GAIN]
            * np.maximum(pressure - axle_par[:, :, L.AP_P_THRESH], 0.0)
            * pad[:, None]
            / radius
        )
        decel = (prev_wheel - wheel) / dt
        prev_wheel = wheel.copy()
        rail_force = np.maximum(force - axle_par[:, :, L.AP_INERTIA] * decel / radius**2, 0.0)
        beyond = np.maximum(slip - 2.0 * scale_error * v_ref[:, None], 0.0)
        slid = np.maximum(slip, 0.0)
        for v, f, s in (("env", force, slid), ("inertia", rail_force, slid),
                        ("band", force, beyond), ("both", rail_force, beyond)):  # fmt: skip
            est[v][live] += (f * s * dt)[live]
        np.testing.assert_allclose(est["env"][live], core.memory_energy_J[live], rtol=1e-9)
        for e in np.flatnonzero(live & core.ended()):
            axles = core.episode_info(int(e))["axles"]
            true_J = np.array([ax["sliding_energy_kJ"] for ax in axles]) * 1e3
            result[e] = {v: est[v][e] / true_J for v in VARIANTS}
            core.freeze(int(e))
            live[e] = False
    return result


def study() -> None:
    sensor_sets = {"ideal": None, "wheels": dataclasses.asdict(TIER_SENSORS["wheels"])}
    print("| sensors | controller | " + " | ".join(VARIANTS) + " |")
    print("|---|---|" + "---|" * len(VARIANTS))
    for name, sensors in sensor_sets.items():
        for controller in ("classical", "target 4 km/h", "none"):
            got = ratios(controller, sensors)
            cells = [
                f"{min(got[v]):.2f}-{max(got[v]):.2f} ({np.median(got[v]):.2f})" for v in VARIANTS
            ]
            print(f"| {name} | {controller} | " + " | ".join(cells) + " |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", default=None, help="also write the figures here")
    args = ap.parse_args()
    printed_results(args.markdown, "The sliding-energy estimate of the memory features", study)


if __name__ == "__main__":
    main()

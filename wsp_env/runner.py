"""Run one braking stop on ``TrainSim`` with a fixed valve policy, recording it like a logger.

Used by ``wsp-env simulate``. The policy here is the physics-level one: ``none`` keeps every
valve in *apply* (full demand, no WSP). Learned and classical WSP policies act through the
Gymnasium environment instead.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wsp_env.config import VehicleConfig
from wsp_env.metrics import run_metrics
from wsp_env.physics import layout as L
from wsp_env.simulator import RunSetup, TrainSim, VehicleArrays
from wsp_env.trace_io import RunRecord

PHYSICS_POLICIES = ("none",)


def run_stop(
    vehicle: VehicleConfig,
    setup: RunSetup,
    policy: str = "none",
    max_time_s: float = 600.0,
    dt_s: float = 1e-3,
) -> tuple[dict[str, Any], RunRecord]:
    """Brake from ``setup.speed_kmh`` to standstill; return (metrics, record at 20 ms)."""
    if policy not in PHYSICS_POLICIES:
        raise ValueError(f"policy: {policy!r} is not a physics-level policy ({PHYSICS_POLICIES})")
    sim = TrainSim(vehicle, n_envs=1, dt_s=dt_s)
    sim.configure(0, setup)
    sim.reset()
    n_max = int(max_time_s / sim.control_period_s)
    rows_t, rows_v, rows_w, rows_p, rows_d, rows_a = [], [], [], [], [], []

    def record() -> None:
        rows_t.append(sim.time_s[0])
        rows_v.append(sim.speed_mps[0])
        rows_w.append(sim.wheel_speed_mps[0].copy())
        rows_p.append(sim.pressure_bar[0].copy())
        rows_d.append(sim.demand_bar()[0])
        rows_a.append(sim.env_state[0, L.ES_DECEL])

    record()
    for _ in range(n_max):
        sim.step()
        record()
        if sim.stopped[0]:
            break
    metrics = run_metrics(sim, 0)
    t = np.asarray(rows_t)
    keep = np.concatenate([[True], np.diff(t) > 1e-9])  # the stop step may be shorter
    p = np.asarray(rows_p)[keep]
    rec = RunRecord(
        time_s=t[keep],
        v_train_kmh=3.6 * np.asarray(rows_v)[keep],
        v_axle_kmh=3.6 * np.asarray(rows_w)[keep],
        p_cyl_bar=p,
        p_demand_bar=np.asarray(rows_d)[keep],
        a_train_mps2=np.asarray(rows_a)[keep],
        v_ref_kmh=None,
        wsp_active=p < np.asarray(rows_d)[keep][:, None] - 0.05,
    )
    return metrics, rec


def trace_metadata(
    vehicle: VehicleConfig, setup: RunSetup, rail_name: str, sample_period_s: float, test_id: str
) -> dict[str, Any]:
    """``*.meta.json`` of a simulated run: nominal vehicle data only (TRACE_FORMAT.md)."""
    sim_arrays = VehicleArrays.from_config(vehicle)
    gain, p_th = vehicle.brake.linear_torque()
    veh: dict[str, Any] = {
        "name": vehicle.name,
        "mass_kg": sim_arrays.body_mass_kg + sim_arrays.rest_mass_kg,
        "n_axles": vehicle.n_axles,
        "wheel_radius_m": vehicle.wheel_radius_m,
        "wheelset_inertia_kgm2": vehicle.wheelset_inertia_kgm2,
        "axle_static_load_kN": [round(x / 1e3, 3) for x in sim_arrays.load_ref_N],
        "brake": {
            "p_threshold_bar": p_th,
            "torque_gain_Nm_per_bar": gain,
            "p_max_bar": vehicle.brake.p_max_bar,
        },
        # nominal running resistance (an optional field: documents give it, traces may not)
        "resistance": {
            "a_N": vehicle.resistance.a_N,
            "b_N_per_mps": vehicle.resistance.b_N_per_mps,
            "c_N_per_mps2": vehicle.resistance.c_N_per_mps2,
        },
    }
    if len(vehicle.cars) == 1:
        car, (b0, b1) = vehicle.cars[0], vehicle.bogies
        veh["cog_height_m"] = car.cog_height_m
        veh["bogie_centre_distance_m"] = b1.position_m - b0.position_m
        veh["bogie_wheelbase_m"] = b0.wheelbase_m
    contaminant = rail_name if rail_name in ("dry", "wet", "soap", "oil", "leaves") else "unknown"
    return {
        "format": "wsp-trace/1",
        "test_id": test_id,
        "sample_period_s": sample_period_s,
        "initial_speed_kmh": setup.speed_kmh,
        "contaminant": contaminant,
        "brake_type": "emergency" if setup.demand_fraction >= 1.0 else "service",
        "vehicle": veh,
    }

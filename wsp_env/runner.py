"""Run one braking stop with any policy, recording it like a logger, and describe it as a trace.

``run_one`` is a one-run suite on the evaluation's code path (``evaluation.run_suite``): the same
environment core, policy interface and metrics as ``wsp-env evaluate``. Used by
``wsp-env simulate`` and the calibration's synthetic traces.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wsp_env.config import VehicleConfig
from wsp_env.evaluation import CaseConfig, SuiteConfig, run_suite
from wsp_env.simulator import VehicleArrays
from wsp_env.trace_io import CONTAMINANTS, RunRecord

# nothing drawn but the rail's adhesion level and pattern: nominal load, pads and level track
NOMINAL_SCENARIO = {"load_factor": [1.0, 1.0], "pad_factor": [1.0, 1.0],
                    "gradient_permille": [0.0, 0.0]}  # fmt: skip


def run_one(
    vehicle: str | VehicleConfig,
    rail_name: str,
    speed_kmh: float,
    policy: Any,
    seed: int,
    case: dict[str, Any] | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> tuple[dict[str, Any], RunRecord]:
    """One stop from ``speed_kmh`` on rail ``rail_name`` with ``policy`` (``policy.make_policy``).

    ``seed`` draws what ``case`` (``evaluation.CaseConfig`` fields: ``mu_contaminated``,
    ``pattern``, ``demand``, ...) leaves open; load, pads and gradient are nominal unless
    ``env_kwargs["scenario"]`` says otherwise. Returns the evaluation's run result (metrics,
    ``conditions``) and the record at the control period.
    """
    suite = SuiteConfig(
        name="one",
        description="",
        seeds=(seed,),
        cases=(
            CaseConfig(name="run", rail=rail_name, speeds_kmh=(str(speed_kmh),), **(case or {})),
        ),
    )
    kwargs = dict(env_kwargs or {})
    kwargs["scenario"] = {
        "rails": {rail_name: 1.0},
        **NOMINAL_SCENARIO,
        **kwargs.get("scenario", {}),
    }
    results, records = run_suite(vehicle, suite, policy, record="all", env_kwargs=kwargs)
    return results[0], next(iter(records.values()))


def trace_metadata(
    vehicle: VehicleConfig,
    conditions: dict[str, Any],
    contaminant: str,
    sample_period_s: float,
    test_id: str,
) -> dict[str, Any]:
    """``*.meta.json`` of a simulated run (``conditions``: a run result's, for the initial
    speed and the demand; ``contaminant``: the trace format's name, ``RailConfig.
    contaminant_name``): nominal vehicle data only (docs/trace_format.md)."""
    sim_arrays = VehicleArrays.from_config(vehicle)
    gain, p_th = vehicle.brake.linear_torque()
    veh: dict[str, Any] = {
        "name": vehicle.name,
        "mass_kg": sim_arrays.body_mass_kg + sim_arrays.rest_mass_kg,
        "n_axles": vehicle.n_axles,
        "wheel_radius_m": vehicle.wheel_radius_m,
        "wheelset_inertia_kgm2": vehicle.wheelset_inertia_kgm2,
        "axle_static_load_kN": [round(x / 1e3, 3) for x in sim_arrays.load_ref_N],
        # optional (docs/trace_format.md): the quasi-static load transfer per axle that the
        # vehicle's documents (its config: pivot and frame heights) give, body and bogie pitch
        # together; calibration reads it when present
        "axle_load_transfer_kN_per_mps2": [
            round(x / 1e3, 4) for x in sim_arrays.transfer_body + sim_arrays.transfer_rest
        ],
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
    if not np.allclose(sim_arrays.brake_gain, gain):
        # optional (docs/trace_format.md): per-axle torque gains where they differ, e.g. motor
        # axles whose ED brake is blended with the friction brake
        veh["brake"]["axle_torque_gain_Nm_per_bar"] = [
            round(float(g), 3) for g in sim_arrays.brake_gain
        ]
    if len(vehicle.cars) == 1:
        car, (b0, b1) = vehicle.cars[0], vehicle.bogies
        veh["cog_height_m"] = car.cog_height_m
        veh["bogie_centre_distance_m"] = b1.position_m - b0.position_m
        veh["bogie_wheelbase_m"] = b0.wheelbase_m
    if contaminant not in CONTAMINANTS:
        raise ValueError(f"contaminant: {contaminant!r} is not one of {', '.join(CONTAMINANTS)}")
    return {
        "format": "wsp-trace/1",
        "test_id": test_id,
        "sample_period_s": sample_period_s,
        "initial_speed_kmh": conditions["speed_kmh"],
        "contaminant": contaminant,
        "brake_type": "emergency" if conditions["demand_fraction"] >= 1.0 else "service",
        "vehicle": veh,
    }

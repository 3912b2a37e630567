"""Synthetic braking traces from the simulator, logged like a real test (``wsp-trace/1``).

``simulate_trace`` runs one stop with a policy in the loop (the classical WSP by default),
samples it like a logger (``evaluation.trace_writer.SensorModel``) and writes only *nominal*
vehicle data in the metadata — whatever the simulation did differently (a rail condition, a
gradient, a changed vehicle) stays undeclared, as in measured data.

The WSP in the loop reads the shared reference-speed estimator as it was until the benchmark's
``-v3`` (``SYNTHETIC_ESTIMATOR``: the spin-up test on one reading, no accelerometer offset
learned). A measured train's WSP is whatever its maker built; fixing this one keeps the data
the calibration's tests and its power study were measured on from moving whenever the
benchmark's estimator does. Under the ``-v3`` estimator the wheels slide elsewhere, and three
of those tests' margins break (docs/calibration.md, "Measured on synthetic traces"): pass
``estimator=None`` for the environment's own.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from wsp_env.core.config import RailConfig, VehicleConfig, load_vehicle
from wsp_env.envs.tiers import ESTIMATOR_BEFORE_V3
from wsp_env.evaluation.runner import run_one, trace_metadata
from wsp_env.evaluation.trace_writer import SensorModel, sample_run, write_trace
from wsp_env.policy import make_policy

# the synthetic train's WSP estimator (module docstring): -v2's
SYNTHETIC_ESTIMATOR: dict[str, Any] = dict(ESTIMATOR_BEFORE_V3)


def simulate_trace(
    stem: str | Path,
    rail: RailConfig,
    speed_kmh: float,
    vehicle: str | VehicleConfig = "uic_z1",
    policy: str = "classical",
    wsp_config: str | None = None,
    sensors: SensorModel | None = None,
    seed: int = 0,
    contaminant: str = "unknown",
    wheel_radius_error: tuple[float, ...] | None = None,
    pad_factor: float = 1.0,
    coast_s: float = 3.0,
    resistance_scale: float = 1.0,
    height_scale: float = 1.0,
    pressure_lag_s: float = 0.0,
    speed_scale_error: float = 0.0,
    speed_lag_s: float = 0.0,
    speed_ripple_kmh: float = 0.0,
    return_record: bool = False,
    estimator: dict[str, Any] | None = SYNTHETIC_ESTIMATOR,
    **case: Any,
) -> Any:
    """Simulate, sample and write ``STEM.csv`` + ``STEM.meta.json``; return paths and metrics.

    ``case`` fixes further scenario fields (``mu_contaminated``, ``pattern``,
    ``gradient_permille``, ``axle_mu_factor``, ...; see ``evaluation.CaseConfig``).
    ``wheel_radius_error``: per axle, the true radius's relative excess over the nominal one
    (applied to the logged axle speeds, which the logger computes with the nominal radius).
    ``pad_factor``: true / nominal pad friction. ``coast_s``: coasting before the demand rises.
    ``resistance_scale``: true / nominal running resistance. ``height_scale``: true / nominal
    CoG and pivot heights (load transfer). ``pressure_lag_s``: the brake force lags the logged
    pressure. ``speed_scale_error`` / ``speed_lag_s``: the ground-speed sensor's scale error and
    lag. ``return_record``: also return the simulator's own record of the stop (the truth the
    trace was sampled from, adhesion forces included) as a fourth item. ``estimator``: the
    WSP's reference-speed estimator (``EstimatorConfig`` fields; module docstring; None: the
    environment's default).
    """
    nominal = vehicle if isinstance(vehicle, VehicleConfig) else load_vehicle(vehicle)
    veh = nominal
    # a coasting lead-in before the brake acts, as test logs have (coasting-creep channel)
    res = veh.resistance
    veh = dataclasses.replace(
        veh,
        brake=dataclasses.replace(veh.brake, demand_delay_s=veh.brake.demand_delay_s + coast_s),
        resistance=dataclasses.replace(
            res,
            a_N=res.a_N * resistance_scale,
            b_N_per_mps=res.b_N_per_mps * resistance_scale,
            c_N_per_mps2=res.c_N_per_mps2 * resistance_scale,
        ),
        cars=tuple(
            dataclasses.replace(c, cog_height_m=c.cog_height_m * height_scale) for c in veh.cars
        ),
        bogies=tuple(
            dataclasses.replace(
                b,
                pivot_height_m=b.pivot_height_m * height_scale,
                frame_cog_height_m=b.frame_cog_height_m * height_scale,
            )
            for b in veh.bogies
        ),
    )
    # nominal everything except what the caller injects
    env_kwargs = {
        "extra_rails": {"_synthetic": rail},
        "scenario": {"pad_factor": [pad_factor] * 2},
        "estimator": None if estimator is None else dict(estimator),
    }
    result, record = run_one(
        veh, "_synthetic", speed_kmh, make_policy(policy, wsp_config), seed, case, env_kwargs
    )
    truth = record
    t = record.time_s
    if pressure_lag_s:  # the brake force follows the logged pressure pressure_lag_s later
        lead = np.stack([np.interp(t + pressure_lag_s, t, p) for p in record.p_cyl_bar.T], axis=1)
        record = dataclasses.replace(record, p_cyl_bar=lead)
    if speed_ripple_kmh:  # outside the effect library: a periodic ground-speed error (7 s)
        ripple = speed_ripple_kmh * np.sin(2.0 * np.pi * t / 7.0)
        record = dataclasses.replace(record, v_train_kmh=record.v_train_kmh + ripple)
    if speed_lag_s:  # the ground-speed reading trails the train by speed_lag_s
        record = dataclasses.replace(
            record, v_train_kmh=np.interp(t - speed_lag_s, t, record.v_train_kmh)
        )
    if speed_scale_error:  # ground-speed sensor reads (1 + error) times the true speed
        record = dataclasses.replace(
            record, v_train_kmh=record.v_train_kmh * (1 + speed_scale_error)
        )
    columns = sample_run(record, sensors or SensorModel(), np.random.default_rng([seed, 7]))
    if wheel_radius_error is not None:
        # a wheel larger than nominal by e turns slower: the logger's omega * r_nominal reads low
        for i, err in enumerate(wheel_radius_error, start=1):
            columns[f"v_axle_{i}_kmh"] = columns[f"v_axle_{i}_kmh"] / (1.0 + err)
    meta = trace_metadata(
        nominal, result["conditions"], contaminant, (sensors or SensorModel()).sample_period_s,
        f"synthetic {nominal.id} {speed_kmh:g} km/h seed {seed}",
    )  # fmt: skip
    csv_path, meta_path = write_trace(stem, columns, meta)
    if return_record:
        return csv_path, meta_path, result, truth
    return csv_path, meta_path, result

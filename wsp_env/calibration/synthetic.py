"""Synthetic braking traces from the simulator, logged like a real test (``wsp-trace/1``).

``simulate_trace`` runs one stop with a policy in the loop (the classical WSP by default),
samples it like a logger (``trace_io.SensorModel``) and writes only *nominal* vehicle data in
the metadata — whatever the simulation did differently (a rail condition, a gradient, a changed
vehicle) stays undeclared, as in measured data.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from wsp_env.config import RailConfig, load_vehicle
from wsp_env.evaluation import CaseConfig, SuiteConfig, run_suite
from wsp_env.policy import make_policy
from wsp_env.runner import trace_metadata
from wsp_env.simulator import RunSetup
from wsp_env.trace_io import SensorModel, sample_run, write_trace


def simulate_trace(
    stem: str | Path,
    rail: RailConfig,
    speed_kmh: float,
    vehicle: str = "uic_z1",
    policy: str = "classical",
    sensors: SensorModel | None = None,
    seed: int = 0,
    contaminant: str = "unknown",
    wheel_radius_error: tuple[float, ...] | None = None,
    pad_factor: float = 1.0,
    coast_s: float = 3.0,
    **case: Any,
) -> tuple[Path, Path, dict[str, Any]]:
    """Simulate, sample and write ``STEM.csv`` + ``STEM.meta.json``; return paths and metrics.

    ``case`` fixes further scenario fields (``mu_contaminated``, ``pattern``,
    ``gradient_permille``, ``axle_mu_factor``, ...; see ``evaluation.CaseConfig``).
    ``wheel_radius_error``: per axle, the true radius's relative excess over the nominal one
    (applied to the logged axle speeds, which the logger computes with the nominal radius).
    ``pad_factor``: true / nominal pad friction. ``coast_s``: coasting before the demand rises.
    """
    suite = SuiteConfig(
        name="synthetic",
        description="",
        seeds=(seed,),
        cases=(CaseConfig(name="trace", rail="_synthetic", speeds_kmh=(str(speed_kmh),), **case),),
    )
    veh = load_vehicle(vehicle)
    # a coasting lead-in before the brake acts, as test logs have (coasting-creep channel)
    veh = dataclasses.replace(
        veh, brake=dataclasses.replace(veh.brake, demand_delay_s=veh.brake.demand_delay_s + coast_s)
    )
    # nominal everything except what the caller injects: no random load, pad or gradient
    scenario = {"load_factor": [1.0, 1.0], "pad_factor": [pad_factor, pad_factor],
                "gradient_permille": [0.0, 0.0]}  # fmt: skip
    env_kwargs = {"extra_rails": {"_synthetic": rail}, "scenario": scenario}
    results, records = run_suite(
        veh, suite, make_policy(policy), record="all", env_kwargs=env_kwargs
    )
    record = next(iter(records.values()))
    columns = sample_run(record, sensors or SensorModel(), np.random.default_rng([seed, 7]))
    if wheel_radius_error is not None:
        # a wheel larger than nominal by e turns slower: the logger's omega * r_nominal reads low
        for i, err in enumerate(wheel_radius_error, start=1):
            columns[f"v_axle_{i}_kmh"] = columns[f"v_axle_{i}_kmh"] / (1.0 + err)
    meta = trace_metadata(
        veh, RunSetup(speed_kmh, rail), contaminant, (sensors or SensorModel()).sample_period_s,
        f"synthetic {vehicle} {speed_kmh:g} km/h seed {seed}",
    )  # fmt: skip
    csv_path, meta_path = write_trace(stem, columns, meta)
    return csv_path, meta_path, results[0]

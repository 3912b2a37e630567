"""Synthetic braking traces from the simulator, logged like a real test (``wsp-trace/1``).

``simulate_trace`` runs one stop with a policy in the loop (the classical WSP by default),
samples it like a logger (``trace_io.SensorModel``) and writes only *nominal* vehicle data in
the metadata — whatever the simulation did differently (a rail condition, a gradient, a changed
vehicle) stays undeclared, as in measured data.
"""

from __future__ import annotations

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
    **case: Any,
) -> tuple[Path, Path, dict[str, Any]]:
    """Simulate, sample and write ``STEM.csv`` + ``STEM.meta.json``; return paths and metrics.

    ``case`` fixes further scenario fields (``mu_contaminated``, ``pattern``,
    ``gradient_permille``, ``axle_mu_factor``, ...; see ``evaluation.CaseConfig``).
    """
    suite = SuiteConfig(
        name="synthetic",
        description="",
        seeds=(seed,),
        cases=(CaseConfig(name="trace", rail="_synthetic", speeds_kmh=(str(speed_kmh),), **case),),
    )
    results, records = run_suite(
        vehicle,
        suite,
        make_policy(policy),
        record="all",
        env_kwargs={"extra_rails": {"_synthetic": rail}},
    )
    record = next(iter(records.values()))
    columns = sample_run(record, sensors or SensorModel(), np.random.default_rng([seed, 7]))
    veh = load_vehicle(vehicle)
    meta = trace_metadata(
        veh, RunSetup(speed_kmh, rail), contaminant, (sensors or SensorModel()).sample_period_s,
        f"synthetic {vehicle} {speed_kmh:g} km/h seed {seed}",
    )  # fmt: skip
    csv_path, meta_path = write_trace(stem, columns, meta)
    return csv_path, meta_path, results[0]

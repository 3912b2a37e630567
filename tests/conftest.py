"""Shared helpers: small configs built from the shipped ones."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wsp_env.core.config import load_rail, load_vehicle
from wsp_env.core.simulator import RunSetup, TrainSim


def instant_brake(vehicle_id: str = "uic_z1", resistance: bool = False):
    """A vehicle whose cylinders follow the demand instantly and whose demand is a step."""
    veh = load_vehicle(vehicle_id)
    brake = dataclasses.replace(
        veh.brake,
        fill_tau_s=0.0,
        fill_rate_bar_per_s=1e9,
        demand_delay_s=0.0,
        demand_rise_s=0.0,
        valve_dead_time_s=0.0,
    )
    res = (
        veh.resistance
        if resistance
        else dataclasses.replace(veh.resistance, a_N=0.0, b_N_per_mps=0.0, c_N_per_mps2=0.0)
    )
    return dataclasses.replace(veh, brake=brake, resistance=res)


def run_to_stop(sim: TrainSim, cmd_fn=None, max_steps: int = 40000) -> int:
    """Step until every run stopped; ``cmd_fn(step, sim)`` gives valve commands (or None)."""
    for n in range(max_steps):
        sim.step(None if cmd_fn is None else cmd_fn(n, sim))
        if sim.stopped.all():
            return n + 1
    raise AssertionError("runs did not stop")


def single(vehicle, rail: str | object, speed_kmh: float = 120.0, dt_s: float = 1e-3, **setup):
    sim = TrainSim(vehicle, n_envs=1, dt_s=dt_s)
    rail_cfg = load_rail(rail) if isinstance(rail, str) else rail
    sim.configure(0, RunSetup(speed_kmh, rail_cfg, **setup))
    sim.reset()
    return sim


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


@pytest.fixture(scope="session")
def local_ray():
    """One local Ray for the tests that split work across workers (each command would
    otherwise start and stop its own: seconds each); ``ray_session`` uses it as it is. A test
    that must start or attach its own shuts it down first (``test_sweep``'s attach test)."""
    import logging
    import os

    ray = pytest.importorskip("ray")
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    if not ray.is_initialized():
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
                 logging_level=logging.ERROR)  # fmt: skip
    yield ray
    ray.shutdown()


def independent_run(tmp_path, seed, effects=(), edit=None, **overrides):
    """A trace of the independent generator (``calibration.independent``), written and read
    back: the scenario of ``seed`` with ``overrides`` (``edit(scenario)`` applied after the
    draw, before the effects'), its ``effects`` ``(category, magnitude)``. Returns the trace,
    the scenario, the effects and the generator's columns."""
    from wsp_env.calibration import independent as ind
    from wsp_env.calibration.traces import read_trace

    rng = np.random.default_rng(seed)
    scenario = ind.random_scenario(rng, **overrides)
    if edit is not None:
        scenario = edit(scenario)
    effs = [ind.random_effect(c, m, rng, scenario) for c, m in effects]
    columns, meta = ind.generate(scenario, effs, seed=seed)
    csv_path, _ = ind.write_trace(tmp_path / f"t{seed}", columns, meta)
    return read_trace(csv_path), scenario, effs, columns


def independent_trace(tmp_path, seed, effects=(), **overrides):
    """``independent_run`` without the scenario: the trace, the effects, the columns."""
    trace, _, effs, columns = independent_run(tmp_path, seed, effects, **overrides)
    return trace, effs, columns


def script(name: str):
    """The module ``scripts/NAME.py`` (the scripts are no package)."""
    import importlib
    import sys
    from pathlib import Path

    scripts = str(Path(__file__).resolve().parents[1] / "scripts")
    sys.path.insert(0, scripts)
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(scripts)

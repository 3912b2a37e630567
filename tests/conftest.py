"""Shared helpers: small configs built from the shipped ones."""

from __future__ import annotations

import dataclasses
import os
from collections import Counter

import numpy as np
import pytest

from wsp_env.core.config import load_rail, load_vehicle
from wsp_env.core.simulator import RunSetup, TrainSim
from wsp_env.threads import ENV_CORES, available_cores

# Under pytest-xdist (`make test` runs one worker a core) each worker gets its share of the
# cores, so the thread policy (wsp_env.threads) of each sizes numba's and torch's threads to
# it and the workers do not oversubscribe the machine; a WSP_CORES already set is kept.
if os.environ.get("PYTEST_XDIST_WORKER_COUNT") and ENV_CORES not in os.environ:
    _workers = int(os.environ["PYTEST_XDIST_WORKER_COUNT"])
    os.environ[ENV_CORES] = str(max(1, available_cores() // _workers))


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


def cached_signatures(fn) -> list:
    """The signatures numba's on-disk cache holds for the compiled function ``fn`` on this
    machine's CPU (every process's compiles since the kernels' sources last changed;
    ``fn.signatures`` lists only what this process compiled or loaded itself, and nothing for a
    callee compiled into its caller). Numba's own index, read through its cache object (a
    private API: the test is skipped with a reason where this numba lacks it)."""
    try:
        index = fn._cache._cache_file._load_index()
        magic = fn.targetctx.codegen().magic_tuple()
    except AttributeError as err:
        pytest.skip(f"numba's cache index is not readable here: {err}")
    return [key[0] for key in index if key[1] == magic]


def compiled_once_for_int64(fn) -> None:
    """``fn`` (whose first argument is an environment index) is in the cache, and only for an
    ``int64`` index: no ``uint64`` (a ``prange`` index) or literal specialisation of its call
    tree, each of which compiles the whole of it again."""
    sigs = cached_signatures(fn)
    assert sigs, f"{fn.__name__}: nothing cached"
    assert all(str(sig[0]) == "int64" for sig in sigs), (fn.__name__, [str(s[0]) for s in sigs])


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


@pytest.fixture(scope="module")
def ray_exclusive(tmp_path_factory):
    """One test module at a time uses Ray on this machine: ``ray stop --force`` (the attach
    test's clean-up) stops every Ray here, and a process whose Ray is stopped under it exits.
    A lock file beside the workers' temporary folders (pytest-xdist's workers share that
    parent) is held for the module (without xdist: the lock that every plain pytest run of
    this user shares)."""
    import fcntl

    lock = tmp_path_factory.getbasetemp().parent / "ray.lock"
    with open(lock, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@pytest.fixture(scope="module")
def local_ray(ray_exclusive):
    """One local Ray for a module's tests that split work across workers (each command would
    otherwise start and stop its own: seconds each); ``ray_session`` uses it as it is. A test
    that must start or attach its own shuts it down first (``test_sweep``'s attach test)."""
    import logging

    ray = pytest.importorskip("ray")
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    if not ray.is_initialized():
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
                 logging_level=logging.ERROR)  # fmt: skip
    yield ray
    ray.shutdown()


def pytest_collection_modifyitems(config, items):
    """Modules in an order that keeps pytest-xdist's workers busy to the end (`make test`:
    ``--dist loadfile --no-loadscope-reorder``, whole modules in this order): the modules with
    a ``wheel`` test (minutes each) first, so that one worker starts them while the others
    share the rest; then the modules with the most tests first (xdist's own reordering), so
    that the suite ends on small ones. Within a module the order is kept."""
    slow = {item.path for item in items if item.get_closest_marker("wheel")}
    count = Counter(item.path for item in items)
    items.sort(key=lambda item: (item.path not in slow, -count[item.path], str(item.path)))


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

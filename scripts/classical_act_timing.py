"""Time one period of the classical WSP (``ClassicalWSP.act``, compiled) against the numpy array
version it replaced (``tests/test_classical_kernel.py``'s ``ArrayWSP``), in one run, on the same
observations: median microseconds per call and the ratio, for batches of 1, 8 and 300 envs.

    .venv/bin/python scripts/classical_act_timing.py
"""

from __future__ import annotations

import importlib.util
import platform
import time
from pathlib import Path

import numpy as np

from wsp_env.baselines.classical import ClassicalWSP, load_wsp_config
from wsp_env.envs import WSPBrakingVectorEnv

ROOT = Path(__file__).resolve().parents[1]
STOP = {"rail": "soap", "mu_contaminated": 0.08, "speed_kmh": 120.0, "pattern": "uniform"}


def _array_reference() -> type:
    spec = importlib.util.spec_from_file_location(
        "ref", ROOT / "tests" / "test_classical_kernel.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.ArrayWSP


def _median_us(policies: list, core, obs: list[np.ndarray], repeats: int) -> list[float]:
    """Median microseconds per call of each policy, the passes over ``obs`` interleaved (one
    policy's pass, then the next's) so that a change in the host's speed hits both alike."""
    for policy in policies:
        policy.bind(core)
        policy.reset(np.arange(core.n_envs))
    times: list[list[float]] = [[] for _ in policies]
    for _ in range(repeats):
        for policy, out in zip(policies, times, strict=True):
            for o in obs:
                t0 = time.perf_counter()
                policy.act(o)
                out.append(time.perf_counter() - t0)
    return [1e6 * float(np.median(t)) for t in times]


def main() -> None:
    array_wsp = _array_reference()
    print(f"{platform.machine()}, {platform.python_version()}; median us per call")
    print("| envs | compiled | numpy arrays | ratio |")
    print("|---|---|---|---|")
    for n in (1, 8, 300):
        env = WSPBrakingVectorEnv(num_envs=n)
        env.reset(seed=list(range(n)), options=STOP)
        core = env.core
        obs = []  # observations of a braking stop on soap, the classical WSP acting
        driver = ClassicalWSP(load_wsp_config())
        driver.bind(core)
        driver.reset(np.arange(n))
        for _ in range(500):
            obs.append(core.obs.copy())
            env.step(driver.act(core.obs))
        cfg = load_wsp_config()
        fast, slow = _median_us([ClassicalWSP(cfg), array_wsp(cfg)], core, obs, 5)
        print(f"| {n} | {fast:.1f} | {slow:.1f} | {slow / fast:.1f} |")


if __name__ == "__main__":
    main()

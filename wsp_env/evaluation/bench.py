"""``wsp-env bench``: environment throughput, with gymnasium's CartPole measured in the same run.

Figures are medians over ``repeats`` timed runs after a warm-up (compilation excluded). Single
env: ``gymnasium.make("WSPBraking-v0")`` with its default wrappers, random actions, resets
included. Vector env: the native vector entry point (one compiled call per step).
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

import wsp_env  # noqa: F401  (registers the environment)


def _median_rate(run: Callable[[], float], repeats: int) -> float:
    run()  # warm-up: compilation, caches
    return statistics.median(run() for _ in range(repeats))


def single_env_rate(env_id: str, n_steps: int, repeats: int, **kwargs: Any) -> float:
    """Steps per second of one environment through ``gymnasium.make``."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = [env.action_space.sample() for _ in range(min(n_steps, 4096))]
    if isinstance(env.action_space, gym.spaces.Box):
        actions = list(
            rng.uniform(-1, 1, size=(len(actions), *env.action_space.shape)).astype(np.float32)
        )

    def run() -> float:
        t0 = time.perf_counter()
        for i in range(n_steps):
            _, _, term, trunc, _ = env.step(actions[i % len(actions)])
            if term or trunc:
                env.reset()
        return n_steps / (time.perf_counter() - t0)

    return _median_rate(run, repeats)


def vector_env_rate(env_id: str, num_envs: int, n_steps: int, repeats: int, **kwargs: Any) -> float:
    """Environment-steps per second of the native vector environment."""
    venv = gym.make_vec(
        env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs
    )
    venv.reset(seed=0)
    rng = np.random.default_rng(0)
    space = venv.action_space
    if isinstance(space, gym.spaces.Box):
        actions = rng.uniform(-1, 1, size=(8, *space.shape)).astype(np.float32)
    else:
        actions = np.stack([space.sample() for _ in range(8)])

    def run() -> float:
        t0 = time.perf_counter()
        for i in range(n_steps):
            venv.step(actions[i % 8])
        return n_steps * num_envs / (time.perf_counter() - t0)

    return _median_rate(run, repeats)


def run_bench(quick: bool = False, repeats: int = 5) -> dict[str, Any]:
    """All figures of ``wsp-env bench`` (``quick``: tiny counts, for tests)."""
    scale = 0.02 if quick else 1.0
    n_single = max(200, int(20000 * scale))
    n_vec = max(5, int(200 * scale))
    n_vec_etr = max(5, int(100 * scale))
    result: dict[str, Any] = {
        "single_env_steps_per_s": single_env_rate("WSPBraking-v0", n_single, repeats),
        "vector_env_steps_per_s": vector_env_rate("WSPBraking-v0", 1024, n_vec, repeats),
        "vector_num_envs": 1024,
        "n_axles": 4,
        "vehicle": "uic_z1",
        "etr1000_vector_env_steps_per_s": vector_env_rate(
            "WSPBraking-v0", 256, n_vec_etr, repeats, vehicle="etr1000"
        ),
        "etr1000_vector_num_envs": 256,
        "etr1000_n_axles": 32,
        "cartpole_single_steps_per_s": single_env_rate("CartPole-v1", n_single * 4, repeats),
        "cartpole_vector_steps_per_s": vector_env_rate("CartPole-v1", 1024, n_vec * 5, repeats),
        "repeats": repeats,
        "statistic": "median",
        "quick": quick,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
    }
    result["single_ratio_to_cartpole"] = (
        result["single_env_steps_per_s"] / result["cartpole_single_steps_per_s"]
    )
    result["vector_ratio_to_cartpole"] = (
        result["vector_env_steps_per_s"] / result["cartpole_vector_steps_per_s"]
    )
    return result


def format_bench(r: dict[str, Any]) -> str:
    single, vec, etr = (
        r["single_env_steps_per_s"],
        r["vector_env_steps_per_s"],
        r["etr1000_vector_env_steps_per_s"],
    )
    cp_single, cp_vec = r["cartpole_single_steps_per_s"], r["cartpole_vector_steps_per_s"]
    return "\n".join(
        [
            f"single env (uic_z1, gymnasium.make):   {single:>12,.0f} steps/s"
            f"   ({r['single_ratio_to_cartpole']:.3f} x CartPole-v1 {cp_single:,.0f})",
            f"vector env (1024 x uic_z1, 4 axles):   {vec:>12,.0f} env-steps/s"
            f"   ({r['vector_ratio_to_cartpole']:.3f} x CartPole vector {cp_vec:,.0f})",
            f"vector env (256 x etr1000, 32 axles):  {etr:>12,.0f} env-steps/s",
            f"medians over {r['repeats']} runs{' (quick)' if r['quick'] else ''}",
        ]
    )

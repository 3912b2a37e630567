"""A stable-baselines3 ``VecEnv`` over the native ``WSPBrakingVectorEnv``.

SB3 has no adapter for Gymnasium's native vector environments (SB3 issue #1745), so training
would otherwise fall back to ``DummyVecEnv`` and step environments one by one in Python. This
adapter keeps the batched path: one compiled call per step for all environments. The vector env
autoresets in the same step, which is exactly SB3's convention: the returned observation already
belongs to the new episode and the last one goes to ``infos[i]["terminal_observation"]``.

At an episode's end ``infos[i]["episode"]`` carries ``{"r", "l", "t"}`` as ``VecMonitor`` writes
it (the undiscounted return of the environment's own reward, before any ``VecNormalize``; the
length in steps; seconds since the adapter was made), so SB3 logs episode statistics without a
``VecMonitor``. ``seed()`` and ``set_options()`` (SB3's ``VecEnv`` API: one seed for all, or
per-environment options) take effect at the next ``reset()``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from gymnasium.utils import seeding
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from wsp_env.envs import WSPBrakingVectorEnv


class SB3VecEnv(VecEnv):
    """Wrap ``WSPBrakingVectorEnv`` (or build one from its keyword arguments)."""

    def __init__(self, venv: WSPBrakingVectorEnv | None = None, **kwargs: Any) -> None:
        self.venv = venv if venv is not None else WSPBrakingVectorEnv(**kwargs)
        super().__init__(
            self.venv.num_envs, self.venv.single_observation_space, self.venv.single_action_space
        )
        self._actions: np.ndarray | None = None
        self._lengths = np.zeros(self.num_envs, dtype=np.int64)
        self._t0 = time.perf_counter()

    def reset(self) -> np.ndarray:
        """Start every environment anew, with the seeds of ``seed()`` and the options of
        ``set_options()`` if given (then forgotten, as SB3's own ``VecEnv`` does)."""
        seeds = list(self._seeds)
        options = [dict(o) if o else None for o in self._options]
        if all(o == options[0] for o in options):
            any_seed = any(x is not None for x in seeds)
            obs, _ = self.venv.reset(seed=seeds if any_seed else None, options=options[0])
        else:  # per-environment options: each env seeded and reset with its own
            core = self.venv.core
            for i, (seed, opts) in enumerate(zip(seeds, options, strict=True)):
                core.rngs[i] = seeding.np_random(seed)[0]
                core.reset_env(i, opts)
            obs = core.obs.copy()
        self._reset_seeds()
        self._reset_options()
        self._lengths[:] = 0
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        assert self._actions is not None, "step_async first"
        obs, rewards, terminated, truncated, info = self.venv.step(self._actions)
        dones = terminated | truncated
        self._lengths += 1
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if dones.any():
            elapsed = round(time.perf_counter() - self._t0, 6)
            for i in np.flatnonzero(dones):
                final = info["final_info"][i]
                infos[i] = {
                    "terminal_observation": info["final_obs"][i],
                    "TimeLimit.truncated": bool(truncated[i] and not terminated[i]),
                    **final,
                    "episode": {
                        "r": float(final["metrics"]["episode_return"]),
                        "l": int(self._lengths[i]),
                        "t": elapsed,
                    },
                }
                self._lengths[i] = 0
        return obs, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.venv, attr_name)] * len(self._indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *args: Any, indices: Any = None, **kwargs: Any) -> list:
        return [getattr(self.venv, method_name)(*args, **kwargs)] * len(self._indices(indices))

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * len(self._indices(indices))

    def _indices(self, indices: Any) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)

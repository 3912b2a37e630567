"""A stable-baselines3 ``VecEnv`` over the native ``WSPBrakingVectorEnv``.

SB3 has no adapter for Gymnasium's native vector environments (SB3 issue #1745), so training
would otherwise fall back to ``DummyVecEnv`` and step environments one by one in Python. This
adapter keeps the batched path: one compiled call per step for all environments. The vector env
autoresets in the same step, which is exactly SB3's convention: the returned observation already
belongs to the new episode and the last one goes to ``infos[i]["terminal_observation"]``.

At an episode's end ``infos[i]["episode"]`` carries ``{"r", "l", "t"}`` as ``VecMonitor`` writes
it (the undiscounted return of the environment's own reward, before any ``VecNormalize``; the
length in steps; seconds since the adapter was made), so SB3 logs episode statistics without a
``VecMonitor``. Both count the steps since ``reset`` returned, as ``VecMonitor`` sees them: with
the vector env's ``stagger_reset_steps`` the first episode of each environment leaves out the
warm-up that ``reset`` drove into its stop (``r`` is then the stop's return less the warm-up's;
``info``'s ``metrics`` still describe the whole stop). ``seed()`` and ``set_options()`` (SB3's
``VecEnv`` API: one seed for all, or per-environment options) take effect at the next
``reset()``. With ``render_mode="rgb_array"`` ``get_images()`` gives every environment's frame
(so SB3's ``render()`` tiles them).

**Per-environment attributes and methods.** SB3's ``get_attr`` / ``set_attr`` / ``env_method``
address environments one by one; here the environments are rows of one batched core
(``self.venv.core``, a ``BrakingCore``). The rule:

* ``get_attr(name, indices)`` looks ``name`` up on the vector env, then on its core. For the
  names in ``PER_ENV_ATTRS`` (the batch's per-environment state: first axis = environment) it
  returns, for each index ``i``, env ``i``'s entry (``value[i]``: a row of the batch's array is
  a view of it). ``observation_space`` / ``action_space`` are one environment's spaces (the
  vector env's ``single_*``), as ``DummyVecEnv``'s environments have them. Any other attribute
  is **shared** by the batch: the same object for every index (``render_mode``, ``spec``,
  ``metadata``, ``num_envs``, the core's configs; the core's other batched arrays whole, to be
  indexed by the caller). A name found on neither is an ``AttributeError`` naming it.
  Shapes are not used to guess which attribute is per environment: ``num_envs`` equal to the
  number of axles (4) would make the valve map ``valve_of_axle`` look batched.
* ``set_attr(name, value, indices)``: a ``PER_ENV_ATTRS`` name writes ``value`` into env ``i``'s
  entry for each index; any other name sets the shared attribute (where ``get_attr`` finds it,
  else on the vector env) and only for every environment at once (``indices`` None or all of
  them): otherwise an ``AttributeError`` naming it.
* ``env_method(name, *args, indices, **kwargs)``: the core's queries of one environment
  (``PER_ENV_METHODS``: their first argument is the environment index ``e``) are called once
  per index, ``core.name(i, *args, **kwargs)``. Any other method acts on the whole batch
  (``reset``, ``step``, ``render``, ...) and cannot be called per environment: an
  ``AttributeError`` naming it.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from wsp_env.envs import WSPBrakingVectorEnv

# the batch's per-environment state that get_attr / set_attr address env by env (first axis =
# environment): the vector env's step counts, then the core's
PER_ENV_ATTRS = (
    "episode_steps", "obs", "terms", "episode_return", "episode_terms", "prev_action",
    "reference_speed_mps", "measured_wheel_speed_mps", "accelerometer_reading_mps2", "rngs",
)  # fmt: skip
# the core's queries of one environment (first argument: its index) that env_method calls per
# index
PER_ENV_METHODS = ("episode_info", "watchdog_interventions", "describe", "final_obs")
# what get_attr gives for the spaces: one environment's, as DummyVecEnv's environments have them
SINGLE_SPACES = {
    "observation_space": "single_observation_space",
    "action_space": "single_action_space",
}


class SB3VecEnv(VecEnv):
    """Wrap ``WSPBrakingVectorEnv`` (or build one from its keyword arguments)."""

    def __init__(self, venv: WSPBrakingVectorEnv | None = None, **kwargs: Any) -> None:
        self.venv = venv if venv is not None else WSPBrakingVectorEnv(**kwargs)
        super().__init__(
            self.venv.num_envs, self.venv.single_observation_space, self.venv.single_action_space
        )
        self._actions: np.ndarray | None = None
        self._lengths = np.zeros(self.num_envs, dtype=np.int64)
        # each current stop's return before the adapter's first step in it (a staggered
        # reset's warm-up), left out of its episode statistics
        self._warmup_return = np.zeros(self.num_envs)
        self._t0 = time.perf_counter()

    def reset(self) -> np.ndarray:
        """Start every environment anew, with the seeds of ``seed()`` and the options of
        ``set_options()`` if given (then forgotten, as SB3's own ``VecEnv`` does)."""
        seeds = list(self._seeds)
        options = [dict(o) if o else None for o in self._options]
        any_seed = any(x is not None for x in seeds)
        obs, _ = self.venv.reset(seed=seeds if any_seed else None, options=options)
        self._reset_seeds()
        self._reset_options()
        self._lengths[:] = 0
        self._warmup_return[:] = self.venv.core.episode_return
        return obs

    # the counters of the stops under way, beside the core's state (``BrakingCore.state_dict``):
    # each stop's steps and control periods towards its limit, and the adapter's episode length
    # and warm-up return (its episode statistics)
    _COUNTERS = (("venv", "episode_steps"), ("venv", "episode_periods"), ("self", "_lengths"),
                 ("self", "_warmup_return"))  # fmt: skip

    def state_dict(self) -> dict[str, np.ndarray]:
        """The stops' counters a resumed run needs beside the core's state (copies)."""
        return {name: getattr(self.venv if owner == "venv" else self, name).copy()
                for owner, name in self._COUNTERS}  # fmt: skip

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restore ``state_dict``'s counters (same number of environments)."""
        for owner, name in self._COUNTERS:
            target = getattr(self.venv if owner == "venv" else self, name)
            if np.shape(state[name]) != target.shape:
                raise ValueError(f"state: {name} for {np.shape(state[name])} environments, this "
                                 f"adapter has {target.shape}")  # fmt: skip
            target[...] = state[name]

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
                        "r": float(final["metrics"]["episode_return"] - self._warmup_return[i]),
                        "l": int(self._lengths[i]),
                        "t": elapsed,
                    },
                }
                self._lengths[i] = 0
                self._warmup_return[i] = 0.0
        return obs, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """Per environment for ``PER_ENV_ATTRS``, else the batch's shared value for every index
        (module docstring)."""
        idx = self._indices(indices)
        if attr_name in SINGLE_SPACES:
            return [getattr(self.venv, SINGLE_SPACES[attr_name])] * len(idx)
        value = getattr(self._owner(attr_name), attr_name)
        if attr_name in PER_ENV_ATTRS:
            return [value[i] for i in idx]
        return [value] * len(idx)

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        """Env ``i``'s entry for ``PER_ENV_ATTRS``, else the shared attribute for every
        environment at once (module docstring)."""
        idx = self._indices(indices)
        if attr_name in PER_ENV_ATTRS:
            target = getattr(self._owner(attr_name), attr_name)
            for i in idx:
                target[i] = value
            return
        if sorted(set(idx)) != list(range(self.num_envs)):
            raise AttributeError(
                f"set_attr: {attr_name!r} is shared by the batch's environments: set it for all "
                f"of them (indices=None); per environment: {', '.join(PER_ENV_ATTRS)}"
            )
        owner = self._find(attr_name)
        setattr(self.venv if owner is None else owner, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any
    ) -> list[Any]:
        """``core.method_name(i, *args, **kwargs)`` for each index, for ``PER_ENV_METHODS``
        (module docstring)."""
        idx = self._indices(indices)
        if method_name in PER_ENV_METHODS:
            method = getattr(self.venv.core, method_name)
            return [method(i, *method_args, **method_kwargs) for i in idx]
        if self._find(method_name) is not None:
            raise AttributeError(
                f"env_method: {method_name!r} acts on the whole batch, not on one environment: "
                f"call it on SB3VecEnv.venv or .venv.core; per environment: "
                f"{', '.join(PER_ENV_METHODS)}"
            )
        raise AttributeError(
            f"env_method: {method_name!r}: no such method (per environment: "
            f"{', '.join(PER_ENV_METHODS)})"
        )

    def get_images(self) -> list[np.ndarray | None]:
        """Every environment's frame (``render_mode="rgb_array"``), else ``None`` each."""
        frames = self.venv.render()
        return [None] * self.num_envs if frames is None else list(frames)

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * len(self._indices(indices))

    def _indices(self, indices: Any) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int | np.integer):
            return [int(indices)]
        return [int(i) for i in indices]

    def _find(self, name: str) -> Any:
        """The vector env if it has ``name``, else its core if that has it, else None (no
        property is evaluated to find out)."""
        for owner in (self.venv, self.venv.core):
            if hasattr(type(owner), name) or name in vars(owner):
                return owner
        return None

    def _owner(self, name: str) -> Any:
        """``_find``, or an ``AttributeError`` naming ``name``."""
        owner = self._find(name)
        if owner is None:
            raise AttributeError(
                f"{name!r}: neither the vector env (WSPBrakingVectorEnv) nor its core "
                "(BrakingCore) has it"
            )
        return owner

"""The policy interface shared by every controller (classical WSP, none, oracle, learned).

A policy is bound to a batch of environments (``bind``), told when some of them start a new
episode (``reset``) and asked for one action per environment per control period (``act``).
Everything is batched over environments, so one evaluation code path serves all of them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

import numpy as np


class Policy(Protocol):
    name: str
    privileged: bool  # True: needs privileged observations / simulator state

    def bind(self, core: Any) -> None:
        """Attach to a ``_BrakingCore`` (spaces, scales; privileged policies may read state)."""

    def reset(self, env_ids: np.ndarray) -> None:
        """Environments ``env_ids`` start a new episode."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(n_envs, n_valves)`` for observations ``(n_envs, obs_dim)``."""


class NoWSP:
    """Full demand on every valve: no wheel slide protection."""

    name = "none"
    privileged = False

    def bind(self, core: Any) -> None:
        self._shape = (core.n_envs, core.n_valves)

    def reset(self, env_ids: np.ndarray) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.ones(self._shape, dtype=np.float32)


class SB3Policy:
    """A trained stable-baselines3 model (``.zip``), deterministic actions.

    If ``vecnormalize.pkl`` sits next to the model, its observation statistics are applied
    (loaded with ``training=False``).
    """

    privileged = False

    def __init__(self, path: str | Path) -> None:
        p = Path(path)
        if not p.exists():
            raise FileNotFoundError(f"{p}: no such policy file")
        from stable_baselines3 import PPO, SAC, TD3

        model = None
        for cls in (PPO, SAC, TD3):
            try:
                model = cls.load(p, device="cpu")
                break
            except Exception:
                continue
        if model is None:
            raise ValueError(f"{p}: not a stable-baselines3 model file (PPO, SAC or TD3)")
        self.model = model
        self.name = p.stem
        self._norm = None
        stats = p.with_name("vecnormalize.pkl")
        if stats.exists():
            import pickle

            with stats.open("rb") as fh:
                self._norm = pickle.load(fh)

    def bind(self, core: Any) -> None:
        space = self.model.observation_space
        if space.shape != (core.obs_dim,):
            raise ValueError(
                f"policy {self.name}: trained on observations of shape {space.shape}, "
                f"this environment gives {(core.obs_dim,)}"
            )

    def reset(self, env_ids: np.ndarray) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        if self._norm is not None:
            obs = self._norm.normalize_obs(obs)
        action, _ = self.model.predict(obs, deterministic=True)
        return np.asarray(action, dtype=np.float32)


def make_policy(name_or_path: str, wsp_config: str | None = None) -> Any:
    """``classical``, ``none``, ``oracle`` or a path to a trained model file."""
    if name_or_path == "none":
        return NoWSP()
    if name_or_path == "classical":
        from wsp_env.baselines.classical import ClassicalWSP, load_wsp_config

        return ClassicalWSP(load_wsp_config(wsp_config))
    if name_or_path == "oracle":
        from wsp_env.baselines.oracle import Oracle

        return Oracle()
    path = Path(name_or_path)
    if path.suffix == ".zip" or path.exists():
        return SB3Policy(path)
    raise ValueError(
        f"policy: {name_or_path!r} is neither a policy name (classical, none, oracle) "
        "nor an existing model file"
    )

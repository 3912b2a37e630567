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

    Found next to the model and applied: its observation normalisation — ``STEM.vecnormalize.pkl``
    (what ``wsp-env train`` writes beside every model and checkpoint), else SB3's checkpoint
    naming ``*_vecnormalize_N_steps.pkl``, else ``vecnormalize.pkl`` in the model's folder or
    the run folder above it — and the environment settings it was trained with
    (``config.yaml`` of its run: action mode, valve grouping, privileged observations,
    accelerometer, control period), which the evaluation then uses (``env_kwargs``). A
    discrete-action model's valve modes (0 vent, 1 hold, 2 fill) therefore reach a
    discrete-mode environment, never read as continuous commands. Frame-stacked policies
    (``frame_stack`` in the run's config) get the stack built as ``VecFrameStack`` builds it
    (normalised frames, newest last, zeros at an episode's start); recurrent ones
    (RecurrentPPO) carry their LSTM state from step to step, reset with each episode.
    """

    privileged = False

    def __init__(self, path: str | Path) -> None:
        p = Path(path)
        if not p.exists():
            raise FileNotFoundError(f"{p}: no such policy file")
        config = _run_config(p)
        algo = config.get("algo") if config else None
        import stable_baselines3 as sb3

        classes = {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3, "a2c": sb3.A2C}
        try:
            import sb3_contrib

            classes.update(recurrent_ppo=sb3_contrib.RecurrentPPO, tqc=sb3_contrib.TQC)
        except ImportError:  # sb3-contrib is optional
            pass
        order = [classes[algo]] if algo in classes else list(classes.values())
        model = None
        for cls in order:
            try:
                model = cls.load(p, device="cpu")
                break
            except Exception:
                continue
        if model is None:
            raise ValueError(f"{p}: not a stable-baselines3 model file ({', '.join(classes)})")
        env_kwargs = (config or {}).get("env_kwargs", {}) or {}
        n_stack = int((config or {}).get("frame_stack", 1) or 1)
        # a run folder's models share stems (best_model, model): the folder tells them apart
        name = f"{p.parent.name}/{p.stem}" if config is not None else p.stem
        self._setup(model, _load_normalisation(p), env_kwargs, name, n_stack)

    @classmethod
    def from_model(
        cls, model: Any, env_kwargs: dict[str, Any], name: str = "current", n_stack: int = 1
    ) -> SB3Policy:
        """A policy over a live model (training's validation): its normalisation as it is now."""
        self = cls.__new__(cls)
        self._setup(model, model.get_vec_normalize_env(), env_kwargs, name, n_stack)
        return self

    def _setup(
        self, model: Any, norm: Any, env_kwargs: dict[str, Any], name: str, n_stack: int = 1
    ) -> None:
        """``norm``: a VecNormalize (its statistics are copied: a live one keeps learning)."""
        import copy

        self.model = model
        self.name = name
        self._obs_rms = copy.deepcopy(norm.obs_rms) if norm is not None else None
        self._clip_obs = float(getattr(norm, "clip_obs", 10.0))
        self._epsilon = float(getattr(norm, "epsilon", 1e-8))
        self._norm_obs = bool(getattr(norm, "norm_obs", True))
        self.env_kwargs = {k: env_kwargs[k] for k in POLICY_ENV_KWARGS if k in env_kwargs}
        self.privileged = bool(self.env_kwargs.get("privileged", False))
        self.n_stack = n_stack
        self.recurrent = hasattr(model.policy, "lstm_actor")
        self._stack: np.ndarray | None = None
        self._state: Any = None
        self._episode_start: np.ndarray | None = None

    def bind(self, core: Any) -> None:
        space = self.model.observation_space
        if space.shape != (core.obs_dim * self.n_stack,):
            raise ValueError(
                f"policy {self.name}: trained on observations of shape {space.shape}, "
                f"this environment gives {(core.obs_dim,)} x {self.n_stack} stacked"
            )
        if self.model.action_space != core.action_space():
            raise ValueError(
                f"policy {self.name}: trained with actions {self.model.action_space}, this "
                f"environment takes {core.action_space()} (its env_kwargs: action_mode, "
                "valve_group)"
            )
        self._discrete = core.action_mode == "discrete"
        self._stack = np.zeros((core.n_envs, core.obs_dim * self.n_stack), dtype=np.float32)
        self._state = None
        self._episode_start = np.ones(core.n_envs, dtype=bool)

    def reset(self, env_ids: np.ndarray) -> None:
        """New episodes: their frame stacks emptied, their recurrent state restarted."""
        if self._stack is not None:
            self._stack[env_ids] = 0.0
        if self._episode_start is not None:
            self._episode_start[env_ids] = True

    def normalise(self, obs: np.ndarray) -> np.ndarray:
        if self._obs_rms is None or not self._norm_obs:
            return obs
        rms = self._obs_rms
        out = (obs - rms.mean) / np.sqrt(rms.var + self._epsilon)
        return np.clip(out, -self._clip_obs, self._clip_obs).astype(np.float32)

    def act(self, obs: np.ndarray) -> np.ndarray:
        x = self.normalise(obs)
        if self.n_stack > 1:
            assert self._stack is not None, "bind first"
            width = x.shape[1]
            self._stack[:, :-width] = self._stack[:, width:]
            self._stack[:, -width:] = x
            x = self._stack.copy()
        if self.recurrent:
            action, self._state = self.model.predict(
                x, state=self._state, episode_start=self._episode_start, deterministic=True
            )
            self._episode_start[:] = False
        else:
            action, _ = self.model.predict(x, deterministic=True)
        return np.asarray(action, dtype=np.float64 if self._discrete else np.float32)


# the environment settings a trained model needs in evaluation (its spaces and timing)
POLICY_ENV_KWARGS = (
    "action_mode", "valve_group", "privileged", "accelerometer", "accelerometer_bias_mps2",
    "control_period_s",
)  # fmt: skip


def _run_config(model_path: Path) -> dict[str, Any] | None:
    """The ``config.yaml`` of the training run a model file belongs to (its folder, or the run
    folder above a checkpoint), or None."""
    import yaml

    for folder in model_path.parents[:4]:
        cfg = folder / "config.yaml"
        if cfg.exists():
            data = yaml.safe_load(cfg.read_text())
            return data if isinstance(data, dict) else None
    return None


def _load_normalisation(model_path: Path) -> Any:
    """The observation statistics saved with a model (see ``SB3Policy``), or None."""
    import pickle
    import re

    candidates = [model_path.with_suffix(".vecnormalize.pkl")]
    m = re.match(r"^(.*)_(\d+)_steps$", model_path.stem)
    if m:  # SB3 CheckpointCallback: rl_model_1000_steps.zip + rl_model_vecnormalize_1000_steps.pkl
        stem = f"{m.group(1)}_vecnormalize_{m.group(2)}_steps.pkl"
        candidates.append(model_path.with_name(stem))
    candidates += [model_path.parent / "vecnormalize.pkl"]
    candidates += [model_path.parent.parent / "vecnormalize.pkl"]
    for c in candidates:
        if c.exists():
            with c.open("rb") as fh:
                return pickle.load(fh)  # a VecNormalize without its venv
    return None


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

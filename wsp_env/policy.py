"""The policy interface shared by every controller (classical WSP, none, oracle, learned).

A policy is bound to a batch of environments (``bind``), told when some of them start a new
episode (``reset``) and asked for one action per environment per control period (``act``).
Everything is batched over environments, so one evaluation code path serves all of them.
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Any, Protocol

import numpy as np


class Policy(Protocol):
    name: str
    privileged: bool  # True: needs privileged observations / simulator state

    def bind(self, core: Any) -> None:
        """Attach to a ``BrakingCore`` (spaces, scales; privileged policies may read state)."""

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


# a trained model acts on blocks of this many observations, the last one padded: torch's CPU
# matrix products pick their code path by the batch's size, so an environment's actions would
# otherwise depend on how many others were evaluated with it (one process or split across
# workers, a suite or one stop). With one block size they do not (tests/test_distributed.py).
INFERENCE_BLOCK = 64


class SB3Policy:
    """A trained stable-baselines3 model (``.zip``), deterministic actions, computed on blocks
    of ``INFERENCE_BLOCK`` observations (an environment's actions do not depend on the batch).

    Found next to the model and applied: its observation normalisation — ``STEM.vecnormalize.pkl``
    (what ``wsp-env train`` writes beside every model and checkpoint), else SB3's checkpoint
    naming ``*_vecnormalize_N_steps.pkl``, else ``vecnormalize.pkl`` in the model's folder or
    the run folder above it — and the environment settings it was trained with
    (``config.yaml`` of its run: action mode and its settings — residual, slip target —, valve
    grouping, privileged observations, accelerometer, memory features, control period), which
    the evaluation then uses (``env_kwargs``). A
    discrete-action model's valve modes (0 vent, 1 hold, 2 fill) therefore reach a
    discrete-mode environment, never read as continuous commands. Frame-stacked policies
    (``frame_stack`` in the run's config) get the stack built as ``VecFrameStack`` builds it
    (normalised frames, newest last, zeros at an episode's start); recurrent ones
    (RecurrentPPO) carry their LSTM state from step to step, reset with each episode.

    The model file's metadata (``wsp_env.json``) says whether it was trained on normalised
    observations (``obs_normalization``): such a model without its normalisation file is an
    error (one line naming the file), and one trained without normalisation ignores any
    statistics file lying about. Older models whose metadata does not say are told by their run's
    config (``config.yaml`` of the run, or ``STEM.yaml`` beside a shipped policy), else the
    statistics are used when found, as before.
    """

    privileged = False

    def __init__(self, path: str | Path) -> None:
        p = Path(path)
        if not p.exists():
            raise FileNotFoundError(f"{p}: no such policy file")
        meta = model_metadata(p)
        require_extras(f"{p}: learned policies need", "rl")
        classes = _algo_classes()
        algo = meta["algo"]
        if algo not in classes:
            raise ValueError(f"{p}: algorithm {algo!r} is not one of {', '.join(classes)}")
        try:
            model = classes[algo].load(p, device="cpu")
        except Exception as err:  # a damaged or foreign file: one line, not a traceback
            raise ValueError(f"{p}: cannot load as a {algo} model ({type(err).__name__})") from None
        needs_norm = meta.get("obs_normalization")  # None: a model from before it was recorded
        norm = None if needs_norm is False else _load_normalisation(p)
        if needs_norm and norm is None:
            raise ValueError(
                f"{p}: trained on normalised observations, but its normalisation file "
                f"{p.with_suffix('.vecnormalize.pkl')} is missing (copy it beside the model)"
            )
        self.vehicle = meta.get("vehicle")
        # observation layout 0: before the reference's age was observed (2026-11-25)
        self.observation_layout = int(meta.get("observation_layout", 0))
        self._setup(model, norm, meta["env_kwargs"], meta["name"], int(meta["frame_stack"]))

    @classmethod
    def from_model(
        cls, model: Any, env_kwargs: dict[str, Any], name: str = "current", n_stack: int = 1
    ) -> SB3Policy:
        """A policy over a live model (training's validation): its normalisation as it is now."""
        self = cls.__new__(cls)
        self.vehicle = None
        self.observation_layout = OBSERVATION_LAYOUT
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
        # the environment held each action this many control periods: the policy holds it
        # itself on the 20 ms core (evaluation, the benchmark), which knows no repeat
        self.action_repeat = int(self.env_kwargs.pop("action_repeat", 1))
        self.privileged = bool(self.env_kwargs.get("privileged", False))
        self.n_stack = n_stack
        self.recurrent = hasattr(model.policy, "lstm_actor")
        self._stack: np.ndarray | None = None
        self._state: Any = None
        self._episode_start: np.ndarray | None = None
        self._phase: np.ndarray | None = None
        self._held: np.ndarray | None = None

    def bind(self, core: Any) -> None:
        if self.vehicle is not None and self.vehicle != core.vehicle.id:
            raise ValueError(
                f"policy {self.name}: trained for vehicle {self.vehicle!r}, this run's vehicle "
                f"is {core.vehicle.id!r}"
            )
        mode = self.env_kwargs.get("action_mode", "continuous")
        if mode != core.action_mode:  # the residual and slip-target modes share their shapes
            raise ValueError(
                f"policy {self.name}: trained in action_mode {mode!r}, this environment's is "
                f"{core.action_mode!r} (build it with the policy's env_kwargs)"
            )
        space = self.model.observation_space
        # a layout-0 model never saw the reference's age (the kernel's last entry): drop it
        self._drop = core.kernel_obs_dim - 1 if self.observation_layout < 1 else None
        width = core.obs_dim - (self._drop is not None)
        if space.shape != (width * self.n_stack,):
            raise ValueError(
                f"policy {self.name}: trained on observations of shape {space.shape}, "
                f"this environment gives {(width,)} x {self.n_stack} stacked"
            )
        if self.model.action_space != core.action_space():
            raise ValueError(
                f"policy {self.name}: trained with actions {self.model.action_space}, this "
                f"environment takes {core.action_space()} (its env_kwargs: action_mode, "
                "valve_group)"
            )
        self._discrete = core.action_mode == "discrete"
        self._stack = np.zeros((core.n_envs, width * self.n_stack), dtype=np.float32)
        self._state = None
        self._episode_start = np.ones(core.n_envs, dtype=bool)
        self._phase = np.zeros(core.n_envs, dtype=np.int64)  # periods since the last decision
        self._held = np.zeros((core.n_envs, core.n_valves),
                              dtype=np.float64 if self._discrete else np.float32)  # fmt: skip

    def reset(self, env_ids: np.ndarray) -> None:
        """New episodes: their frame stacks emptied, their recurrent state restarted, their
        next period a decision."""
        if self._stack is not None:
            self._stack[env_ids] = 0.0
        if self._episode_start is not None:
            self._episode_start[env_ids] = True
        if self._phase is not None:
            self._phase[env_ids] = 0

    def normalisation(self) -> tuple[np.ndarray, np.ndarray, float] | None:
        """The observation normalisation ``clip((obs - mean) / scale, -clip, clip)`` as
        ``(mean, scale, clip)`` for one frame, or None when observations go in unnormalised."""
        if self._obs_rms is None or not self._norm_obs:
            return None
        rms = self._obs_rms
        return np.asarray(rms.mean), np.sqrt(rms.var + self._epsilon), self._clip_obs

    def normalise(self, obs: np.ndarray) -> np.ndarray:
        norm = self.normalisation()
        if norm is None:
            return obs
        mean, scale, clip = norm
        return np.clip((obs - mean) / scale, -clip, clip).astype(np.float32)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Actions for ``obs``; a model trained with ``action_repeat`` k decides on every k-th
        period of each stop (its first included) and holds that action in between, as the
        environment it learned in held it (its frame stack and memory advance per decision)."""
        if self.action_repeat == 1:
            return self._decide(obs, None)
        assert self._phase is not None, "bind first"
        due = self._phase == 0
        if due.any():
            self._held[due] = self._decide(obs, due)[due]
        self._phase = (self._phase + 1) % self.action_repeat
        return self._held.copy()

    def _decide(self, obs: np.ndarray, rows: np.ndarray | None) -> np.ndarray:
        """The model's actions for every row; the frame stack and the recurrent state advance
        for ``rows`` only (a mask; None: all)."""
        if self._drop is not None:
            obs = np.delete(obs, self._drop, axis=1)
        x = self.normalise(obs)
        if self.n_stack > 1:
            assert self._stack is not None, "bind first"
            width = x.shape[1]
            stack = self._stack if rows is None else self._stack[rows]
            stack[:, :-width] = stack[:, width:]
            stack[:, -width:] = x if rows is None else x[rows]
            if rows is not None:
                self._stack[rows] = stack
            x = self._stack.copy()
        n = x.shape[0]
        pad = (-n) % INFERENCE_BLOCK
        if pad:
            x = np.concatenate([x, np.zeros((pad, x.shape[1]), dtype=x.dtype)])
        blocks = range(0, n + pad, INFERENCE_BLOCK)
        if self.recurrent:
            start = np.concatenate([self._episode_start, np.ones(pad, dtype=bool)])
            state = self._state
            if state is not None and pad:
                state = tuple(np.concatenate([h, np.zeros((h.shape[0], pad, *h.shape[2:]),
                                                          dtype=h.dtype)], axis=1)
                              for h in state)  # fmt: skip
            actions, states = [], []
            for b in blocks:
                part = slice(b, b + INFERENCE_BLOCK)
                a, st = self.model.predict(
                    x[part], state=None if state is None else tuple(h[:, part] for h in state),
                    episode_start=start[part], deterministic=True,
                )  # fmt: skip
                actions.append(a)
                states.append(st)
            action = np.concatenate(actions)[:n]
            new_state = tuple(np.concatenate(hs, axis=1)[:, :n] for hs in zip(*states, strict=True))
            if rows is None or self._state is None:
                self._state = new_state
            else:  # only the environments that decided move on
                for h_old, h_new in zip(self._state, new_state, strict=True):
                    h_old[:, rows] = h_new[:, rows]
            if rows is None:
                self._episode_start[:] = False
            else:
                self._episode_start[rows] = False
        else:
            action = self._forward(x)[:n]
        return np.asarray(action, dtype=np.float64 if self._discrete else np.float32)

    def _forward(self, x: np.ndarray) -> np.ndarray:
        """A feed-forward model's deterministic actions for every row of ``x`` (normalised,
        stacked, padded to a multiple of ``INFERENCE_BLOCK``; a subclass may run other weights
        per row: ``training.es.PopulationPolicy``)."""
        return np.concatenate(
            [
                self.model.predict(x[b : b + INFERENCE_BLOCK], deterministic=True)[0]
                for b in range(0, x.shape[0], INFERENCE_BLOCK)
            ]
        )


# the environment settings a trained model needs in evaluation (its spaces and timing)
POLICY_ENV_KWARGS = (
    "action_mode", "residual_scale", "residual_deadband", "valve_group", "privileged",
    "accelerometer", "accelerometer_bias_mps2", "control_period_s", "action_repeat",
    "slip_target_min_kmh", "slip_target_max_kmh", "slip_target_gain_per_kmh",
    "slip_target_lead_s", "slip_target_release", "slip_target_max_creep",
    "slip_target_drift_correction", "slip_target_gain_scale_floor", "slip_target_onset_drift",
    "slip_target_scale_calibration", "slip_target_onset_two_sided", "slip_target_lock_guard",
    "memory_features",
    "memory_target_mean",
)  # fmt: skip
# the slip-target loop's periodic-release gate of a model file that does not name it: written
# before the gate existed (2026-11-27), trained and judged with the ungated loop
LEGACY_SLIP_TARGET_RELEASE = "always"
# the slip-target loop's settings added after its first models, each with the value a model
# file or run folder that does not name it gets (written before the setting existed: the loop
# it was trained and judged with); what files name now: ``loop_settings_now``
LEGACY_LOOP_SETTINGS: dict[str, Any] = {
    "slip_target_release": LEGACY_SLIP_TARGET_RELEASE,
    "slip_target_max_creep": 0.0,
    "slip_target_drift_correction": False,
    "slip_target_gain_scale_floor": 1.0,
    "slip_target_onset_drift": False,
    "slip_target_scale_calibration": False,
    "slip_target_onset_two_sided": False,
    "slip_target_lock_guard": False,
}


def loop_settings_now() -> dict[str, Any]:
    """The slip-target loop's later settings (``LEGACY_LOOP_SETTINGS``' keys) as the environment
    sets them by default now: what model files and run folders are written with."""
    from wsp_env.baselines.slip_target import (
        DEFAULT_DRIFT_CORRECTION,
        DEFAULT_GAIN_SCALE_FLOOR,
        DEFAULT_LOCK_GUARD,
        DEFAULT_MAX_CREEP,
        DEFAULT_ONSET_DRIFT,
        DEFAULT_ONSET_TWO_SIDED,
        DEFAULT_RELEASE,
        DEFAULT_SCALE_CALIBRATION,
    )

    return {
        "slip_target_release": DEFAULT_RELEASE,
        "slip_target_max_creep": DEFAULT_MAX_CREEP,
        "slip_target_drift_correction": DEFAULT_DRIFT_CORRECTION,
        "slip_target_gain_scale_floor": DEFAULT_GAIN_SCALE_FLOOR,
        "slip_target_onset_drift": DEFAULT_ONSET_DRIFT,
        "slip_target_scale_calibration": DEFAULT_SCALE_CALIBRATION,
        "slip_target_onset_two_sided": DEFAULT_ONSET_TWO_SIDED,
        "slip_target_lock_guard": DEFAULT_LOCK_GUARD,
    }


META_NAME = "wsp_env.json"  # the metadata entry ``wsp-env train`` adds to every model file
# the observation layout models are trained on now: 1 = with the reference's age (the kernel's
# last entry, 2026-11-25); models without the field are layout 0 and get it removed
OBSERVATION_LAYOUT = 1

# the optional dependency groups (pyproject.toml) and the modules that tell they are installed
EXTRAS = {
    "rl": ("torch", "stable_baselines3"),
    "export": ("onnx", "onnxruntime"),
    "sweep": ("ray", "optuna"),
}


class MissingExtraError(ValueError):
    """An optional dependency group of the package is not installed (one line saying which)."""


def require_extras(needs: str, *extras: str) -> None:
    """Raise ``MissingExtraError`` unless every module of ``extras`` (``EXTRAS``) imports:
    ``f"{needs} the rl extra: pip install 'wsp-env[rl]' (no module named 'torch')"``."""
    import importlib

    for extra in extras:
        for module in EXTRAS[extra]:
            try:
                importlib.import_module(module)
            except ImportError as err:
                word = "extra" if len(extras) == 1 else "extras"
                raise MissingExtraError(
                    f"{needs} the {' and '.join(extras)} {word}: pip install "
                    f"'wsp-env[{','.join(extras)}]' (no module named {err.name or module!r})"
                ) from None


def obs_normalization(config: dict[str, Any]) -> bool:
    """Whether a training config (``config.yaml``'s content) normalises observations:
    ``normalize`` true, or a mapping without ``norm_obs: false``."""
    norm = config.get("normalize")
    if isinstance(norm, dict):
        return bool(norm.get("norm_obs", True))
    return bool(norm)


def _algo_classes() -> dict[str, type]:
    import stable_baselines3 as sb3

    classes = {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3, "a2c": sb3.A2C}
    try:
        import sb3_contrib

        classes.update(recurrent_ppo=sb3_contrib.RecurrentPPO, tqc=sb3_contrib.TQC)
    except ImportError:  # sb3-contrib is optional
        pass
    return classes


def policy_metadata(config: dict[str, Any], name: str) -> dict[str, Any]:
    """What a model file must say about itself to be evaluated (``write_model_metadata``)."""
    from wsp_env.core.config import ConfigError, load_vehicle

    env_kwargs = config.get("env_kwargs") or {}
    vehicle = env_kwargs.get("vehicle", "uic_z1")
    if isinstance(vehicle, str):  # an id or a YAML path: the id is what evaluation compares
        try:
            vehicle = load_vehicle(vehicle).id
        except (ConfigError, OSError):
            pass
    # the sensor tier is written out even where the config leaves it to the defaults, and so
    # are the slip-target loop's later settings (a file without one loads with the old loop)
    written: dict[str, Any] = {"privileged": False, "accelerometer": False}
    if env_kwargs.get("action_mode") == "slip_target":
        written.update(loop_settings_now())
    return {
        "format": "wsp-env-policy/1",
        "name": name,
        "algo": config["algo"],
        "vehicle": vehicle if isinstance(vehicle, str) else None,
        "frame_stack": int(config.get("frame_stack", 1) or 1),
        "observation_layout": OBSERVATION_LAYOUT,
        # True: the model needs its STEM.vecnormalize.pkl (SB3Policy refuses it without)
        "obs_normalization": obs_normalization(config),
        "env_kwargs": {
            **written,
            **{k: env_kwargs[k] for k in POLICY_ENV_KWARGS if k in env_kwargs},
        },
    }


def write_model_metadata(model_path: str | Path, meta: dict[str, Any]) -> None:
    """Store ``meta`` inside the model's zip (SB3 ignores the extra entry), replacing any."""
    import json
    import zipfile

    p = Path(model_path)
    with zipfile.ZipFile(p) as z:
        entries = {n: z.read(n) for n in z.namelist() if n != META_NAME}
    tmp = p.with_name(p.name + ".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for n, data in entries.items():
            z.writestr(n, data)
        z.writestr(META_NAME, json.dumps(meta, indent=1))
    tmp.replace(p)


def model_metadata(model_path: Path) -> dict[str, Any]:
    """The algorithm and environment settings of a model file: its own metadata entry, else the
    ``config.yaml`` of the training run it sits in. Neither: one line saying so.

    ``obs_normalization`` is True, False, or None where nothing tells (an entry written before
    the field existed, with no run config beside it to read it from)."""
    import json
    import zipfile

    try:
        with zipfile.ZipFile(model_path) as z:
            if META_NAME in z.namelist():
                meta = json.loads(z.read(META_NAME))
                if isinstance(meta, dict) and "algo" in meta:
                    meta.setdefault("name", model_path.stem)
                    meta.setdefault("frame_stack", 1)
                    meta.setdefault("env_kwargs", {})
                    legacy_loop_settings(meta["env_kwargs"])
                    if "obs_normalization" not in meta:  # written before the field existed
                        config = _run_config(model_path)
                        known = config is not None and "algo" in config
                        meta["obs_normalization"] = obs_normalization(config) if known else None
                    return meta
    except zipfile.BadZipFile:
        raise ValueError(f"{model_path}: not a model file (not a zip archive)") from None
    config = _run_config(model_path)
    if config is None or "algo" not in config:
        raise ValueError(
            f"{model_path}: no {META_NAME} inside and no config.yaml of a training run beside "
            "it: cannot tell the algorithm (models written by `wsp-env train` carry both)"
        )
    # a run folder's models share stems (best_model, model): the folder tells them apart;
    # a model without its own entry predates the entry's observation layout (layout 0)
    meta = policy_metadata(config, f"{model_path.parent.name}/{model_path.stem}")
    meta["observation_layout"] = 0
    named = config.get("env_kwargs") or {}
    for key in LEGACY_LOOP_SETTINGS:
        if key not in named:
            meta["env_kwargs"].pop(key, None)
    legacy_loop_settings(meta["env_kwargs"])
    return meta


def legacy_loop_settings(env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """A slip-target model's or run's environment settings, each of the loop's later settings
    (``LEGACY_LOOP_SETTINGS``) it does not name set, in place, to the value of the loop it was
    trained and judged with (it was written before the setting existed); returned."""
    if env_kwargs.get("action_mode") == "slip_target":
        for key, before in LEGACY_LOOP_SETTINGS.items():
            env_kwargs.setdefault(key, before)
    return env_kwargs


def _run_config(model_path: Path) -> dict[str, Any] | None:
    """The ``config.yaml`` of the training run a model file belongs to (its folder, or the run
    folder above a checkpoint), else a shipped policy's ``STEM.yaml`` beside it (the config it
    was trained with), or None."""
    import yaml

    beside = model_path.with_suffix(".yaml")
    for cfg in [folder / "config.yaml" for folder in model_path.parents[:4]] + [beside]:
        if cfg.exists():
            try:
                data = yaml.safe_load(cfg.read_text())
            except yaml.YAMLError:
                data = None
            if cfg != beside or (isinstance(data, dict) and "algo" in data):
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


def pretrained_dir() -> Path:
    """Where the shipped policies live (``agents/pretrained``, installed with the package)."""
    import wsp_env.agents

    return Path(wsp_env.agents.__file__).parent / "pretrained"


def shipped_policies() -> list[str]:
    return sorted(p.stem for p in pretrained_dir().glob("*.zip"))


def sensor_tier(policy: Any) -> str | None:
    """The sensor tier a policy was trained in (``wheels`` or ``wheels+accel``, from its
    ``env_kwargs``), or None where it does not say (the built-in controllers run in any)."""
    accel = (getattr(policy, "env_kwargs", None) or {}).get("accelerometer")
    from wsp_env.baselines.classical import accelerometer_tier

    return None if accel is None else accelerometer_tier(bool(accel))


def check_sensor_tier(policy: Any, tier: str) -> None:
    """Refuse, in one line, a policy trained in another sensor tier than ``tier``."""
    own = sensor_tier(policy)
    if own is not None and own != tier:
        have = "with" if own == "wheels+accel" else "without"
        raise ValueError(
            f"policy {policy.name}: trained {have} an accelerometer, so it belongs to tier "
            f"{own}, not {tier}"
        )


POLICY_METHODS = ("bind", "reset", "act")


def load_callable_policy(spec: str) -> Any:
    """``module:callable``: import ``module``, call ``callable()`` and return the policy it makes
    (an object with ``bind`` / ``reset`` / ``act``, ``Policy``), so that a controller from any
    framework can be evaluated. Every failure is one line naming ``spec``."""
    import importlib
    import os
    import sys

    module_name, _, attr = spec.partition(":")
    if os.getcwd() not in sys.path:  # a module in the current folder, as `python -m` finds it
        sys.path.append(os.getcwd())
    if not module_name or not attr:
        raise ValueError(f"policy: {spec!r} is not module:callable")
    try:
        module = importlib.import_module(module_name)
    except Exception as err:  # a missing module or one that fails on import: one line
        raise ValueError(
            f"policy: {spec}: cannot import {module_name!r} ({type(err).__name__}: {err})"
        ) from None
    factory = module
    for part in attr.split("."):
        if not hasattr(factory, part):
            raise ValueError(f"policy: {spec}: {module_name!r} has no attribute {attr!r}")
        factory = getattr(factory, part)
    if not callable(factory):
        raise ValueError(f"policy: {spec}: {attr!r} is not callable")
    try:
        policy = factory()
    except Exception as err:
        raise ValueError(
            f"policy: {spec}: calling {attr}() failed ({type(err).__name__}: {err})"
        ) from None
    missing = [m for m in POLICY_METHODS if not callable(getattr(policy, m, None))]
    if missing:
        raise ValueError(
            f"policy: {spec}: {attr}() returned a {type(policy).__name__} without "
            f"{', '.join(missing)} (a policy needs bind, reset and act: wsp_env.policy.Policy)"
        )
    if not isinstance(getattr(policy, "name", None), str):
        try:
            policy.name = spec
        except AttributeError:
            raise ValueError(f"policy: {spec}: the policy has no name and takes none") from None
    if not hasattr(policy, "privileged"):
        policy.privileged = False
    return policy


def make_policy(name_or_path: str, wsp_config: str | None = None, tier: str = "wheels") -> Any:
    """``classical`` (the frozen classical WSP of sensor ``tier``: ``wheels`` or
    ``wheels+accel``), ``none``, ``oracle``, a shipped policy's name (``agents/pretrained``), a
    path to a trained model file, or ``module:callable`` (``load_callable_policy``). Model files
    are pickles, and a module runs code: load only what you trust.

    The policy keeps its arguments as ``policy.spec`` (where it takes attributes), so that an
    evaluation split across workers can build it again there
    (``evaluation.distributed.PolicySpec``)."""
    policy = _make_policy(name_or_path, wsp_config, tier)
    with contextlib.suppress(AttributeError, TypeError):
        policy.spec = (name_or_path, wsp_config, tier)
    return policy


def _make_policy(name_or_path: str, wsp_config: str | None, tier: str) -> Any:
    if name_or_path == "none":
        return NoWSP()
    if name_or_path == "classical":
        from wsp_env.baselines.classical import ClassicalWSP, load_wsp_config

        return ClassicalWSP(load_wsp_config(wsp_config, tier))
    if name_or_path == "oracle":
        from wsp_env.baselines.oracle import Oracle

        return Oracle()
    path = Path(name_or_path)
    if path.suffix == ".zip" or path.exists():
        return SB3Policy(path)
    if name_or_path in shipped_policies():
        require_extras(f"{name_or_path}: learned policies need", "rl")
        return SB3Policy(pretrained_dir() / f"{name_or_path}.zip")
    if ":" in name_or_path:
        return load_callable_policy(name_or_path)
    names = ", ".join(["classical", "none", "oracle", *shipped_policies()])
    raise ValueError(
        f"policy: {name_or_path!r} is neither a policy name ({names}), an existing model file "
        "nor module:callable"
    )

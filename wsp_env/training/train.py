"""Training learned WSP controllers with stable-baselines3 (``wsp-env train``).

**Config** (``configs/train/NAME.yaml``), in the layout of rl-baselines3-zoo's hyperparameter
files: ``algo`` (``ppo``, ``sac``, ``td3``, ``a2c``), ``policy`` (``MlpPolicy``), ``n_envs``,
``n_timesteps``, ``seed``, ``normalize`` (``true`` or VecNormalize's keyword arguments),
``policy_kwargs`` (``net_arch``, ``activation_fn`` by name, ...), the algorithm's own
hyperparameters at the same level (``learning_rate``, ``n_steps``, ``gamma``, ...; schedules
written ``lin_3e-4``: linear from 3e-4 to 0), plus

* ``env_kwargs``: ``WSPBraking-v0``'s keyword arguments (vehicle, action mode, valve grouping,
  reward exchange rates, the scenario distribution ``reset`` draws from, ...);
* ``eval``: the periodic model selection — ``suite`` (default ``validation``; ``heldout`` is
  refused: it is for final comparisons only) and ``every_timesteps``;
* ``checkpoint_every_timesteps``.

Every field is checked before anything runs; a mistake is one line naming the file and field.

**Run** (``train``): the native vector env through ``SB3VecEnv`` (one compiled step for all
environments), ``VecNormalize`` if asked; every ``eval.every_timesteps`` the current policy and
the frozen classical WSP run the validation suite through ``evaluation.run_suite`` (one code
path) and the best model so far is kept — most runs passing the suite's criteria, then the
shortest mean stop; checkpoints at rollout boundaries hold everything a bit-for-bit resume
needs (model, optimiser, normalisation, the environments' physical state and random
generators, torch's and numpy's random state, an off-policy algorithm's replay buffer);
TensorBoard and CSV logs carry per-episode stopping distance, sliding energy, lock, air and
each reward term next to SB3's own. A fixed seed reproduces a run.

**Output folder**: ``config.yaml`` (the exact config, seed included), ``model.zip`` +
``model.vecnormalize.pkl`` (final), ``best_model.zip`` + ``best_model.vecnormalize.pkl``,
``checkpoints/step_N/``, ``validation.json`` (every evaluation), ``logs/from_step_N/`` (each
call's TensorBoard events and CSV), ``progress.csv`` (all calls' CSV rows), ``train.json`` (the
result, DESIGN §8).
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import pickle
import random
import re
import shutil
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from wsp_env.core.config import ConfigError, configs_root, read_yaml

ALGO_NAMES = ("ppo", "sac", "td3", "a2c", "recurrent_ppo", "tqc")  # the last two: sb3-contrib
OFF_POLICY = ("sac", "td3", "tqc")
RECURRENT = ("recurrent_ppo",)
ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu", "gelu")
POLICY_KWARGS = (
    "net_arch", "activation_fn", "log_std_init", "ortho_init", "n_critics", "n_quantiles",
    "lstm_hidden_size", "n_lstm_layers", "enable_critic_lstm", "shared_lstm",
)  # fmt: skip
# keyword arguments of the algorithm that the trainer sets itself
MANAGED = ("policy", "env", "seed", "policy_kwargs", "tensorboard_log", "verbose", "device")
ENV_KWARGS = (
    "vehicle", "action_mode", "residual_scale", "residual_deadband", "valve_group", "privileged",
    "accelerometer", "accelerometer_bias_mps2", "reward", "scenario", "rails_config",
    "control_period_s", "substep_s", "max_time_s",
)  # fmt: skip
SCHEDULE = re.compile(r"^lin_([0-9.eE+-]+)$")
CONFIG_NAME = "config.yaml"
JUDGING_SUITES = ("heldout", "en15595")  # never used for model selection
KEEP_CHECKPOINTS = 3  # the newest ones; the best model is kept apart (best_model.zip)


# ---- config ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class EvalConfig:
    suite: str = "validation"
    every_timesteps: int = field(default=500_000, metadata={"gt": 0})
    # the judging suites (JUDGING_SUITES) are refused by name once loaded (Validator)


@dataclass(frozen=True)
class TrainConfig:
    """A validated training config (module docstring); ``hyperparams`` go to the algorithm."""

    algo: str
    n_timesteps: int
    policy: str = "MlpPolicy"
    n_envs: int = 64
    frame_stack: int = 1
    seed: int = 0
    normalize: dict[str, Any] | None = None
    policy_kwargs: dict[str, Any] = field(default_factory=dict)
    hyperparams: dict[str, Any] = field(default_factory=dict)
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    eval: EvalConfig = field(default_factory=EvalConfig)
    checkpoint_every_timesteps: int = 1_000_000
    source: str = ""  # the file it came from (for messages)
    pretrain: Any = None  # imitation.PretrainConfig: a warm start before learning (fresh runs)

    def as_yaml_dict(self) -> dict[str, Any]:
        """The config as a file would hold it (what ``config.yaml`` in a run folder keeps)."""
        out: dict[str, Any] = {"algo": self.algo, "policy": self.policy, "n_envs": self.n_envs,
                               "n_timesteps": self.n_timesteps, "seed": self.seed,
                               "frame_stack": self.frame_stack}  # fmt: skip
        out["normalize"] = self.normalize if self.normalize is not None else False
        if self.policy_kwargs:
            out["policy_kwargs"] = self.policy_kwargs
        out.update(self.hyperparams)
        out["env_kwargs"] = self.env_kwargs
        out["eval"] = dataclasses.asdict(self.eval)
        out["checkpoint_every_timesteps"] = self.checkpoint_every_timesteps
        if self.pretrain is not None:
            out["pretrain"] = dataclasses.asdict(self.pretrain)
        return out


def _algo_class(name: str) -> type:
    if name in ("recurrent_ppo", "tqc"):
        import sb3_contrib

        return {"recurrent_ppo": sb3_contrib.RecurrentPPO, "tqc": sb3_contrib.TQC}[name]
    import stable_baselines3 as sb3

    return {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3, "a2c": sb3.A2C}[name]


_RUN_CLASSES: dict[str, type] = {}


def _run_class(name: str) -> type:
    """The algorithm with schedules driven by the *run's* progress (``run_total_timesteps``),
    not by one ``learn`` call's: a run trained in chunks (``--chunk-timesteps``, ``--resume``)
    follows the same learning-rate and clip-range schedule as one trained in one go."""
    if name not in _RUN_CLASSES:
        base = _algo_class(name)

        def _update_current_progress_remaining(
            self: Any, num_timesteps: int, total_timesteps: int
        ) -> None:
            total = getattr(self, "run_total_timesteps", None) or total_timesteps
            self._current_progress_remaining = 1.0 - float(num_timesteps) / float(total)

        _RUN_CLASSES[name] = type(
            base.__name__,
            (base,),
            {"_update_current_progress_remaining": _update_current_progress_remaining},
        )
    return _RUN_CLASSES[name]


def _int(value: Any, where: str, low: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ConfigError(f"{where}: expected an integer >= {low}, got {value!r}")
    return value


def parse_schedule(value: Any, where: str) -> Any:
    """``lin_X`` -> a linear schedule from X to 0 (SB3 progress 1 -> 0); numbers pass."""
    if isinstance(value, str) and value.startswith("lin_"):
        m = SCHEDULE.match(value)
        if m is None:
            raise ConfigError(f"{where}: {value!r} is not lin_<number>")
        try:
            start = float(m.group(1))
        except ValueError:
            raise ConfigError(f"{where}: {value!r} is not lin_<number>") from None
        if not math.isfinite(start):
            raise ConfigError(f"{where}: {value!r} is not lin_<number>")
        return LinearSchedule(start)
    return value


@dataclass(frozen=True)
class LinearSchedule:
    """``start * progress_remaining`` (picklable, so saved models load anywhere)."""

    start: float

    def __call__(self, progress_remaining: float) -> float:
        return self.start * progress_remaining


def load_train_config(path: str | Path) -> TrainConfig:
    """Read and check a training config; errors name the file and the field."""
    p = Path(path)
    if p.suffix not in (".yaml", ".yml") and not p.exists():
        p = configs_root() / "train" / f"{path}.yaml"
    if not p.exists():
        raise ConfigError(f"{path}: no such training config")
    data = read_yaml(p)
    try:
        return parse_train_config(data, str(p))
    except ConfigError as err:
        raise ConfigError(f"{p}: {err}") from None


def parse_train_config(data: Any, source: str = "") -> TrainConfig:
    from wsp_env.core.config import from_dict

    if not isinstance(data, dict):
        raise ConfigError("(top level): expected a mapping")
    data = dict(data)
    algo = data.pop("algo", None)
    if algo not in ALGO_NAMES:
        raise ConfigError(f"algo: {algo!r} is not one of {', '.join(ALGO_NAMES)}")
    if "n_timesteps" not in data:
        raise ConfigError("n_timesteps: missing required field")
    n_timesteps = _int(data.pop("n_timesteps"), "n_timesteps")
    want = "MlpLstmPolicy" if algo in RECURRENT else "MlpPolicy"
    policy = data.pop("policy", want)
    if policy != want:
        raise ConfigError(f"policy: {policy!r} is not {want} (flat observations, {algo})")
    n_envs = _int(data.pop("n_envs", 64), "n_envs")
    frame_stack = _int(data.pop("frame_stack", 1), "frame_stack")
    seed = _int(data.pop("seed", 0), "seed", low=0)
    normalize = data.pop("normalize", False)
    if normalize is True:
        normalize = {}
    elif normalize is False or normalize is None:
        normalize = None
    elif isinstance(normalize, dict):
        from stable_baselines3.common.vec_env import VecNormalize

        allowed = set(inspect.signature(VecNormalize.__init__).parameters) - {"self", "venv"}
        for k in normalize:
            if k not in allowed:
                raise ConfigError(f"normalize.{k}: unknown (allowed: {', '.join(sorted(allowed))})")
    else:
        raise ConfigError(f"normalize: expected true, false or a mapping, got {normalize!r}")
    policy_kwargs = data.pop("policy_kwargs", {}) or {}
    if not isinstance(policy_kwargs, dict):
        raise ConfigError(f"policy_kwargs: expected a mapping, got {policy_kwargs!r}")
    for k, v in policy_kwargs.items():
        if k not in POLICY_KWARGS:
            raise ConfigError(f"policy_kwargs.{k}: unknown (allowed: {', '.join(POLICY_KWARGS)})")
        if k == "activation_fn" and v not in ACTIVATIONS:
            raise ConfigError(f"policy_kwargs.activation_fn: {v!r} is not one of "
                              f"{', '.join(ACTIVATIONS)}")  # fmt: skip
        if k == "net_arch" and not _is_net_arch(v):
            raise ConfigError(
                "policy_kwargs.net_arch: expected a list of layer sizes or a mapping of them "
                f"(pi/vf/qf), got {v!r}"
            )
    env_kwargs = data.pop("env_kwargs", {}) or {}
    if not isinstance(env_kwargs, dict):
        raise ConfigError(f"env_kwargs: expected a mapping, got {env_kwargs!r}")
    for k in env_kwargs:
        if k not in ENV_KWARGS:
            raise ConfigError(f"env_kwargs.{k}: unknown (allowed: {', '.join(ENV_KWARGS)})")
    eval_cfg = from_dict(EvalConfig, data.pop("eval", {}) or {}, "eval")
    pretrain_cfg = None
    if data.get("pretrain") is not None:
        from wsp_env.training.imitation import PretrainConfig

        pretrain_cfg = from_dict(PretrainConfig, data.pop("pretrain"), "pretrain")
        if pretrain_cfg.steps_per_round < n_envs:
            raise ConfigError(f"pretrain.steps_per_round: {pretrain_cfg.steps_per_round} is "
                              f"fewer than one step of the {n_envs} environments")  # fmt: skip
        if algo not in ("ppo", "a2c"):
            raise ConfigError(
                f"pretrain: a warm start of the actor-critic of ppo or a2c, not {algo}"
            )
        if env_kwargs.get("action_mode", "continuous") != "continuous":
            raise ConfigError("pretrain: needs env_kwargs.action_mode continuous (the teacher's "
                              "actions are valve fractions)")  # fmt: skip
    data.pop("pretrain", None)
    every = _int(data.pop("checkpoint_every_timesteps", 1_000_000), "checkpoint_every_timesteps")
    try:
        cls = _algo_class(algo)
    except ImportError as err:
        raise ConfigError(f"algo: {algo} needs a package that is not installed ({err})") from None
    params = inspect.signature(cls.__init__).parameters
    allowed = set(params) - {"self", *MANAGED}
    hyper = {}
    for k, v in data.items():
        if k not in allowed:
            raise ConfigError(f"{k}: unknown field (neither a trainer field nor a {algo} "
                              f"hyperparameter)")  # fmt: skip
        _check_hyperparameter(k, v, params[k].default)
        hyper[k] = v
    cfg = TrainConfig(algo, n_timesteps, policy, n_envs, frame_stack, seed, normalize,
                      policy_kwargs, hyper, env_kwargs, eval_cfg, every, source,
                      pretrain_cfg)  # fmt: skip
    check_env_kwargs(cfg.env_kwargs)
    reward = cfg.env_kwargs.get("reward") or {}
    if isinstance(reward, dict) and float(reward.get("shaping_decel_mps2", 0.0) or 0.0) > 0.0:
        gamma = float(hyper.get("gamma", params["gamma"].default))
        shaping_gamma = float(reward.get("shaping_gamma", 0.999))
        if abs(gamma - shaping_gamma) > 1e-12:
            raise ConfigError(
                f"env_kwargs.reward.shaping_gamma: {shaping_gamma} differs from the learner's "
                f"gamma {gamma} (the shaping leaves the best policy unchanged only at the "
                "learner's discount)"
            )
    return cfg


SCHEDULABLE = ("learning_rate", "clip_range", "clip_range_vf")


def _check_hyperparameter(name: str, value: Any, default: Any) -> None:
    """Types that SB3 would only trip over inside ``learn``: numbers where the default is a
    number (a ``lin_X`` schedule where SB3 takes one), true/false where it is a flag."""
    if isinstance(value, str) and value.startswith("lin_"):
        if name not in SCHEDULABLE:
            raise ConfigError(f"{name}: a schedule ({value!r}) is not allowed here")
        parse_schedule(value, name)
        return
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{name}: expected true or false, got {value!r}")
    elif isinstance(default, int | float) and default is not None:
        number = isinstance(value, int | float) and not isinstance(value, bool)
        if not number or not math.isfinite(float(value)):
            raise ConfigError(f"{name}: expected a number, got {value!r}")


def _is_net_arch(v: Any) -> bool:
    def sizes(x: Any) -> bool:
        return isinstance(x, list) and all(isinstance(n, int) and n > 0 for n in x)

    return sizes(v) or (isinstance(v, dict) and all(sizes(x) for x in v.values()))


def check_env_kwargs(env_kwargs: dict[str, Any]) -> None:
    """Build one environment from ``env_kwargs``: every field checked by the environment."""
    from wsp_env.core.braking import BrakingCore

    try:
        BrakingCore(1, **env_kwargs)
    except ConfigError as err:
        raise ConfigError(f"env_kwargs.{err}") from None
    except (ValueError, TypeError) as err:
        raise ConfigError(f"env_kwargs: {err}") from None


def _hyperparams(cfg: TrainConfig) -> dict[str, Any]:
    out = {}
    for k, v in cfg.hyperparams.items():
        out[k] = parse_schedule(v, k)
    return out


def _policy_kwargs(cfg: TrainConfig) -> dict[str, Any]:
    import torch

    out = dict(cfg.policy_kwargs)
    if "activation_fn" in out:
        out["activation_fn"] = {
            "tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU,
            "leaky_relu": torch.nn.LeakyReLU, "gelu": torch.nn.GELU,
        }[out["activation_fn"]]  # fmt: skip
    return out


# ---- the training run -----------------------------------------------------------------------


def _make_venv(cfg: TrainConfig) -> Any:
    from wsp_env.agents.sb3_vec import SB3VecEnv

    return SB3VecEnv(num_envs=cfg.n_envs, **cfg.env_kwargs)


def _wrap_normalize(cfg: TrainConfig, venv: Any) -> Any:
    if cfg.normalize is None:
        return venv
    from stable_baselines3.common.vec_env import VecNormalize

    kwargs = {"gamma": float(cfg.hyperparams.get("gamma", 0.99)), **cfg.normalize}
    return VecNormalize(venv, **kwargs)


def _wrap_frame_stack(cfg: TrainConfig, env: Any) -> Any:
    """Stacked frames over the normalised observations (rl-baselines3-zoo's order)."""
    if cfg.frame_stack == 1:
        return env
    from stable_baselines3.common.vec_env import VecFrameStack

    return VecFrameStack(env, cfg.frame_stack)


def _braking_core(env: Any) -> Any:
    """The ``BrakingCore`` under an SB3 env (through VecNormalize if any)."""
    while not hasattr(env, "venv") or not hasattr(env.venv, "core"):
        env = env.venv
    return env.venv.core


def save_policy_files(model: Any, stem: Path, cfg: TrainConfig) -> None:
    """``stem.zip`` (with the run's algorithm and environment settings inside: it loads
    anywhere, ``policy.model_metadata``) and, with normalisation, ``stem.vecnormalize.pkl``."""
    from wsp_env.policy import policy_metadata, write_model_metadata

    model.save(stem.with_suffix(".zip"))
    name = f"{stem.parent.name.removesuffix('.tmp')}/{stem.name}"
    write_model_metadata(stem.with_suffix(".zip"), policy_metadata(cfg.as_yaml_dict(), name))
    norm = model.get_vec_normalize_env()
    if norm is not None:
        norm.save(str(stem.with_suffix(".vecnormalize.pkl")))


def _save_checkpoint(model: Any, cfg: TrainConfig, folder: Path) -> None:
    """Everything a bit-for-bit resume needs, written to a temp folder and renamed."""
    import torch

    tmp = folder.with_name(folder.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    save_policy_files(model, tmp / "model", cfg)
    if cfg.algo in OFF_POLICY:
        model.save_replay_buffer(tmp / "replay_buffer.pkl")
    norm = model.get_vec_normalize_env()
    state = {
        "core": _braking_core(model.get_env()).state_dict(),
        "torch_rng": torch.get_rng_state(),
        "numpy_rng": np.random.get_state(),  # noqa: NPY002 (SB3 draws from numpy's global)
        "python_rng": random.getstate(),
        "norm_returns": None if norm is None else norm.returns.copy(),
        "stacked_obs": _stacked(model.get_env()),
        # RecurrentPPO keeps its rollout's LSTM state out of the model file
        "lstm_states": getattr(model, "_last_lstm_states", None),
        # off-policy algorithms sample random actions from it before learning_starts
        "action_space_rng": model.action_space.np_random.bit_generator.state,
        "num_timesteps": model.num_timesteps,
        "run_total_timesteps": model.run_total_timesteps,
    }
    with (tmp / "state.pkl").open("wb") as fh:
        pickle.dump(state, fh)
    shutil.rmtree(folder, ignore_errors=True)
    tmp.rename(folder)
    older = sorted(
        (int(p.name[5:]), p) for p in folder.parent.glob("step_*") if p.name[5:].isdigit()
    )
    for _, p in older[:-KEEP_CHECKPOINTS]:  # an off-policy replay buffer is large
        shutil.rmtree(p, ignore_errors=True)


def _stacked(env: Any) -> np.ndarray | None:
    """The frame stack's buffer (VecFrameStack is the outermost wrapper), or None."""
    buf = getattr(getattr(env, "stacked_obs", None), "stacked_obs", None)
    return None if buf is None else np.array(buf, copy=True)


def latest_checkpoint(run_dir: Path) -> Path | None:
    found = []
    for p in (run_dir / "checkpoints").glob("step_*"):
        if p.is_dir() and (p / "state.pkl").exists() and p.name[5:].isdigit():
            found.append((int(p.name[5:]), p))
    return max(found)[1] if found else None


def _callbacks(cfg: TrainConfig, out: Path, total: int, progress: bool, state: dict) -> Any:
    """The run's SB3 callbacks (defined here: SB3 is imported only when training)."""
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList

    class EpisodeMetrics(BaseCallback):
        """Per-episode physics metrics and reward terms into SB3's logger (TensorBoard,
        CSV): the safety costs logged apart from the return."""

        def _on_step(self) -> bool:
            for info in self.locals.get("infos", ()):
                m = info.get("metrics")
                if m is None:
                    continue
                self.logger.record_mean("episode/stopping_distance_m", m["stopping_distance_m"])
                self.logger.record_mean("episode/sliding_energy_kJ", m["sliding_energy_kJ"])
                self.logger.record_mean("episode/max_lock_s", m["max_lock_s"])
                self.logger.record_mean("episode/air_litres", m["air_litres"])
                self.logger.record_mean("episode/max_sliding_kmh", m["max_sliding_kmh"])
                self.logger.record_mean("episode/return", m["episode_return"])
                for k, v in m["episode_reward_terms"].items():
                    self.logger.record_mean(f"episode/reward_{k}", v)
                sc = info.get("scenario")
                if sc is not None:  # learning curves split by condition
                    self.logger.record_mean(
                        f"episode_by_rail/{sc['rail']}_stopping_distance_m",
                        m["stopping_distance_m"],
                    )
            return True

    class Periodic(BaseCallback):
        """Checkpoints and validation at rollout boundaries (a clean state to resume from)."""

        def __init__(self) -> None:
            super().__init__()
            self.next_ckpt = _next_multiple(state["start"], cfg.checkpoint_every_timesteps)
            self.next_eval = _next_multiple(state["start"], cfg.eval.every_timesteps)

        def _on_step(self) -> bool:
            return True

        def _on_rollout_start(self) -> None:
            n = self.model.num_timesteps
            if n >= self.next_eval:
                self.next_eval = _next_multiple(n, cfg.eval.every_timesteps)
                state["validator"].evaluate(self.model, self.logger)
            if n >= self.next_ckpt:
                self.next_ckpt = _next_multiple(n, cfg.checkpoint_every_timesteps)
                _save_checkpoint(self.model, cfg, out / "checkpoints" / f"step_{n}")

    class Progress(BaseCallback):
        def _on_training_start(self) -> None:
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=self.model.num_timesteps, unit="step",
                            desc="train", smoothing=0.1, dynamic_ncols=True)  # fmt: skip

        def _on_step(self) -> bool:
            self.bar.n = self.model.num_timesteps
            if self.n_calls % 50 == 0:
                self.bar.refresh()
            return True

        def _on_training_end(self) -> None:
            self.bar.n = self.model.num_timesteps
            self.bar.close()

    cbs = [EpisodeMetrics(), Periodic()]
    if progress:
        cbs.append(Progress())
    return CallbackList(cbs)


def _next_multiple(n: int, every: int) -> int:
    return (n // every + 1) * every


class Validator:
    """The periodic model selection: the current policy and the frozen classical WSP on the
    validation suite, one code path (``evaluation.run_suite``); keeps the best model."""

    def __init__(self, cfg: TrainConfig, out: Path, resume_step: int = 0) -> None:
        from wsp_env.evaluation import load_suite, run_suite
        from wsp_env.policy import make_policy

        self.cfg, self.out = cfg, out
        try:
            self.suite = load_suite(cfg.eval.suite)
        except ConfigError as err:
            raise ConfigError(f"{cfg.source}: eval.suite: {err}") from None
        if self.suite.name in JUDGING_SUITES:
            raise ConfigError(
                f"{cfg.source}: eval.suite: {self.suite.name} judges controllers; selecting "
                "models on it would reward tuning on the judge (use validation)"
            )
        self.vehicle = cfg.env_kwargs.get("vehicle", "uic_z1")
        self.env_kwargs = {k: v for k, v in cfg.env_kwargs.items()
                           if k in ("reward", "rails_config", "substep_s")}  # fmt: skip
        classical, _ = run_suite(self.vehicle, self.suite, make_policy("classical"), record="none",
                                 env_kwargs=self.env_kwargs)  # fmt: skip
        self.classical = summarise_validation(classical)
        self.history: list[dict[str, Any]] = []
        self.best: dict[str, Any] | None = None
        hist = out / "validation.json"
        if hist.exists():  # a resumed run keeps its history up to where it resumes
            saved = json.loads(hist.read_text())
            self.history = [h for h in saved["history"] if h["timesteps"] <= resume_step]
            self.best = max(self.history, key=_rank) if self.history else None

    def evaluate(self, model: Any, logger: Any = None) -> dict[str, Any]:
        from wsp_env.evaluation import run_suite
        from wsp_env.policy import SB3Policy

        policy = SB3Policy.from_model(
            model, self.cfg.env_kwargs, name="current", n_stack=self.cfg.frame_stack
        )
        kwargs = {**self.env_kwargs, **policy.env_kwargs}
        results, _ = run_suite(self.vehicle, self.suite, policy, record="none", env_kwargs=kwargs)
        row = {"timesteps": int(model.num_timesteps), **summarise_validation(results)}
        row["stop_vs_classical"] = row["mean_stopping_distance_m"] / max(
            self.classical["mean_stopping_distance_m"], 1e-9
        )
        self.history.append(row)
        if self.best is None or _better(row, self.best):
            self.best = row
            save_policy_files(model, self.out / "best_model", self.cfg)
        if logger is not None:
            for k in ("mean_stopping_distance_m", "passed", "mean_sliding_energy_kJ",
                      "stop_vs_classical"):  # fmt: skip
                logger.record(f"validation/{k}", row[k])
        payload = {"suite": self.suite.name, "classical": self.classical,
                   "history": self.history, "best": self.best}  # fmt: skip
        from wsp_env.files import write_json

        write_json(self.out / "validation.json", payload)
        return row


def summarise_validation(results: list[dict[str, Any]]) -> dict[str, Any]:
    stops = [r["stopping_distance_m"] for r in results]
    return {
        "runs": len(results),
        "passed": sum(bool(r["passed"]) for r in results),
        "mean_stopping_distance_m": statistics.fmean(stops),
        "mean_sliding_energy_kJ": statistics.fmean(r["sliding_energy_kJ"] for r in results),
        "max_lock_s": max(r["max_lock_s"] for r in results),
        "mean_air_litres": statistics.fmean(r["air_litres"] for r in results),
        "stop_vs_classical": float("nan"),
    }


def _rank(row: dict[str, Any]) -> tuple[int, float]:
    """More runs passing the criteria, then the shorter mean stop."""
    return (row["passed"], -row["mean_stopping_distance_m"])


def _better(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return _rank(a) > _rank(b)


def train(
    config: str | Path | TrainConfig | None,
    out: str | Path,
    seed: int | None = None,
    resume: str | Path | None = None,
    total_timesteps: int | None = None,
    progress: bool = True,
    chunk_timesteps: int | None = None,
) -> dict[str, Any]:
    """Train (or resume) a run; returns ``train.json``'s content (DESIGN §8).

    ``config``: a path, a built-in name or a ``TrainConfig`` (ignored when resuming: the run's
    own ``config.yaml`` is used). ``seed`` overrides the config's. ``total_timesteps``: the
    run's total, which the schedules run over (default the config's ``n_timesteps``; a resumed
    run keeps the total it was started with unless given another). ``chunk_timesteps``: stop
    after about this many steps (at the next rollout boundary) with a checkpoint, to go on
    with ``resume``: chunks resumed in turn give the run trained in one go, bit for bit.
    """
    import torch
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import VecNormalize

    out = Path(out)
    if resume is not None:
        resume = Path(resume)
        ckpt = latest_checkpoint(resume)
        if ckpt is None:
            raise ConfigError(f"{resume}: no checkpoint to resume from (checkpoints/step_N)")
        cfg = parse_train_config(read_yaml(resume / CONFIG_NAME), str(resume / CONFIG_NAME))
        if out.resolve() != resume.resolve() and out.exists() and any(out.iterdir()):
            raise ConfigError(f"{out}: exists and is not empty; not overwriting")
    else:
        if config is None:
            raise ConfigError("--config: required unless --resume")
        cfg = config if isinstance(config, TrainConfig) else load_train_config(config)
        if seed is not None:
            cfg = dataclasses.replace(cfg, seed=seed)
        if out.exists() and any(out.iterdir()):
            raise ConfigError(f"{out}: exists and is not empty (use --resume {out} to continue)")
    cls = _run_class(cfg.algo)
    venv = _make_venv(cfg)
    started = time.perf_counter()
    if resume is not None:
        with (ckpt / "state.pkl").open("rb") as fh:
            state = pickle.load(fh)
        _braking_core(venv).load_state_dict(state["core"])
        env: Any = venv
        if cfg.normalize is not None:
            env = VecNormalize.load(str(ckpt / "model.vecnormalize.pkl"), venv)
            env.returns = state["norm_returns"]
        env = _wrap_frame_stack(cfg, env)
        if state.get("stacked_obs") is not None:
            env.stacked_obs.stacked_obs[...] = state["stacked_obs"]
        model = cls.load(ckpt / "model.zip", env=env, device="cpu", force_reset=False)
        if cfg.algo in OFF_POLICY:
            model.load_replay_buffer(ckpt / "replay_buffer.pkl")
        if state.get("lstm_states") is not None:
            model._last_lstm_states = state["lstm_states"]
        start = int(model.num_timesteps)
        total = int(total_timesteps or state["run_total_timesteps"])
    else:
        total = int(total_timesteps or cfg.n_timesteps)
        env = _wrap_frame_stack(cfg, _wrap_normalize(cfg, venv))
        try:
            model = cls(cfg.policy, env, seed=cfg.seed, policy_kwargs=_policy_kwargs(cfg) or None,
                        device="cpu", verbose=0, **_hyperparams(cfg))  # fmt: skip
        except (AssertionError, TypeError, ValueError) as err:  # SB3's own checks
            raise ConfigError(f"{cfg.source}: {cfg.algo} hyperparameters: {err}") from None
        start = 0
    model.run_total_timesteps = total
    # the validation suite is checked (and the classical WSP run on it) before anything is
    # written; a resumed run's history is read from the folder it resumes
    validator = Validator(cfg, resume if resume is not None else out, resume_step=start)
    validator.out = out
    if resume is None:
        out.mkdir(parents=True, exist_ok=True)
        (out / CONFIG_NAME).write_text(yaml.safe_dump(cfg.as_yaml_dict(), sort_keys=False))
    elif out.resolve() != resume.resolve():
        shutil.copytree(resume, out, dirs_exist_ok=True)
    if resume is not None:  # last: nothing above may draw from what the run draws from
        torch.set_rng_state(state["torch_rng"])
        np.random.set_state(state["numpy_rng"])  # noqa: NPY002 (SB3 draws from numpy's global)
        random.setstate(state["python_rng"])
        if state.get("action_space_rng") is not None:
            model.action_space.np_random.bit_generator.state = state["action_space_rng"]
    pretrained = None
    try:
        if resume is None and cfg.pretrain is not None:
            from wsp_env.files import write_json
            from wsp_env.training.imitation import pretrain

            gamma = float(cfg.hyperparams.get("gamma", 0.99))
            t0 = time.perf_counter()
            pretrained = pretrain(model, env, _braking_core(venv), cfg.pretrain, gamma)
            pretrained["wall_time_s"] = time.perf_counter() - t0
            pretrained["validation"] = validator.evaluate(model)  # the warm start, at step 0
            write_json(out / "pretrain.json", pretrained)
        formats = ["csv"] + (["tensorboard"] if _have_tensorboard() else [])
        model.set_logger(configure(str(out / "logs" / f"from_step_{start}"), formats))
        callbacks = _callbacks(cfg, out, total, progress, {"start": start, "validator": validator})
        remaining = max(total - start, 0)
        if chunk_timesteps is not None:
            remaining = min(remaining, chunk_timesteps)
        if remaining:
            model.learn(remaining, callback=callbacks, reset_num_timesteps=False,
                        log_interval=10 if cfg.algo in OFF_POLICY else 1)  # fmt: skip
        wall = time.perf_counter() - started
        learn_wall = wall - (pretrained["wall_time_s"] if pretrained is not None else 0.0)
        steps = int(model.num_timesteps) - start
        final = validator.evaluate(model)
        save_policy_files(model, out / "model", cfg)
        _save_checkpoint(model, cfg, out / "checkpoints" / f"step_{model.num_timesteps}")
        _merge_progress(out)
        result = {
            "model_path": str(out / "best_model.zip"),
            "final_model_path": str(out / "model.zip"),
            "algo": cfg.algo,
            "total_timesteps": int(model.num_timesteps),
            "run_total_timesteps": total,
            "finished": int(model.num_timesteps) >= total,
            "timesteps_this_call": steps,
            "wall_time_s": wall,
            "env_steps_per_s": steps / learn_wall if learn_wall > 0 else 0.0,
            "seed": cfg.seed,
            "resumed_from": start if resume is not None else None,
            "best_validation": validator.best,
            "final_validation": final,
            "classical_validation": validator.classical,
            "validation_suite": validator.suite.name,
        }
        if pretrained is not None:
            result["pretrain_env_steps"] = pretrained["env_steps"]
            result["pretrain_wall_time_s"] = pretrained["wall_time_s"]
        from wsp_env.files import write_json

        write_json(out / "train.json", result)
        return result
    except BaseException:
        # a fresh run that ends before its first checkpoint leaves no folder behind (it could
        # neither be resumed nor started again in place)
        if resume is None and latest_checkpoint(out) is None:
            shutil.rmtree(out, ignore_errors=True)
        raise


def _merge_progress(out: Path) -> None:
    """``progress.csv``: the CSV logs of every call of the run (``logs/from_step_N``), in order."""
    import csv

    parts = sorted(
        (int(p.name.rsplit("_", 1)[1]), p / "progress.csv")
        for p in (out / "logs").glob("from_step_*")
        if (p / "progress.csv").exists() and p.name.rsplit("_", 1)[1].isdigit()
    )
    rows: list[dict[str, str]] = []
    names: dict[str, None] = {}
    for _, path in parts:
        with path.open(newline="") as fh:
            reader = csv.DictReader(fh)
            names.update(dict.fromkeys(reader.fieldnames or ()))
            rows.extend(reader)
    from wsp_env.files import write_atomically

    def write(fh: Any) -> None:
        w = csv.DictWriter(fh, fieldnames=list(names))
        w.writeheader()
        w.writerows(rows)

    write_atomically(out / "progress.csv", write)


def _have_tensorboard() -> bool:
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        return False
    return True


__all__ = [
    "LinearSchedule",
    "TrainConfig",
    "Validator",
    "latest_checkpoint",
    "load_train_config",
    "parse_train_config",
    "save_policy_files",
    "train",
]

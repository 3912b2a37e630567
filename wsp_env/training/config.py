"""``wsp-env train``'s config (``configs/train/NAME.yaml``): parsing and checking every field
before anything runs (a mistake is one line naming the file and field), the algorithm classes
and the keyword arguments the config gives them. The format is described in ``train.py``'s
docstring and ``docs/training.md``.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

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
    "accelerometer", "accelerometer_bias_mps2", "sensors", "estimator", "watchdog", "reward",
    "scenario", "rails_config",
    "control_period_s", "substep_s", "max_time_s", "action_repeat",
    "slip_target_min_kmh", "slip_target_max_kmh", "slip_target_gain_per_kmh",
    "slip_target_lead_s", "slip_target_release", "slip_target_max_creep",
    "slip_target_drift_correction", "slip_target_gain_scale_floor", "slip_target_onset_drift",
    "slip_target_scale_calibration", "slip_target_onset_two_sided", "slip_target_lock_guard",
    "memory_features", "memory_target_mean",
    "stagger_reset_steps",
)  # fmt: skip
SCHEDULE = re.compile(r"^lin_([0-9.eE+-]+)$")
JUDGING_SUITES = ("heldout", "en15595")  # never used for model selection


# ---- config ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class EvalConfig:
    """When the model is selected and the learning curve measured (``docs/training.md``).

    ``every_timesteps``: the validation suite runs (model selection); ``first_timesteps``: the
    first validation and the first checkpoint (0: a tenth of ``n_timesteps`` or
    ``every_timesteps``, whichever is sooner, so a run stopped early leaves something).
    ``curve_every_timesteps`` / ``curve_runs``: the fixed-seed learning curve, the first
    ``curve_runs`` runs of the suite, deterministic, the same stops every time (0: curve off)."""

    suite: str = "validation"
    every_timesteps: int = field(default=500_000, metadata={"gt": 0})
    first_timesteps: int = field(default=0, metadata={"ge": 0})
    curve_every_timesteps: int = field(default=250_000, metadata={"ge": 0})
    curve_runs: int = field(default=8, metadata={"gt": 0})
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
    stop_weight: Any = None  # stop_weight.StopWeightConfig: the learner's reward weighted per stop

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
        if self.stop_weight is not None:
            out["stop_weight"] = dataclasses.asdict(self.stop_weight)
        return out


def _algo_class(name: str) -> type:
    if name in ("recurrent_ppo", "tqc"):
        import sb3_contrib

        return {"recurrent_ppo": sb3_contrib.RecurrentPPO, "tqc": sb3_contrib.TQC}[name]
    import stable_baselines3 as sb3

    return {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3, "a2c": sb3.A2C}[name]


_RUN_CLASSES: dict[str, type] = {}


def algo_class(name: str) -> type:
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


def config_teacher_table(path: str | Path) -> dict[str, float]:
    """The rail table (``pretrain.teacher_targets_kmh``, km/h by rail) of the training config
    at ``path``, checked as ``load_train_config`` checks it; a one-line ``ConfigError`` naming
    the file where the config is bad or names no table."""
    cfg = load_train_config(path)
    table = cfg.pretrain.teacher_targets_kmh if cfg.pretrain is not None else None
    if not table:
        raise ConfigError(f"{path}: no pretrain.teacher_targets_kmh (the rail teacher's table)")
    return dict(table)


def config_teacher_creep(path: str | Path) -> tuple[dict[str, float], float]:
    """The rail teacher's creep schedules of the training config at ``path``
    (``pretrain.teacher_creep``, rail -> creep; empty where it has none) and their floor
    (``pretrain.teacher_creep_floor_kmh``), checked as ``load_train_config`` checks them."""
    from wsp_env.training.imitation import PretrainConfig

    cfg = load_train_config(path)
    pre = cfg.pretrain if cfg.pretrain is not None else PretrainConfig()
    return dict(pre.teacher_creep or {}), float(pre.teacher_creep_floor_kmh)


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
    if algo in OFF_POLICY and frame_stack > 1 and normalize is not None:
        # SB3's off-policy learners store VecNormalize's original observation, which under the
        # frame stack is one frame where the replay buffer holds the stack
        raise ConfigError(
            f"frame_stack: {frame_stack} with normalize is not supported for {algo} (its replay "
            "buffer stores the un-normalised observation, one frame under the stack); use "
            "frame_stack 1 (memory_features give the WSP's history) or normalize: false"
        )
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
    if eval_cfg.first_timesteps >= eval_cfg.every_timesteps:
        raise ConfigError(
            f"eval.first_timesteps: {eval_cfg.first_timesteps} is not before the first "
            f"multiple of eval.every_timesteps ({eval_cfg.every_timesteps}); 0: automatic"
        )
    pretrain_cfg = None
    if data.get("pretrain") is not None:
        from wsp_env.training.imitation import TARGET_TEACHERS, PretrainConfig

        pretrain_cfg = from_dict(PretrainConfig, data.pop("pretrain"), "pretrain")
        if pretrain_cfg.steps_per_round < n_envs:
            raise ConfigError(f"pretrain.steps_per_round: {pretrain_cfg.steps_per_round} is "
                              f"fewer than one step of the {n_envs} environments")  # fmt: skip
        if algo not in ("ppo", "a2c"):
            raise ConfigError(
                f"pretrain: a warm start of the actor-critic of ppo or a2c, not {algo}"
            )
        mode = env_kwargs.get("action_mode", "continuous")
        if pretrain_cfg.teacher_targets_kmh is not None:
            _check_teacher_table(pretrain_cfg, env_kwargs)
        if pretrain_cfg.teacher_creep is not None:
            _check_teacher_creep(pretrain_cfg)
        if pretrain_cfg.teacher in TARGET_TEACHERS:
            if mode != "slip_target":
                raise ConfigError(
                    f"pretrain.teacher: {pretrain_cfg.teacher} gives slip targets; needs "
                    f"env_kwargs.action_mode slip_target, not {mode}"
                )
        else:
            if mode != "continuous":
                raise ConfigError(f"pretrain: needs env_kwargs.action_mode continuous (the "
                                  f"teacher's actions are valve fractions), not {mode}; "
                                  f"oracle_target_rail teaches slip targets")  # fmt: skip
            if env_kwargs.get("action_repeat", 1) != 1:
                raise ConfigError("pretrain: the teacher acts every control period; drop "
                                  "env_kwargs.action_repeat or the warm start")  # fmt: skip
    data.pop("pretrain", None)
    stop_weight_cfg = None
    if data.get("stop_weight") is not None:
        from wsp_env.training.stop_weight import StopWeightConfig

        raw = data.pop("stop_weight")
        stop_weight_cfg = from_dict(StopWeightConfig, {} if raw is True else raw, "stop_weight")
        if stop_weight_cfg.min_weight > stop_weight_cfg.max_weight:
            raise ConfigError(f"stop_weight.min_weight: {stop_weight_cfg.min_weight} is above "
                              f"max_weight {stop_weight_cfg.max_weight}")  # fmt: skip
    data.pop("stop_weight", None)
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
                      pretrain_cfg, stop_weight_cfg)  # fmt: skip
    check_env_kwargs(cfg.env_kwargs)
    reward = cfg.env_kwargs.get("reward") or {}
    if isinstance(reward, dict) and float(reward.get("shaping_decel_mps2", 0.0) or 0.0) > 0.0:
        if cfg.env_kwargs.get("action_repeat", 1) != 1:
            raise ConfigError(
                "env_kwargs.reward.shaping_decel_mps2: the shaping is written per control "
                "period; with action_repeat its sum over a step no longer leaves the best "
                "policy unchanged (drop one of them)"
            )
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
# counts SB3 only trips over inside ``learn`` (n_epochs 0: an unbound local in PPO.train)
POSITIVE_COUNTS = ("n_steps", "batch_size", "n_epochs", "buffer_size")


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
        if name in POSITIVE_COUNTS and (not isinstance(value, int) or value < 1):
            raise ConfigError(f"{name}: expected a whole number >= 1, got {value!r}")


def _is_net_arch(v: Any) -> bool:
    def sizes(x: Any) -> bool:
        return isinstance(x, list) and all(isinstance(n, int) and n > 0 for n in x)

    return sizes(v) or (isinstance(v, dict) and all(sizes(x) for x in v.values()))


def check_env_kwargs(env_kwargs: dict[str, Any]) -> None:
    """Build one environment from ``env_kwargs``: every field checked by the environment."""
    from wsp_env.envs import check_action_repeat, check_stagger_reset_steps, make_core

    kwargs = dict(env_kwargs)
    # the environments' own, not the core's: the repeat, and the vector env's staggered resets
    for name, check in (
        ("action_repeat", check_action_repeat),
        ("stagger_reset_steps", check_stagger_reset_steps),
    ):
        if name in kwargs:
            try:
                check(kwargs.pop(name))
            except ValueError as err:
                raise ConfigError(f"env_kwargs.{err}") from None
    try:
        make_core(1, **kwargs)
    except ConfigError as err:
        raise ConfigError(f"env_kwargs.{err}") from None
    except (ValueError, TypeError) as err:
        raise ConfigError(f"env_kwargs: {err}") from None


def algo_hyperparams(cfg: TrainConfig) -> dict[str, Any]:
    out = {}
    for k, v in cfg.hyperparams.items():
        out[k] = parse_schedule(v, k)
    return out


def algo_policy_kwargs(cfg: TrainConfig) -> dict[str, Any]:
    import torch

    out = dict(cfg.policy_kwargs)
    if "activation_fn" in out:
        out["activation_fn"] = {
            "tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU,
            "leaky_relu": torch.nn.LeakyReLU, "gelu": torch.nn.GELU,
        }[out["activation_fn"]]  # fmt: skip
    return out


def _check_teacher_table(pretrain_cfg: Any, env_kwargs: dict[str, Any]) -> None:
    """``pretrain.teacher_targets_kmh``: only for a slip-target teacher; one target for every
    rail the scenario draws (a rail of weight 0 may have one) and none for a rail it does not
    name; each within the slip-target mode's range (``env_kwargs.slip_target_min_kmh`` ..
    ``slip_target_max_kmh``; a malformed scenario or range is the environment's to refuse)."""
    from wsp_env.core.braking import ScenarioConfig
    from wsp_env.training.imitation import TARGET_TEACHERS

    where = "pretrain.teacher_targets_kmh"
    table = pretrain_cfg.teacher_targets_kmh
    if pretrain_cfg.teacher not in TARGET_TEACHERS:
        teachers = ", ".join(TARGET_TEACHERS)
        raise ConfigError(f"{where}: a table for a slip-target teacher ({teachers}), "
                          f"not {pretrain_cfg.teacher}")  # fmt: skip
    scenario = env_kwargs.get("scenario") or {}
    rails = scenario.get("rails") if isinstance(scenario, dict) else None
    weights = rails if isinstance(rails, dict) else ScenarioConfig().rails
    named = sorted(weights)
    drawn = [r for r in named if not _number(weights[r]) or weights[r] > 0]
    missing = [r for r in drawn if r not in table]
    if missing:
        raise ConfigError(f"{where}: no target for rail {missing[0]} (the scenario draws "
                          f"{', '.join(drawn)})")  # fmt: skip
    extra = sorted(set(table) - set(named))
    if extra:
        raise ConfigError(f"{where}.{extra[0]}: not a rail the scenario names "
                          f"({', '.join(named)})")  # fmt: skip
    lo = env_kwargs.get("slip_target_min_kmh", 0.5)
    hi = env_kwargs.get("slip_target_max_kmh", 8.0)
    if not (_number(lo) and _number(hi)):
        return
    for rail, kmh in table.items():
        if not lo <= kmh <= hi:
            raise ConfigError(f"{where}.{rail}: {kmh} km/h is outside the slip-target range "
                              f"{lo:g}-{hi:g} km/h")  # fmt: skip


def _check_teacher_creep(pretrain_cfg: Any) -> None:
    """``pretrain.teacher_creep``: only beside a rail table (``teacher_targets_kmh``), and only
    for rails the table names (each value's range is the field's own check)."""
    where = "pretrain.teacher_creep"
    table = pretrain_cfg.teacher_targets_kmh
    if table is None:
        raise ConfigError(f"{where}: needs pretrain.teacher_targets_kmh (the rail table whose "
                          "targets it schedules)")  # fmt: skip
    extra = sorted(set(pretrain_cfg.teacher_creep) - set(table))
    if extra:
        raise ConfigError(f"{where}.{extra[0]}: not a rail of pretrain.teacher_targets_kmh "
                          f"({', '.join(sorted(table))})")  # fmt: skip


def _number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)

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
  refused: it is for final comparisons only), ``every_timesteps`` and ``first_timesteps`` (the
  first validation and checkpoint, early by default) — and the fixed-seed learning curve
  (``curve_every_timesteps``, ``curve_runs``: ``LearningCurve``);
* ``checkpoint_every_timesteps``;
* ``pretrain`` (``imitation.PretrainConfig``), the imitation warm start, and ``stop_weight``
  (``stop_weight.StopWeightConfig``), the learner's reward weighted per stop.

**Threads** (``wsp_env.threads``, role ``train``): the kernel serial below 8 cores, torch with
1 thread while collecting and the measured best count while updating (``thread_switch``).

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
``checkpoints/step_N/``, ``validation.json`` (every evaluation), ``curve.json`` (the
learning curve); with ``pretrain:``, ``pretrain.json`` (each imitation round) and
``student.zip`` + ``student.vecnormalize.pkl`` (the imitation start as handed over to RL);
``logs/from_step_N/`` (each
call's TensorBoard events and CSV), ``progress.csv`` (all calls' CSV rows), ``train.json`` (the
result, DESIGN §8).
"""

from __future__ import annotations

import dataclasses
import json
import pickle
import random
import shutil
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from wsp_env.core.config import ConfigError, load_vehicle, read_yaml
from wsp_env.threads import AdaptiveThreads, ThreadPolicy, thread_policy
from wsp_env.threads import applied as applied_threads
from wsp_env.training.config import (
    JUDGING_SUITES,
    OFF_POLICY,
    LinearSchedule,
    TrainConfig,
    algo_class,
    algo_hyperparams,
    algo_policy_kwargs,
    load_train_config,
    parse_train_config,
)

CONFIG_NAME = "config.yaml"
KEEP_CHECKPOINTS = 3  # the newest ones; the best model is kept apart (best_model.zip)


# ---- the training run -----------------------------------------------------------------------


def _make_venv(cfg: TrainConfig) -> Any:
    from wsp_env.agents.sb3_vec import SB3VecEnv

    venv = SB3VecEnv(num_envs=cfg.n_envs, **cfg.env_kwargs)
    if cfg.stop_weight is None:
        return venv
    from wsp_env.training.stop_weight import StopWeightedReward

    return StopWeightedReward(venv, cfg.stop_weight)


def make_training_env(cfg: TrainConfig) -> Any:
    """The environment a fresh run of ``cfg`` trains on: the native vector env through
    ``SB3VecEnv``, ``VecNormalize`` and frame stacking as the config asks (``wsp-env bench
    --train`` measures exactly this)."""
    return _wrap_frame_stack(cfg, _wrap_normalize(cfg, _make_venv(cfg)))


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


def _adapter(env: Any) -> Any:
    """The ``SB3VecEnv`` under an SB3 env's wrappers."""
    from wsp_env.agents.sb3_vec import SB3VecEnv

    while not isinstance(env, SB3VecEnv):
        if not hasattr(env, "venv"):
            raise TypeError(f"{type(env).__name__}: no SB3VecEnv under this training env")
        env = env.venv
    return env


def _braking_core(env: Any) -> Any:
    """The ``BrakingCore`` under an SB3 env (through VecNormalize if any)."""
    return _adapter(env).venv.core


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


def _save_checkpoint(model: Any, cfg: TrainConfig, folder: Path, handover: Any = None) -> None:
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
        # the stops' counters: steps towards the time limit, the episode statistics
        "adapter": _adapter(model.get_env()).state_dict(),
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
        # the imitation start a fine-tune is pulled towards (imitation.HandOver)
        "handover": None if handover is None else handover.state(),
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


def thread_switch(adaptive: AdaptiveThreads) -> Any:
    """An SB3 callback that gives torch the rollout's thread count while collecting and
    ``adaptive``'s measured best one while updating (``threads.AdaptiveThreads``). Put it first
    in a callback list: validation and checkpoints at a rollout's start are then not timed as
    part of the update."""
    from stable_baselines3.common.callbacks import BaseCallback

    class ThreadSwitch(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.updating = False

        def _on_step(self) -> bool:
            return True

        def _on_rollout_end(self) -> None:  # the update follows
            adaptive.begin_update()
            self.updating = True

        def _on_rollout_start(self) -> None:
            self._end()

        def _on_training_end(self) -> None:
            self._end()

        def _end(self) -> None:
            if self.updating:
                adaptive.end_update()
                self.updating = False

    return ThreadSwitch()


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
            first = first_timesteps(cfg, total)
            self.next_ckpt = next_due(state["start"], first, cfg.checkpoint_every_timesteps)
            self.next_eval = next_due(state["start"], first, cfg.eval.every_timesteps)
            curve_every = cfg.eval.curve_every_timesteps
            # the curve's points: the first rollout start at or past each multiple of its
            # cadence, step 0 included (the untrained or imitation policy); a call that ends
            # with a point due takes it there (curve_due), so a resumed run's rows are the
            # one-go run's
            start, self.next_curve = state["start"], None
            if curve_every:
                due = curve_due(state["curve"].history, start, curve_every)
                self.next_curve = start if due else next_due(start, 0, curve_every)

        def _on_step(self) -> bool:
            return True

        def _on_rollout_start(self) -> None:
            n = self.model.num_timesteps
            first = first_timesteps(cfg, total)
            if self.next_curve is not None and n >= self.next_curve:
                self.next_curve = next_due(n, 0, cfg.eval.curve_every_timesteps)
                state["curve"].evaluate(self.model, self.logger)
            if n >= self.next_eval:
                self.next_eval = next_due(n, first, cfg.eval.every_timesteps)
                state["validator"].evaluate(self.model, self.logger)
            if n >= self.next_ckpt:
                self.next_ckpt = next_due(n, first, cfg.checkpoint_every_timesteps)
                _save_checkpoint(self.model, cfg, out / "checkpoints" / f"step_{n}",
                                 state["handover"])  # fmt: skip

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

    class HandOverSteps(BaseCallback):
        """The hand-over's critic-only warm-up before each update and its pull towards the
        imitation start after it (on the update's own observations, kept at the rollout's
        end: the buffer is emptied before the next rollout starts)."""

        def __init__(self) -> None:
            super().__init__()
            self.observations: np.ndarray | None = None

        def _on_step(self) -> bool:
            return True

        def _on_rollout_end(self) -> None:
            buffer = getattr(self.model, "rollout_buffer", None)
            obs = getattr(buffer, "observations", None)
            self.observations = None if obs is None else np.array(obs, copy=True)
            state["handover"].before_update(self.model)

        def _on_rollout_start(self) -> None:
            self._after()

        def _on_training_end(self) -> None:
            self._after()

        def _after(self) -> None:
            if self.observations is None:
                return
            moved = state["handover"].after_update(self.model, self.observations)
            if moved is not None:
                self.logger.record("handover/anchor_mse", moved)
            self.logger.record(
                "handover/anchor_weight", state["handover"].anchor_weight(self.model.num_timesteps)
            )
            self.observations = None

    cbs = [thread_switch(state["threads"])]
    if state.get("handover") is not None:
        cbs.append(HandOverSteps())
    cbs += [EpisodeMetrics(), Periodic()]
    if progress:
        cbs.append(Progress())
    return CallbackList(cbs)


def first_timesteps(cfg: TrainConfig, total: int) -> int:
    """The first validation's and checkpoint's step: ``eval.first_timesteps``, or (0) a tenth
    of the run's total or ``eval.every_timesteps``, whichever is sooner."""
    if cfg.eval.first_timesteps:
        return cfg.eval.first_timesteps
    return max(1, min(cfg.eval.every_timesteps, total // 10))


def curve_due(history: list[dict[str, Any]], n: int, every: int) -> bool:
    """Whether the learning curve owes a point at step ``n``: none taken at or after the last
    multiple of ``every`` up to ``n``."""
    mark = (n // every) * every
    return not any(h["timesteps"] >= mark for h in history)


def next_due(n: int, first: int, every: int) -> int:
    """The first step after ``n`` in the schedule ``first, every, 2 every, ...`` (``first`` 0 or
    at least ``every``: the multiples of ``every``)."""
    if n < first < every:
        return first
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


class LearningCurve:
    """The fixed-seed learning curve: the current policy, deterministic, on the first
    ``eval.curve_runs`` runs of the validation suite (the same stops every time), beside the
    classical WSP's constant line and locked wheels (the score's ends, as the benchmark's:
    ``evaluation.benchmark.score``). Rows go to ``curve.json`` and the logger (``curve/*``);
    unlike SB3's rollout means, no row depends on which episodes happened to end."""

    def __init__(self, validator: Validator, resume_step: int = 0) -> None:
        from wsp_env.evaluation import expand
        from wsp_env.evaluation.runner import run_runs
        from wsp_env.policy import make_policy

        self.validator = validator
        cfg = validator.cfg
        veh = load_vehicle(validator.vehicle)
        self.runs = expand(validator.suite, veh)[: cfg.eval.curve_runs]
        self.vehicle = veh
        ends = {}
        for name in ("none", "classical"):
            res, _ = run_runs(veh, self.runs, make_policy(name), env_kwargs=validator.env_kwargs)
            ends[name] = res
        self.none = np.array([r["return"] for r in ends["none"]])
        self.classical_results = ends["classical"]
        self.classical = self._row(ends["classical"])
        self.history: list[dict[str, Any]] = []
        path = validator.out / "curve.json"
        if path.exists():  # a resumed run keeps its curve up to where it resumes
            saved = json.loads(path.read_text())
            self.history = [h for h in saved["history"] if h["timesteps"] <= resume_step]

    def _row(self, results: list[dict[str, Any]]) -> dict[str, Any]:
        from wsp_env.evaluation.benchmark import score

        r = np.array([x["return"] for x in results])
        sc = score(r, self.none, np.array([x["return"] for x in self.classical_results]))
        stops = np.array([x["stopping_distance_m"] for x in results])
        cls_stops = np.array([x["stopping_distance_m"] for x in self.classical_results])
        return {
            "score": sc["score"],
            "score_mean": sc.get("score_mean"),
            "scored_runs": sc["scored_runs"],
            "mean_return": float(r.mean()),
            "mean_stopping_distance_m": float(stops.mean()),
            "stop_vs_classical": float(stops.mean() / max(cls_stops.mean(), 1e-9)),
            "passed": int(sum(bool(x["passed"]) for x in results)),
            "watchdog_runs": int(sum(x["watchdog"]["total"] > 0 for x in results)),
        }

    def evaluate(self, model: Any, logger: Any = None) -> dict[str, Any]:
        from wsp_env.evaluation.runner import run_runs
        from wsp_env.files import write_json
        from wsp_env.policy import SB3Policy

        v = self.validator
        policy = SB3Policy.from_model(model, v.cfg.env_kwargs, name="current",
                                      n_stack=v.cfg.frame_stack)  # fmt: skip
        kwargs = {**v.env_kwargs, **policy.env_kwargs}
        res, _ = run_runs(self.vehicle, self.runs, policy, env_kwargs=kwargs)
        row = {"timesteps": int(model.num_timesteps), **self._row(res)}
        self.history.append(row)
        if logger is not None:
            for k in ("score", "mean_return", "mean_stopping_distance_m", "stop_vs_classical",
                      "passed"):  # fmt: skip
                if row[k] is not None:
                    logger.record(f"curve/{k}", row[k])
        payload = {"suite": v.suite.name, "runs": [r.seed for r in self.runs],
                   "cases": [r.scenario for r in self.runs], "classical": self.classical,
                   "history": self.history}  # fmt: skip
        write_json(v.out / "curve.json", payload)
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
    # the thread policy for a learner in this process, for the run only (wsp_env.threads);
    # before the environments are built: the kernel's serial or parallel path is chosen then
    with applied_threads(thread_policy("train")) as policy_threads:
        return _train(config, out, seed, resume, total_timesteps, progress, chunk_timesteps,
                      policy_threads)  # fmt: skip


def _train(
    config: str | Path | TrainConfig | None,
    out: str | Path,
    seed: int | None,
    resume: str | Path | None,
    total_timesteps: int | None,
    progress: bool,
    chunk_timesteps: int | None,
    policy_threads: ThreadPolicy,
) -> dict[str, Any]:
    from wsp_env.policy import require_extras

    require_extras("training needs", "rl")  # one line, before the config (its checks use SB3)
    import torch
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import VecNormalize

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{out}: exists and is not a folder (the run folder)")
    if resume is not None:
        resume = Path(resume)
        ckpt = latest_checkpoint(resume)
        if ckpt is None:
            raise ConfigError(f"{resume}: no checkpoint to resume from (checkpoints/step_N)")
        cfg = parse_train_config(read_yaml(resume / CONFIG_NAME), str(resume / CONFIG_NAME))
        cfg = pin_loop_settings(cfg, started_before=True)
        if out.resolve() != resume.resolve() and out.exists() and any(out.iterdir()):
            raise ConfigError(f"{out}: exists and is not empty; not overwriting")
    else:
        if config is None:
            raise ConfigError("--config: required unless --resume")
        cfg = config if isinstance(config, TrainConfig) else load_train_config(config)
        if seed is not None:
            cfg = dataclasses.replace(cfg, seed=seed)
        cfg = pin_loop_settings(cfg, started_before=False)
        if out.exists() and any(out.iterdir()):
            raise ConfigError(f"{out}: exists and is not empty (use --resume {out} to continue)")
    cls = algo_class(cfg.algo)
    venv = _make_venv(cfg)
    started = time.perf_counter()
    if resume is not None:
        with (ckpt / "state.pkl").open("rb") as fh:
            state = pickle.load(fh)
        _braking_core(venv).load_state_dict(state["core"])
        if state.get("adapter") is not None:  # checkpoints from 2026-11-26 on
            _adapter(venv).load_state_dict(state["adapter"])
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
            kwargs = algo_policy_kwargs(cfg) or None
            model = cls(cfg.policy, env, seed=cfg.seed, policy_kwargs=kwargs, device="cpu",
                        verbose=0, **algo_hyperparams(cfg))  # fmt: skip
        except (AssertionError, TypeError, ValueError) as err:  # SB3's own checks
            raise ConfigError(f"{cfg.source}: {cfg.algo} hyperparameters: {err}") from None
        start = 0
    model.run_total_timesteps = total
    # the validation suite is checked (and the classical WSP run on it) before anything is
    # written; a resumed run's history is read from the folder it resumes
    validator = Validator(cfg, resume if resume is not None else out, resume_step=start)
    curve = LearningCurve(validator, start) if cfg.eval.curve_every_timesteps else None
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
            # the imitation start as handed over, beside what RL makes of it (``model``,
            # ``best_model``): item 4 of issue 23 compares the two on the benchmark
            save_policy_files(model, out / "student", cfg)
            write_json(out / "pretrain.json", pretrained)
        handover = None
        if cfg.pretrain is not None:  # the RL side of the hand-over (imitation.HandOver)
            from wsp_env.training.imitation import HandOver

            handover = HandOver(model, cfg.pretrain)
            if resume is not None and state.get("handover") is not None:
                handover.load(state["handover"])
        formats = ["csv"] + (["tensorboard"] if _have_tensorboard() else [])
        model.set_logger(configure(str(out / "logs" / f"from_step_{start}"), formats))
        adaptive = AdaptiveThreads(policy_threads.update_torch_threads,
                                   policy_threads.rollout_torch_threads)  # fmt: skip
        callbacks = _callbacks(
            cfg,
            out,
            total,
            progress,
            {
                "start": start,
                "validator": validator,
                "curve": curve,
                "threads": adaptive,
                "handover": handover,
            },
        )
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
        n_now = int(model.num_timesteps)
        if curve is not None:
            every = cfg.eval.curve_every_timesteps
            last = curve.history[-1]["timesteps"] if curve.history else -1
            # a point due where this call ends (the one-go run takes it at its next rollout's
            # start, at this same step), and the run's last point where it ends
            if curve_due(curve.history, n_now, every) or (n_now >= total and last != n_now):
                curve.evaluate(model)
        save_policy_files(model, out / "model", cfg)
        _save_checkpoint(model, cfg, out / "checkpoints" / f"step_{model.num_timesteps}", handover)
        merge_progress(out)
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
            "threads": {**policy_threads.as_dict(), "update": adaptive.as_dict()},
        }
        if curve is not None:
            result["curve"] = {"classical": curve.classical, "last": curve.history[-1:]}
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


def merge_progress(out: Path) -> None:
    """``progress.csv``: the CSV logs of every call of the run (``logs/from_step_N``) as one
    row per timestep (``time/total_timesteps``), in order.

    A call that resumed from the checkpoint at step N discarded what earlier calls did after N
    (a run killed after its last checkpoint and resumed logs those steps again): its rows
    replace every earlier call's rows past N, and at any timestep logged twice the later call's
    row wins. A row without a timestep stays after the row logged before it in its file."""
    import csv

    parts = sorted(
        (int(p.name.rsplit("_", 1)[1]), p / "progress.csv")
        for p in (out / "logs").glob("from_step_*")
        if (p / "progress.csv").exists() and p.name.rsplit("_", 1)[1].isdigit()
    )
    by_step: dict[int, list[dict[str, str]]] = {}  # timestep -> its row and any untimed after it
    names: dict[str, None] = {}
    for start, path in parts:  # in the order the calls ran (each resumes the latest checkpoint)
        by_step = {n: rows for n, rows in by_step.items() if n <= start}
        with path.open(newline="") as fh:
            reader = csv.DictReader(fh)
            names.update(dict.fromkeys(reader.fieldnames or ()))
            last = start
            for row in reader:
                n = _timestep(row.get("time/total_timesteps"))
                if n is None:  # no timestep: kept with the row before it
                    by_step.setdefault(last, []).append(row)
                else:
                    by_step[n] = [row]  # the later row at a timestep replaces the earlier
                    last = n
    rows = [row for n in sorted(by_step) for row in by_step[n]]
    from wsp_env.files import write_atomically

    def write(fh: Any) -> None:
        w = csv.DictWriter(fh, fieldnames=list(names))
        w.writeheader()
        w.writerows(rows)

    write_atomically(out / "progress.csv", write)


def _timestep(text: str | None) -> int | None:
    try:
        return int(float(text))  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        return None


def _have_tensorboard() -> bool:
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        return False
    return True


__all__ = [
    "LearningCurve",
    "LinearSchedule",
    "TrainConfig",
    "Validator",
    "curve_due",
    "first_timesteps",
    "latest_checkpoint",
    "load_train_config",
    "make_training_env",
    "merge_progress",
    "next_due",
    "parse_train_config",
    "save_policy_files",
    "thread_switch",
    "train",
]


def pin_loop_settings(cfg: TrainConfig, started_before: bool) -> TrainConfig:
    """A slip-target run's config with its loop's later settings (``policy.
    LEGACY_LOOP_SETTINGS``: the periodic release's gate, the creep cap, the drift correction,
    the gain's scale floor, the onset reading, the wheel-scale calibration, the onset reading's
    other sense, the lock guard)
    named, as it is written
    to the run folder (``config.yaml``): a new run gets the defaults (``policy.
    loop_settings_now``); a run folder whose config does not name one was started before that
    setting existed and resumes with the loop it began with (the setting's legacy value)."""
    from wsp_env.policy import LEGACY_LOOP_SETTINGS, loop_settings_now

    kw = cfg.env_kwargs
    if kw.get("action_mode") != "slip_target" or all(k in kw for k in LEGACY_LOOP_SETTINGS):
        return cfg
    fill = LEGACY_LOOP_SETTINGS if started_before else loop_settings_now()
    return dataclasses.replace(cfg, env_kwargs={**fill, **kw})

"""Warm start by imitation: the learner's actor regresses a privileged teacher's actions on its
own (non-privileged) observations, DAgger-style, before reinforcement learning starts.

The teacher sees what no WSP measures (``baselines/oracle.py``: ``oracle_peak`` holds every axle
at the peak of its current adhesion curve from the simulator's true state, ``oracle_rail`` does
that where the rail does not recover and holds a 4 km/h slide where it does); the student sees the
observation the environment gives it (wheel speeds, decelerations, pressures, the reference
speed, an accelerometer if configured), normalised and frame-stacked exactly as the learner
will see it. Rounds (Ross, Gordon & Bagnell 2011, DAgger): in round 0 the teacher drives; in
later rounds the student drives (deterministic) and the teacher labels the states the student
reaches; the actor is refitted on everything gathered so far after each round. The critic is
fitted to the discounted (normalised) returns of the last round's rollouts, so that the first
policy-gradient updates see sensible advantages. VecNormalize's statistics are warmed up on
teacher-driven steps and held fixed while the data are gathered (the regression targets stay on
one scale), then released for the reinforcement learning that follows.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np

TEACHERS = ("oracle_peak", "oracle_rail", "classical")


@dataclass(frozen=True)
class PretrainConfig:
    """The ``pretrain`` block of a training config (module docstring)."""

    teacher: str = field(default="oracle_peak", metadata={"choices": TEACHERS})
    rounds: int = field(default=6, metadata={"gt": 0})
    steps_per_round: int = field(default=131_072, metadata={"gt": 0})
    warmup_steps: int = field(default=65_536, metadata={"ge": 0})
    epochs: int = field(default=8, metadata={"gt": 0})
    batch_size: int = field(default=4096, metadata={"gt": 0})
    learning_rate: float = field(default=1e-3, metadata={"gt": 0.0})
    max_samples: int = field(default=1_000_000, metadata={"gt": 0})  # the newest are kept


def make_teacher(name: str) -> Any:
    if name == "oracle_peak":
        from wsp_env.baselines.oracle import SlipTracker

        return SlipTracker(None)
    if name == "oracle_rail":
        from wsp_env.baselines.oracle import RailAwareTracker

        return RailAwareTracker()
    from wsp_env.baselines.classical import ClassicalWSP, load_wsp_config

    return ClassicalWSP(load_wsp_config())


def pretrain(model: Any, env: Any, core: Any, cfg: PretrainConfig, gamma: float) -> dict[str, Any]:
    """Fit ``model``'s actor (and critic) by DAgger on ``env`` (the learner's wrapped VecEnv,
    whose environments are ``core``'s). Returns per-round figures for the run's record."""
    import torch

    norm = _find_wrapper(env, "VecNormalize")
    teacher = make_teacher(cfg.teacher)
    teacher.bind(core)
    n = core.n_envs
    teacher.reset(np.arange(n))
    obs = env.reset()
    for _ in range(cfg.warmup_steps // n):  # normalisation statistics on teacher-driven states
        obs, _, dones, _ = env.step(teacher.act(core.obs))
        if dones.any():
            teacher.reset(np.flatnonzero(dones))
    if norm is not None:
        norm.training = False
    policy = model.policy
    actor = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters()]
    critic = [*policy.mlp_extractor.value_net.parameters(), *policy.value_net.parameters()]
    opt_actor = torch.optim.Adam(actor, lr=cfg.learning_rate)
    opt_critic = torch.optim.Adam(critic, lr=cfg.learning_rate)
    steps = cfg.steps_per_round // n
    cap = min(cfg.rounds * steps * n, cfg.max_samples)
    x_all = np.zeros((cap, obs.shape[1]), dtype=np.float32)
    y_all = np.zeros((cap, core.n_valves), dtype=np.float32)
    filled = 0  # samples written (a ring buffer once full: the newest are kept)
    history = []
    rng = np.random.default_rng(int(model.seed or 0))
    for rnd in range(cfg.rounds):
        r_obs = np.zeros((steps, n, obs.shape[1]), dtype=np.float32)
        r_rew = np.zeros((steps, n), dtype=np.float32)
        r_done = np.zeros((steps, n), dtype=bool)
        agree = []
        for t in range(steps):
            label = np.asarray(teacher.act(core.obs), dtype=np.float32)
            r_obs[t] = obs
            rows = (filled + np.arange(n)) % cap
            x_all[rows] = obs
            y_all[rows] = np.clip(label, -1.0, 1.0)
            filled += n
            if rnd == 0:
                action = label
            else:
                action, _ = model.predict(obs, deterministic=True)
                agree.append(float(np.mean(np.abs(np.clip(action, -1, 1) - label))))
            obs, rew, dones, _ = env.step(action)
            r_rew[t], r_done[t] = rew, dones
            if dones.any():
                teacher.reset(np.flatnonzero(dones))
        size = min(filled, cap)
        before = _mae(policy, x_all[:size], y_all[:size], torch)
        actor_mean = partial(_actor_mean, policy)
        loss = _regress(actor_mean, opt_actor, x_all[:size], y_all[:size], cfg, rng, torch)
        after = _mae(policy, x_all[:size], y_all[:size], torch)
        returns = _returns(r_rew, r_done, gamma).reshape(-1)
        v_loss = _regress(partial(_critic_value, policy), opt_critic,
                          r_obs.reshape(-1, r_obs.shape[2]), returns, cfg, rng, torch)  # fmt: skip
        mae = float(np.mean(agree)) if agree else None
        history.append({"round": rnd, "samples": int(size), "actor_mse": loss,
                        "critic_mse": v_loss, "student_vs_teacher_mae": mae,
                        "data_mae_before_fit": before, "data_mae_after_fit": after})  # fmt: skip
    if norm is not None:
        norm.training = True
    model._last_obs = obs  # the first rollout continues from here
    model._last_episode_starts = dones
    env_steps = (cfg.warmup_steps // n + cfg.rounds * steps) * n
    return {"teacher": cfg.teacher, "env_steps": int(env_steps), "rounds": history}


def _find_wrapper(env: Any, name: str) -> Any:
    """The wrapper of class ``name`` in ``env``'s chain of VecEnv wrappers, or None."""
    while env is not None:
        if type(env).__name__ == name:
            return env
        env = getattr(env, "venv", None)
    return None


def _returns(rew: np.ndarray, done: np.ndarray, gamma: float) -> np.ndarray:
    out = np.zeros_like(rew)
    acc = np.zeros(rew.shape[1], dtype=np.float32)
    for t in range(rew.shape[0] - 1, -1, -1):
        acc = rew[t] + gamma * acc * (~done[t])
        out[t] = acc
    return out


def _batches(n: int, cfg: PretrainConfig, rng: np.random.Generator) -> Any:
    for _ in range(cfg.epochs):
        order = rng.permutation(n)
        for i in range(0, n, cfg.batch_size):
            yield order[i : i + cfg.batch_size]


def _mae(policy: Any, x: np.ndarray, y: np.ndarray, torch: Any) -> float:
    """Mean |actor mean (clipped) - teacher| over the data set (deterministic actions)."""
    total = 0.0
    with torch.no_grad():
        for i in range(0, len(x), 65536):
            mean = _actor_mean(policy, torch.as_tensor(x[i : i + 65536]))
            diff = torch.clamp(mean, -1.0, 1.0) - torch.as_tensor(y[i : i + 65536])
            total += float(torch.abs(diff).sum())
    return total / max(y.size, 1)


def _actor_mean(policy: Any, obs: Any) -> Any:
    features = policy.extract_features(obs, policy.pi_features_extractor)
    return policy.action_net(policy.mlp_extractor.forward_actor(features))


def _critic_value(policy: Any, obs: Any) -> Any:
    features = policy.extract_features(obs, policy.vf_features_extractor)
    return policy.value_net(policy.mlp_extractor.forward_critic(features)).squeeze(-1)


def _regress(predict: Any, opt: Any, x: np.ndarray, y: np.ndarray, cfg: PretrainConfig,
             rng: np.random.Generator, torch: Any) -> float:  # fmt: skip
    """Minibatch least squares of ``predict(obs)`` on ``y``; returns the mean squared error."""
    total, count = 0.0, 0
    for idx in _batches(len(x), cfg, rng):
        loss = torch.mean((predict(torch.as_tensor(x[idx])) - torch.as_tensor(y[idx])) ** 2)
        opt.zero_grad()
        loss.backward()
        opt.step()
        total += float(loss.detach()) * len(idx)
        count += len(idx)
    return total / max(count, 1)

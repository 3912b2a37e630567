"""Warm start by imitation: the learner's actor regresses a privileged teacher's actions on its
own (non-privileged) observations, DAgger-style, before reinforcement learning starts.

The teacher sees what no WSP measures (``baselines/oracle.py``: ``oracle_peak`` holds every axle
at the peak of its current adhesion curve from the simulator's true state, ``oracle_rail`` does
that where the rail does not recover and holds a 4 km/h slide where it does; they and
``classical`` command valve fractions every control period, so the learner's environment must
be ``continuous`` without an action repeat; ``oracle_target_rail`` acts in the ``slip_target``
action space instead, one target sliding speed a stop picked by its rail, for a learner on
that mode, any repeat); the student sees the observation the environment gives it (wheel
speeds, decelerations, pressures, the reference speed, an accelerometer if configured),
normalised and frame-stacked exactly as the learner will see it. Rounds (Ross, Gordon &
Bagnell 2011, DAgger): in round 0 the teacher drives; in later rounds the student drives
(deterministic) and the teacher labels the states the student reaches; the actor is refitted
on everything gathered so far after each round. The critic is fitted to the discounted
(normalised) returns of the last round's rollouts, bootstrapped at the round's end by its own
value of the state reached (a stop of 15,000 steps is not cut to the round's 4,096), so that
the first policy-gradient updates see sensible advantages.

**The hand-over** (issue 23: the fine-tune of the first shipped student collapsed):

* VecNormalize's statistics are fitted on teacher-driven **whole stops** (``warmup_episodes``:
  until every environment has finished that many, at least ``warmup_steps``), not on the first
  seconds of stops that all started together, and held fixed while the data are gathered;
* with ``freeze_normalization`` (default) they stay fixed for the reinforcement learning that
  follows (observation and reward scales: the fitted actor and critic keep their inputs and
  targets), else they are released;
* ``critic_warmup_timesteps``: the first RL updates move the critic only (``HandOver``: the
  actor's parameters, its log-std included, do not move), so the actor's first gradients use a
  critic fitted to the RL's own returns;
* ``anchor_coef``: after each RL update, the actor is pulled back towards the imitation start's
  actions on that update's own observations (plain gradient descent on the squared distance of
  the mean actions, step ``learning_rate x weight``, the weight ``anchor_coef`` decaying
  linearly to 0 over ``anchor_timesteps``): a behaviour-cloning term to the student of the
  teacher that fades as RL takes over. The start's weights travel in every
  checkpoint, so a resumed run pulls to the same start.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np

TEACHERS = ("oracle_peak", "oracle_rail", "classical", "oracle_target_rail")
# teachers whose actions are slip targets (``action_mode="slip_target"``), not valve fractions
TARGET_TEACHERS = ("oracle_target_rail",)


@dataclass(frozen=True)
class PretrainConfig:
    """The ``pretrain`` block of a training config (module docstring)."""

    teacher: str = field(default="oracle_peak", metadata={"choices": TEACHERS})
    # oracle_target_rail's table (rail -> km/h of measured slip), every rail the scenario draws;
    # None: baselines.oracle.RAIL_TARGETS_KMH (chosen on the UIC-Z1's development stops)
    teacher_targets_kmh: dict[str, float] | None = field(
        default=None, metadata={"ge": 0.0, "le": 30.0}
    )
    # oracle_target_rail's creep schedules (rail -> a fraction of the reference speed; a rail
    # not named: its constant target), never under teacher_creep_floor_kmh
    # (``baselines.oracle.SlipTargetTeacher``)
    teacher_creep: dict[str, float] | None = field(default=None, metadata={"gt": 0.0, "le": 1.0})
    teacher_creep_floor_kmh: float = field(default=0.5, metadata={"ge": 0.0, "le": 30.0})
    rounds: int = field(default=6, metadata={"gt": 0})
    steps_per_round: int = field(default=131_072, metadata={"gt": 0})
    warmup_steps: int = field(default=65_536, metadata={"ge": 0})
    epochs: int = field(default=8, metadata={"gt": 0})
    batch_size: int = field(default=4096, metadata={"gt": 0})
    learning_rate: float = field(default=1e-3, metadata={"gt": 0.0})
    max_samples: int = field(default=1_000_000, metadata={"gt": 0})  # the newest are kept
    # the hand-over to RL (module docstring)
    warmup_episodes: int = field(default=1, metadata={"ge": 0})
    freeze_normalization: bool = True
    critic_warmup_timesteps: int = field(default=0, metadata={"ge": 0})
    anchor_coef: float = field(default=0.0, metadata={"ge": 0.0})
    anchor_timesteps: int = field(default=0, metadata={"ge": 0})
    anchor_epochs: int = field(default=1, metadata={"gt": 0})


def make_teacher(
    name: str,
    targets_kmh: dict[str, float] | None = None,
    creep: dict[str, float] | None = None,
    creep_floor_kmh: float = 0.5,
) -> Any:
    """The teacher ``name`` (``TEACHERS``); ``targets_kmh``: ``oracle_target_rail``'s table,
    ``creep`` and ``creep_floor_kmh`` its creep schedules (``SlipTargetTeacher``)."""
    if name == "oracle_peak":
        from wsp_env.baselines.oracle import SlipTracker

        return SlipTracker(None)
    if name == "oracle_rail":
        from wsp_env.baselines.oracle import RailAwareTracker

        return RailAwareTracker()
    if name == "oracle_target_rail":
        from wsp_env.baselines.oracle import SlipTargetTeacher

        return SlipTargetTeacher(targets_kmh, creep, creep_floor_kmh)
    from wsp_env.baselines.classical import ClassicalWSP

    return ClassicalWSP()  # the learner's tier's frozen thresholds, taken at ``bind``


def pretrain(model: Any, env: Any, core: Any, cfg: PretrainConfig, gamma: float) -> dict[str, Any]:
    """Fit ``model``'s actor (and critic) by DAgger on ``env`` (the learner's wrapped VecEnv,
    whose environments are ``core``'s). Returns per-round figures for the run's record."""
    import torch

    norm = _find_wrapper(env, "VecNormalize")
    teacher = make_teacher(
        cfg.teacher, cfg.teacher_targets_kmh, cfg.teacher_creep, cfg.teacher_creep_floor_kmh
    )
    teacher.bind(core)
    n = core.n_envs
    obs = env.reset()
    # after the reset: with staggered resets (``stagger_reset_steps``) it drives every stop
    # some way in, and a teacher's memory must start with the stop it then takes over
    teacher.reset(np.arange(n))
    # normalisation statistics on teacher-driven states: whole stops (every environment has
    # finished warmup_episodes), and at least warmup_steps
    finished = np.zeros(n, dtype=np.int64)
    limit = cfg.warmup_steps // n + (WARMUP_STOP_STEPS_MAX if cfg.warmup_episodes else 0)
    warm = 0
    while warm < limit:
        if warm >= cfg.warmup_steps // n and (finished >= cfg.warmup_episodes).all():
            break
        obs, _, dones, _ = env.step(teacher.act(core.obs))
        warm += 1
        finished += dones
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
        with torch.no_grad():  # the round's end bootstrapped by the critic's value there
            tail = _critic_value(policy, torch.as_tensor(np.asarray(obs, dtype=np.float32)))
        returns = _returns(r_rew, r_done, gamma, tail.numpy()).reshape(-1)
        v_loss = _regress(partial(_critic_value, policy), opt_critic,
                          r_obs.reshape(-1, r_obs.shape[2]), returns, cfg, rng, torch)  # fmt: skip
        mae = float(np.mean(agree)) if agree else None
        history.append({"round": rnd, "samples": int(size), "actor_mse": loss,
                        "critic_mse": v_loss, "student_vs_teacher_mae": mae,
                        "data_mae_before_fit": before, "data_mae_after_fit": after})  # fmt: skip
    if norm is not None:  # frozen for the RL that follows, or released
        norm.training = not cfg.freeze_normalization
    model._last_obs = obs  # the first rollout continues from here
    model._last_episode_starts = dones
    env_steps = (warm + cfg.rounds * steps) * n
    table = getattr(teacher, "table", None)  # oracle_target_rail's targets, as it used them
    creep = getattr(teacher, "creep", None) or None  # its creep schedules, if any
    return {"teacher": cfg.teacher, "teacher_targets_kmh": table,
            **({"teacher_creep": creep, "teacher_creep_floor_kmh": teacher.floor_kmh}
               if creep else {}),
            "env_steps": int(env_steps),
            "warmup_steps": int(warm * n), "warmup_episodes_min": int(finished.min()),
            "rounds": history}  # fmt: skip


WARMUP_STOP_STEPS_MAX = 30_000  # per environment: twice the longest stop (600 s at 20 ms)


class HandOver:
    """The RL side of the hand-over (module docstring): the critic-only warm-up and the decaying
    pull towards the imitation start. ``before_update(model)`` before each RL update,
    ``after_update(model)`` after it; ``state()`` / ``load(state)`` for checkpoints."""

    def __init__(self, model: Any, cfg: PretrainConfig, start_step: int = 0) -> None:
        import copy

        self.cfg = cfg
        self.start_step = start_step  # where RL began (after the imitation)
        self.anchor = copy.deepcopy(model.policy).eval() if cfg.anchor_coef > 0 else None
        self._frozen: list[Any] = []

    def _actor_params(self, model: Any) -> list[Any]:
        policy = model.policy
        params = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters()]
        log_std = getattr(policy, "log_std", None)
        return params + ([log_std] if log_std is not None else [])

    def before_update(self, model: Any) -> None:
        """The actor frozen for the updates of rollouts that began within the first
        ``critic_warmup_timesteps`` of RL (called at a rollout's end: it has been counted)."""
        rollout = int(model.n_steps) * int(model.n_envs)
        began = model.num_timesteps - rollout - self.start_step
        warm = began < self.cfg.critic_warmup_timesteps
        for p in self._actor_params(model):
            p.requires_grad_(not warm)

    def anchor_weight(self, num_timesteps: int) -> float:
        if self.anchor is None:
            return 0.0
        span = max(self.cfg.anchor_timesteps, 1)
        done = (num_timesteps - self.start_step) / span
        return self.cfg.anchor_coef * max(0.0, 1.0 - done)

    def after_update(self, model: Any, observations: np.ndarray) -> float | None:
        """The pull towards the start on ``observations`` (the update's rollout); returns the
        mean squared distance before it (None when off)."""
        import torch

        for p in self._actor_params(model):
            p.requires_grad_(True)
        weight = self.anchor_weight(model.num_timesteps)
        if weight <= 0.0 or self.anchor is None:
            return None
        policy = model.policy
        obs = np.asarray(observations, dtype=np.float32)  # (n_steps, n_envs, obs_dim)
        x = obs.reshape(-1, obs.shape[-1])
        with torch.no_grad():
            target = _actor_mean(self.anchor, torch.as_tensor(x))
        rng = np.random.default_rng(int(model.num_timesteps))
        # plain gradient descent, step pretrain.learning_rate x weight: the weight is a real
        # coefficient (Adam would divide its scale out) and PPO's optimiser moments stay PPO's
        params = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters()]
        opt = torch.optim.SGD(params, lr=self.cfg.learning_rate * weight)
        first = None
        for _ in range(self.cfg.anchor_epochs):
            order = rng.permutation(len(x))
            for i in range(0, len(x), self.cfg.batch_size):
                idx = order[i : i + self.cfg.batch_size]
                diff = _actor_mean(policy, torch.as_tensor(x[idx])) - target[idx]
                loss = torch.mean(diff**2)
                if first is None:
                    first = float(loss.detach())
                opt.zero_grad()
                loss.backward()
                opt.step()
        policy.optimizer.zero_grad()  # nothing of the pull left in the actor-critic's grads
        return first

    def state(self) -> dict[str, Any]:
        return {"start_step": self.start_step,
                "anchor": None if self.anchor is None else self.anchor.state_dict()}  # fmt: skip

    def load(self, state: dict[str, Any]) -> None:
        self.start_step = int(state["start_step"])
        if self.anchor is not None and state.get("anchor") is not None:
            self.anchor.load_state_dict(state["anchor"])


def _find_wrapper(env: Any, name: str) -> Any:
    """The wrapper of class ``name`` in ``env``'s chain of VecEnv wrappers, or None."""
    while env is not None:
        if type(env).__name__ == name:
            return env
        env = getattr(env, "venv", None)
    return None


def _returns(
    rew: np.ndarray, done: np.ndarray, gamma: float, tail: np.ndarray | None = None
) -> np.ndarray:
    """Discounted returns of a rollout, each environment's last step bootstrapped by ``tail``
    (its value of the state reached; zeros: none) unless its stop ended there."""
    out = np.zeros_like(rew)
    acc = np.zeros(rew.shape[1], dtype=np.float32) if tail is None else tail.astype(np.float32)
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

"""A training reward weighted per stop (config field ``stop_weight``; issue 23 item 4).

**Why.** PPO maximises the mean return over stops; the benchmark scores the interquartile mean
of per-stop *normalised* returns, ``s = (R - R_none) / G`` with ``G`` the classical WSP's gain on
that stop (``evaluation.benchmark``). A stop's return is its cost in metres / 100, so a 10 km
leaves stop down a gradient weighs in the mean as much as a hundred 100 m stops, and a fine-tune
that gains a few metres there while most stops get worse raises the mean return and lowers the
score (docs/training_log.md, "The fine-tune against its imitation start"). Maximising the mean of
``R / G`` instead is maximising the mean of ``s`` (``R_none / G`` is a constant of the stop).

**The weight.** ``G`` is not known while training (it takes a classical and a locked-wheel run
of the same stop), so each stop's rewards are multiplied by ``reference_m / d_est``, where
``d_est`` is the stop's braking distance from its scenario alone::

    a_est = max(g (min(mu, demand_fraction * demand_decel_mps2 / g) + sin(theta)), min_decel_mps2)
    d_est = V0^2 / (2 a_est)

(``mu``: the rail's contaminated adhesion level, ``mu_contaminated``; ``theta``: the gradient,
> 0 uphill; ``demand_decel_mps2``: the full demand's deceleration), clipped to
``[min_weight, max_weight]``. On the 219 of the benchmark's 300 development stops that it
scores (``wheels+accel`` tier), ``log G`` and ``log d_est`` correlate at 0.70 and ``G / d_est``
spans 3.2x between its quartiles against 5.7x for ``G`` alone (``scripts/stop_weight_fit.py`` on
``wsp-env benchmark --stops development --tier wheels+accel --policy none --policy classical
--json F``): a rough but flatter scale. The weight
is a constant of the stop, so potential-based shaping stays potential-based (its potential is
scaled by the same constant).

The weight is the learner's only: the episode statistics (``infos[i]["episode"]``), the learning
curve, validation and the benchmark see the environment's own reward. The weight reads the
scenario (rail level, gradient, speed), which no sensor measures: a training-only privilege,
like the shaping's true speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnvWrapper

G_MPS2 = 9.81


@dataclass(frozen=True)
class StopWeightConfig:
    """``stop_weight:`` in a training config (module docstring; every field optional)."""

    reference_m: float = field(default=500.0, metadata={"gt": 0})
    demand_decel_mps2: float = field(default=1.2, metadata={"gt": 0})
    min_decel_mps2: float = field(default=0.2, metadata={"gt": 0})
    min_weight: float = field(default=0.1, metadata={"gt": 0})
    max_weight: float = field(default=10.0, metadata={"gt": 0})


def braking_distance_m(scenario: dict[str, Any], cfg: StopWeightConfig) -> float:
    """``d_est`` (module docstring) of one stop from its scenario (``BrakingCore.describe``)."""
    if scenario.get("mu_contaminated") is None:
        raise ValueError("stop_weight: the stop has no adhesion level (mu_contaminated None); "
                         "give one in the reset options or drop stop_weight")  # fmt: skip
    v0 = float(scenario["speed_kmh"]) / 3.6
    mu = float(scenario["mu_contaminated"])
    demand_g = float(scenario["demand_fraction"]) * cfg.demand_decel_mps2 / G_MPS2
    slope = math.sin(math.atan(float(scenario["gradient_permille"]) / 1000.0))
    a_est = max(G_MPS2 * (min(mu, demand_g) + slope), cfg.min_decel_mps2)
    return v0 * v0 / (2.0 * a_est)


def stop_weight(scenario: dict[str, Any], cfg: StopWeightConfig) -> float:
    """The weight of one stop's rewards: ``reference_m / braking_distance_m``, clipped."""
    w = cfg.reference_m / braking_distance_m(scenario, cfg)
    return float(min(max(w, cfg.min_weight), cfg.max_weight))


class StopWeightedReward(VecEnvWrapper):
    """Multiply each environment's rewards by its current stop's ``stop_weight``. Sits directly
    on ``SB3VecEnv`` (under ``VecNormalize``); reads each new stop's scenario through
    ``env_method("describe")`` after every reset and autoreset. Nothing to checkpoint: the weights
    are a function of the stops under way."""

    def __init__(self, venv: Any, cfg: StopWeightConfig) -> None:
        super().__init__(venv)
        self.cfg = cfg
        self.weights: np.ndarray | None = None  # computed at reset, or lazily after a resume

    def _weigh(self, indices: np.ndarray) -> None:
        assert self.weights is not None
        scenarios = self.venv.env_method("describe", indices=[int(i) for i in indices])
        for i, s in zip(indices, scenarios, strict=True):
            self.weights[i] = stop_weight(s, self.cfg)

    def reset(self) -> np.ndarray:
        obs = self.venv.reset()
        self.weights = np.ones(self.num_envs)
        self._weigh(np.arange(self.num_envs))
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        if self.weights is None:  # a resumed run: the stops under way were restored, not reset
            self.weights = np.ones(self.num_envs)
            self._weigh(np.arange(self.num_envs))
        self.venv.step_async(actions)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        obs, rewards, dones, infos = self.venv.step_wait()
        assert self.weights is not None
        rewards = (rewards * self.weights).astype(np.float32)
        ended = np.flatnonzero(dones)
        if ended.size:  # their next stop has begun (the autoreset): its own weight from now
            self._weigh(ended)
        return obs, rewards, dones, infos

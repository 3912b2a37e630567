"""``WSPBraking-v0``: wheel slide protection as a Gymnasium environment (single and native vector).

A train brakes from ``speed_kmh`` to standstill on a rail drawn at ``reset`` (contaminant,
adhesion level and pattern, load, pad friction, gradient, demand). Every control period
(20 ms, the BCU cycle) the agent sets each WSP valve; the physics runs 1 ms substeps inside.

**Action** — ``action_mode="continuous"`` (default): ``Box(-1, 1, (n_valves,), float32)``; valve
``j`` asks for the fraction ``(a_j + 1) / 2`` of the current demand pressure (the pneumatics
decide how fast the cylinder gets there; nothing can exceed the demand). Out-of-range values are
clipped and counted in ``info["action_clipped"]``; a NaN raises ``ValueError``.
``action_mode="discrete"``: ``MultiDiscrete([3] * n_valves)`` with 0 = vent, 1 = hold,
2 = fill (apply), like real dump/hold valves. ``action_mode="residual"``: a residual on the
frozen classical WSP (``configs/wsp/classical.yaml``), which runs inside the environment on the
same observation: ``Box(-1, 1, (n_valves,))``, valve ``j`` asks for the fraction
``clip(f_j + residual_scale * a_j, 0, 1)`` of the demand, ``f_j`` the classical WSP's own
request — so the zero action *is* the classical WSP, and a learner starts from it.
``residual_deadband`` (0 by default) zeroes residuals up to that size and rescales the rest
continuously (``sign(a) (|a| - band) / (1 - band)``): a policy's small, ever-changing outputs
would otherwise move every *hold* a little, and each small drop of the target vents air.
Valves are per axle, or per bogie with ``valve_group="bogie"``.

**Observation** — ``Box(-5, 5, float32)``, what a WSP measures, normalised (``v_s`` = vehicle
maximum speed): per axle the wheel speed ``/ v_s``, the wheel deceleration ``/ 10 m/s^2``, the
slip against the reference speed ``(v_ref - v_i) / max(v_ref, 1 m/s)``, the cylinder pressure
``/ p_max``; then the demand ``/ p_max``, the reference speed ``/ v_s`` (fastest wheel, falling
at most 2.5 m/s^2 — above any dry-rail deceleration, so it is the train speed on good adhesion),
and the previous valve command. ``privileged=True`` appends the true train speed, each
axle's friction level and true creepage. ``accelerometer=True`` gives the WSP a body
accelerometer, as accelerometer-aided WSPs have: the reference speed then falls at the
deceleration it reads over each period — a specific force, so the gradient's ``g sin(theta)``
is missing from it, plus a bias drawn per episode within ``+-accelerometer_bias_mps2``
(0.05 m/s^2) — instead of the fixed limit, and the reading ``/ 10 m/s^2`` is appended to the
observation. With it the reference follows the train when every wheel slides. With
``action_mode="residual"`` the classical WSP's requests for this period (one per valve, as
actions in ``[-1, 1]``) come last of all.

**Reward** — minus the stop's cost in metres of stopping distance, divided by
``distance_scale_m`` (100 m); the terms, each in ``info["reward_terms"]``, and their exchange
rates (``reward``, ``RewardConfig``):

* ``distance``  ``-dx``: over an episode it sums to ``-stopping_distance / distance_scale_m``;
* ``damage``    wheel damage, priced per axle and superlinearly: axle ``i`` with cumulative
  sliding energy ``E_i`` costs ``damage_m_per_MJ E_i (1 + E_i / damage_ref_MJ)`` metres
  (20 m per MJ, doubled at 1 MJ), so a slide concentrated on one wheel costs more than the same
  energy spread over four;
* ``lock``      ``lock_m_per_s`` (10 m) per second each axle is locked (a wheel flat);
* ``air``       ``air_m_per_100l`` (5 m) per 100 free-air litres vented;
* ``shaping``   a training option, off by default (``shaping_decel_mps2 = 0``): potential-based
  shaping ``gamma Phi(V') - Phi(V)`` with ``Phi(V) = -V^2 / (2 a0)``, the distance the train
  would still run at ``a0``, and ``gamma = shaping_gamma`` (set it to the learner's discount).
  It pays now for the speed a harder brake takes off, which the distance term only pays as the
  metres are not run, and by Ng, Harada & Russell (1999) leaves the optimal policy unchanged:
  its *discounted* sum over a stop is exactly ``V0^2 / (2 a0)``, a constant of the scenario
  (the undiscounted sum is not: with gamma < 1 it grows with the stop's length, so logged
  episode returns with shaping on are not comparable with returns without it). It reads the
  true train speed: a reward-only privilege (observations are unchanged);
* ``slide``     an option, off by default (``slide_m_per_s = 0``): metres per second each axle
  slides deeper than the slide threshold ``max(3 km/h, 20 % V)`` — the time the damage
  criterion "longest slide" judges, which the sliding energy alone does not price.

With these defaults the classical WSP's return is about nine tenths distance; a locked-wheel
policy (``none``) and one that brakes less than the demand return clearly less on soap and
leaves (``tests/test_reward.py``). The episodic sum is what the weights price: every term is
paid when it happens and a stop lasts 10-90 s (500-4500 steps), so train with a discount whose
horizon covers a stop (gamma >= 0.999: ~20 s) — with gamma 0.99 (2 s) the distance a harder
brake saves later is invisible to the step that applies it.

**Episodes** — ``terminated`` at standstill, ``truncated`` when ``max_time_s`` of braking has
passed. ``info["metrics"]`` at the end carries the run's metrics (``metrics.run_metrics``).
``reset(options=...)`` fixes any drawn parameter (``speed_kmh``, ``rail``, ``mu_contaminated``,
``pattern``, ``load_factor``, ``pad_factor``, ``gradient_permille``, ``demand``, ``sections``,
``axle_mu_factor``, ``recovery_basis``).

The vector class steps all environments in one compiled call and autoresets in the same step
(``AutoresetMode.SAME_STEP``): an ended environment's last observation and info are in
``info["final_obs"]`` / ``info["final_info"]`` (masks ``_final_obs`` / ``_final_info``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from wsp_env.core import kernel as K
from wsp_env.core.braking import TERM_NAMES, BrakingCore
from wsp_env.envs.rendering import render_core


class WSPBrakingEnv(gym.Env):
    __doc__ = __doc__
    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode: {render_mode!r} (supported: rgb_array)")
        self.render_mode = render_mode
        self.core = BrakingCore(1, **kwargs)
        self.action_space = self.core.action_space()
        self.observation_space = self.core.observation_space()
        self._reward_terms = np.zeros(K.N_TERMS)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.core.rngs[0] = self.np_random
        info = self.core.reset_env(0, options)
        return self.core.obs[0].copy(), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        core = self.core
        a = core.check_actions(np.reshape(action, (1, -1)) if np.ndim(action) == 1 else action)
        core.step(a)
        terms = core.terms[0]
        reward = float(terms.sum())
        core.episode_return[0] += reward
        core.episode_terms[0] += terms
        terminated = bool(core.flags[0, K.F_TERMINATED])
        truncated = bool(core.flags[0, K.F_TRUNCATED])
        info: dict[str, Any] = {
            "reward_terms": dict(zip(TERM_NAMES, terms.tolist(), strict=True)),
            "action_clipped": int(core.flags[0, K.F_CLIPPED]),
        }
        if terminated or truncated:
            info["metrics"] = core.episode_info(0)
        return core.obs[0].copy(), reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        return render_core(self.core, 0)


class WSPBrakingVectorEnv(VectorEnv):
    """``num_envs`` environments stepped by one compiled call; same-step autoreset."""

    metadata: ClassVar[dict[str, Any]] = {
        "render_modes": ["rgb_array"],
        "render_fps": 50,
        "autoreset_mode": AutoresetMode.SAME_STEP,
    }

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        if max_episode_steps is not None:  # gymnasium passes the spec's value; ours is time-based
            kwargs.setdefault(
                "max_time_s", max_episode_steps * kwargs.get("control_period_s", 0.02)
            )
        self.core = BrakingCore(num_envs, **kwargs)
        self.num_envs = num_envs
        self.render_mode = render_mode
        self.single_action_space = self.core.action_space()
        self.single_observation_space = self.core.observation_space()
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self._ended = np.zeros(num_envs, dtype=bool)

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        if isinstance(seed, int):
            seeds: list[int | None] = [seed + i for i in range(self.num_envs)]
        elif seed is None:
            seeds = [None] * self.num_envs
        else:
            if len(seed) != self.num_envs:
                raise ValueError(f"seed: {len(seed)} seeds for {self.num_envs} environments")
            seeds = list(seed)
        for i, s in enumerate(seeds):
            self.core.rngs[i] = seeding.np_random(s)[0]
        scenarios = [self.core.reset_env(i, options)["scenario"] for i in range(self.num_envs)]
        return self.core.obs.copy(), {"scenario": np.array(scenarios, dtype=object)}

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        core = self.core
        a = core.check_actions(actions)
        core.step(a)
        rewards = core.terms.sum(axis=1)
        core.episode_return += rewards
        core.episode_terms += core.terms
        terminated = core.flags[:, K.F_TERMINATED].astype(bool)
        truncated = core.flags[:, K.F_TRUNCATED].astype(bool)
        info: dict[str, Any] = {
            "reward_terms": {n: core.terms[:, i].copy() for i, n in enumerate(TERM_NAMES)},
            "action_clipped": core.flags[:, K.F_CLIPPED].copy(),
        }
        ended = np.flatnonzero(terminated | truncated)
        if ended.size:
            final_obs = np.zeros((self.num_envs, core.obs_dim), dtype=np.float32)
            final_info = np.full(self.num_envs, None, dtype=object)
            mask = np.zeros(self.num_envs, dtype=bool)
            mask[ended] = True
            for e in ended:  # only the environments that just ended
                final_obs[e] = core.final_obs(int(e))
                final_info[e] = {"metrics": core.episode_info(e), "scenario": core.describe(e)}
                core.reset_env(int(e), None)
            info.update(
                final_obs=final_obs, _final_obs=mask, final_info=final_info, _final_info=mask.copy()
            )
        return core.obs.copy(), rewards, terminated, truncated, info

    def render(self) -> tuple[np.ndarray, ...] | None:
        if self.render_mode != "rgb_array":
            return None
        return tuple(render_core(self.core, e) for e in range(self.num_envs))

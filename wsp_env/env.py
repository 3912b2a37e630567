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

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from wsp_env import env_kernel as K
from wsp_env.config import (
    ConfigError,
    RailConfig,
    VehicleConfig,
    from_dict,
    load_rails,
    load_vehicle,
)
from wsp_env.metrics import run_metrics
from wsp_env.physics.layout import CMD_HOLD, EP_P_MAX
from wsp_env.simulator import RunSetup, TrainSim, draw_run_setup

PARALLEL_MIN_ENVS = 64


@dataclass(frozen=True)
class RewardConfig:
    """Exchange rates of the reward terms in metres of stopping distance (module docstring)."""

    distance_scale_m: float = field(default=100.0, metadata={"gt": 0.0})
    damage_m_per_MJ: float = field(default=20.0, metadata={"ge": 0.0})
    damage_ref_MJ: float = field(default=1.0, metadata={"gt": 0.0})
    lock_m_per_s: float = field(default=10.0, metadata={"ge": 0.0})
    air_m_per_100l: float = field(default=5.0, metadata={"ge": 0.0})
    # training option: potential-based distance shaping (module docstring); 0 = off
    shaping_decel_mps2: float = field(default=0.0, metadata={"ge": 0.0})
    shaping_gamma: float = field(default=0.999, metadata={"gt": 0.0, "le": 1.0})
    # option: price the time an axle slides deeper than the slide threshold; 0 = off
    slide_m_per_s: float = field(default=0.0, metadata={"ge": 0.0})

    def vector(self) -> np.ndarray:
        v = np.zeros(K.N_RP)
        v[K.RP_DISTANCE_SCALE] = self.distance_scale_m
        v[K.RP_DAMAGE_M_PER_MJ] = self.damage_m_per_MJ
        v[K.RP_DAMAGE_REF_MJ] = self.damage_ref_MJ
        v[K.RP_LOCK_M_PER_S] = self.lock_m_per_s
        v[K.RP_AIR_M_PER_100L] = self.air_m_per_100l
        v[K.RP_SHAPING_DECEL] = self.shaping_decel_mps2
        v[K.RP_SHAPING_GAMMA] = self.shaping_gamma
        v[K.RP_SLIDE_M_PER_S] = self.slide_m_per_s
        return v


TERM_NAMES = ("distance", "damage", "lock", "air", "shaping", "slide")


@dataclass(frozen=True)
class ScenarioConfig:
    """The distribution ``reset`` draws from. Ranges are ``[low, high]`` (uniform)."""

    speed_kmh: tuple[float, ...] | None = field(default=None, metadata={"len": 2, "gt": 0.0})
    rails: dict[str, float] = field(
        default_factory=lambda: {"soap": 0.5, "leaves": 0.2, "oil": 0.15, "wet": 0.15}
    )
    load_factor: tuple[float, ...] = field(default=(0.85, 1.15), metadata={"len": 2, "gt": 0.0})
    pad_factor: tuple[float, ...] = field(default=(0.9, 1.1), metadata={"len": 2, "gt": 0.0})
    gradient_permille: tuple[float, ...] = field(default=(-5.0, 5.0), metadata={"len": 2})
    emergency_probability: float = field(default=0.7, metadata={"ge": 0.0, "le": 1.0})
    service_demand_fraction: float = field(default=0.85, metadata={"gt": 0.0, "le": 1.0})

    def validate(self, where: str) -> None:
        prefix = f"{where}." if where else ""
        for name in ("speed_kmh", "load_factor", "pad_factor", "gradient_permille"):
            rng = getattr(self, name)
            if rng is not None and rng[0] > rng[1]:
                raise ConfigError(f"{prefix}{name}: low end exceeds high end")
        if not self.rails or min(self.rails.values()) < 0 or sum(self.rails.values()) <= 0:
            raise ConfigError(f"{prefix}rails: needs non-negative weights, not all zero")


ACTION_MODES = ("continuous", "discrete", "residual")

OPTION_KEYS = (
    "speed_kmh", "rail", "mu_contaminated", "pattern", "load_factor", "pad_factor",
    "gradient_permille", "demand", "sections", "axle_mu_factor", "recovery_basis",
    "background", "extra_brake_force_N",
)  # fmt: skip


def _config(cls: type, value: Any, name: str) -> Any:
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    return from_dict(cls, value, name)


class _BrakingCore:
    """State and stepping shared by the single and the vector environment."""

    def __init__(
        self,
        n_envs: int,
        vehicle: str | VehicleConfig = "uic_z1",
        action_mode: str = "continuous",
        residual_scale: float = 1.0,
        residual_deadband: float = 0.0,
        valve_group: str | None = None,
        privileged: bool = False,
        accelerometer: bool = False,
        accelerometer_bias_mps2: float = 0.05,
        reward: RewardConfig | dict | None = None,
        scenario: ScenarioConfig | dict | None = None,
        rails_config: str | None = None,
        extra_rails: dict[str, RailConfig] | None = None,
        control_period_s: float = 0.02,
        substep_s: float = 1e-3,
        max_time_s: float = 300.0,
    ) -> None:
        veh = vehicle if isinstance(vehicle, VehicleConfig) else load_vehicle(vehicle)
        if valve_group is not None:
            if valve_group not in ("axle", "bogie"):
                raise ValueError(f"valve_group: {valve_group!r} is not 'axle' or 'bogie'")
            veh = dataclasses.replace(
                veh, brake=dataclasses.replace(veh.brake, valve_group=valve_group)
            )
        if action_mode not in ACTION_MODES:
            raise ValueError(
                f"action_mode: {action_mode!r} is not one of {', '.join(map(repr, ACTION_MODES))}"
            )
        if not (np.isfinite(residual_scale) and 0.0 < residual_scale <= 1.0):
            raise ValueError(f"residual_scale: must be in (0, 1], got {residual_scale!r}")
        if not (np.isfinite(residual_deadband) and 0.0 <= residual_deadband < 1.0):
            raise ValueError(f"residual_deadband: must be in [0, 1), got {residual_deadband!r}")
        self.vehicle = veh
        self.reward = _config(RewardConfig, reward, "reward")
        self.scenario = _config(ScenarioConfig, scenario, "scenario")
        self.rails: dict[str, RailConfig] = {**load_rails(rails_config), **(extra_rails or {})}
        for name in self.scenario.rails:
            if name not in self.rails:
                raise ConfigError(
                    f"scenario.rails.{name}: unknown rail (known: {', '.join(self.rails)})"
                )
        self.sim = TrainSim(veh, n_envs=n_envs, dt_s=substep_s, control_period_s=control_period_s)
        self.n_envs = n_envs
        self.n_axles = self.sim.n_axles
        self.valve_of_axle = self.sim.arrays.valve_of_axle
        self.n_valves = int(self.valve_of_axle.max()) + 1
        self.mode = K.MODE_DISCRETE if action_mode == "discrete" else K.MODE_CONTINUOUS
        self.action_mode = action_mode
        self.residual_scale = float(residual_scale)
        self.residual_deadband = float(residual_deadband)
        self.privileged = privileged
        if not (np.isfinite(accelerometer_bias_mps2) and accelerometer_bias_mps2 >= 0.0):
            raise ValueError(
                f"accelerometer_bias_mps2: must be >= 0, got {accelerometer_bias_mps2!r}"
            )
        self.accelerometer = bool(accelerometer)
        self.accelerometer_bias_mps2 = float(accelerometer_bias_mps2)
        kernel_dim = K.obs_size(self.n_axles, self.n_valves, privileged, self.accelerometer)
        self._kobs = np.zeros((n_envs, kernel_dim), dtype=np.float32)  # the kernel writes it
        residual = action_mode == "residual"
        self.obs_dim = kernel_dim + (self.n_valves if residual else 0)
        self.terms = np.zeros((n_envs, K.N_TERMS))
        self.flags = np.zeros((n_envs, K.N_F), dtype=np.int64)
        self.wsp = np.zeros((n_envs, K.N_W))
        self.prev_wheel = np.zeros((n_envs, self.n_axles))
        self.prev_action = np.ones((n_envs, self.n_valves))
        self.obs_par = np.zeros(K.N_OP)
        self.obs_par[K.OP_SPEED_SCALE] = veh.max_speed_kmh / 3.6
        self.obs_par[K.OP_DECEL_SCALE] = 10.0
        self.obs_par[K.OP_REF_DECEL_LIMIT] = 2.5
        self.obs_par[K.OP_REF_RISE_LIMIT] = 0.5
        self.obs_par[K.OP_MAX_TIME] = max_time_s
        self.obs_par[K.OP_PRIVILEGED] = 1.0 if privileged else 0.0
        self.obs_par[K.OP_ACCELEROMETER] = 1.0 if self.accelerometer else 0.0
        self.reward_par = self.reward.vector()
        self.rngs: list[np.random.Generator] = [np.random.default_rng() for _ in range(n_envs)]
        self.episode_return = np.zeros(n_envs)
        self.episode_terms = np.zeros((n_envs, K.N_TERMS))
        self._step_fn = K.env_step_parallel if n_envs >= PARALLEL_MIN_ENVS else K.env_step_serial
        # residual mode: the classical WSP runs beside the kernel; its requests for the coming
        # period are computed once per period, when the observation is first read after a step
        # or a reset (``obs``), so that it advances exactly once per control period
        self.base: Any = None
        if residual:
            from wsp_env.baselines.classical import ClassicalWSP, load_wsp_config

            self.base = ClassicalWSP(load_wsp_config())
            self.base.bind(self)
            self.base_action = np.ones((n_envs, self.n_valves), dtype=np.float32)
            self._obs_full = np.zeros((n_envs, self.obs_dim), dtype=np.float32)
            self._base_stale = True
            self._base_pending: list[int] = list(range(n_envs))

    # ---- observation ------------------------------------------------------------------------

    @property
    def obs(self) -> np.ndarray:
        """Current observations ``(n_envs, obs_dim)`` (module docstring)."""
        if self.base is None:
            return self._kobs
        if self._base_stale:
            self._refresh_base()
        return self._obs_full

    def _refresh_base(self) -> None:
        """Residual mode: advance the classical WSP one period on the current observations."""
        if self._base_pending:
            self.base.reset(np.array(self._base_pending, dtype=np.int64))
            self._base_pending.clear()
        self.base_action[...] = self.base.act(self._kobs)
        width = self._kobs.shape[1]
        self._obs_full[:, :width] = self._kobs
        self._obs_full[:, width:] = self.base_action
        self._base_stale = False

    def final_obs(self, e: int) -> np.ndarray:
        """The observation env ``e`` ended with, without advancing the classical WSP (residual
        mode: its requests of the last period stand in; nothing acts on a final observation)."""
        if self.base is None:
            return self._kobs[e].copy()
        return np.concatenate([self._kobs[e], self.base_action[e]])

    # ---- spaces ----------------------------------------------------------------------------

    def action_space(self) -> spaces.Space:
        if self.mode == K.MODE_CONTINUOUS:
            return spaces.Box(-1.0, 1.0, (self.n_valves,), dtype=np.float32)
        return spaces.MultiDiscrete([3] * self.n_valves)

    def observation_space(self) -> spaces.Box:
        return spaces.Box(-K.OBS_CLIP, K.OBS_CLIP, (self.obs_dim,), dtype=np.float32)

    # ---- scenario draws --------------------------------------------------------------------

    def draw_setup(self, rng: np.random.Generator, options: dict[str, Any] | None) -> RunSetup:
        opts = dict(options or {})
        unknown = sorted(set(opts) - set(OPTION_KEYS))
        if unknown:
            raise ValueError(f"options.{unknown[0]}: unknown (allowed: {', '.join(OPTION_KEYS)})")
        sc = self.scenario
        names = list(sc.rails)
        weights = np.array([sc.rails[n] for n in names], dtype=float)
        rail_name = names[int(rng.choice(len(names), p=weights / weights.sum()))]
        lo, hi = sc.speed_kmh or (40.0, self.vehicle.max_speed_kmh)
        speed = float(rng.uniform(lo, hi))
        load = float(rng.uniform(*sc.load_factor))
        pad = float(rng.uniform(*sc.pad_factor))
        grade = float(rng.uniform(*sc.gradient_permille))
        emergency = bool(rng.uniform() < sc.emergency_probability)
        rail_name = str(opts.pop("rail", rail_name))
        if rail_name not in self.rails:
            raise ValueError(
                f"options.rail: unknown rail {rail_name!r} (known: {', '.join(self.rails)})"
            )
        rail = self.rails[rail_name]
        pattern = opts.pop("pattern", None)
        if pattern is not None:
            rail = dataclasses.replace(rail, patterns={str(pattern): 1.0})
        demand = opts.pop("demand", "emergency" if emergency else "service")
        if demand not in ("emergency", "service"):
            raise ValueError(f"options.demand: {demand!r} is not 'emergency' or 'service'")
        speed = float(opts.pop("speed_kmh", speed))
        fixed: dict[str, Any] = {
            "load_factor": load,
            "pad_factor": pad,
            "gradient_permille": grade,
            "demand_fraction": 1.0 if demand == "emergency" else sc.service_demand_fraction,
        }
        fixed.update(opts)
        if "sections" in fixed:
            fixed["sections"] = tuple(tuple(float(v) for v in s) for s in fixed["sections"])
        if "axle_mu_factor" in fixed and fixed["axle_mu_factor"] is not None:
            fixed["axle_mu_factor"] = tuple(float(v) for v in fixed["axle_mu_factor"])
        fixed["rail_name"] = rail_name
        return draw_run_setup(rail, rng, speed, **fixed)

    def reset_env(self, e: int, options: dict[str, Any] | None) -> dict[str, Any]:
        setup = self.draw_setup(self.rngs[e], options)
        sim = self.sim
        sim.configure(e, setup)
        sim.reset([e])
        sim.cmd[e] = 1.0
        # drawn after the scenario: the first scenario after seeding is the same with or without
        # the accelerometer (later autoreset draws differ: the bias advanced the generator)
        bias = self.accelerometer_bias_mps2
        drawn = self.rngs[e].uniform(-bias, bias) if self.accelerometer else 0.0
        self.wsp[e, K.W_ACC_BIAS] = drawn
        K.reset_obs(
            e, sim.env_par, sim.axle_par, sim.env_state, sim.axle_state, self.wsp,
            self.prev_wheel, self.prev_action, self.obs_par, sim.control_period_s, self._kobs,
        )  # fmt: skip
        if self.base is not None:
            self._base_pending.append(e)
            self._base_stale = True
        self.episode_return[e] = 0.0
        self.episode_terms[e] = 0.0
        return {"scenario": self.describe(e)}

    def describe(self, e: int) -> dict[str, Any]:
        s = self.sim.setups[e]
        assert s is not None
        return {
            "vehicle": self.vehicle.id,
            "speed_kmh": s.speed_kmh,
            "rail": s.rail_name,
            "mu_contaminated": s.mu_contaminated,
            "sections": [list(x) for x in s.sections],
            "background": s.background,
            "load_factor": s.load_factor,
            "pad_factor": s.pad_factor,
            "gradient_permille": s.gradient_permille,
            "demand_fraction": s.demand_fraction,
        }

    # ---- stepping --------------------------------------------------------------------------

    def check_actions(self, actions: np.ndarray) -> np.ndarray:
        a = np.asarray(actions)
        if a.shape != (self.n_envs, self.n_valves):
            want = (self.n_valves,) if self.n_envs == 1 else (self.n_envs, self.n_valves)
            raise ValueError(f"action: expected shape {want}, got {np.shape(actions)}")
        if self.mode == K.MODE_CONTINUOUS:
            if a.dtype.kind not in "fiu":
                raise ValueError(f"action: expected numbers, got dtype {a.dtype}")
            if np.isnan(a).any():
                raise ValueError("action: NaN in a valve command (expected values in [-1, 1])")
            return a if a.dtype in (np.float32, np.float64) else a.astype(np.float64)
        a = a.astype(np.float64)
        if not np.isin(a, (0.0, 1.0, 2.0)).all():
            raise ValueError("action: discrete valve modes must be 0 (vent), 1 (hold) or 2 (fill)")
        return a

    def compose(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Residual mode: the valve actions the residual ``actions`` make of the classical WSP's
        requests for this period, and the count of clipped components per env; otherwise
        ``actions`` unchanged and None."""
        if self.base is None:
            return actions, None
        if self._base_stale:
            self._refresh_base()
        residual = np.clip(actions, -1.0, 1.0).astype(np.float64)
        clipped = (residual != actions).sum(axis=1)
        band = self.residual_deadband
        if band > 0.0:  # small residuals leave the classical request (a hold stays a hold)
            residual = np.sign(residual) * np.maximum(np.abs(residual) - band, 0.0) / (1.0 - band)
        # float64: with a zero residual the command is the classical WSP's, bit for bit
        frac = 0.5 * (self.base_action.astype(np.float64) + 1.0) + self.residual_scale * residual
        return 2.0 * np.clip(frac, 0.0, 1.0) - 1.0, clipped

    def valve_commands(self, actions: np.ndarray) -> np.ndarray:
        """Per-axle valve commands ``(n_envs, n_axles)`` as the kernel makes them from checked
        actions (a fraction of the demand, or ``CMD_HOLD``): for models outside the kernel (the
        roller rig's physical vehicle)."""
        a, _ = self.compose(actions)
        a = np.asarray(a, dtype=np.float64)[:, self.valve_of_axle]
        if self.mode == K.MODE_CONTINUOUS:
            return 0.5 * (np.clip(a, -1.0, 1.0) + 1.0)
        return np.where(a == 0.0, 0.0, np.where(a == 1.0, CMD_HOLD, 1.0))

    def step(self, actions: np.ndarray) -> None:
        sim = self.sim
        actions, clipped = self.compose(actions)
        self._step_fn(
            self.mode, actions, self.valve_of_axle, sim.n_sub, sim.dt_s, sim.control_period_s,
            sim.cmd, sim.env_par, sim.axle_par, sim.sections, sim.env_state, sim.axle_state,
            sim.field, sim.env_acc, sim.axle_acc, self.wsp, self.prev_wheel, self.prev_action,
            self.obs_par, self.reward_par, self._kobs, self.terms, self.flags,
        )  # fmt: skip
        if clipped is not None:  # residual mode
            self.flags[:, K.F_CLIPPED] = clipped
            self._base_stale = True

    # ---- state (checkpoints: a resumed training run continues bit for bit) -----------------

    _STATE_ARRAYS = ("_kobs", "terms", "flags", "wsp", "prev_wheel", "prev_action",
                     "episode_return", "episode_terms")  # fmt: skip
    _SIM_ARRAYS = ("env_par", "axle_par", "sections", "env_state", "axle_state", "field",
                   "env_acc", "axle_acc", "cmd", "initial_energy_J")  # fmt: skip

    def state_dict(self) -> dict[str, Any]:
        """Everything that evolves: the physics, the WSP observation state, the episodes'
        scenarios and each environment's random generator (copies)."""
        state = {
            "n_envs": self.n_envs,
            "core": {k: getattr(self, k).copy() for k in self._STATE_ARRAYS},
            "sim": {k: getattr(self.sim, k).copy() for k in self._SIM_ARRAYS},
            "setups": list(self.sim.setups),
            "rngs": [r.bit_generator.state for r in self.rngs],
        }
        if self.base is not None:
            state["base"] = {
                "wsp": self.base.state_dict(),
                "action": self.base_action.copy(),
                "obs": self._obs_full.copy(),
                "stale": self._base_stale,
                "pending": list(self._base_pending),
            }
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore ``state_dict``'s content into this core (same vehicle and ``n_envs``)."""
        if state["n_envs"] != self.n_envs:
            raise ValueError(f"state: {state['n_envs']} environments, this core has {self.n_envs}")
        for k in self._STATE_ARRAYS:
            getattr(self, k)[...] = state["core"][k]
        for k in self._SIM_ARRAYS:
            getattr(self.sim, k)[...] = state["sim"][k]
        self.sim.setups[:] = state["setups"]
        for r, s in zip(self.rngs, state["rngs"], strict=True):
            r.bit_generator.state = s
        if self.base is not None:
            base = state["base"]
            self.base.load_state_dict(base["wsp"])
            self.base_action[...] = base["action"]
            self._obs_full[...] = base["obs"]
            self._base_stale = bool(base["stale"])
            self._base_pending[:] = base["pending"]

    def episode_info(self, e: int) -> dict[str, Any]:
        metrics = run_metrics(self.sim, e)
        metrics["episode_return"] = float(self.episode_return[e])
        metrics["episode_reward_terms"] = dict(
            zip(TERM_NAMES, (float(x) for x in self.episode_terms[e]), strict=True)
        )
        return metrics

    def render(self, e: int = 0) -> np.ndarray:
        from wsp_env.plotting import render_state

        sim = self.sim
        return render_state(
            wheel_kmh=3.6 * sim.wheel_speed_mps[e],
            train_kmh=3.6 * sim.speed_mps[e],
            ref_kmh=3.6 * self.wsp[e, K.W_VREF],
            pressure_bar=sim.pressure_bar[e],
            demand_bar=float(sim.demand_bar()[e]),
            p_max_bar=float(sim.env_par[e, EP_P_MAX]),
            time_s=float(sim.time_s[e]),
            distance_m=float(sim.position_m[e]),
            v_max_kmh=self.vehicle.max_speed_kmh,
        )


class WSPBrakingEnv(gym.Env):
    __doc__ = __doc__
    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode: {render_mode!r} (supported: rgb_array)")
        self.render_mode = render_mode
        self.core = _BrakingCore(1, **kwargs)
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
        return self.core.render(0)


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
        self.core = _BrakingCore(num_envs, **kwargs)
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
        return tuple(self.core.render(e) for e in range(self.num_envs))

"""The braking core: the one way anything steps a stop (environments, evaluation, training's
validation, the roller rig, the scripts).

:class:`BrakingCore` holds ``n_envs`` stops side by side: a :class:`~wsp_env.core.kernel.Params`
bundle (what each stop is: vehicle, rail, scenario, observation and reward settings; fixed from
``reset`` to the stop) and a :class:`~wsp_env.core.kernel.State` bundle (what evolves: the
physics, the WSP's reference speed, the observation, reward terms and flags), stepped together
by one compiled call (``core.kernel``). It offers what its users need: ``reset_env`` with
options (and a seed), ``step``, ``ended`` and ``freeze`` for finished runs, a :class:`Recorder`
for a run's rows, ``observe_external`` / ``act_external`` for a vehicle outside the kernel (the
rig), and ``state_dict`` for checkpoints. Nothing outside it reads the WSP state, the
observation or the reward by column (the rig, a second physical model, sets external torques).

The Gymnasium classes over it are in ``wsp_env.envs``; the observation, action and reward it
implements are documented there (``WSPBrakingEnv``'s docstring).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding

from wsp_env import threads
from wsp_env.core import kernel as K
from wsp_env.core.config import (
    OPTION_SPECS,
    ConfigError,
    RailConfig,
    VehicleConfig,
    check_number,
    check_option,
    check_options,
    from_dict,
    load_rails,
    load_vehicle,
)
from wsp_env.core.kernel import Params, State
from wsp_env.core.metrics import run_metrics
from wsp_env.core.records import RunRecord
from wsp_env.core.sensors import (
    EstimatorConfig,
    SensorConfig,
    WatchdogConfig,
    draw_sensors,
    fill_obs_par,
)
from wsp_env.core.simulator import RunSetup, TrainSim, draw_run_setup
from wsp_env.physics import layout as L
from wsp_env.physics.brake import PAD_FACTOR_MIN
from wsp_env.physics.layout import CMD_HOLD


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


ACTION_MODES = ("continuous", "discrete", "residual", "slip_target")
# slip-target mode: the bounds of the target sliding speed an action may ask for (km/h)
SLIP_TARGET_MAX_KMH = 30.0
# memory features (``memory_features=True``): how their three per-axle channels are scaled
MEMORY_TIME_SCALE_S = 10.0  # time in the current slide, time since the last release: / 10 s
MEMORY_ENERGY_SCALE_MJ = 1.0  # the sliding-energy estimate: / 1 MJ (the damage term's E_ref)
# Timing bounds (the CLI's --dt-s shares them): a substep below 10 us only multiplies the work
# (the linearly implicit scheme is stable at 1 ms, docs/physics.md; 1e-12 s made one step take
# hours), a control period beyond 1 s is no WSP, and a stop lasts minutes, not hours.
SUBSTEP_MIN_S = 1e-5
CONTROL_PERIOD_S = {"gt": 0.0, "le": 1.0}
MAX_TIME_S = {"gt": 0.0, "le": 3600.0}

# what ``reset(options=...)`` may fix: the names of ``config.OPTION_SPECS`` (their bounds);
# the sensor options set a stop's sensor errors, the rest its scenario
OPTION_KEYS = tuple(OPTION_SPECS)
SENSOR_OPTIONS = ("accelerometer_bias_mps2", "wheel_speed_noise_kmh")


def _config(cls: type, value: Any, name: str) -> Any:
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    return from_dict(cls, value, name)


class BrakingCore:
    """``n_envs`` stops stepped together (module docstring); the arguments are
    ``WSPBrakingEnv``'s (``wsp_env.envs``)."""

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
        accelerometer_bias_mps2: float | None = None,
        sensors: SensorConfig | dict | None = None,
        estimator: EstimatorConfig | dict | None = None,
        watchdog: WatchdogConfig | dict | None = None,
        reward: RewardConfig | dict | None = None,
        scenario: ScenarioConfig | dict | None = None,
        rails_config: str | None = None,
        extra_rails: dict[str, RailConfig] | None = None,
        control_period_s: float = 0.02,
        substep_s: float = 1e-3,
        max_time_s: float = 300.0,
        residual_base: Any = None,
        slip_target_min_kmh: float = 0.5,
        slip_target_max_kmh: float = 8.0,
        slip_target_loop: Any = None,
        memory_features: bool = False,
        memory_target_mean: bool = False,
    ) -> None:
        if isinstance(n_envs, bool) or not isinstance(n_envs, int | np.integer) or n_envs < 1:
            raise ValueError(f"n_envs: must be a positive integer, got {n_envs!r}")
        control_period_s = check_number(control_period_s, "control_period_s", **CONTROL_PERIOD_S)
        substep_s = check_number(substep_s, "substep_s", ge=SUBSTEP_MIN_S, le=control_period_s)
        n_sub = round(control_period_s / substep_s)  # TrainSim's rule, named here
        if abs(n_sub * substep_s - control_period_s) > 1e-9:
            raise ValueError(
                f"substep_s: must divide the control period ({control_period_s:g} s), "
                f"got {substep_s:g} s"
            )
        max_time_s = check_number(max_time_s, "max_time_s", **MAX_TIME_S)
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
        lo = check_number(slip_target_min_kmh, "slip_target_min_kmh", ge=0.0,
                          le=SLIP_TARGET_MAX_KMH)  # fmt: skip
        hi = check_number(slip_target_max_kmh, "slip_target_max_kmh", ge=0.0,
                          le=SLIP_TARGET_MAX_KMH)  # fmt: skip
        if hi <= lo:
            raise ValueError(
                f"slip_target_max_kmh: must exceed slip_target_min_kmh ({lo:g}), got {hi:g}"
            )
        if not isinstance(memory_features, bool | np.bool_):
            raise ValueError(f"memory_features: must be True or False, got {memory_features!r}")
        if not isinstance(memory_target_mean, bool | np.bool_):
            raise ValueError(
                f"memory_target_mean: must be True or False, got {memory_target_mean!r}"
            )
        if memory_target_mean and action_mode != "slip_target":
            raise ValueError(
                "memory_target_mean: observes the stop's mean slip target, so it needs "
                f"action_mode 'slip_target', got {action_mode!r}"
            )
        self.vehicle = veh
        self.reward = _config(RewardConfig, reward, "reward")
        self.scenario = _config(ScenarioConfig, scenario, "scenario")
        self.rails: dict[str, RailConfig] = {**load_rails(rails_config), **(extra_rails or {})}
        for name in self.scenario.rails:
            if name not in self.rails:
                raise ConfigError(
                    f"scenario.rails.{name}: unknown rail (known: {', '.join(self.rails)})"
                )
        for name in ("speed_kmh", "load_factor", "pad_factor", "gradient_permille"):
            for i, end in enumerate(getattr(self.scenario, name) or ()):  # options' bounds
                check_option(name, end, veh, f"scenario.{name}[{i}]")
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
        self.sensors = _config(SensorConfig, sensors, "sensors")
        if accelerometer_bias_mps2 is not None:  # the older keyword for the bias's bound
            bias = check_number(accelerometer_bias_mps2, "accelerometer_bias_mps2", ge=0.0, le=2.0)
            self.sensors = dataclasses.replace(self.sensors, accelerometer_bias_mps2=bias)
        self.estimator = _config(EstimatorConfig, estimator, "estimator")
        self.watchdog = _config(WatchdogConfig, watchdog, "watchdog")
        self.accelerometer = bool(accelerometer)
        self.accelerometer_bias_mps2 = self.sensors.accelerometer_bias_mps2
        kernel_dim = K.obs_size(self.n_axles, self.n_valves, privileged, self.accelerometer)
        self.kernel_obs_dim = kernel_dim
        self._kobs = np.zeros((n_envs, kernel_dim), dtype=np.float32)  # the kernel writes it
        residual = action_mode == "residual"
        slip_target = action_mode == "slip_target"
        self.memory_features = bool(memory_features)
        memory_dim = 3 * self.n_axles if self.memory_features else 0
        self.memory_target_mean = bool(memory_target_mean)
        target_dim = self.n_valves if self.memory_target_mean else 0
        tail = self.n_valves if residual or slip_target else 0
        self.obs_dim = kernel_dim + memory_dim + target_dim + tail
        # the observation beyond the kernel's: memory features, the stop's mean slip target,
        # then the action mode's tail
        self._extended = self.obs_dim > kernel_dim
        self.terms = np.zeros((n_envs, K.N_TERMS))
        self.flags = np.zeros((n_envs, K.N_F), dtype=np.int64)
        self.wsp = np.zeros((n_envs, K.N_W))
        self.axle_wsp = np.zeros((n_envs, self.n_axles, K.N_AW))
        self.axle_wsp[:, :, K.AW_SCALE] = 1.0
        self.sensor_par = np.zeros((n_envs, K.N_SP))
        self.sensor_rng = np.zeros(n_envs, dtype=np.uint64)
        self.prev_wheel = np.zeros((n_envs, self.n_axles))
        self.prev_action = np.ones((n_envs, self.n_valves))
        self.obs_par = np.zeros(K.N_OP)
        self.obs_par[K.OP_SPEED_SCALE] = veh.max_speed_kmh / 3.6
        self.obs_par[K.OP_DECEL_SCALE] = 10.0
        self.obs_par[K.OP_MAX_TIME] = max_time_s
        self.obs_par[K.OP_AGE_SCALE] = 10.0
        fill_obs_par(self.obs_par, self.estimator, self.watchdog)
        self.obs_par[K.OP_PRIVILEGED] = 1.0 if privileged else 0.0
        self.obs_par[K.OP_ACCELEROMETER] = 1.0 if self.accelerometer else 0.0
        self.reward_par = self.reward.vector()
        self.rngs: list[np.random.Generator] = [np.random.default_rng() for _ in range(n_envs)]
        self.episode_return = np.zeros(n_envs)
        self.episode_terms = np.zeros((n_envs, K.N_TERMS))
        # stepping before every env's first reset is an error (its arrays are not a stop):
        # one flag read per step once all are started (``_check_started``)
        self._started = np.zeros(n_envs, dtype=bool)
        self._all_started = False
        # the thread policy (wsp_env.threads) says from how many environments the parallel
        # path pays: from 64 without a learner in the process, never below 8 cores with one
        parallel = n_envs >= threads.parallel_min_envs()
        self._step_fn = K.env_step_parallel if parallel else K.env_step_serial
        # residual mode: the classical WSP runs beside the kernel; its requests for the coming
        # period are computed once per period, when the observation is first read after a step
        # or a reset (``obs``), so that it advances exactly once per control period
        # (``residual_base``: the controller the residual acts on, a policy object with
        # ``bind`` / ``reset`` / ``act``; ``envs.make_core`` gives the frozen classical WSP)
        self.base: Any = None
        self.loop: Any = None
        self.slip_target_min_kmh, self.slip_target_max_kmh = lo, hi
        if self._extended:
            self._obs_full = np.zeros((n_envs, self.obs_dim), dtype=np.float32)
            self._base_stale = True
            self._base_pending: list[int] = list(range(n_envs))
        if self.memory_features:  # per axle (module docstring of wsp_env.envs)
            self.memory_slide_s = np.zeros((n_envs, self.n_axles))
            self.memory_since_release_s = np.zeros((n_envs, self.n_axles))
            self.memory_energy_J = np.zeros((n_envs, self.n_axles))
        if self.memory_target_mean:  # the sum of the agent's targets (as actions) and periods
            self.memory_target_sum = np.zeros((n_envs, self.n_valves))
            self.memory_target_periods = np.zeros(n_envs)
        # slip-target mode: the inner loop (``slip_target_loop``, ``baselines.slip_target``;
        # ``envs.make_core`` supplies it) advances once per period, as the residual's base does,
        # and turns each period's targets into valve commands; ``slip_action``: the agent's last
        # action (clipped), observed as the tail
        if slip_target:
            if slip_target_loop is None:
                raise ValueError(
                    "action_mode: 'slip_target' needs slip_target_loop (envs.make_core supplies "
                    "the slip-target inner loop)"
                )
            self.loop = slip_target_loop
            self.slip_action = np.ones((n_envs, self.n_valves))
        if residual:
            if residual_base is None:
                raise ValueError(
                    "action_mode: 'residual' needs residual_base (envs.make_core supplies the "
                    "classical WSP)"
                )
            self.base = residual_base
            self.base_action = np.ones((n_envs, self.n_valves), dtype=np.float32)

        sim = self.sim
        self.params = Params(
            valve_of_axle=self.valve_of_axle, env_par=sim.env_par, axle_par=sim.axle_par,
            sections=sim.sections, obs_par=self.obs_par, sensor_par=self.sensor_par,
            reward_par=self.reward_par,
        )  # fmt: skip
        self.state = State(
            cmd=sim.cmd, env_state=sim.env_state, axle_state=sim.axle_state, field=sim.field,
            env_acc=sim.env_acc, axle_acc=sim.axle_acc, wsp=self.wsp, axle_wsp=self.axle_wsp,
            rng=self.sensor_rng, prev_wheel=self.prev_wheel, prev_action=self.prev_action,
            obs=self._kobs, terms=self.terms, flags=self.flags,
        )  # fmt: skip
        self._step_args = K.step_args(
            sim.n_sub, sim.dt_s, sim.control_period_s, self.params, self.state
        )
        if self.base is not None:
            self.base.bind(self)  # last: a base may read anything of the core
        if self.loop is not None:
            self.loop.bind(self)

    # ---- observation ------------------------------------------------------------------------

    @property
    def obs(self) -> np.ndarray:
        """Current observations ``(n_envs, obs_dim)`` (module docstring)."""
        if not self._extended:
            return self._kobs
        if self._base_stale:
            self._refresh_base()
        return self._obs_full

    def _refresh_base(self) -> None:
        """Once per period, on the first read after a step or a reset: the residual mode's
        classical WSP or the slip-target loop advances one period on the current observations,
        and the observation beyond the kernel's is assembled."""
        if self._base_pending:
            ids = np.array(self._base_pending, dtype=np.int64)
            for controller in (self.base, self.loop):
                if controller is not None:
                    controller.reset(ids)
            self._base_pending.clear()
        if self.base is not None:
            self.base_action[...] = self.base.act(self._kobs)
        if self.loop is not None:
            self.loop.advance(self._kobs)
        width = self._kobs.shape[1]
        self._obs_full[:, :width] = self._kobs
        if self.memory_features:
            self._obs_full[:, width : width + 3 * self.n_axles] = self.memory_obs()
            width += 3 * self.n_axles
        if self.memory_target_mean:
            self._obs_full[:, width : width + self.n_valves] = self.target_mean_obs()
        tail = self._tail()
        if tail is not None:
            self._obs_full[:, self.obs_dim - tail.shape[1] :] = tail
        self._base_stale = False

    def _tail(self) -> np.ndarray | None:
        """The action mode's last ``n_valves`` observation entries: the classical WSP's requests
        (residual), the agent's last slip-target action (slip_target), else None."""
        if self.base is not None:
            return self.base_action
        if self.loop is not None:
            return self.slip_action
        return None

    def memory_obs(self, rows: Any = slice(None)) -> np.ndarray:
        """The memory features of environments ``rows`` (all by default) as observed
        ``(len(rows), 3 n_axles)``: time in the current slide and time since the last release
        (each / ``MEMORY_TIME_SCALE_S``), the sliding-energy estimate
        (/ ``MEMORY_ENERGY_SCALE_MJ``), clipped to the observation's bound (``memory_features``:
        ``WSPBrakingEnv``'s docstring)."""
        parts = (
            self.memory_slide_s[rows] / MEMORY_TIME_SCALE_S,
            self.memory_since_release_s[rows] / MEMORY_TIME_SCALE_S,
            self.memory_energy_J[rows] * 1e-6 / MEMORY_ENERGY_SCALE_MJ,
        )
        return np.clip(np.concatenate(parts, axis=-1), -K.OBS_CLIP, K.OBS_CLIP)

    def target_mean_obs(self, rows: Any = slice(None)) -> np.ndarray:
        """``memory_target_mean``: the stop's mean slip-target action of environments ``rows``
        so far ``(len(rows), n_valves)``, per valve, over the control periods stepped since the
        reset (each period's clipped action, as the tail shows it); before the first period the
        tail's own value (1: no target asked for yet). A WSP's memory of what it asked for: a
        policy that reads the rail early in the stop keeps what it read (``WSPBrakingEnv``'s
        docstring)."""
        n = self.memory_target_periods[rows]
        mean = self.memory_target_sum[rows] / np.maximum(n, 1.0)[..., None]
        return np.where((n > 0.0)[..., None], mean, self.slip_action[rows])

    def _update_memory(self, rows: Any = slice(None)) -> None:
        """Advance the memory features of ``rows`` by the period just stepped, from what the
        observation shows: the measured slip ``v_ref - v_i`` (wheel-speed readings, the shared
        reference), the cylinder pressures, this period's valve commands (``WSPBrakingEnv``'s
        docstring: Observation Space, memory features)."""
        sim, dt = self.sim, self.sim.control_period_s
        env_par, axle_par = sim.env_par[rows], sim.axle_par[rows]
        v_ref = self.wsp[rows, K.W_VREF]
        slip = v_ref[:, None] - self.axle_wsp[rows, :, K.AW_WHEEL]
        # the metrics' slide threshold max(3 km/h, 20 % of the speed), on the reference
        threshold = np.maximum(env_par[:, L.EP_SLIDE_THRESH], env_par[:, L.EP_SLIDE_REL] * v_ref)
        sliding = slip > threshold[:, None]
        self.memory_slide_s[rows] = np.where(sliding, self.memory_slide_s[rows] + dt, 0.0)
        # a release: the valve asked for under the watchdog's release fraction of the demand;
        # the period's commands as the valves got them, after the watchdog's say
        cmd = sim.cmd[rows]
        vent = (cmd >= 0.0) & (cmd < self.obs_par[K.OP_WD_RELEASE_FRACTION])
        self.memory_since_release_s[rows] = np.where(
            vent, 0.0, self.memory_since_release_s[rows] + dt
        )
        # brake force at the rail from the observed pressure and the vehicle's brake constants,
        # the pads' nominal friction at the reference speed (the stop's drawn pad scale is
        # unknown to a WSP): brake.brake_torque / r with pad_factor's scale 1
        pad = np.maximum(
            PAD_FACTOR_MIN, 1.0 + env_par[:, L.EP_PAD_SLOPE] * (v_ref - env_par[:, L.EP_PAD_VREF])
        )
        p = sim.axle_state[rows, :, L.AS_P]
        force = (
            axle_par[:, :, L.AP_BRAKE_GAIN]
            * np.maximum(p - axle_par[:, :, L.AP_P_THRESH], 0.0)
            * pad[:, None]
            / axle_par[:, :, L.AP_RADIUS]
        )
        self.memory_energy_J[rows] += force * np.maximum(slip, 0.0) * dt

    def final_obs(self, e: int) -> np.ndarray:
        """The observation env ``e`` ended with, without advancing the classical WSP or the
        slip-target loop (their last period's entries stand in; nothing acts on a final
        observation)."""
        if not self._extended:
            return self._kobs[e].copy()
        parts = [self._kobs[e]]
        if self.memory_features:
            parts.append(self.memory_obs(e))  # its row only
        if self.memory_target_mean:
            parts.append(self.target_mean_obs(e))
        tail = self._tail()
        if tail is not None:
            parts.append(tail[e])
        return np.concatenate(parts).astype(np.float32)

    # ---- spaces ----------------------------------------------------------------------------

    def action_space(self) -> spaces.Space:
        if self.mode == K.MODE_CONTINUOUS:
            return spaces.Box(-1.0, 1.0, (self.n_valves,), dtype=np.float32)
        return spaces.MultiDiscrete([3] * self.n_valves)

    def observation_space(self) -> spaces.Box:
        return spaces.Box(-K.OBS_CLIP, K.OBS_CLIP, (self.obs_dim,), dtype=np.float32)

    # ---- scenario draws --------------------------------------------------------------------

    def draw_setup(self, rng: np.random.Generator, options: dict[str, Any] | None) -> RunSetup:
        """A stop's conditions: ``options`` (checked against ``config.OPTION_SPECS`` and this
        core's vehicle and rails; a problem is a one-line ``ConfigError`` naming the option)
        fix what they name, ``rng`` draws the rest from the scenario and the rail."""
        opts = check_options(options, self.vehicle)
        for key in SENSOR_OPTIONS:
            opts.pop(key, None)
        if "rail" in opts and opts["rail"] not in self.rails:
            raise ConfigError(
                f"options.rail: unknown rail {opts['rail']!r} (known: {', '.join(self.rails)})"
            )
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
        rail_name = opts.pop("rail", rail_name)
        rail = self.rails[rail_name]
        pattern = opts.pop("pattern", None)
        if pattern is not None:
            rail = dataclasses.replace(rail, patterns={pattern: 1.0})
        demand = opts.pop("demand", "emergency" if emergency else "service")
        speed = opts.pop("speed_kmh", speed)
        fixed: dict[str, Any] = {
            "load_factor": load,
            "pad_factor": pad,
            "gradient_permille": grade,
            "demand_fraction": 1.0 if demand == "emergency" else sc.service_demand_fraction,
        }
        fixed.update(opts)
        fixed["rail_name"] = rail_name
        return draw_run_setup(rail, rng, speed, **fixed)

    def reset_env(
        self, e: int, options: dict[str, Any] | None = None, seed: int | None = None
    ) -> dict[str, Any]:
        """Start a new stop in env ``e``: draw its scenario (``options`` fix any drawn
        parameter; ``seed``, if given, first reseeds env ``e``'s generator)."""
        if seed is not None:
            self.rngs[e] = seeding.np_random(seed)[0]
        setup = self.draw_setup(self.rngs[e], options)
        sim = self.sim
        sim.configure(e, setup)
        sim.reset([e])
        self._started[e] = True
        sim.cmd[e] = 1.0
        # drawn after the scenario: the first scenario after seeding is the same whatever the
        # sensors (later autoreset draws differ where a sensor error advanced the generator)
        fixed = {k: v for k, v in check_options(options, self.vehicle).items()
                 if k in SENSOR_OPTIONS}  # fmt: skip
        row, scales, noise_seed = draw_sensors(
            self.sensors, self.rngs[e], self.n_axles, self.accelerometer, fixed
        )
        self.sensor_par[e] = row
        self.axle_wsp[e, :, K.AW_SCALE] = scales
        self.sensor_rng[e] = noise_seed
        K.reset_observation(e, self.params, self.state, sim.control_period_s)
        if self.memory_features:
            self.memory_slide_s[e] = 0.0
            self.memory_since_release_s[e] = 0.0
            self.memory_energy_J[e] = 0.0
        if self.memory_target_mean:
            self.memory_target_sum[e] = 0.0
            self.memory_target_periods[e] = 0.0
        if self.loop is not None:
            self.slip_action[e] = 1.0
        if self._extended:
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
            "sensors": {
                "wheel_speed_noise_kmh": 3.6 * float(self.sensor_par[e, K.SP_WHEEL_NOISE]),
                "wheel_speed_scale": [float(x) for x in self.axle_wsp[e, :, K.AW_SCALE]],
                "accelerometer_bias_mps2": (
                    float(self.sensor_par[e, K.SP_ACC_BIAS]) if self.accelerometer else None
                ),
            },
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
            # float64 whatever the policy gave (SB3 gives float32): one compiled specialisation
            # of the step, not one per dtype (the kernel computes in float64 either way)
            return np.ascontiguousarray(a, dtype=np.float64)
        a = a.astype(np.float64)
        if not np.isin(a, (0.0, 1.0, 2.0)).all():
            raise ValueError("action: discrete valve modes must be 0 (vent), 1 (hold) or 2 (fill)")
        return a

    def slip_targets_kmh(self, actions: np.ndarray) -> np.ndarray:
        """Slip-target mode: the target sliding speeds (km/h) of ``actions`` (clipped to
        [-1, 1]): ``min + (a + 1) / 2 (max - min)``."""
        a = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
        lo, hi = self.slip_target_min_kmh, self.slip_target_max_kmh
        return lo + 0.5 * (a + 1.0) * (hi - lo)

    def compose(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Residual mode: the valve actions the residual ``actions`` make of the classical WSP's
        requests for this period, and the count of clipped components per env; slip-target
        mode: the inner loop's valve actions for the targets ``actions`` ask for, and the same
        count; otherwise ``actions`` unchanged and None."""
        if self.loop is not None:
            if self._base_stale:
                self._refresh_base()
            clipped = (np.clip(actions, -1.0, 1.0) != actions).sum(axis=1)
            return self.loop.command(self._kobs, self.slip_targets_kmh(actions)), clipped
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
        """One control period of every environment (checked ``actions``, ``check_actions``);
        every environment must have been reset (``reset_env``) at least once."""
        if not self._all_started:
            self._check_started()
        given = actions
        actions, clipped = self.compose(actions)
        self._step_fn(self.mode, actions, *self._step_args)
        if clipped is not None:  # residual and slip-target modes: the agent's clipped entries
            self.flags[:, K.F_CLIPPED] = clipped
        if self.loop is not None:
            self.slip_action[...] = np.clip(given, -1.0, 1.0)
        if self.memory_target_mean:
            self.memory_target_sum += self.slip_action
            self.memory_target_periods += 1.0
        if self.memory_features:
            self._update_memory()
        if self._extended:
            self._base_stale = True

    def _check_started(self) -> None:
        """Raise unless every environment has been reset; remember when all have been."""
        if not self._started.all():
            waiting = np.flatnonzero(~self._started)
            which = "" if self.n_envs == 1 else f" (environment {int(waiting[0])} never reset)"
            raise RuntimeError(f"step before reset: call reset() first{which}")
        self._all_started = True

    def ended(self) -> np.ndarray:
        """``(n_envs,)`` bool: the stops that ended in the last step (standstill or time)."""
        return (self.flags[:, K.F_TERMINATED] | self.flags[:, K.F_TRUNCATED]).astype(bool)

    def freeze(self, e: int) -> None:
        """Hold env ``e`` where it ended: later steps of the batch leave it unchanged (a
        truncated run is otherwise still moving)."""
        self.sim.env_state[e, L.ES_STOPPED] = 1.0

    @property
    def reference_speed_mps(self) -> np.ndarray:
        """``(n_envs,)`` the shared reference-speed estimate every controller observes (a
        view; ``kernel.update_reference``)."""
        return self.wsp[:, K.W_VREF]

    @property
    def measured_wheel_speed_mps(self) -> np.ndarray:
        """``(n_envs, n_axles)`` the wheel-speed sensors' last readings (a view)."""
        return self.axle_wsp[:, :, K.AW_WHEEL]

    @property
    def accelerometer_reading_mps2(self) -> np.ndarray:
        """``(n_envs,)`` the accelerometer's last deceleration reading (zero without one)."""
        return self.wsp[:, K.W_ACC]

    def watchdog_interventions(self, e: int) -> dict[str, int]:
        """What the safety watchdog did in env ``e``'s stop: the axles it restored after the
        safety time, whether the minimum-deceleration supervision overrode the releases, and
        whether that override gave way (every axle locked under it; ``WatchdogConfig``)."""
        axles = int((self.axle_wsp[e, :, K.AW_WD_RESTORED] > 0.0).sum())
        decel = int(self.wsp[e, K.W_OVERRIDE] > 0.0)
        gave_way = int(self.wsp[e, K.W_OVERRIDE] == 2.0)
        return {"safety_time_axles": axles, "min_deceleration": decel, "gave_way": gave_way,
                "total": axles + decel}  # fmt: skip

    # ---- a vehicle outside the kernel (hardware in the loop: the roller rig) ----------------

    def observe_external(
        self,
        e: int,
        wheel_speed_mps: np.ndarray,
        pressure_bar: np.ndarray,
        decel_mps2: float | None,
    ) -> None:
        """Write env ``e``'s observation from sensors outside the kernel: the wheel speeds and
        cylinder pressures a rig measures, and the vehicle deceleration over the last period
        (``None`` on the first period: nothing is advanced). The readings are the rig's own
        (no sensor model is added: an accelerometer reads the deceleration, the gradient's part
        and the stop's bias); the reference speed and the watchdog advance as in the kernel
        (``kernel.estimate_and_supervise``, the same code); the previous period's wheel speeds
        give the observed decelerations."""
        sim = self.sim
        self.axle_wsp[e, :, K.AW_WHEEL] = wheel_speed_mps
        state = sim.axle_state.copy()  # the rig's pressures, the virtual vehicle's untouched
        state[e, :, L.AS_P] = pressure_bar
        external = self.state._replace(axle_state=state)
        if decel_mps2 is not None:
            if self.accelerometer:
                self.wsp[e, K.W_ACC] = (
                    decel_mps2 - sim.env_par[e, L.EP_GRADE_ACC] + self.sensor_par[e, K.SP_ACC_BIAS]
                )
            K.estimate_external(
                e, float(sim.env_state[e, L.ES_T]), self.params, external, sim.control_period_s,
                self.mode,
            )  # fmt: skip
        K.write_observation(e, self.params, external, sim.control_period_s)
        self.prev_wheel[e] = wheel_speed_mps
        if self.memory_features and decel_mps2 is not None:
            self._update_memory(slice(e, e + 1))
        if self._extended:
            self._base_stale = True

    def act_external(self, e: int, actions: np.ndarray) -> np.ndarray:
        """Env ``e``'s per-axle valve commands from checked ``actions`` for a vehicle outside the
        kernel (a fraction of the demand, or ``CMD_HOLD``); the previous action is kept for the
        observation as the kernel keeps it; the safety watchdog has its say as in the kernel
        (``kernel.watchdog_commands``)."""
        cmd = self.valve_commands(actions)[e : e + 1].copy()
        K.watchdog_commands(0, cmd, self.wsp[e : e + 1], self.axle_wsp[e : e + 1], self.obs_par)
        cmd = cmd[0]
        self.sim.cmd[e] = cmd  # the period's commands, for the estimator's next update
        if self.loop is not None:
            self.slip_action[e] = np.clip(np.asarray(actions, dtype=float)[e], -1.0, 1.0)
        if self.memory_target_mean:
            self.memory_target_sum[e] += self.slip_action[e]
            self.memory_target_periods[e] += 1.0
        if self.mode == K.MODE_CONTINUOUS:
            self.prev_action[e] = np.clip(self.compose(actions)[0][e], -1.0, 1.0)
        else:
            self.prev_action[e] = np.asarray(actions, dtype=float)[e] - 1.0
        return cmd

    # ---- state (checkpoints: a resumed training run continues bit for bit) -----------------

    _MEMORY_ARRAYS = ("memory_slide_s", "memory_since_release_s", "memory_energy_J")
    _TARGET_MEAN_ARRAYS = ("memory_target_sum", "memory_target_periods")
    _STATE_ARRAYS = ("_kobs", "terms", "flags", "wsp", "axle_wsp", "sensor_par", "sensor_rng",
                     "prev_wheel", "prev_action", "episode_return", "episode_terms")  # fmt: skip
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
        elif self._extended:
            state["extended"] = {
                "obs": self._obs_full.copy(),
                "stale": self._base_stale,
                "pending": list(self._base_pending),
            }
        if self.loop is not None:
            state["slip_target"] = {
                "loop": self.loop.state_dict(),
                "action": self.slip_action.copy(),
            }
        if self.memory_features:
            state["memory"] = {k: getattr(self, k).copy() for k in self._MEMORY_ARRAYS}
        if self.memory_target_mean:
            state["target_mean"] = {k: getattr(self, k).copy() for k in self._TARGET_MEAN_ARRAYS}
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore ``state_dict``'s content into this core (same vehicle and ``n_envs``)."""
        if state["n_envs"] != self.n_envs:
            raise ValueError(f"state: {state['n_envs']} environments, this core has {self.n_envs}")
        missing = [k for k in self._STATE_ARRAYS if k not in state["core"]]
        if missing:  # a checkpoint from before the sensor model (2026-11-25)
            raise ValueError(
                f"state: no {', '.join(missing)} (saved before the sensor model and the shared "
                "reference estimator existed: resume it with the version that wrote it)"
            )
        for k in self._STATE_ARRAYS:
            if getattr(self, k).shape != np.shape(state["core"][k]):  # e.g. before -v2's column
                raise ValueError(
                    f"state: {k} has shape {np.shape(state['core'][k])}, this core's is "
                    f"{getattr(self, k).shape} (saved by another version: resume it with the "
                    "version that wrote it)"
                )
            getattr(self, k)[...] = state["core"][k]
        for k in self._SIM_ARRAYS:
            getattr(self.sim, k)[...] = state["sim"][k]
        self.sim.setups[:] = state["setups"]
        self._started[:] = [s is not None for s in self.sim.setups]  # a reset env is configured
        self._all_started = bool(self._started.all())
        for r, s in zip(self.rngs, state["rngs"], strict=True):
            r.bit_generator.state = s
        if self.base is not None:
            base = state["base"]
            self.base.load_state_dict(base["wsp"])
            self.base_action[...] = base["action"]
            self._obs_full[...] = base["obs"]
            self._base_stale = bool(base["stale"])
            self._base_pending[:] = base["pending"]
        elif self._extended:
            ext = state["extended"]
            self._obs_full[...] = ext["obs"]
            self._base_stale = bool(ext["stale"])
            self._base_pending[:] = ext["pending"]
        if self.loop is not None:
            self.loop.load_state_dict(state["slip_target"]["loop"])
            self.slip_action[...] = state["slip_target"]["action"]
        if self.memory_features:
            for k in self._MEMORY_ARRAYS:
                getattr(self, k)[...] = state["memory"][k]
        if self.memory_target_mean:
            for k in self._TARGET_MEAN_ARRAYS:
                getattr(self, k)[...] = state["target_mean"][k]

    def episode_info(self, e: int) -> dict[str, Any]:
        metrics = run_metrics(self.sim, e)
        metrics["watchdog"] = self.watchdog_interventions(e)
        metrics["episode_return"] = float(self.episode_return[e])
        metrics["episode_reward_terms"] = dict(
            zip(TERM_NAMES, (float(x) for x in self.episode_terms[e]), strict=True)
        )
        return metrics


class Recorder:
    """A run's rows at every control period, for chosen environments of a core (what
    ``evaluate --report``, ``simulate --trace`` and the calibration's synthetic traces record):
    time, train speed, demand, the WSP reference speed, the train's deceleration, the wheel
    speeds, cylinder pressures and adhesion forces. Call :meth:`snapshot` after ``reset_env``
    and after every ``step``; an environment's rows stop once it is marked done."""

    def __init__(self, core: BrakingCore, env_ids: list[int]) -> None:
        self.core = core
        self.env_ids = list(env_ids)
        self.rows: dict[int, list[np.ndarray]] = {e: [] for e in self.env_ids}

    def snapshot(self, done: np.ndarray) -> None:
        """Append a row for every recorded environment not ``done``."""
        sim = self.core.sim
        demand = sim.demand_bar()
        for e in self.env_ids:
            if not done[e]:
                v_ref = self.core.reference_speed_mps[e]
                head = [sim.time_s[e], sim.speed_mps[e], demand[e], v_ref]
                head.append(sim.env_state[e, L.ES_DECEL])
                wheels = [sim.wheel_speed_mps[e], sim.pressure_bar[e], sim.axle_state[e, :, L.AS_F]]
                self.rows[e].append(np.concatenate([head, *wheels]))

    def record(self, e: int) -> RunRecord:
        """Env ``e``'s rows as a :class:`RunRecord` (a repeated time stamp kept once)."""
        n = self.core.n_axles
        a = np.asarray(self.rows[e])
        keep = np.concatenate([[True], np.diff(a[:, 0]) > 1e-9])
        a = a[keep]
        p = a[:, 5 + n : 5 + 2 * n]
        return RunRecord(
            time_s=a[:, 0],
            v_train_kmh=3.6 * a[:, 1],
            v_axle_kmh=3.6 * a[:, 5 : 5 + n],
            p_cyl_bar=p,
            p_demand_bar=a[:, 2],
            a_train_mps2=a[:, 4],
            v_ref_kmh=3.6 * a[:, 3],
            wsp_active=p < a[:, 2:3] - 0.05,
            f_adhesion_N=a[:, 5 + 2 * n : 5 + 3 * n],
        )

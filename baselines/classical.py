"""Classical wheel slide protection, batched over environments (seed 002 §3.1.4, Fig. 6).

The three tasks of a WSP (seed 002 Fig. 6), as a WSP engineer would set them up:

1. **Reference speed**: the environment's shared estimator (``core.sensors.EstimatorConfig``,
   ``core.kernel.update_reference``), read from the observation exactly as a learned policy
   reads it — one implementation for every controller. It follows the fastest wheel, falls at a
   bounded or adaptive slope while the valves work (with an accelerometer, at the deceleration
   it reads) and is re-anchored, up or down, on a wheel whose brake has been off for a while and
   which no longer spins up. Its age (seconds since the last anchor) is observed too.
2. **Slide detection** per axle by a speed-difference criterion — absolute and relative, so
   speed-dependent: ``v_ref - v_i > max(slip_abs_kmh, slip_rel v_ref)`` — and an accelerometer
   criterion — wheel deceleration above ``decel_vent_mps2``.
3. **Discrete state control** driving the dump/hold valves: *vent* while the axle slides and is
   not yet recovering; *hold* while it recovers (re-accelerating faster than
   ``accel_hold_mps2``) or while its slip lies between ``release_ratio`` times the threshold and
   the threshold; *apply* otherwise. **Re-application in steps**: after a vent, *apply* first
   fills straight back to ``reapply_fast_fraction`` of the pressure at which the slide began (the
   WSP remembers it: the rail carried about that much), then in pulses of ``reapply_fill_s``
   separated by ``reapply_hold_s`` of hold until the cylinder is back at the demand
   (``reapply_hold_s = 0``: one continuous fill), so the pressure creeps up to the adhesion limit
   instead of overshooting it.

Plus **periodic release** (when the reference has gone ``periodic_release_interval_s`` without
an anchor while the WSP works, and as long since the last release began, one axle in turn
from the last is vented for at least ``periodic_release_duration_s`` and on until it stops
spinning up and the estimator has anchored on it — the observed age falls — at most
``periodic_release_max_s``) and the
**safety timer**: an axle venting continuously for longer than ``safety_timer_s`` gets the full
demand back until standstill (EN 15595 §5.1.4 "WSP watchdog"; Open Rails uses 7 s; the
environment's own watchdog, ``core.sensors.WatchdogConfig``, stands behind it for every
controller). Below ``min_speed_kmh`` the WSP applies the full demand.

Acting through the continuous action space: *vent* -> -1 (target 0 bar), *apply* -> +1 (the
demand), *hold* -> the valve's current pressure as a fraction of the demand, so the same
environment serves this policy and learned ones. The WSP reads only the observation (wheel
speed readings, decelerations, cylinder pressures, demand, the reference and its age): nothing a
real WSP does not measure. Two frozen configurations, one per sensor tier:
``configs/wsp/classical.yaml`` (``wheels``) and ``configs/wsp/classical_accel.yaml``
(``wheels+accel``: the same logic on the accelerometer-aided reference, its thresholds tuned for
it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wsp_env.core import kernel as K
from wsp_env.core.config import ConfigError, configs_root, from_dict, read_yaml
from wsp_env.physics.layout import EP_P_MAX

VENT, HOLD, APPLY = 0, 1, 2


@dataclass(frozen=True)
class WSPConfig:
    """Thresholds; the frozen values live in ``configs/wsp/classical.yaml`` (tuned there)."""

    slip_abs_kmh: float = field(default=3.0, metadata={"gt": 0.0})
    slip_rel: float = field(default=0.15, metadata={"ge": 0.0, "le": 1.0})
    release_ratio: float = field(default=0.5, metadata={"gt": 0.0, "le": 1.0})
    decel_vent_mps2: float = field(default=5.0, metadata={"gt": 0.0})
    accel_hold_mps2: float = field(default=2.0, metadata={"ge": 0.0})
    reapply_fast_fraction: float = field(default=0.7, metadata={"ge": 0.0, "le": 1.0})
    reapply_fill_s: float = field(default=0.06, metadata={"gt": 0.0})
    reapply_hold_s: float = field(default=0.2, metadata={"ge": 0.0})
    safety_timer_s: float = field(default=7.0, metadata={"gt": 0.0})
    periodic_release_interval_s: float = field(default=3.0, metadata={"gt": 0.0})
    periodic_release_duration_s: float = field(default=0.4, metadata={"ge": 0.0})
    periodic_release_max_s: float = field(default=1.5, metadata={"ge": 0.0})
    release_accel_done_mps2: float = field(default=0.5, metadata={"ge": 0.0})
    min_speed_kmh: float = field(default=3.0, metadata={"ge": 0.0})


TIER_CONFIGS = {"wheels": "classical.yaml", "wheels+accel": "classical_accel.yaml"}


def load_wsp_config(path: str | Path | None = None, tier: str = "wheels") -> WSPConfig:
    """Load thresholds (by default the frozen file of sensor ``tier``, ``TIER_CONFIGS``);
    errors name file and field."""
    if tier not in TIER_CONFIGS:
        raise ValueError(f"tier: {tier!r} is not one of {', '.join(TIER_CONFIGS)}")
    p = Path(path) if path is not None else configs_root() / "wsp" / TIER_CONFIGS[tier]
    try:
        return from_dict(WSPConfig, read_yaml(p) or {})
    except ConfigError as err:
        if str(err).startswith(str(p)):
            raise
        raise ConfigError(f"{p}: {err}") from None


def accelerometer_tier(accelerometer: bool) -> str:
    """The benchmark's sensor tier of a sensor set (``TIER_CONFIGS``' keys): ``wheels+accel``
    with an accelerometer, else ``wheels``. The one mapping every module uses."""
    return "wheels+accel" if accelerometer else "wheels"


def core_tier(core: Any) -> str:
    """The sensor tier whose frozen thresholds a controller built without its own runs on, for
    the core it binds to (``accelerometer_tier`` of its sensors; as ``envs.make_core`` picks
    them for the residual and slip-target modes)."""
    return accelerometer_tier(bool(core.accelerometer))


class ArrayState:
    """``state_dict`` / ``load_state_dict`` for a batched controller whose evolving state is
    its numpy arrays: every array attribute except those named in ``_CONSTANT`` (bound once)."""

    _CONSTANT: frozenset[str] = frozenset()

    def state_dict(self) -> dict[str, np.ndarray]:
        """Copies of the evolving state (a checkpointed run resumes bit for bit)."""
        return {
            k: v.copy()
            for k, v in vars(self).items()
            if isinstance(v, np.ndarray) and k not in self._CONSTANT
        }

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        for k, v in state.items():
            setattr(self, k, v.copy())


class PeriodicRelease:
    """The periodic release (module docstring) as state of a batched controller: when the
    reference has gone ``periodic_release_interval_s`` without an anchor, and as long since the
    last release began, one axle in turn from the last is released for at least
    ``periodic_release_duration_s`` and on until it stops spinning up and the estimator has
    anchored on it, at most ``periodic_release_max_s``. Shared by the classical WSP and the
    slip-target loop (``slip_target``); needs ``cfg`` (``WSPConfig``) and ``_rows``."""

    cfg: WSPConfig
    _rows: np.ndarray

    def _release_init(self, n: int, next_axle: int = 0) -> None:
        self.since_release = np.zeros(n)  # s since the last periodic release began
        self.release_left = np.zeros(n)  # s of the minimum periodic release still to run
        self.release_time = np.zeros(n)  # s the current periodic release has lasted
        self.releasing = np.zeros(n, dtype=bool)
        self.release_axle = np.zeros(n, dtype=np.int64)
        self.next_release = np.full(n, next_axle, dtype=np.int64)

    def _release_reset(self, env_ids: np.ndarray, n_axles: int) -> None:
        self.since_release[env_ids] = np.inf
        self.release_left[env_ids] = 0.0
        self.release_time[env_ids] = 0.0
        self.releasing[env_ids] = False
        self.next_release[env_ids] = n_axles - 1  # the last axle first

    def _release_step(
        self, age: np.ndarray, decel: np.ndarray, dt: float, allowed: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Advance the release by one period (``age``: the reference's, s, per env; ``decel``:
        per axle, m/s^2; ``allowed``: envs where a release may begin); returns the (env, axle)
        pairs to vent this period."""
        cfg, na = self.cfg, decel.shape[1]
        self.since_release += dt
        start = (
            (age > cfg.periodic_release_interval_s)
            & (self.since_release > cfg.periodic_release_interval_s)
            & ~self.releasing
        )
        if allowed is not None:
            start &= allowed
        if start.any():
            self.release_axle[start] = self.next_release[start]
            self.next_release[start] = (self.next_release[start] - 1) % na
            self.release_left[start] = cfg.periodic_release_duration_s
            self.release_time[start] = 0.0
            self.releasing |= start
            self.since_release[start] = 0.0
        if not self.releasing.any():
            return self._rows[:0], self._rows[:0]
        rows = self._rows[self.releasing]
        axle = self.release_axle[self.releasing]
        # at least the minimum time, then until the wheel has stopped spinning up and the
        # estimator has anchored on it (the observed age fell below the release's time)
        still = (
            (self.release_left[self.releasing] > 0)
            | (-decel[rows, axle] > cfg.release_accel_done_mps2)
            | (age[rows] >= self.release_time[self.releasing])
        )
        still &= self.release_time[self.releasing] < cfg.periodic_release_max_s
        self.release_left[rows] -= dt
        self.release_time[rows] += dt
        self.releasing[rows[~still]] = False
        return rows[still], axle[still]


class ClassicalWSP(ArrayState, PeriodicRelease):
    """The classical WSP as a batched policy (see the module docstring). ``config``: its
    thresholds; None: the frozen file of the sensor tier of the core it binds to
    (``core_tier``), as the benchmark's classical WSP of that tier (before 2026-11-28,
    ``WSPConfig()``'s defaults)."""

    name = "classical"
    privileged = False

    def __init__(self, config: WSPConfig | None = None) -> None:
        self.config_given = config  # None: the bound core's tier's thresholds (``bind``)
        self.cfg = config or WSPConfig()

    def bind(self, core: Any) -> None:
        n, na = core.n_envs, core.n_axles
        if self.config_given is None:
            self.cfg = load_wsp_config(tier=core_tier(core))
        self.n_axles = na
        self.dt = core.sim.control_period_s
        self.v_scale = core.obs_par[K.OP_SPEED_SCALE]
        self.a_scale = core.obs_par[K.OP_DECEL_SCALE]
        self.age_scale = core.obs_par[K.OP_AGE_SCALE]
        self.age_index = core.kernel_obs_dim - 1  # the reference's age: the kernel's last entry
        self.p_max = core.sim.env_par[:, EP_P_MAX]  # a view: observations give p / p_max
        self.valve_of_axle = core.valve_of_axle
        self.n_valves = core.n_valves
        # first axle of each valve (valves are contiguous groups of axles)
        self.valve_starts = np.flatnonzero(np.r_[True, np.diff(self.valve_of_axle) != 0])
        self.venting_for = np.zeros((n, na))  # s of continuous venting
        self.locked_out = np.zeros((n, na), dtype=bool)
        self.stepping = np.zeros((n, na), dtype=bool)  # re-applying in steps after a vent
        self.step_clock = np.zeros((n, na))  # s into the current fill/hold pulse
        self.slide_pressure = np.zeros((n, na))  # / p_max, when the last vent began
        self.active = np.zeros(n, dtype=bool)  # some axle out of apply in the last period
        self._release_init(n)
        self._rows = np.arange(n)

    def reset(self, env_ids: np.ndarray) -> None:
        self.venting_for[env_ids] = 0.0
        self.locked_out[env_ids] = False
        self.stepping[env_ids] = False
        self.step_clock[env_ids] = 0.0
        self.slide_pressure[env_ids] = 0.0
        self.active[env_ids] = False
        self._release_reset(env_ids, self.n_axles)

    # bound once (``bind``); everything else that is an array evolves (``state_dict``)
    _CONSTANT = frozenset({"p_max", "valve_of_axle", "valve_starts", "_rows"})

    def act(self, obs: np.ndarray) -> np.ndarray:
        cfg, na, dt = self.cfg, self.n_axles, self.dt
        v = obs[:, :na].astype(np.float64) * self.v_scale
        decel = obs[:, na : 2 * na].astype(np.float64) * self.a_scale
        pressure = obs[:, 3 * na : 4 * na].astype(np.float64)  # / p_max
        demand = obs[:, 4 * na].astype(np.float64)  # / p_max
        # 1. the shared reference speed and its age (module docstring)
        v_ref = obs[:, 4 * na + 1].astype(np.float64)[:, None] * self.v_scale
        age = obs[:, self.age_index].astype(np.float64) * self.age_scale
        # 2. slide detection
        slip = v_ref - v
        threshold = np.maximum(cfg.slip_abs_kmh / 3.6, cfg.slip_rel * v_ref)
        sliding = (slip > threshold) | (decel > cfg.decel_vent_mps2)
        recovering = -decel > cfg.accel_hold_mps2
        # 3. discrete state control
        state = np.full(v.shape, APPLY, dtype=np.int64)
        state[slip > cfg.release_ratio * threshold] = HOLD
        state[sliding & ~recovering] = VENT
        # periodic release: while the WSP works and the reference has gone long without an
        # anchor, release one axle now and then so that it spins up to the train speed and the
        # estimator anchors on it
        self.active = (state != APPLY).any(axis=1)
        rows, axles = self._release_step(age, decel, dt, self.active)
        state[rows, axles] = VENT
        # re-application after a vent: straight back to a share of the pressure the slide began
        # at, then fill pulses separated by holds
        onset = (state == VENT) & (self.venting_for == 0.0)  # a vent begins this period
        self.slide_pressure = np.where(onset, pressure, self.slide_pressure)
        self.stepping |= state == VENT
        self.stepping &= pressure < demand[:, None] - 0.02
        pulse = cfg.reapply_fill_s + cfg.reapply_hold_s
        fast = pressure < cfg.reapply_fast_fraction * self.slide_pressure
        in_step = self.stepping & (state == APPLY) & ~fast
        self.step_clock = np.where(in_step, self.step_clock + dt, 0.0)
        state[in_step & (np.mod(self.step_clock - dt, pulse) >= cfg.reapply_fill_s)] = HOLD
        # safety timer: continuous venting beyond the limit restores braking until standstill
        self.venting_for = np.where(state == VENT, self.venting_for + dt, 0.0)
        self.locked_out |= self.venting_for > cfg.safety_timer_s
        state[self.locked_out] = APPLY
        state[v_ref[:, 0] < cfg.min_speed_kmh / 3.6] = APPLY
        # valves: the most cautious state of their axles; hold = keep the current pressure
        valve_state = np.minimum.reduceat(state, self.valve_starts, axis=1)
        valve_p = np.maximum.reduceat(pressure, self.valve_starts, axis=1)
        hold_frac = np.where(
            demand[:, None] > 1e-6, valve_p / np.maximum(demand[:, None], 1e-6), 1.0
        )
        action = np.where(
            valve_state == APPLY, 1.0, np.where(valve_state == VENT, -1.0, 2.0 * hold_frac - 1.0)
        )
        return np.clip(action, -1.0, 1.0).astype(np.float32)

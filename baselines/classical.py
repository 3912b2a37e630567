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
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from wsp_env.core import kernel as K
from wsp_env.core.config import ConfigError, configs_root, from_dict, read_yaml
from wsp_env.physics.integrator import INLINE_FLAGS, KERNEL_FLAGS
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


# ---- compiled: one definition of each rule, IEEE arithmetic as numpy's (``KERNEL_FLAGS``) ----
# Each env's step is a short run of scalar comparisons; as numpy array operations on a batch
# of one it cost 90-175 us a period in interpreter overhead (a single stop, a trace, a
# calibration), compiled 4.4-9.4 us (scripts/classical_act_timing.py, nine runs). The same
# floating-point operations in the same order, so the results are bit for bit those of the
# array version they replaced (2026-12-07: the quick suite, the benchmark and ``validate`` gave
# identical JSON;
# tests/test_classical_kernel.py keeps that version and compares every period).

# the release's thresholds in ``release_par`` (``PeriodicRelease._release_par``)
RP_INTERVAL, RP_DURATION, RP_ACCEL_DONE, RP_MAX = 0, 1, 2, 3
# the classical WSP's thresholds in ``wsp_par`` (``ClassicalWSP._wsp_par``)
(WP_SLIP_ABS, WP_SLIP_REL, WP_RELEASE_RATIO, WP_DECEL_VENT, WP_ACCEL_HOLD, WP_FAST_FRACTION,
 WP_FILL, WP_HOLD, WP_SAFETY, WP_MIN_SPEED) = range(10)  # fmt: skip


@lru_cache(maxsize=64)
def _release_par_of(cfg: WSPConfig) -> np.ndarray:
    """``cfg``'s release thresholds in ``RP_`` order, built once per config (a frozen dataclass:
    the same object or an equal one gives the same numbers), not every period."""
    return np.array(
        [cfg.periodic_release_interval_s, cfg.periodic_release_duration_s,
         cfg.release_accel_done_mps2, cfg.periodic_release_max_s], dtype=np.float64,
    )  # fmt: skip


@lru_cache(maxsize=64)
def _wsp_par_of(cfg: WSPConfig) -> np.ndarray:
    """``cfg``'s thresholds in ``WP_`` order, built once per config (as ``_release_par_of``)."""
    return np.array(
        [cfg.slip_abs_kmh, cfg.slip_rel, cfg.release_ratio, cfg.decel_vent_mps2,
         cfg.accel_hold_mps2, cfg.reapply_fast_fraction, cfg.reapply_fill_s,
         cfg.reapply_hold_s, cfg.safety_timer_s, cfg.min_speed_kmh], dtype=np.float64,
    )  # fmt: skip


@njit(**INLINE_FLAGS)
def _np_maximum(a: float, b: float) -> float:
    """``np.maximum`` of two floats: NaN if either is (numpy's rule, not Python's ``max``)."""
    return a if (a >= b or a != a) else b


@njit(**INLINE_FLAGS)
def release_env(
    i, age, decel_row, dt, allowed, since, left, elapsed, releasing, axle, next_axle, par
):  # fmt: skip
    """The periodic release of env ``i`` over one period (``PeriodicRelease``): ``age`` its
    reference's age (s), ``decel_row`` its axles' decelerations (m/s^2), ``allowed`` whether a
    release may begin; updates the env's release state in place and returns the axle to vent
    this period, or -1."""
    na = decel_row.shape[0]
    since[i] += dt
    interval = par[RP_INTERVAL]
    if age > interval and since[i] > interval and not releasing[i] and allowed:
        axle[i] = next_axle[i]
        next_axle[i] = (next_axle[i] - 1) % na
        left[i] = par[RP_DURATION]
        elapsed[i] = 0.0
        releasing[i] = True
        since[i] = 0.0
    if not releasing[i]:
        return -1
    a = axle[i]
    # at least the minimum time, then until the wheel has stopped spinning up and the
    # estimator has anchored on it (the observed age fell below the release's time)
    still = left[i] > 0 or -decel_row[a] > par[RP_ACCEL_DONE] or age >= elapsed[i]
    still = still and elapsed[i] < par[RP_MAX]
    left[i] -= dt
    elapsed[i] += dt
    if not still:
        releasing[i] = False
        return -1
    return a


@njit(**KERNEL_FLAGS)
def release_step(
    age, decel, dt, allowed, since, left, elapsed, releasing, axle, next_axle, par, vent
):  # fmt: skip
    """``release_env`` for every env: marks in ``vent`` ``(n_envs, n_axles)`` the axles to
    vent this period (``allowed``: per env)."""
    for i in range(age.shape[0]):
        a = release_env(
            i, age[i], decel[i], dt, allowed[i], since, left, elapsed, releasing, axle,
            next_axle, par,
        )  # fmt: skip
        if a >= 0:
            vent[i, a] = True


class PeriodicRelease:
    """The periodic release (module docstring) as state of a batched controller: when the
    reference has gone ``periodic_release_interval_s`` without an anchor, and as long since the
    last release began, one axle in turn from the last is released for at least
    ``periodic_release_duration_s`` and on until it stops spinning up and the estimator has
    anchored on it, at most ``periodic_release_max_s``. Shared by the classical WSP and the
    slip-target loop (``slip_target``); needs ``cfg`` (``WSPConfig``). The rule itself is the
    compiled ``release_env``."""

    cfg: WSPConfig

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

    def _release_par(self) -> np.ndarray:
        """The release's thresholds from ``cfg`` as the kernels read them (``RP_``)."""
        return _release_par_of(self.cfg)

    def _release_state(self) -> tuple[np.ndarray, ...]:
        """The release's state arrays in ``release_env``'s order (updated in place)."""
        return (self.since_release, self.release_left, self.release_time, self.releasing,
                self.release_axle, self.next_release)  # fmt: skip

    def _release_step(
        self, age: np.ndarray, decel: np.ndarray, dt: float, allowed: np.ndarray, vent: np.ndarray
    ) -> None:
        """Advance the release by one period (``age``: the reference's, s, per env; ``decel``:
        per axle, m/s^2; ``allowed``: envs where a release may begin); marks the axles to vent
        this period in ``vent`` (bool, per axle)."""
        n = self.since_release.shape[0]
        if not (len(age) == len(decel) == len(allowed) == len(vent) == n):  # the kernel's rows
            raise ValueError(f"periodic release: batches of {n} environments expected")
        release_step(
            np.ascontiguousarray(age, dtype=np.float64),
            np.ascontiguousarray(decel, dtype=np.float64), float(dt),
            np.ascontiguousarray(allowed, dtype=np.bool_), *self._release_state(),
            self._release_par(), vent,
        )  # fmt: skip


@njit(**KERNEL_FLAGS)
def classical_act(
    obs, scales, age_index, valve_starts, par, release_par, dt, venting_for, locked_out,
    stepping, step_clock, slide_pressure, active, since, left, elapsed, releasing, axle,
    next_axle, action,
):  # fmt: skip
    """One period of the classical WSP (module docstring) for every env: reads the kernel's
    observation ``obs`` (``scales``: speed, deceleration and age scales), updates the state
    arrays in place and writes the valve actions into ``action`` ``(n_envs, n_valves)``."""
    n, na = obs.shape[0], venting_for.shape[1]
    nv = valve_starts.shape[0]
    v_scale, a_scale, age_scale = scales[0], scales[1], scales[2]
    slip_abs = par[WP_SLIP_ABS] / 3.6
    min_speed = par[WP_MIN_SPEED] / 3.6
    pulse = par[WP_FILL] + par[WP_HOLD]
    state = np.empty(na, dtype=np.int64)
    decel = np.empty(na)
    for i in range(n):
        demand = np.float64(obs[i, 4 * na])  # / p_max
        # 1. the shared reference speed and its age (module docstring)
        v_ref = np.float64(obs[i, 4 * na + 1]) * v_scale
        age = np.float64(obs[i, age_index]) * age_scale
        # 2. slide detection; 3. discrete state control
        working = False
        for j in range(na):
            v = np.float64(obs[i, j]) * v_scale
            decel[j] = np.float64(obs[i, na + j]) * a_scale
            slip = v_ref - v
            threshold = _np_maximum(slip_abs, par[WP_SLIP_REL] * v_ref)
            sliding = slip > threshold or decel[j] > par[WP_DECEL_VENT]
            recovering = -decel[j] > par[WP_ACCEL_HOLD]
            s = APPLY
            if slip > par[WP_RELEASE_RATIO] * threshold:
                s = HOLD
            if sliding and not recovering:
                s = VENT
            state[j] = s
            working = working or s != APPLY
        # periodic release: while the WSP works and the reference has gone long without an
        # anchor, release one axle now and then so that it spins up to the train speed and the
        # estimator anchors on it
        active[i] = working
        a = release_env(
            i, age, decel, dt, working, since, left, elapsed, releasing, axle, next_axle,
            release_par,
        )  # fmt: skip
        if a >= 0:
            state[a] = VENT
        for j in range(na):
            pressure = np.float64(obs[i, 3 * na + j])  # / p_max
            # re-application after a vent: straight back to a share of the pressure the slide
            # began at, then fill pulses separated by holds
            if state[j] == VENT:
                if venting_for[i, j] == 0.0:  # a vent begins this period
                    slide_pressure[i, j] = pressure
                stepping[i, j] = True
            stepping[i, j] = stepping[i, j] and pressure < demand - 0.02
            fast = pressure < par[WP_FAST_FRACTION] * slide_pressure[i, j]
            if stepping[i, j] and state[j] == APPLY and not fast:
                step_clock[i, j] = step_clock[i, j] + dt
                if np.mod(step_clock[i, j] - dt, pulse) >= par[WP_FILL]:
                    state[j] = HOLD
            else:
                step_clock[i, j] = 0.0
            # safety timer: continuous venting beyond the limit restores braking until standstill
            venting_for[i, j] = venting_for[i, j] + dt if state[j] == VENT else 0.0
            if venting_for[i, j] > par[WP_SAFETY]:
                locked_out[i, j] = True
            if locked_out[i, j] or v_ref < min_speed:
                state[j] = APPLY
        # valves: the most cautious state of their axles; hold = keep the current pressure
        for k in range(nv):
            lo = valve_starts[k]
            hi = valve_starts[k + 1] if k + 1 < nv else na
            valve_state = state[lo]
            valve_p = np.float64(obs[i, 3 * na + lo])
            for j in range(lo + 1, hi):
                valve_state = min(valve_state, state[j])
                valve_p = _np_maximum(valve_p, np.float64(obs[i, 3 * na + j]))
            if valve_state == APPLY:
                u = 1.0
            elif valve_state == VENT:
                u = -1.0
            else:
                hold_frac = valve_p / _np_maximum(demand, 1e-6) if demand > 1e-6 else 1.0
                u = 2.0 * hold_frac - 1.0
            if u < -1.0:
                u = -1.0
            elif u > 1.0:
                u = 1.0
            action[i, k] = np.float32(u)


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
        self._scales = np.array([self.v_scale, self.a_scale, self.age_scale], dtype=np.float64)

    def reset(self, env_ids: np.ndarray) -> None:
        self.venting_for[env_ids] = 0.0
        self.locked_out[env_ids] = False
        self.stepping[env_ids] = False
        self.step_clock[env_ids] = 0.0
        self.slide_pressure[env_ids] = 0.0
        self.active[env_ids] = False
        self._release_reset(env_ids, self.n_axles)

    # bound once (``bind``); everything else that is an array evolves (``state_dict``)
    _CONSTANT = frozenset({"p_max", "valve_of_axle", "valve_starts", "_scales"})

    def _wsp_par(self) -> np.ndarray:
        """The thresholds from ``cfg`` as ``classical_act`` reads them (``WP_``)."""
        return _wsp_par_of(self.cfg)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Valve actions ``(n_envs, n_valves)`` (float32 in [-1, 1]) for the kernel's
        observation ``obs``; advances the state by one period (the compiled ``classical_act``)."""
        obs = np.asarray(obs)
        n = self.venting_for.shape[0]  # the kernel reads n rows up to the age's column
        if obs.ndim != 2 or obs.shape[0] != n or obs.shape[1] <= self.age_index:
            raise ValueError(
                f"classical WSP: observations of shape {obs.shape}, bound to {n} environments "
                f"of {self.age_index + 1} kernel observations"
            )
        action = np.empty((obs.shape[0], self.n_valves), dtype=np.float32)
        classical_act(
            obs, self._scales, self.age_index, self.valve_starts, self._wsp_par(),
            self._release_par(), float(self.dt), self.venting_for, self.locked_out,
            self.stepping, self.step_clock, self.slide_pressure, self.active,
            *self._release_state(), action,
        )  # fmt: skip
        return action

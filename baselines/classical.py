"""Classical wheel slide protection, batched over environments (seed 002 §3.1.4).

The three tasks of a WSP (seed 002 Fig. 6):

1. **Reference speed** from the axle speeds: the fastest wheel, but falling at most at
   ``ref_decel_limit_mps2`` — ``ref_decel_active_mps2`` while the WSP is working, when the train
   can only be decelerating at low-adhesion rates (all wheels may slide at once; the reference
   must not follow them).
2. **Slide detection** per axle by a speed-difference criterion — absolute and relative,
   so speed-dependent: ``v_ref - v_i > max(slip_abs, slip_rel * v_ref)`` — and an
   accelerometer criterion — wheel deceleration above ``decel_vent_mps2``.
3. **Discrete state control** driving the dump/hold valves:
   *vent* while the axle slides and is not yet recovering; *hold* while it recovers
   (re-accelerating faster than ``accel_hold_mps2``) or its slip is between the release level
   and the threshold; *apply* otherwise.

Plus **periodic release** (``periodic_release_interval_s`` after the last re-anchoring, if the
WSP has acted since, one axle, in turn from the last, is vented for at least
``periodic_release_duration_s`` and on
until it stops spinning up, at most ``periodic_release_max_s``; its speed then re-anchors the
reference, and the drop between two anchors gives the train's deceleration, from which the
reference slope during WSP activity adapts: ``ref_adapt_margin`` times it, within
``[ref_decel_min_mps2, ref_decel_limit_mps2]``) and the
**safety timer**: an axle venting continuously for longer than ``safety_timer_s`` gets the full
demand back until standstill (EN 15595 §5.1.4 "WSP watchdog"; Open Rails uses 7 s).

Acting through the continuous action space: *vent* -> -1 (target 0 bar), *apply* -> +1
(the demand), *hold* -> the valve's current pressure as a fraction of the demand, so the same
environment serves this policy and learned ones.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wsp_env.config import ConfigError, _configs_root, from_dict, read_yaml

VENT, HOLD, APPLY = 0, 1, 2


@dataclass(frozen=True)
class WSPConfig:
    """Thresholds (defaults = configs/wsp/classical.yaml, tuned on the en15595 suite)."""

    ref_decel_limit_mps2: float = field(default=1.2, metadata={"gt": 0.0})
    ref_decel_active_mps2: float = field(default=0.98, metadata={"gt": 0.0})
    slip_abs_kmh: float = field(default=2.8, metadata={"gt": 0.0})
    slip_rel: float = field(default=0.26, metadata={"ge": 0.0, "le": 1.0})
    release_ratio: float = field(default=0.44, metadata={"gt": 0.0, "le": 1.0})
    decel_vent_mps2: float = field(default=5.8, metadata={"gt": 0.0})
    accel_hold_mps2: float = field(default=2.5, metadata={"ge": 0.0})
    safety_timer_s: float = field(default=7.0, metadata={"gt": 0.0})
    periodic_release_interval_s: float = field(default=2.6, metadata={"gt": 0.0})
    periodic_release_duration_s: float = field(default=0.4, metadata={"ge": 0.0})
    periodic_release_max_s: float = field(default=1.5, metadata={"ge": 0.0})
    release_accel_done_mps2: float = field(default=0.5, metadata={"ge": 0.0})
    ref_decel_min_mps2: float = field(default=0.3, metadata={"gt": 0.0})
    ref_adapt_margin: float = field(default=1.24, metadata={"ge": 1.0})
    min_speed_kmh: float = field(default=3.0, metadata={"ge": 0.0})


def load_wsp_config(path: str | Path | None = None) -> WSPConfig:
    """Load thresholds (``configs/wsp/classical.yaml`` by default); errors name file and field."""
    p = Path(path) if path is not None else _configs_root() / "wsp" / "classical.yaml"
    try:
        return from_dict(WSPConfig, read_yaml(p) or {})
    except ConfigError as err:
        if str(err).startswith(str(p)):
            raise
        raise ConfigError(f"{p}: {err}") from None


class ClassicalWSP:
    """The classical WSP as a batched policy (see the module docstring)."""

    name = "classical"
    privileged = False

    def __init__(self, config: WSPConfig | None = None) -> None:
        self.cfg = config or WSPConfig()

    def bind(self, core: Any) -> None:
        n, na = core.n_envs, core.n_axles
        self.n_axles = na
        self.dt = core.sim.control_period_s
        self.v_scale = core.obs_par[0]  # OP_SPEED_SCALE
        self.a_scale = core.obs_par[1]  # OP_DECEL_SCALE
        self.valve_of_axle = core.valve_of_axle
        self.n_valves = core.n_valves
        # first axle of each valve (valves are contiguous groups of axles)
        self.valve_starts = np.flatnonzero(np.r_[True, np.diff(self.valve_of_axle) != 0])
        self.v_ref = np.zeros(n)
        self.venting_for = np.zeros((n, na))  # s of continuous venting
        self.locked_out = np.zeros((n, na), dtype=bool)
        self.since_clean = np.zeros(n)  # s since the last re-anchoring, once the WSP has acted
        self.active = np.zeros(n, dtype=bool)  # some valve out of apply in the last period
        self.worked = np.zeros(n, dtype=bool)  # the WSP has acted since the last anchoring
        self.release_left = np.zeros(n)  # s of the minimum periodic release still to run
        self.release_time = np.zeros(n)  # s the current periodic release has lasted
        self.releasing = np.zeros(n, dtype=bool)
        self.ref_slope = np.zeros(n)  # m/s^2 the reference may fall while the WSP works
        self.t = np.zeros(n)
        self.anchor_v = np.full(n, np.nan)  # train speed at the last re-anchoring
        self.anchor_t = np.zeros(n)
        self.release_axle = np.zeros(n, dtype=np.int64)
        self.next_release = np.zeros(n, dtype=np.int64)
        self._rows = np.arange(n)

    def reset(self, env_ids: np.ndarray) -> None:
        self.v_ref[env_ids] = np.inf  # re-initialised from the first observation
        self.venting_for[env_ids] = 0.0
        self.locked_out[env_ids] = False
        self.since_clean[env_ids] = 0.0
        self.active[env_ids] = False
        self.worked[env_ids] = False
        self.release_left[env_ids] = 0.0
        self.release_time[env_ids] = 0.0
        self.releasing[env_ids] = False
        self.ref_slope[env_ids] = self.cfg.ref_decel_active_mps2
        self.t[env_ids] = 0.0
        self.anchor_v[env_ids] = np.nan
        self.next_release[env_ids] = self.n_axles - 1  # the last axle first

    def _anchor(self, rows: np.ndarray, wheel: np.ndarray) -> None:
        """A released wheel has spun up to the train speed: re-anchor, adapt the slope."""
        cfg = self.cfg
        span = self.t[rows] - self.anchor_t[rows]
        ok = np.isfinite(self.anchor_v[rows]) & (span > 1.0)
        est = (self.anchor_v[rows] - wheel) / np.maximum(span, 1e-9)
        slope = np.clip(
            cfg.ref_adapt_margin * est, cfg.ref_decel_min_mps2, cfg.ref_decel_limit_mps2
        )
        self.ref_slope[rows] = np.where(ok, slope, self.ref_slope[rows])
        self.v_ref[rows] = np.maximum(self.v_ref[rows], wheel)
        self.anchor_v[rows] = wheel
        self.anchor_t[rows] = self.t[rows]

    def act(self, obs: np.ndarray) -> np.ndarray:
        cfg, na, dt = self.cfg, self.n_axles, self.dt
        v = obs[:, :na].astype(np.float64) * self.v_scale
        decel = obs[:, na : 2 * na].astype(np.float64) * self.a_scale
        pressure = obs[:, 3 * na : 4 * na].astype(np.float64)  # / p_max
        demand = obs[:, 4 * na].astype(np.float64)  # / p_max
        # 1. reference speed
        fastest = v.max(axis=1)
        fresh = ~np.isfinite(self.v_ref)
        self.t += dt
        limit = np.where(self.active, self.ref_slope, cfg.ref_decel_limit_mps2)
        self.v_ref = np.where(fresh, fastest, np.maximum(fastest, self.v_ref - limit * dt))
        v_ref = self.v_ref[:, None]
        # 2. slide detection
        slip = v_ref - v
        threshold = np.maximum(cfg.slip_abs_kmh / 3.6, cfg.slip_rel * v_ref)
        sliding = (slip > threshold) | (decel > cfg.decel_vent_mps2)
        recovering = -decel > cfg.accel_hold_mps2
        # 3. discrete state control
        state = np.full(v.shape, APPLY, dtype=np.int64)
        state[slip > cfg.release_ratio * threshold] = HOLD
        state[sliding & ~recovering] = VENT
        # periodic release: while the WSP works without pause, release one axle now and then
        # so that it spins up to the train speed and re-anchors the reference
        self.active = (state != APPLY).any(axis=1)
        self.worked |= self.active
        self.since_clean = np.where(self.worked, self.since_clean + dt, 0.0)
        start = (self.since_clean > cfg.periodic_release_interval_s) & ~self.releasing & self.active
        if start.any():
            self.release_axle[start] = self.next_release[start]
            self.next_release[start] = (self.next_release[start] - 1) % na
            self.release_left[start] = cfg.periodic_release_duration_s
            self.release_time[start] = 0.0
            self.releasing |= start
            self.since_clean[start] = 0.0
        if self.releasing.any():
            rows = self._rows[self.releasing]
            axle = self.release_axle[self.releasing]
            # run at least the minimum time, then until the wheel has stopped spinning up
            still = (self.release_left[self.releasing] > 0) | (
                -decel[rows, axle] > cfg.release_accel_done_mps2
            )
            still &= self.release_time[self.releasing] < cfg.periodic_release_max_s
            state[rows[still], axle[still]] = VENT
            self.release_left[rows] -= dt
            self.release_time[rows] += dt
            done = rows[~still]
            if done.size:
                self._anchor(done, v[done, self.release_axle[done]])
                self.releasing[done] = False
                self.worked[done] = False
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

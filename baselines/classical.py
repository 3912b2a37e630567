"""Classical wheel slide protection, batched over environments (seed 002 §3.1.4, Fig. 6).

The three tasks of a WSP (seed 002 Fig. 6), as a WSP engineer would set them up:

1. **Reference speed** from the axle speeds alone. It follows the fastest wheel but falls at
   most at ``ref_decel_limit_mps2`` — chosen above any deceleration the vehicles reach on dry
   rail, so that on good adhesion the reference *is* the fastest wheel and the WSP stays quiet.
   While the WSP works (some axle out of *apply*), all wheels may slide at once and the
   reference must not follow them down: it then falls at an adaptive slope, ``ref_adapt_margin``
   times the train deceleration measured between two anchors, within
   ``[ref_decel_min_mps2, ref_decel_limit_mps2]`` (``ref_decel_active_mps2`` before the first
   measurement). **Anchors**: a wheel whose brake has been off (cylinder below
   ``free_roll_pressure_bar``, under the brake's threshold) for ``free_roll_min_s`` and which no
   longer spins up (acceleration below ``release_accel_done_mps2``) rolls with the train: the
   reference is set to its speed, up or down. Without that, a reference that lags a train
   braking harder than its slope (at the end of a stop, adhesion rises) makes every axle look
   like it slides and the WSP releases them all.
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

Plus **periodic release** (``periodic_release_interval_s`` after the last anchor, while the WSP
works without pause, one axle in turn from the last is vented for at least
``periodic_release_duration_s`` and on until it stops spinning up, at most
``periodic_release_max_s``: it then anchors the reference) and the **safety timer**: an axle
venting continuously for longer than ``safety_timer_s`` gets the full demand back until
standstill (EN 15595 §5.1.4 "WSP watchdog"; Open Rails uses 7 s). Below ``min_speed_kmh`` the
WSP applies the full demand.

Acting through the continuous action space: *vent* -> -1 (target 0 bar), *apply* -> +1 (the
demand), *hold* -> the valve's current pressure as a fraction of the demand, so the same
environment serves this policy and learned ones. The WSP reads only the observation (wheel
speeds, decelerations, cylinder pressures, demand): nothing a real WSP does not measure.
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

    ref_decel_limit_mps2: float = field(default=2.5, metadata={"gt": 0.0})
    ref_decel_active_mps2: float = field(default=1.0, metadata={"gt": 0.0})
    ref_decel_min_mps2: float = field(default=0.3, metadata={"gt": 0.0})
    ref_adapt_margin: float = field(default=1.2, metadata={"ge": 1.0})
    free_roll_pressure_bar: float = field(default=0.1, metadata={"ge": 0.0})
    free_roll_min_s: float = field(default=0.3, metadata={"ge": 0.0})
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


def load_wsp_config(path: str | Path | None = None) -> WSPConfig:
    """Load thresholds (``configs/wsp/classical.yaml`` by default); errors name file and field."""
    p = Path(path) if path is not None else configs_root() / "wsp" / "classical.yaml"
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
        self.v_scale = core.obs_par[K.OP_SPEED_SCALE]
        self.a_scale = core.obs_par[K.OP_DECEL_SCALE]
        self.p_max = core.sim.env_par[:, EP_P_MAX]  # a view: observations give p / p_max
        self.valve_of_axle = core.valve_of_axle
        self.n_valves = core.n_valves
        # first axle of each valve (valves are contiguous groups of axles)
        self.valve_starts = np.flatnonzero(np.r_[True, np.diff(self.valve_of_axle) != 0])
        self.v_ref = np.zeros(n)
        self.venting_for = np.zeros((n, na))  # s of continuous venting
        self.locked_out = np.zeros((n, na), dtype=bool)
        self.stepping = np.zeros((n, na), dtype=bool)  # re-applying in steps after a vent
        self.step_clock = np.zeros((n, na))  # s into the current fill/hold pulse
        self.slide_pressure = np.zeros((n, na))  # / p_max, when the last vent began
        self.released_for = np.zeros((n, na))  # s with the cylinder below free_roll_pressure
        self.since_anchor = np.zeros(n)  # s since the last anchor, while the WSP has acted
        self.active = np.zeros(n, dtype=bool)  # some axle out of apply in the last period
        self.worked = np.zeros(n, dtype=bool)  # the WSP has acted since the last anchor
        self.release_left = np.zeros(n)  # s of the minimum periodic release still to run
        self.release_time = np.zeros(n)  # s the current periodic release has lasted
        self.releasing = np.zeros(n, dtype=bool)
        self.ref_slope = np.zeros(n)  # m/s^2 the reference may fall while the WSP works
        self.t = np.zeros(n)
        self.anchor_v = np.full(n, np.nan)  # train speed at the last anchor
        self.anchor_t = np.zeros(n)
        self.release_axle = np.zeros(n, dtype=np.int64)
        self.next_release = np.zeros(n, dtype=np.int64)
        self._rows = np.arange(n)

    def reset(self, env_ids: np.ndarray) -> None:
        self.v_ref[env_ids] = np.inf  # re-initialised from the first observation
        self.venting_for[env_ids] = 0.0
        self.locked_out[env_ids] = False
        self.stepping[env_ids] = False
        self.step_clock[env_ids] = 0.0
        self.slide_pressure[env_ids] = 0.0
        self.released_for[env_ids] = 0.0
        self.since_anchor[env_ids] = 0.0
        self.active[env_ids] = False
        self.worked[env_ids] = False
        self.release_left[env_ids] = 0.0
        self.release_time[env_ids] = 0.0
        self.releasing[env_ids] = False
        self.ref_slope[env_ids] = self.cfg.ref_decel_active_mps2
        self.t[env_ids] = 0.0
        self.anchor_v[env_ids] = np.nan
        self.next_release[env_ids] = self.n_axles - 1  # the last axle first

    # bound once (``bind``); everything else that is an array evolves (``state_dict``)
    _CONSTANT = frozenset({"p_max", "valve_of_axle", "valve_starts", "_rows"})

    def state_dict(self) -> dict[str, np.ndarray]:
        """Copies of the evolving state (a checkpointed residual-mode run resumes bit for bit)."""
        return {
            k: v.copy()
            for k, v in vars(self).items()
            if isinstance(v, np.ndarray) and k not in self._CONSTANT
        }

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        for k, v in state.items():
            setattr(self, k, v.copy())

    def reference_speed(self) -> np.ndarray:
        """The WSP's current reference-speed estimate (m/s) per environment."""
        return self.v_ref

    def _anchor(self, rows: np.ndarray, wheel: np.ndarray, trusted: np.ndarray) -> None:
        """A released wheel at ``wheel`` m/s. ``trusted``: it no longer spins up, so it rolls
        with the train: set the reference to it and adapt the slope. Otherwise it is still
        catching up (the release ended first, on very low adhesion): it only bounds the
        reference from below."""
        cfg = self.cfg
        wheel = np.where(trusted, wheel, np.maximum(wheel, self.v_ref[rows]))
        span = self.t[rows] - self.anchor_t[rows]
        ok = trusted & np.isfinite(self.anchor_v[rows]) & (span > 1.0)
        est = (self.anchor_v[rows] - wheel) / np.maximum(span, 1e-9)
        slope = np.clip(
            cfg.ref_adapt_margin * est, cfg.ref_decel_min_mps2, cfg.ref_decel_limit_mps2
        )
        self.ref_slope[rows] = np.where(ok, slope, self.ref_slope[rows])
        self.v_ref[rows] = wheel
        self.anchor_v[rows] = np.where(trusted, wheel, self.anchor_v[rows])
        self.anchor_t[rows] = np.where(trusted, self.t[rows], self.anchor_t[rows])
        self.since_anchor[rows] = 0.0
        self.worked[rows] = False

    def act(self, obs: np.ndarray) -> np.ndarray:
        cfg, na, dt = self.cfg, self.n_axles, self.dt
        v = obs[:, :na].astype(np.float64) * self.v_scale
        decel = obs[:, na : 2 * na].astype(np.float64) * self.a_scale
        pressure = obs[:, 3 * na : 4 * na].astype(np.float64)  # / p_max
        demand = obs[:, 4 * na].astype(np.float64)  # / p_max
        self.t += dt
        # 1. reference speed: the fastest wheel, falling at most at the limit or the slope
        fastest = v.max(axis=1)
        fresh = ~np.isfinite(self.v_ref)
        limit = np.where(self.active, self.ref_slope, cfg.ref_decel_limit_mps2)
        self.v_ref = np.where(fresh, fastest, np.maximum(fastest, self.v_ref - limit * dt))
        # ... anchored by a wheel that rolls freely with the train (brake off, not spinning up)
        released = pressure * self.p_max[:, None] < cfg.free_roll_pressure_bar
        self.released_for = np.where(released, self.released_for + dt, 0.0)
        free = (self.released_for >= cfg.free_roll_min_s) & (-decel < cfg.release_accel_done_mps2)
        free[self.releasing] = False  # a periodic release anchors when it ends
        rolling = free.any(axis=1) & self.active & (demand > 0.0)
        if rolling.any():
            rows = self._rows[rolling]
            wheel = np.where(free[rows], v[rows], -np.inf).max(axis=1)
            self._anchor(rows, wheel, np.ones(rows.size, dtype=bool))
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
        # so that it spins up to the train speed and anchors the reference
        self.active = (state != APPLY).any(axis=1)
        self.worked |= self.active
        self.since_anchor = np.where(self.worked, self.since_anchor + dt, 0.0)
        start = (
            (self.since_anchor > cfg.periodic_release_interval_s) & ~self.releasing & self.active
        )
        if start.any():
            self.release_axle[start] = self.next_release[start]
            self.next_release[start] = (self.next_release[start] - 1) % na
            self.release_left[start] = cfg.periodic_release_duration_s
            self.release_time[start] = 0.0
            self.releasing |= start
            self.since_anchor[start] = 0.0
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
                axle_done = self.release_axle[done]
                settled = -decel[done, axle_done] <= cfg.release_accel_done_mps2
                self._anchor(done, v[done, axle_done], settled)
                self.releasing[done] = False
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

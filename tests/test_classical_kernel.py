"""The compiled classical WSP (``classical_act``, ``release_env``) against the numpy array
version it replaced (2026-12-07), kept here as the reference: the same rules written as
whole-batch array operations. Both are driven through the same stops, period by period, and
must give the same valve actions and the same state to the bit (the same IEEE operations in
the same order; no tolerance, since a last-bit difference would move every frozen figure of
the classical WSP). One-valve-per-axle and grouped-valve vehicles, both sensor tiers."""

from __future__ import annotations

import numpy as np
import pytest

from wsp_env.baselines.classical import (
    APPLY,
    HOLD,
    VENT,
    ClassicalWSP,
    WSPConfig,
    load_wsp_config,
)
from wsp_env.evaluation import load_suite, run_suite


class ArrayWSP(ClassicalWSP):
    """The classical WSP as numpy array operations on the whole batch (the version before the
    compiled one): ``act`` and the periodic release re-written here, state as ``ClassicalWSP``'s."""

    def _array_release(self, age, decel, dt, allowed):
        cfg, na = self.cfg, decel.shape[1]
        rows_all = np.arange(len(age))
        self.since_release += dt
        start = (
            (age > cfg.periodic_release_interval_s)
            & (self.since_release > cfg.periodic_release_interval_s)
            & ~self.releasing
        )
        start &= allowed
        if start.any():
            self.release_axle[start] = self.next_release[start]
            self.next_release[start] = (self.next_release[start] - 1) % na
            self.release_left[start] = cfg.periodic_release_duration_s
            self.release_time[start] = 0.0
            self.releasing |= start
            self.since_release[start] = 0.0
        if not self.releasing.any():
            return rows_all[:0], rows_all[:0]
        rows = rows_all[self.releasing]
        axle = self.release_axle[self.releasing]
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

    def act(self, obs):
        cfg, na, dt = self.cfg, self.n_axles, self.dt
        v = obs[:, :na].astype(np.float64) * self.v_scale
        decel = obs[:, na : 2 * na].astype(np.float64) * self.a_scale
        pressure = obs[:, 3 * na : 4 * na].astype(np.float64)
        demand = obs[:, 4 * na].astype(np.float64)
        v_ref = obs[:, 4 * na + 1].astype(np.float64)[:, None] * self.v_scale
        age = obs[:, self.age_index].astype(np.float64) * self.age_scale
        slip = v_ref - v
        threshold = np.maximum(cfg.slip_abs_kmh / 3.6, cfg.slip_rel * v_ref)
        sliding = (slip > threshold) | (decel > cfg.decel_vent_mps2)
        recovering = -decel > cfg.accel_hold_mps2
        state = np.full(v.shape, APPLY, dtype=np.int64)
        state[slip > cfg.release_ratio * threshold] = HOLD
        state[sliding & ~recovering] = VENT
        self.active[...] = (state != APPLY).any(axis=1)
        rows, axles = self._array_release(age, decel, dt, self.active)
        state[rows, axles] = VENT
        onset = (state == VENT) & (self.venting_for == 0.0)
        self.slide_pressure[...] = np.where(onset, pressure, self.slide_pressure)
        self.stepping |= state == VENT
        self.stepping &= pressure < demand[:, None] - 0.02
        pulse = cfg.reapply_fill_s + cfg.reapply_hold_s
        fast = pressure < cfg.reapply_fast_fraction * self.slide_pressure
        in_step = self.stepping & (state == APPLY) & ~fast
        self.step_clock[...] = np.where(in_step, self.step_clock + dt, 0.0)
        state[in_step & (np.mod(self.step_clock - dt, pulse) >= cfg.reapply_fill_s)] = HOLD
        self.venting_for[...] = np.where(state == VENT, self.venting_for + dt, 0.0)
        self.locked_out |= self.venting_for > cfg.safety_timer_s
        state[self.locked_out] = APPLY
        state[v_ref[:, 0] < cfg.min_speed_kmh / 3.6] = APPLY
        valve_state = np.minimum.reduceat(state, self.valve_starts, axis=1)
        valve_p = np.maximum.reduceat(pressure, self.valve_starts, axis=1)
        hold_frac = np.where(
            demand[:, None] > 1e-6, valve_p / np.maximum(demand[:, None], 1e-6), 1.0
        )
        action = np.where(
            valve_state == APPLY, 1.0, np.where(valve_state == VENT, -1.0, 2.0 * hold_frac - 1.0)
        )
        return np.clip(action, -1.0, 1.0).astype(np.float32)


class Twin:
    """Runs the compiled WSP and the array reference side by side on the same observations;
    asserts that actions and state agree every period, and drives the stop with the compiled
    one's actions."""

    name = "classical"
    privileged = False

    def __init__(self, config: WSPConfig | None) -> None:
        self.compiled, self.reference = ClassicalWSP(config), ArrayWSP(config)
        self.periods = 0
        self.seen = {VENT: 0, HOLD: 0, "release": 0, "locked_out": 0, "stepping": 0}

    def bind(self, core):
        self.compiled.bind(core)
        self.reference.bind(core)

    def reset(self, env_ids):
        self.compiled.reset(env_ids)
        self.reference.reset(env_ids)

    def act(self, obs):
        a = self.compiled.act(obs)
        b = self.reference.act(obs)
        assert a.dtype == b.dtype == np.float32
        np.testing.assert_array_equal(a, b, strict=True)
        ca, cb = self.compiled.state_dict(), self.reference.state_dict()
        assert ca.keys() == cb.keys()
        for k in ca:
            np.testing.assert_array_equal(ca[k], cb[k], err_msg=k, strict=True)
        self.periods += 1
        self.seen[VENT] += int((a == -1.0).sum())
        self.seen[HOLD] += int(((a > -1.0) & (a < 1.0)).sum())
        self.seen["release"] += int(self.compiled.releasing.sum())
        self.seen["locked_out"] += int(self.compiled.locked_out.sum())
        self.seen["stepping"] += int(self.compiled.stepping.sum())
        return a


@pytest.mark.parametrize(
    ("vehicle", "tier", "timer_s"),
    [("regiolis", "wheels", None), ("uic_z1", "wheels+accel", 0.5)],
)  # fmt: skip
def test_compiled_classical_wsp_equals_the_array_version_to_the_bit(vehicle, tier, timer_s):
    """Grouped valves on the wheels tier's frozen thresholds; one valve per axle on the
    accelerometer tier's with a short safety timer (``timer_s``), so that its lock-out acts.
    Every branch is exercised (vents, holds, stepped re-application, periodic releases, the
    lock-out where the timer is short), or the comparison would prove little."""
    cfg = load_wsp_config(tier=tier)
    if timer_s is not None:
        cfg = WSPConfig(**{**vars(cfg), "safety_timer_s": timer_s})
    twin = Twin(cfg)
    env_kwargs = {"accelerometer": tier == "wheels+accel"}
    results, _ = run_suite(vehicle, load_suite("quick"), twin, record="none", env_kwargs=env_kwargs)
    assert results and all(r["stopped"] for r in results)
    assert twin.periods > 1000
    seen = dict(twin.seen)
    assert (seen.pop("locked_out") > 0) == (timer_s is not None), twin.seen
    assert all(count > 0 for count in seen.values()), twin.seen


def test_changed_thresholds_reach_the_compiled_rules():
    """``cfg`` is read every period: the same stops with a shorter safety timer differ."""
    suite = load_suite("quick")
    base, _ = run_suite("uic_z1", suite, ClassicalWSP(load_wsp_config()), record="none")
    short = ClassicalWSP(load_wsp_config())
    short.cfg = WSPConfig(**{**vars(load_wsp_config()), "safety_timer_s": 0.2})
    changed, _ = run_suite("uic_z1", suite, short, record="none")
    assert [r["stopping_distance_m"] for r in base] != [r["stopping_distance_m"] for r in changed]


def test_a_batch_of_another_size_is_refused_not_read_past_its_end():
    """The kernel trusts its arrays' sizes: ``act`` checks them first (a batch bound to two
    environments given three rows, or rows too short to hold the reference's age)."""
    from wsp_env.envs import WSPBrakingVectorEnv

    env = WSPBrakingVectorEnv(num_envs=2)
    env.reset(seed=[0, 1])
    wsp = ClassicalWSP(load_wsp_config())
    wsp.bind(env.core)
    wsp.reset(np.arange(2))
    assert wsp.act(env.core.obs).shape == (2, env.core.n_valves)
    for bad in (np.vstack([env.core.obs, env.core.obs[:1]]), env.core.obs[:, :5]):
        with pytest.raises(ValueError, match="classical WSP: observations of shape"):
            wsp.act(bad)

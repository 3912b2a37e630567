"""The slip-target inner loop: each valve's target sliding speed, tracked every control period
from what the sensors measure (the environment's ``action_mode="slip_target"``).

A learner that commands the valves directly acts every 20 ms on pneumatics that answer in
100 ms and more, so most of its exploration is filtered out; a WSP engineer's controller works a
level up, on the slip it wants each axle to run at. This loop turns that target into valve
commands, batched over environments, reading **only the observation** (the kernel's part:
what the sensor model measures) — exactly as the classical WSP (``classical.py``) does:

* measured slip ``s_i = v_ref - v_i`` (m/s): the shared estimator's reference speed less the
  wheel-speed reading, never the true train speed or creepage;
* a lead on the measured slip's rate: ``s_hat_i = s_i + lead_s (d_i - d_ref)``, ``d_i`` the
  wheel's measured deceleration over the last period (m/s^2), ``d_ref`` the reference speed's
  (its fall over the period, in the loop's state: kept through a re-anchor, where the reference
  jumps to a wheel — told by the reference's age falling, or with the drift correction by the
  anchors it reads — and held within [0, the estimator's deceleration limit]), so the slip
  ``lead_s`` ahead if it goes on growing as it did. A slip held steady has no lead term, so the
  loop settles on the target itself: the median measured slip mid-stop is 3.85-3.98 km/h for a
  4 km/h target on soap (0.07 at 120 km/h, 0.05 at 160, 0.08 at 60; 1.75-1.95 for 2 km/h,
  5.88-5.99 for 6 from 120 and 160 km/h, 5.44-5.85 from 60, where the creep cap below takes it
  down under 30 km/h; ``scripts/slip_target_study.py --part slip``, wheels-tier sensors, six
  seeds). A lead on the
  wheel's absolute deceleration would settle ``lead_s`` times the train's deceleration below it
  (3.55 km/h at 0.9 m/s^2). The pneumatics' lag is the reason for the lead: the valve's dead
  time plus the vent's time constant are about 0.1 s (``configs/vehicles``: ``vent_tau_s``
  0.12 s), and a wheel that starts to slide on soap passes a few km/h of slip in that time. It
  is the classical WSP's deceleration criterion (``decel_vent_mps2``: a wheel slowing fast is
  about to slide) made continuous. Without it the loop overshoots into long slides: on those
  three soap stops (two seeds each) a 4 km/h target stops 8-13 % longer than the classical WSP
  with ``lead_s = 0`` and 2-5 % shorter with 0.1 s at the default gain (0.2 s ties, 0.05 s lies
  between; at 0.1 s a gain of 0.1 per km/h gives 1-3 % shorter, 0.4 2-4 %: ``--part lead``);
* a proportional law on the pressure fraction: valve ``j``'s axles ask for
  ``f_i = clip(p_i / p_d + gain_per_kmh (target_kmh - 3.6 s_hat_i), 0, 1)`` of the demand
  ``p_d``, ``p_i`` the observed cylinder pressure. ``p_i / p_d`` is the classical WSP's *hold*
  (keep the pressure there), so a slip on target holds, a slip below it fills, a slip above it
  vents, each in proportion; the cylinder's own fill and vent lags integrate the request. With
  the default 0.2 per km/h, 5 km/h of error swings the request over the whole demand;
* optionally, **a gain scaled by the pressure held** (``gain_scale_floor`` below 1; 1, a fixed
  gain, by default): ``gain_per_kmh clip(p_i / p_d, gain_scale_floor, 1)``. A fixed gain
  changes the request by the same share of the demand per km/h of error whatever the axle
  holds, so the same step is a large share of the brake force of an axle held at a low pressure
  (low adhesion: 0.5 bar of 3.2 on leaves) and a small one of an axle near the full demand;
  scaled, each km/h of error changes the force held by about the same share (a gain scheduled
  on the operating point), and a larger gain at the full pressure does not lock on soap where
  a fixed 0.4 and more locks for over 1 s. Measured, ``gain_per_kmh`` 0.8 with the floor 0.25
  (0.2 per km/h, the fixed default, at and under a quarter of the demand) is no better loop:
  it shortens low targets' stops on leaves and oil by about 1 %, but it works the valves harder
  on soap (the same stops with 73 % more air at 4.25 km/h), and the benchmark's score, which
  counts the air, falls (a student of its teacher: −0.0011 paired, two seeds;
  ``docs/training_log.md``, "The slip-target loop's gain scaled by the pressure held");
* the classical WSP's recovery rule: an axle re-accelerating faster than ``accel_hold_mps2``
  is not vented further (it is on its way back), at most held;
* a target of at most ``max_creep`` of the reference speed, or the floor (``creep_floor_kmh``,
  ``MAX_CREEP_FLOOR_KMH``, 2 km/h, in the environment) where that is more
  (``target_kmh <= max(max_creep 3.6 v_ref, floor)``; 0: no cap, the loop
  before 2026-11-27's cap): a target fixed in km/h is a creep that grows as the train slows
  (8 km/h is 20 % at 40 km/h, 80 % at 10), far beyond the adhesion peak of every rail, and near
  standstill the wheel it asks for is nearly locked. With the cap, 0.2 by default, an 8 km/h
  target's stops on the UIC-Z1's 300 development stops meet the damage criteria on 89 % of
  them instead of 36 % (its longest lock 0.66 s instead of 13.5 s), its score 1.017 instead of
  1.003. The trade is on leaves: capped, the targets of 3 km/h and more trip the
  minimum-deceleration supervision on 4-8 of those stops, uncapped on none (near the end all
  axles slide alike at a low slip, which looks like grip, and the train slows by less than its
  0.2 m/s^2). The floor keeps the cap off the targets of 2 km/h and less, which the learned
  policies ask for on leaves (without it the cap tripped the supervision on three more stops
  of a learned policy). ``docs/training_log.md``, "The slip-target loop's creep cap";
* below ``min_speed_kmh`` the full demand (the classical WSP's rule: the last metres);
* **periodic release**, as the classical WSP makes it (its ``periodic_release_*`` thresholds,
  ``release_accel_done_mps2``): an axle held at a target slip never rolls freely, so the shared
  reference speed has nothing to anchor on and falls at its slope below the train — the measured
  slip then understates the true one and the wheels lock while their *measured* slip is on
  target (a 4 km/h target on soap 0.07 at 120 km/h without it: a wheel locked for 8-16 s in
  each of six stops, against under 0.8 s with it: ``--part release``). So when the reference
  has gone ``periodic_release_interval_s`` without an anchor (its observed age) and as long
  since the last release began, one axle in turn, from the last, is vented for at least
  ``periodic_release_duration_s`` and on until it stops spinning up and the estimator has
  anchored on it, at most ``periodic_release_max_s``. As in the classical WSP, a release
  begins only while the loop works (``release="working"``: some axle's request was under the
  full demand in the last period, or a wheel's measured slip is beyond the estimator's working
  band, ``max(active_slip_kmh, active_slip_rel v_ref)``, as the kernel judges that the WSP
  works): on a stop where no wheel slides the reference's age still
  counts (the loop's request dips under the demand while the cylinders fill at the brakes'
  onset, and the estimator then counts the age until an anchor), and an ungated release
  (``release="always"``, the loop before 2026-11-27) vented one axle after another of a train
  whose wheels all gripped (a wet Régiolis stop at 3 km/h: three axles, 97.3 m against 95.9 m);
* a valve of several axles (bogie valves) asks for its most cautious axle's request;
* **the reference's drift, corrected** (``drift_correction``; the ``wheels+accel`` tier's aided
  reference only; off by default): the shared estimator dead-reckons on the accelerometer and
  learns the reading's offset (bias and the gradient a specific-force sensor reads) only at an
  anchor at least ``kernel.ACC_LEARN_MIN_SPAN_S`` (2 s) after the last, and then
  ``accel_offset_gain`` (half) of it. A loop holding a low target can keep it from ever learning:
  on an uphill leaves stop (+21.4 per mille, bias -0.12 m/s^2, 60 km/h, 1.5 km/h) the reference
  rises above the train, the target reads as reached with every wheel gripping, the loop vents
  every axle, every wheel rolls free and the estimator anchors on them under 2 s after the last
  anchor (mostly within 0.5 s, in runs of consecutive periods) — too soon to learn — and the cycle
  repeats to standstill (94 anchors, none 2 s after the last, nothing learned, 301.2 m). With the
  correction the loop reads each anchor from the observation by the estimator's own rule, reads
  the anchor's jump of the reference (what it drifted since the last anchor, a rate over the time
  between them), takes away the share the estimator learned at that anchor, and subtracts the rest
  times the time since the anchor from the reference it tracks (never below the fastest wheel): 49
  anchors, 5 of them 2 s after the last, 0.32 m/s^2 learned, 286.0 m
  (``tests/test_slip_target.py``).
  ``docs/training_log.md``, "The slip-target loop's drift correction".
  With ``onset_drift`` the correction's drift is also read at every stop's start, before any
  anchor: while every cylinder is under its brake's threshold every wheel rolls with the
  train, so the accelerometer's mean reading less the wheels' mean deceleration is its offset
  (``_read_onset``; ``docs/training_log.md``, "The onset reading of the accelerometer's offset").
  With ``onset_two_sided`` it reads a reading of too much deceleration too (a downhill's
  ``g sin(theta)``, a positive bias: the aided reference sinks below the train, which matters
  when every wheel slides below it), and every drift downward, the onset's or an anchor's,
  raises the tracked reference only for the time no wheel has held the estimator's up
  (``docs/training_log.md``, "The onset reading's other sense").
* **the wheel-speed sensors' scales, calibrated** (``scale_calibration``; either tier; off by
  default): in that same window each sensor's mean reading against the wheels' mean is its
  scale error (a wheel diameter known to the BCU only roughly), divided out of every reading
  and of the estimator's reference for the rest of the stop (``_calibrate``): with the
  benchmark's +-0.5 % a 2 km/h target's leaves watchdog stops fall from 7 to 1 of 593 fresh
  stops (``docs/training_log.md``, "The wheel-scale calibration").
* **the lock guard** (``lock_guard``; off by default): on a patchy leaves rail at low speed a
  wheel braked at the full demand on a clean patch locks within two periods when it meets a
  contaminated one, and stays locked while its cylinder vents (0.32 s from 3.8 bar on the
  Régiolis: the event behind the longest locks of the classical WSP and the students there).
  Below 15 km/h, on a stop whose reference has slowed at under 0.85 m/s^2 on average after a
  wheel slipped (and 6 s or more into the stop), each request is capped at 0.8 of the demand
  (``_guard``): the Régiolis student's longest lock on its development stops 0.32 → 0.28 s for
  0.0007 of its mean stop ratio (``docs/training_log.md``, "The lock guard, and a creep
  schedule for the Régiolis's leaves teacher").

The commands are continuous valve actions (``2 f - 1``), so the loop can drive any continuous
environment from outside (``SlipTargetPolicy``: a constant target) and gives, bit for bit, the
stop the environment's ``slip_target`` mode gives (``tests/test_slip_target.py``).

State: the periodic release's and the reference's deceleration (``advance``, once per control
period; ``reset`` starts both anew for an environment's new stop); ``command`` is a pure
function of the observation, the targets and that state.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wsp_env.baselines.classical import (
    ArrayState,
    PeriodicRelease,
    WSPConfig,
    core_tier,
    load_wsp_config,
)
from wsp_env.core import kernel as K
from wsp_env.core.config import ConfigError, check_number

RELEASE_GATES = ("working", "always")
# the loop's settings by default (``SlipTargetLoop``, the environment's ``slip_target_release``
# and ``slip_target_max_creep``); ``policy.LEGACY_LOOP_SETTINGS`` says what a model file
# written before each existed gets
DEFAULT_RELEASE = "working"
DEFAULT_MAX_CREEP = 0.2
DEFAULT_DRIFT_CORRECTION = False
DEFAULT_GAIN_PER_KMH = 0.2  # the loop's fixed gain by default
# the gain's scale never falls below this (``gain_scale_floor``); 1: a fixed gain (the default)
DEFAULT_GAIN_SCALE_FLOOR = 1.0
DEFAULT_ONSET_DRIFT = False
DEFAULT_SCALE_CALIBRATION = False
DEFAULT_ONSET_TWO_SIDED = False
# the two-sided onset reading (``onset_two_sided``): the estimator's reference is held up by a
# wheel when it is within this of the fastest reading (m/s: 0.1 km/h, the wheel sensors' noise
# and resolution)
REF_HELD_TOL_MPS = 0.1 / 3.6
# the drift correction reads a rate from an anchor's jump only over at least this long (s)
DRIFT_MIN_SPAN_S = 0.5
# the onset reading (``onset_drift``) needs every cylinder under its brake's threshold for at
# least this long (s)
ONSET_MIN_S = 0.2
# the wheel-scale calibration (``scale_calibration``) reads its window only where every wheel's
# mean reading is above this (m/s: 10 km/h), and keeps each factor within this of 1 (the sensor
# model's scale errors are at most 0.1)
CAL_MIN_SPEED_MPS = 10.0 / 3.6
CAL_MAX_FACTOR = 0.1
# the lock guard (``lock_guard``): below this reference speed (km/h), on a stop where a wheel has
# slipped beyond the estimator's working band and the reference's deceleration, averaged over
# ``LOCK_GUARD_TAU_S``, is under ``LOCK_GUARD_DECEL_MPS2`` (a low-adhesion rail: leaves, oil; a
# dry or wet rail brakes at 1 m/s^2 and more at the full demand), every valve asks for at most
# ``LOCK_GUARD_FRACTION`` of the demand. Chosen on the Régiolis's development stops
# (``docs/training_log.md``, "The lock guard, and a creep schedule for the Régiolis's leaves
# teacher")
DEFAULT_LOCK_GUARD = False
LOCK_GUARD_SPEED_KMH = 15.0
LOCK_GUARD_FRACTION = 0.8
LOCK_GUARD_DECEL_MPS2 = 0.85
LOCK_GUARD_TAU_S = 2.0
# the guard acts only after this long into a stop (s: three of the average's time constants),
# so the average, which starts at 0, has forgotten its start (a stop begun at low speed on a dry
# rail would otherwise read as a low-adhesion one)
LOCK_GUARD_SETTLE_S = 3.0 * LOCK_GUARD_TAU_S
# the creep cap's default floor: it never asks for less than this (km/h of measured slip; a
# lower target is kept); the environment's loop always has it, a probe may lower it
MAX_CREEP_FLOOR_KMH = 2.0


def check_loop_args(gain_per_kmh: Any, lead_s: Any) -> tuple[float, float]:
    """The loop's gain and lead as floats, or a one-line ``ConfigError`` (a ``ValueError``)
    naming the environment argument: ``slip_target_gain_per_kmh`` in (0, 10],
    ``slip_target_lead_s`` in [0, 1] s."""
    gain = check_number(gain_per_kmh, "slip_target_gain_per_kmh", gt=0.0, le=10.0)
    return gain, check_number(lead_s, "slip_target_lead_s", ge=0.0, le=1.0)


def check_max_creep(max_creep: Any) -> float:
    """The cap on the target as a fraction of the reference speed, a float in [0, 1] (0: no
    cap), or a one-line ``ConfigError`` naming the environment argument
    ``slip_target_max_creep``."""
    return check_number(max_creep, "slip_target_max_creep", ge=0.0, le=1.0)


def check_gain_scale_floor(floor: Any) -> float:
    """The floor of the gain's scale by the pressure held, a float in (0, 1] (1: a fixed gain,
    the loop before), or a one-line ``ConfigError`` naming the environment argument
    ``slip_target_gain_scale_floor``."""
    return check_number(floor, "slip_target_gain_scale_floor", gt=0.0, le=1.0)


def parse_pressure_gain(text: str, where: str) -> tuple[float, float]:
    """A command line's gain setting as the loop's ``(gain_per_kmh, gain_scale_floor)``:
    ``off``, the fixed default gain; ``GxF``, G per km/h times the pressure held over the
    demand, never below F of it (``0.8x0.25``); else a one-line ``ValueError`` beginning with
    ``where`` (the option and its value)."""
    if text == "off":
        return DEFAULT_GAIN_PER_KMH, DEFAULT_GAIN_SCALE_FLOOR
    gain, sep, floor = text.partition("x")
    if not sep:
        raise ValueError(f"{where}: off or GAINxFLOOR (e.g. 0.8x0.25), got {text!r}")
    try:
        return check_loop_args(gain, 0.1)[0], check_gain_scale_floor(floor)
    except ConfigError as err:
        raise ValueError(f"{where}: {err}") from None


def check_onset_drift(onset_drift: Any, drift_correction: bool) -> bool:
    """The onset reading's switch as a bool, or a one-line ``ConfigError`` naming the
    environment argument ``slip_target_onset_drift`` (true or false; true only with the drift
    correction, whose drift it sets)."""
    if not isinstance(onset_drift, (bool, np.bool_)):
        raise ConfigError(f"slip_target_onset_drift: must be true or false, got {onset_drift!r}")
    if onset_drift and not drift_correction:
        raise ConfigError(
            "slip_target_onset_drift: needs slip_target_drift_correction (it sets the drift "
            "the correction takes away)"
        )
    return bool(onset_drift)


def check_onset_two_sided(two_sided: Any, onset_drift: bool) -> bool:
    """The two-sided onset reading's switch as a bool, or a one-line ``ConfigError`` naming the
    environment argument ``slip_target_onset_two_sided`` (true or false; true only with the
    onset reading, whose other sense it adds)."""
    if not isinstance(two_sided, (bool, np.bool_)):
        raise ConfigError(f"slip_target_onset_two_sided: must be true or false, got {two_sided!r}")
    if two_sided and not onset_drift:
        raise ConfigError(
            "slip_target_onset_two_sided: needs slip_target_onset_drift (it adds that "
            "reading's other sense)"
        )
    return bool(two_sided)


def check_drift_correction(drift_correction: Any) -> bool:
    """The drift correction's switch as a bool, or a one-line ``ConfigError`` naming the
    environment argument ``slip_target_drift_correction`` (true or false; a number or a
    string is refused, not read as true)."""
    if not isinstance(drift_correction, (bool, np.bool_)):
        raise ConfigError(
            f"slip_target_drift_correction: must be true or false, got {drift_correction!r}"
        )
    return bool(drift_correction)


def check_release(release: Any) -> str:
    """The periodic release's gate (``RELEASE_GATES``), or a one-line ``ConfigError`` naming the
    environment argument ``slip_target_release``."""
    if not isinstance(release, str) or release not in RELEASE_GATES:
        raise ConfigError(
            f"slip_target_release: must be one of {', '.join(RELEASE_GATES)}, got {release!r}"
        )
    return release


def check_scale_calibration(scale_calibration: Any) -> bool:
    """The wheel-scale calibration's switch as a bool, or a one-line ``ConfigError`` naming the
    environment argument ``slip_target_scale_calibration`` (true or false)."""
    if not isinstance(scale_calibration, (bool, np.bool_)):
        raise ConfigError(
            f"slip_target_scale_calibration: must be true or false, got {scale_calibration!r}"
        )
    return bool(scale_calibration)


def check_lock_guard(lock_guard: Any) -> bool:
    """The lock guard's switch as a bool, or a one-line ``ConfigError`` naming the environment
    argument ``slip_target_lock_guard`` (true or false)."""
    if not isinstance(lock_guard, (bool, np.bool_)):
        raise ConfigError(f"slip_target_lock_guard: must be true or false, got {lock_guard!r}")
    return bool(lock_guard)


class SlipTargetLoop(ArrayState, PeriodicRelease):
    """Valve commands that track per-valve target sliding speeds (module docstring). ``wsp``:
    the classical WSP's thresholds it reuses (recovery, minimum speed, periodic release); None:
    the frozen file of the sensor tier of the core it binds to (``classical.core_tier``: with
    an accelerometer ``wheels+accel``'s, else ``wheels``'), the thresholds the environment's
    mode runs on (``envs.make_core``), so a loop built without them is that mode's loop (before
    2026-11-28 it took ``WSPConfig()``'s defaults); ``release``: when a
    periodic release may begin (``RELEASE_GATES``): ``"working"``, only while the loop works
    (some axle's request was under the full demand in the last period, or a wheel's measured
    slip is beyond the estimator's working band: the kernel's test that the WSP works), as the
    classical WSP only while it is active;
    ``"always"``, whenever the reference's age allows (the loop before 2026-11-27);
    ``max_creep``: each target at most this fraction of the reference speed (0: no cap, the loop
    before the cap), or ``creep_floor_kmh`` where that is more (``MAX_CREEP_FLOOR_KMH``, 2 km/h,
    by default; a lower floor makes the cap a creep schedule for low targets as well: a probe's
    setting, not an environment argument); ``drift_correction``: track the slip against the
    estimator's reference less the drift its last anchor showed and it has not learned (module
    docstring; needs the accelerometer: ``bind`` refuses a core without one);
    ``gain_scale_floor``: the gain times
    the pressure held over the demand, never below this (1: a fixed gain; module
    docstring); ``onset_drift``: with the drift correction, its drift read at the stop's start
    as well (``_read_onset``); ``onset_two_sided``: with the onset reading, its other sense too
    (a reading of too much deceleration), the tracked reference raised only while no wheel
    holds the estimator's up (``_correct_drift``); ``scale_calibration``: each wheel-speed
    reading's scale, relative
    to the wheels' mean, read while every wheel rolls free at the stop's start and divided out
    (``_calibrate``; either tier); ``lock_guard``: at low speed on a low-adhesion stop, every
    valve's request capped under the demand (``LOCK_GUARD_*``; module docstring)."""

    name = "slip_target_loop"
    privileged = False

    def __init__(
        self,
        wsp: WSPConfig | None = None,
        gain_per_kmh: float = DEFAULT_GAIN_PER_KMH,
        lead_s: float = 0.1,
        release: str = DEFAULT_RELEASE,
        max_creep: float = DEFAULT_MAX_CREEP,
        drift_correction: bool = DEFAULT_DRIFT_CORRECTION,
        gain_scale_floor: float = DEFAULT_GAIN_SCALE_FLOOR,
        onset_drift: bool = DEFAULT_ONSET_DRIFT,
        scale_calibration: bool = DEFAULT_SCALE_CALIBRATION,
        onset_two_sided: bool = DEFAULT_ONSET_TWO_SIDED,
        creep_floor_kmh: float = MAX_CREEP_FLOOR_KMH,
        lock_guard: bool = DEFAULT_LOCK_GUARD,
    ) -> None:
        self.wsp_given = wsp  # None: the bound core's tier's thresholds (``bind``)
        self.cfg = wsp or WSPConfig()
        self.gain_per_kmh, self.lead_s = check_loop_args(gain_per_kmh, lead_s)
        self.release = check_release(release)
        self.max_creep = check_max_creep(max_creep)
        self.drift_correction = check_drift_correction(drift_correction)
        self.gain_scale_floor = check_gain_scale_floor(gain_scale_floor)
        self.onset_drift = check_onset_drift(onset_drift, self.drift_correction)
        self.scale_calibration = check_scale_calibration(scale_calibration)
        self.onset_two_sided = check_onset_two_sided(onset_two_sided, self.onset_drift)
        self.creep_floor_kmh = check_number(creep_floor_kmh, "creep_floor_kmh", ge=0.0, le=30.0)
        self.lock_guard = check_lock_guard(lock_guard)

    def bind(self, core: Any) -> None:
        """Attach to a ``BrakingCore``: its scales, valve map and batch size."""
        n, na = core.n_envs, core.n_axles
        if self.wsp_given is None:  # the tier's frozen thresholds, as the environment's mode
            self.cfg = load_wsp_config(tier=core_tier(core))
        self.n_axles = na
        self.dt = core.sim.control_period_s
        self.v_scale = core.obs_par[K.OP_SPEED_SCALE]
        self.a_scale = core.obs_par[K.OP_DECEL_SCALE]
        self.age_scale = core.obs_par[K.OP_AGE_SCALE]
        self.age_index = core.kernel_obs_dim - 1  # the reference's age: the kernel's last entry
        self.valve_of_axle = core.valve_of_axle
        self.valve_starts = np.flatnonzero(np.r_[True, np.diff(self.valve_of_axle) != 0])
        self._release_init(n, next_axle=na - 1)
        self.since_release[:] = np.inf
        self.vent = np.zeros((n, na), dtype=bool)  # this period's periodic-release vents
        # some axle's request under the full demand in the last period (``command``): the loop
        # works, and a periodic release may begin (``release="working"``)
        self.working = np.zeros(n, dtype=bool)
        self.always = np.ones(n, dtype=bool)  # a release may begin anywhere (``release="always"``)
        # the reference's deceleration over the last period (m/s^2; NaN: no period yet), its
        # speed and age then (the lead's relative term, ``advance``)
        self.ref_limit = float(core.obs_par[K.OP_REF_DECEL_LIMIT])
        # the estimator's working band: a wheel this far below the reference slips (m/s, and a
        # fraction of the reference), as the kernel judges that the WSP works
        self.active_slip = float(core.obs_par[K.OP_ACTIVE_SLIP])
        self.active_slip_rel = float(core.obs_par[K.OP_ACTIVE_SLIP_REL])
        self.decel_ref = np.zeros(n)
        self.prev_ref = np.full(n, np.nan)
        self.prev_age = np.zeros(n)
        self._rows = np.arange(n)
        # the drift correction (``drift_correction``): the estimator's share of an offset it
        # learns at an anchor; the reference the loop tracks (m/s), the estimator's a period
        # before and its fall (m/s^2), the time since the last anchor (s) and the drift taken
        # away (m/s a second)
        if self.drift_correction and not getattr(core, "accelerometer", False):
            raise ConfigError(
                "slip_target_drift_correction: needs the accelerometer (the wheels+accel tier): "
                "it corrects the aided reference's drift"
            )
        self.learn_gain = float(core.obs_par[K.OP_ACC_OFFSET_GAIN])
        # the kernel's previous-action entries: the valve commands of the period just run
        self.valve_cols = slice(4 * na + 2, 4 * na + 2 + core.n_valves)
        self.v_ref = np.zeros(n)
        self.raw_ref = np.full(n, np.nan)
        self.raw_decel = np.zeros(n)
        self.prev_wheels = np.zeros((n, na))
        self.since_anchor = np.zeros(n)
        self.drift = np.zeros(n)
        self.anchored = np.zeros(n, dtype=bool)  # the estimator anchored in the last period
        # the time since no wheel held the estimator's reference up or it anchored (s): what
        # an upward correction multiplies with ``onset_two_sided``
        self.unheld_s = np.zeros(n)
        # that time restarted in the last period with a raise standing: the tracked reference
        # stepped down by the raise, which is no fall of the train (``advance``)
        self.raise_dropped = np.zeros(n, dtype=bool)
        # a rate read from an anchor's jump since the stop began (the onset reading yields)
        self.rate_read = np.zeros(n, dtype=bool)
        # the onset reading (``onset_drift``): the accelerometer's reading column, each axle's
        # brake threshold as a share of the full pressure (design data: no brake torque below
        # it), and per environment whether the window is open, its periods, the readings'
        # sum, the wheels' mean speed at its start and now (m/s)
        self.acc_index = core.kernel_obs_dim - 2
        # (the vehicle's brake data; the observation's share is of the stop's full pressure,
        # the vehicle's at most, so a share under this is under the threshold)
        brake = core.vehicle.brake
        self.free_share = np.full(na, brake.linear_torque()[1] / brake.p_max_bar)
        self.onset_open = np.ones(n, dtype=bool)
        self.onset_n = np.zeros(n)
        self.onset_acc = np.zeros(n)
        self.onset_v0 = np.full(n, np.nan)
        self.onset_v = np.zeros(n)
        # the wheel-scale calibration (``scale_calibration``): per environment whether its
        # window is open, its periods, each wheel's readings' sum (m/s), each wheel's factor
        # (the wheels' mean over its own mean: 1 until the window closes) and the factor of
        # the wheel the estimator's reference last equalled (``_calibrate``)
        self.cal_open = np.ones(n, dtype=bool)
        self.cal_n = np.zeros(n)
        self.cal_sum = np.zeros((n, na))
        self.cal_factor = np.ones((n, na))
        self.cal_ref_factor = np.ones(n)
        # the estimator's reference and the wheels' readings of the last period, uncalibrated
        # (m/s): its anchor rule's inputs (``_correct_drift``)
        self.kernel_ref = np.zeros(n)
        self.kernel_wheels = np.zeros((n, na))
        # the lock guard (``lock_guard``): a wheel slipped beyond the working band since the
        # stop began; the reference's deceleration averaged over ``LOCK_GUARD_TAU_S`` (m/s^2);
        # whether the guard caps the requests this period (``advance``)
        self.guard_slipped = np.zeros(n, dtype=bool)
        self.guard_decel = np.zeros(n)
        self.guard_time_s = np.zeros(n)  # the time since the stop began (s)
        self.guard_on = np.zeros(n, dtype=bool)

    def reset(self, env_ids: np.ndarray) -> None:
        """Environments ``env_ids`` start a new stop."""
        self._release_reset(env_ids, self.n_axles)
        self.vent[env_ids] = False
        self.working[env_ids] = False
        self.decel_ref[env_ids] = 0.0
        self.prev_ref[env_ids] = np.nan
        self.prev_age[env_ids] = 0.0
        self.raw_ref[env_ids] = np.nan
        self.raw_decel[env_ids] = 0.0
        self.prev_wheels[env_ids] = 0.0
        self.anchored[env_ids] = False
        self.since_anchor[env_ids] = 0.0
        self.unheld_s[env_ids] = 0.0
        self.raise_dropped[env_ids] = False
        self.drift[env_ids] = 0.0
        self.rate_read[env_ids] = False
        self.onset_open[env_ids] = True
        self.onset_n[env_ids] = 0.0
        self.onset_acc[env_ids] = 0.0
        self.onset_v0[env_ids] = np.nan
        self.onset_v[env_ids] = 0.0
        self.cal_open[env_ids] = True
        self.cal_n[env_ids] = 0.0
        self.cal_sum[env_ids] = 0.0
        self.cal_factor[env_ids] = 1.0
        self.cal_ref_factor[env_ids] = 1.0
        self.kernel_ref[env_ids] = 0.0
        self.kernel_wheels[env_ids] = 0.0
        self.guard_slipped[env_ids] = False
        self.guard_decel[env_ids] = 0.0
        self.guard_time_s[env_ids] = 0.0
        self.guard_on[env_ids] = False

    # bound once (``bind``); every other array evolves (``state_dict``)
    _CONSTANT = frozenset({"valve_of_axle", "valve_starts", "_rows", "free_share", "always"})

    def _slips(self, v_ref: np.ndarray, wheels: np.ndarray) -> np.ndarray:
        """Per environment, whether a wheel's reading (m/s) is below the reference (m/s) by more
        than the estimator's working band, ``max(active_slip, active_slip_rel v_ref)``: the
        kernel's test that the WSP works (``kernel.estimate_and_supervise``)."""
        band = np.maximum(self.active_slip, self.active_slip_rel * v_ref)
        return ((v_ref[:, None] - wheels) > band[:, None]).any(axis=1)

    def _correct_drift(
        self, obs: np.ndarray, v_ref: np.ndarray, age: np.ndarray, v: np.ndarray,
        raw: np.ndarray | None = None,
    ) -> np.ndarray:  # fmt: skip
        """The reference the loop tracks (m/s): the estimator's ``v_ref`` less the drift its last
        anchor showed and it did not learn, times the time since that anchor (module
        docstring), never below the fastest wheel (or ``v_ref``, where that is lower); advances
        the correction's state.

        **An anchor** is read from the observation by the estimator's own rule
        (``kernel.update_reference``, ``estimate_and_supervise``): it anchors only while the WSP
        works — a valve was out of apply in the period (the kernel's previous-action entries
        under 1), or a wheel slipped beyond the working band at its start (the last period's
        reading and reference) — and the demand stands, and an anchor sets the reference's age
        to 0, which otherwise grows while the WSP has worked since the last anchor. So the age
        at 0 in a period in which the WSP worked is an anchor, and no other period is: anchors
        in consecutive periods (a wheel rolling free for several) and anchors after an idle
        spell (the age held at 0) are each seen, and the time since the last one is the
        estimator's own span. **Its jump** (the estimator's reference a period before, less its
        fall over the period before that, less now) is what the reference drifted over that
        span, over which the estimator learned ``learn_gain`` of its miss if the span was at
        least ``ACC_LEARN_MIN_SPAN_S``; the rest a second is the drift taken away until the
        next anchor (read only over ``DRIFT_MIN_SPAN_S`` or more). A drift downward is bounded
        by the fastest wheel, which holds the estimator's reference up; only what the jump
        shows is corrected. With ``onset_two_sided`` a drift downward (the reference sinking
        below the train, read at the onset or from an anchor's jump) raises the tracked
        reference by the drift times ``unheld_s``, the time since a wheel last held the
        estimator's reference up (within ``REF_HELD_TOL_MPS`` of the fastest reading) or it
        anchored, instead of the time since the anchor."""
        dt = self.dt
        na = self.n_axles
        out_of_apply = (obs[:, self.valve_cols] < 1.0 - 1e-6).any(axis=1)
        # at the period's start, on the readings the estimator judged (``raw``: the observation
        # before the wheel-scale calibration, where it runs)
        if raw is not None:
            slipped = self._slips(self.kernel_ref, self.kernel_wheels)
            self.kernel_ref = raw[:, 4 * na + 1].astype(np.float64) * self.v_scale
            self.kernel_wheels = raw[:, :na].astype(np.float64) * self.v_scale
        else:
            slipped = self._slips(self.raw_ref, self.prev_wheels)
        demand = obs[:, 4 * na] > 0.0
        known = np.isfinite(self.raw_ref)  # not the stop's first observation
        anchored = known & (age == 0.0) & (out_of_apply | slipped) & demand
        span = np.maximum(self.since_anchor, dt)  # the estimator's time since its last anchor
        jump = self.raw_ref - self.raw_decel * dt - v_ref
        learned = np.where(span >= K.ACC_LEARN_MIN_SPAN_S - 1e-9, self.learn_gain, 0.0)
        rate = np.clip((1.0 - learned) * jump / span, -K.ACC_CORR_MAX, K.ACC_CORR_MAX)
        # a jump over a short span is mostly the wheels' noise and scale errors over it: kept
        read = anchored & (span >= DRIFT_MIN_SPAN_S - 1e-9)
        self.drift = np.where(read, rate, self.drift)
        self.rate_read |= read
        since = np.where(anchored, 0.0, self.since_anchor)
        self.since_anchor = since + dt  # at the next period's observation
        self.anchored = anchored
        # the estimator's reference's own fall a second, kept through an anchor
        self.raw_decel = np.where(anchored | ~known, self.raw_decel, (self.raw_ref - v_ref) / dt)
        self.raw_ref, self.prev_wheels = v_ref, v  # fresh arrays of ``advance``'s
        corrected = v_ref - self.drift * since
        fastest = v.max(axis=1)
        if self.onset_two_sided:  # a drift down (the reference below the train) is made up
            # only for the time no wheel has held the estimator's reference up: a wheel within
            # REF_HELD_TOL_MPS of it, or an anchor, restarts that time
            held = (v_ref <= fastest + REF_HELD_TOL_MPS) | anchored
            self.raise_dropped = held & (self.unheld_s > 0.0) & (self.drift < 0.0)
            self.unheld_s = np.where(held, 0.0, self.unheld_s + dt)
            corrected = np.where(self.drift < 0.0, v_ref - self.drift * self.unheld_s, corrected)
        return np.maximum(corrected, np.minimum(fastest, v_ref))

    def _free(self, obs: np.ndarray) -> np.ndarray:
        """Per environment, whether every cylinder is under its brake's threshold (its share of
        the full pressure under ``free_share``): every wheel rolls with the train, the window
        the onset reading and the wheel-scale calibration read."""
        na = self.n_axles
        return (obs[:, 3 * na : 4 * na] < self.free_share[None, :]).all(axis=1)

    def _read_onset(self, obs: np.ndarray, v: np.ndarray) -> np.ndarray | None:
        """The onset reading (``onset_drift``; module docstring): while every cylinder is under
        its brake's threshold since the stop began, every wheel rolls with the train, so the
        wheels' mean deceleration over that window is the train's, and the accelerometer's mean
        reading less it is the reading's offset. When the window closes (the first period with
        a cylinder at or over its threshold), after at least ``ONSET_MIN_S``, and no anchor's
        jump has been read yet, the drift the correction takes away becomes the rate at which
        that offset carries the aided reference above the train: ``max(0, wheels' deceleration
        - reading)``, within ``ACC_CORR_MAX``. Only that sense: a reading of too much
        deceleration carries the reference down, where the fastest wheel holds it up — unless
        every wheel slides below it; ``onset_two_sided`` reads that sense too (``wheels -
        reading`` within ``+-ACC_CORR_MAX``), made up only while no wheel holds the reference
        up (``_correct_drift``). Returns
        where the drift was set (the tracked reference steps there, down, or with
        ``onset_two_sided`` up: no fall of the train either way), or None once every
        environment's window has closed (nothing left to read)."""
        if not self.onset_open.any():
            return None
        free = self._free(obs)
        acc = obs[:, self.acc_index].astype(np.float64) * self.a_scale
        mean_v = v.mean(axis=1)
        still = self.onset_open & free
        first = still & np.isnan(self.onset_v0)
        more = still & ~first
        self.onset_v0 = np.where(first, mean_v, self.onset_v0)
        self.onset_n = np.where(more, self.onset_n + 1.0, self.onset_n)
        self.onset_acc = np.where(more, self.onset_acc + acc, self.onset_acc)
        self.onset_v = np.where(still, mean_v, self.onset_v)
        closing = self.onset_open & ~free
        span = self.onset_n * self.dt
        use = closing & (span >= ONSET_MIN_S - 1e-9) & ~self.rate_read
        wheels = (self.onset_v0 - self.onset_v) / np.maximum(span, 1e-9)
        reading = self.onset_acc / np.maximum(self.onset_n, 1.0)
        low = -K.ACC_CORR_MAX if self.onset_two_sided else 0.0
        rate = np.clip(wheels - reading, low, K.ACC_CORR_MAX)
        self.drift = np.where(use, rate, self.drift)
        self.onset_open &= free
        return use

    def _calibrate(self, obs: np.ndarray) -> None:
        """The wheel-scale calibration's state on the raw observation (``scale_calibration``):
        while every cylinder is under its brake's threshold since the stop began (the onset
        reading's window), every wheel rolls with the train, so each sensor's mean reading over
        the window against the wheels' mean is its scale error relative to the others (a wheel
        diameter known only to ``wheel_speed_scale_error``; a BCU calibrates it while coasting).
        When the window closes, after at least ``ONSET_MIN_S`` with every wheel's mean reading
        above ``CAL_MIN_SPEED_MPS``, each wheel's factor becomes the wheels' mean over its own
        mean (within ``CAL_MAX_FACTOR`` of 1), and the last period's reference and readings the
        loop keeps are put on the new scales (the step is no fall of the train); a window that
        closes shorter or slower leaves the factors at 1. Then, every period, the factor of the
        wheel the estimator's reference equals (it follows the fastest wheel and re-anchors on
        a wheel's reading) is the reference's. The drift correction still reads the estimator's
        anchors on the uncalibrated readings its rule judges (``_correct_drift``)."""
        na = self.n_axles
        v = obs[:, :na].astype(np.float64)
        if self.cal_open.any():
            free = self._free(obs)
            still = self.cal_open & free
            self.cal_sum[still] += v[still] * self.v_scale
            self.cal_n[still] += 1.0
            closing = self.cal_open & ~free
            mean = self.cal_sum / np.maximum(self.cal_n, 1.0)[:, None]
            ok = closing & (self.cal_n * self.dt >= ONSET_MIN_S - 1e-9)
            ok &= mean.min(axis=1) > CAL_MIN_SPEED_MPS
            factor = mean.mean(axis=1, keepdims=True) / np.maximum(mean, 1e-9)
            factor = np.clip(factor, 1.0 - CAL_MAX_FACTOR, 1.0 + CAL_MAX_FACTOR)
            self.cal_factor = np.where(ok[:, None], factor, self.cal_factor)
            self.cal_open &= free
        else:
            ok = None
        ref = obs[:, 4 * na + 1].astype(np.float64)
        equal = v == ref[:, None]
        wheel = np.argmax(equal, axis=1)
        self.cal_ref_factor = np.where(
            equal.any(axis=1), self.cal_factor[self._rows, wheel], self.cal_ref_factor
        )
        if ok is not None and ok.any():  # the scales change: the last period's readings the
            # loop keeps, on the new scales (they were on 1), so no step reads as a fall
            self.prev_ref = np.where(ok, self.prev_ref * self.cal_ref_factor, self.prev_ref)
            self.raw_ref = np.where(ok, self.raw_ref * self.cal_ref_factor, self.raw_ref)
            self.prev_wheels = np.where(ok[:, None], self.prev_wheels * self.cal_factor,
                                        self.prev_wheels)  # fmt: skip

    def _calibrated(self, obs: np.ndarray) -> np.ndarray:
        """``obs`` with the wheels' speeds and decelerations and the estimator's reference
        divided by their scale (``_calibrate``'s factors): a float64 copy."""
        na = self.n_axles
        out = obs.astype(np.float64)  # a copy
        out[:, :na] *= self.cal_factor
        out[:, na : 2 * na] *= self.cal_factor
        out[:, 4 * na + 1] *= self.cal_ref_factor
        return out

    def advance(self, obs: np.ndarray) -> None:
        """One control period of the loop's state on the kernel's observation ``obs``
        (``(n_envs, kernel_obs_dim)``): the reference's deceleration over the period and the
        periodic release. Call it exactly once per period, before ``command``."""
        na, dt = self.n_axles, self.dt
        raw = None
        if self.scale_calibration:  # every reading below on the calibrated scales
            self._calibrate(obs)
            raw, obs = obs, self._calibrated(obs)
        decel = obs[:, na : 2 * na].astype(np.float64) * self.a_scale
        age = obs[:, self.age_index].astype(np.float64) * self.age_scale
        # the reference's deceleration over the period: kept through a re-anchor (its age fell,
        # or with the drift correction the anchor it reads: the reference jumped to a wheel, up
        # or down, which is no deceleration of the train) and within [0, the estimator's
        # limit] (what a braking train does)
        v_ref = obs[:, 4 * na + 1].astype(np.float64) * self.v_scale
        v = obs[:, :na].astype(np.float64) * self.v_scale
        onset_set = None
        if self.onset_drift:  # the accelerometer's offset read at the stop's onset
            onset_set = self._read_onset(obs, v)
        if self.drift_correction:  # the reference the loop tracks (``_correct_drift``)
            v_ref = self._correct_drift(obs, v_ref, age, v, raw)
            self.v_ref = v_ref
        slope = (self.prev_ref - v_ref) / dt
        known = np.isfinite(slope) & (age >= self.prev_age)
        if self.drift_correction:  # the anchors read exactly (``_correct_drift``): an anchor
            # in a period after an anchor or an idle spell leaves the age at 0, not falling
            known &= ~self.anchored
        if onset_set is not None:  # the step the onset reading's drift makes is no fall either
            known &= ~onset_set
        known &= ~self.raise_dropped  # nor the two-sided raise's drop (``_correct_drift``)
        self.decel_ref = np.where(known, np.clip(slope, 0.0, self.ref_limit), self.decel_ref)
        self.prev_ref, self.prev_age = v_ref, age
        self.vent[...] = False
        allowed = self.always
        if self.release == "working":  # the loop works: it asked for under the demand in the
            # last period, or a wheel slips beyond the estimator's working band now
            allowed = self.working | self._slips(v_ref, v)
        self._release_step(age, decel, dt, allowed, self.vent)
        if self.lock_guard:
            self._guard(v_ref, v)

    def _guard(self, v_ref: np.ndarray, v: np.ndarray) -> None:
        """The lock guard's state for this period (``lock_guard``): on a patchy low-adhesion rail
        at low speed a wheel that runs at the full demand from a clean patch onto a
        contaminated one locks within two periods (its inertia is small there) and stays
        locked for as long as its cylinder takes to vent to what the patch holds: 0.3 s from
        the Régiolis's 3.8 bar at its 10 bar/s. So below ``LOCK_GUARD_SPEED_KMH``, on a stop
        where a wheel has slipped beyond the working band and the reference has slowed at
        under ``LOCK_GUARD_DECEL_MPS2`` on average (a first-order average over
        ``LOCK_GUARD_TAU_S`` of the period's fall, ``decel_ref``, from 0 at the stop's start,
        so only after ``LOCK_GUARD_SETTLE_S``), ``command`` asks for at most
        ``LOCK_GUARD_FRACTION`` of the demand; never below the minimum speed, where the full
        demand is the rule. The threshold is absolute, chosen on the Régiolis (its dry, wet and
        ``soap_etr1000`` stops traced read 0.99-1.04 m/s^2 at 15 km/h, its leaves and oil
        stops 0.29-0.82)."""
        self.guard_slipped |= self._slips(v_ref, v)
        self.guard_decel += (self.dt / LOCK_GUARD_TAU_S) * (self.decel_ref - self.guard_decel)
        self.guard_time_s += self.dt
        self.guard_on[...] = (
            self.guard_slipped
            & (v_ref < LOCK_GUARD_SPEED_KMH / 3.6)
            & (self.guard_decel < LOCK_GUARD_DECEL_MPS2)
            & (self.guard_time_s >= LOCK_GUARD_SETTLE_S - 1e-9)
        )

    def reference_mps(self, obs: np.ndarray) -> np.ndarray:
        """The reference speed (m/s, ``(n_envs,)``) the loop tracks the slip against on the
        kernel's observation ``obs``, on the state as ``advance`` left it: with the drift
        correction its corrected reference, else the estimator's, on the calibrated scale with
        the wheel-scale calibration (as ``command`` reads it)."""
        if self.drift_correction:
            return self.v_ref.copy()
        ref = obs[:, 4 * self.n_axles + 1].astype(np.float64)
        if self.scale_calibration:
            ref = ref * self.cal_ref_factor
        return ref * self.v_scale

    def command(self, obs: np.ndarray, target_kmh: np.ndarray) -> np.ndarray:
        """Valve actions ``(n_envs, n_valves)`` (float64 in [-1, 1], the continuous action
        space) that track ``target_kmh`` (``(n_envs, n_valves)``, km/h of measured slip) on the
        kernel's observation ``obs``, on the state as ``advance`` left it; its one write is
        whether the loop works (``working``: some axle's own request, before the periodic
        release's vents and the lock guard's cap, under the full demand), which the next
        ``advance`` reads, so calling
        it twice in a period with the same arguments changes nothing."""
        cfg, na = self.cfg, self.n_axles
        if self.scale_calibration:  # the scales ``advance`` read
            obs = self._calibrated(obs)
        v = obs[:, :na].astype(np.float64) * self.v_scale
        decel = obs[:, na : 2 * na].astype(np.float64) * self.a_scale
        pressure = obs[:, 3 * na : 4 * na].astype(np.float64)  # / p_max
        demand = obs[:, 4 * na].astype(np.float64)[:, None]  # / p_max
        # the estimator's reference, or with ``drift_correction`` the corrected one (``advance``)
        if self.drift_correction:
            v_ref = self.v_ref[:, None]
        else:
            v_ref = obs[:, 4 * na + 1].astype(np.float64)[:, None] * self.v_scale
        # the measured slip a lead ahead: its rate is the wheel's deceleration less the
        # reference's (``advance``), so a slip held on target has no lead term
        slip_ahead = (v_ref - v) + self.lead_s * (decel - self.decel_ref[:, None])  # m/s
        hold = np.where(demand > 1e-6, pressure / np.maximum(demand, 1e-6), 1.0)
        target = np.asarray(target_kmh, dtype=np.float64)[:, self.valve_of_axle]
        if self.max_creep > 0.0:  # at most max_creep of the reference speed, or the floor
            cap = np.maximum((3.6 * self.max_creep) * v_ref, self.creep_floor_kmh)
            target = np.minimum(target, cap)
        gain: float | np.ndarray = self.gain_per_kmh
        if self.gain_scale_floor < 1.0:  # scaled by the pressure held (module docstring)
            gain = self.gain_per_kmh * np.clip(hold, self.gain_scale_floor, 1.0)
        frac = hold + gain * (target - 3.6 * slip_ahead)
        frac = np.where(-decel > cfg.accel_hold_mps2, np.maximum(frac, hold), frac)
        frac = np.clip(frac, 0.0, 1.0)
        slow = v_ref[:, 0] < cfg.min_speed_kmh / 3.6
        self.working[...] = (frac < 1.0 - 1e-6).any(axis=1) & ~slow  # in place
        frac[self.vent] = 0.0
        frac[slow] = 1.0
        if self.lock_guard:  # at most the guard's share of the demand (``_guard``)
            guard = self.guard_on & ~slow
            frac[guard] = np.minimum(frac[guard], LOCK_GUARD_FRACTION)
        valve = np.minimum.reduceat(frac, self.valve_starts, axis=1)
        return 2.0 * valve - 1.0

    def act(self, obs: np.ndarray, target_kmh: np.ndarray) -> np.ndarray:
        """``advance`` then ``command``: one control period from outside an environment."""
        self.advance(obs)
        return self.command(obs, target_kmh)


def loop_suffix(loop: SlipTargetLoop) -> str:
    """What a policy's name adds for a loop whose settings are not the defaults:
    ``_<release>`` for the gate, ``_creep<x>`` for the cap (``_creep<x>at<floor>`` with another
    floor), ``_drift`` for the drift correction,
    ``_onset`` for its onset reading (``_onset2`` two-sided), ``_pgain<gain>x<floor>`` for a
    gain scaled by the pressure held, ``_gain<gain>`` for another fixed gain, ``_cal`` for the
    wheel-scale calibration, ``_guard`` for the lock guard
    (``""`` for the default loop), so that two loops never share a name."""
    gate = "" if loop.release == DEFAULT_RELEASE else f"_{loop.release}"
    floor = "" if loop.creep_floor_kmh == MAX_CREEP_FLOOR_KMH else f"at{loop.creep_floor_kmh:g}"
    cap = "" if loop.max_creep == DEFAULT_MAX_CREEP and not floor else f"_creep{loop.max_creep:g}"
    cap += floor
    scaled = ""
    if loop.gain_scale_floor != DEFAULT_GAIN_SCALE_FLOOR:
        scaled = f"_pgain{loop.gain_per_kmh:g}x{loop.gain_scale_floor:g}"
    elif loop.gain_per_kmh != DEFAULT_GAIN_PER_KMH:
        scaled = f"_gain{loop.gain_per_kmh:g}"
    drift = ("_drift" if loop.drift_correction else "") + ("_onset" if loop.onset_drift else "")
    drift += "2" if loop.onset_two_sided else ""  # the onset reading's both senses
    cal = "_cal" if loop.scale_calibration else ""
    guard = "_guard" if loop.lock_guard else ""
    return gate + cap + drift + scaled + cal + guard


class SlipTargetPolicy:
    """A constant target sliding speed on every valve, tracked by ``SlipTargetLoop``: a policy
    (``bind`` / ``reset`` / ``act``) for any continuous-action environment, reading the kernel's
    part of the observation. Without ``loop``, the environment's default loop on the bound
    core's tier's thresholds: bit for bit the slip-target mode holding that target."""

    privileged = False

    def __init__(self, target_kmh: float, loop: SlipTargetLoop | None = None) -> None:
        self.target_kmh = float(target_kmh)
        self.loop = loop or SlipTargetLoop()
        self.name = f"slip_target_{self.target_kmh:g}kmh{loop_suffix(self.loop)}"

    def bind(self, core: Any) -> None:
        self.loop.bind(core)
        self.width = core.kernel_obs_dim
        self.target = np.full((core.n_envs, core.n_valves), self.target_kmh)

    def reset(self, env_ids: np.ndarray) -> None:
        self.loop.reset(env_ids)

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self.loop.act(obs[:, : self.width], self.target)

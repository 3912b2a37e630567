"""The environment's compiled step: actions -> valves -> physics -> WSP reference speed ->
observation and reward terms, for every environment in one call (no Python per env).

Kept apart from ``braking.py`` (the core's Python side) so the hot path is one numba function.
Its arrays travel in two named bundles, in the spirit of gymnax's ``EnvParams`` / ``EnvState``:
:class:`Params` (what a stop is; fixed from reset to the end) and :class:`State` (what evolves).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit, prange

from wsp_env.physics.brake import demand_bar
from wsp_env.physics.integrator import INLINE_FLAGS, KERNEL_FLAGS, is_locked, step_env
from wsp_env.physics.layout import (
    AA_AIR_L,
    AA_SLIDE_E,
    AA_SLIDE_T,
    AP_P_THRESH,
    AP_RADIUS,
    AS_CMD,
    AS_MU_LEVEL,
    AS_OMEGA,
    AS_P,
    CMD_HOLD,
    EP_DEMAND_DELAY,
    EP_DEMAND_RISE,
    EP_GRADE_ACC,
    EP_P_MAX,
    ES_STOPPED,
    ES_T,
    ES_V,
    ES_X,
)


class Params(NamedTuple):
    """What each stop is, one row per environment (columns: ``physics.layout`` and the
    ``OP_`` / ``RP_`` indices below); fixed from ``reset`` until the stop ends."""

    valve_of_axle: np.ndarray  # (n_axles,) int: the valve each axle hangs on
    env_par: np.ndarray  # (n_envs, N_EP): vehicle, brake, rail and scenario per env
    axle_par: np.ndarray  # (n_envs, n_axles, N_AP): radius, inertia, loads, brake gains
    sections: np.ndarray  # (n_envs, MAX_SECTIONS, 3): the rail's adhesion sections
    obs_par: np.ndarray  # (N_OP,): observation scales and options, estimator, watchdog
    sensor_par: np.ndarray  # (n_envs, N_SP): the sensors' errors of each stop
    reward_par: np.ndarray  # (N_RP,): the reward's exchange rates


class State(NamedTuple):
    """What evolves (``physics.layout`` columns; the ``W_``, ``R_`` and ``F_`` indices below)."""

    cmd: np.ndarray  # (n_envs, n_axles): valve commands, fraction of demand or CMD_HOLD
    env_state: np.ndarray  # (n_envs, N_ES): time, position, speed, deceleration, stopped
    axle_state: np.ndarray  # (n_envs, n_axles, N_AS): wheel speed, pressure, forces, levels
    field: np.ndarray  # (n_envs, n_cells): the rail's contamination along the track
    env_acc: np.ndarray  # (n_envs, N_EA): accumulated energies
    axle_acc: np.ndarray  # (n_envs, n_axles, N_AA): sliding energy, air, slide times
    wsp: np.ndarray  # (n_envs, N_W): reference speed, accelerometer reading, watchdog
    axle_wsp: np.ndarray  # (n_envs, n_axles, N_AW): measured wheel speeds, timers
    rng: np.ndarray  # (n_envs,) uint64: each env's sensor-noise generator (``uniform``)
    prev_wheel: np.ndarray  # (n_envs, n_axles) m/s: measured wheel speeds at the period's start
    prev_action: np.ndarray  # (n_envs, n_valves): the last valve action, for the observation
    obs: np.ndarray  # (n_envs, obs_size) float32: the kernel's observation
    terms: np.ndarray  # (n_envs, N_TERMS): the last step's reward terms
    flags: np.ndarray  # (n_envs, N_F) int: terminated, truncated, clipped, NaN actions


# reward terms (columns of ``terms``); the reward is their sum; every term is a cost in metres
# of stopping distance divided by the distance scale (braking.RewardConfig gives the exchange rates)
R_DISTANCE = 0  # -dx: sums to -stopping_distance
R_DAMAGE = 1  # -(sum_i f(E_i)) increment, f(E) = m_per_MJ E (1 + E / E_ref), E_i per axle
R_LOCK = 2  # -lock_m_per_s * (number of locked axles) * dt
R_AIR = 3  # -air_m_per_100l * vented free-air litres / 100
# potential-based shaping (training option, off by default): gamma Phi(V') - Phi(V) with
# Phi(V) = -V^2 / (2 a0), the distance still to run at a0; over an episode it sums to -Phi(V0)
# (discounted: leaves the optimal policy unchanged, Ng, Harada & Russell 1999)
R_SHAPING = 4
# -slide_m_per_s * (axle-seconds sliding deeper than the slide threshold): the time the damage
# criterion "longest slide" judges (off by default)
R_SLIDE = 5
N_TERMS = 6

# reward parameters (``reward_par``)
RP_DISTANCE_SCALE = 0  # m: every term is divided by it
RP_DAMAGE_M_PER_MJ = 1  # m of stopping distance per MJ of sliding energy on one axle
RP_DAMAGE_REF_MJ = 2  # MJ per axle at which the damage cost has doubled (superlinear part)
RP_LOCK_M_PER_S = 3  # m per second one axle is locked
RP_AIR_M_PER_100L = 4  # m per 100 free-air litres vented
RP_SHAPING_DECEL = 5  # m/s^2: a0 of the shaping potential; 0 = no shaping
RP_SHAPING_GAMMA = 6  # the discount the shaping is written for (the learner's)
RP_SLIDE_M_PER_S = 7  # m per second one axle slides deeper than the slide threshold
N_RP = 8

# observation parameters (``obs_par``): scales, options, the shared reference-speed estimator
# (``update_reference``) and the safety watchdog (``watchdog``)
OP_SPEED_SCALE = 0  # m/s
OP_DECEL_SCALE = 1  # m/s^2
OP_REF_DECEL_LIMIT = 2  # m/s^2: the reference falls at most this fast (wheels only)
OP_REF_DECEL_ACTIVE = 3  # m/s^2: ... while the WSP works, before the first slope estimate
OP_MAX_TIME = 4  # s: truncation
OP_PRIVILEGED = 5  # 1.0: append true speed, friction level and true creepage
OP_ACCELEROMETER = 6  # 1.0: a body accelerometer aids the reference speed and is observed
OP_REF_DECEL_MIN = 7  # m/s^2: the adaptive slope's floor
OP_REF_ADAPT_MARGIN = 8  # the adaptive slope is this x the deceleration between two anchors
OP_FREE_ROLL_BAR = 9  # bar: a cylinder below this has its brake off
OP_FREE_ROLL_S = 10  # s: ... for this long, and a wheel no longer spinning up, rolls freely
OP_FREE_ROLL_ACCEL = 11  # m/s^2: "no longer spinning up"
OP_WD_ON = 12  # 1.0: the safety watchdog acts
OP_WD_SAFETY_S = 13  # s: an axle released longer than this gets the demand back to standstill
OP_WD_RELEASE_FRACTION = 14  # an axle counts as released below this fraction of the demand
OP_WD_MIN_DECEL = 15  # m/s^2: minimum-deceleration supervision's floor (0: off)
OP_WD_MIN_DECEL_S = 16  # s: ... for this long while the full demand stands: override
OP_WD_DECEL_TAU = 17  # s: time constant of the measured deceleration it supervises
OP_AGE_SCALE = 18  # s: the observed reference age is age / this
OP_ACTIVE_SLIP = 19  # m/s: a wheel this far below the reference counts as working ...
OP_ACTIVE_SLIP_REL = 20  # ... or this fraction of the reference, whichever is larger
OP_WD_GIVE_WAY_S = 21  # s: the override ends once every axle has been locked this long (0: never)
OP_FREE_ROLL_FILTER_S = 22  # s: the spin-up test's filter on the wheel's acceleration (0: none)
OP_ACC_OFFSET_GAIN = 23  # share of the accelerometer offset an anchor corrects (0: none)
N_OP = 24

# per-env sensor parameters (``sensor_par``; drawn per stop, or fixed by reset options)
SP_WHEEL_NOISE = 0  # m/s: standard deviation of a wheel-speed reading
SP_WHEEL_QUANTUM = 1  # m/s: the phonic wheel's speed resolution (0: exact)
SP_ACC_BIAS = 2  # m/s^2: the accelerometer's bias
SP_ACC_NOISE = 3  # m/s^2: standard deviation of an accelerometer reading
SP_ACC_LAG = 4  # s: the accelerometer's first-order lag (0: none)
N_SP = 5

# per-env WSP-side state (``wsp``)
W_VREF = 0  # m/s, reference speed estimate
W_ACC = 1  # m/s^2, the accelerometer's deceleration reading over the last period
W_SLOPE = 2  # m/s^2, the slope the reference falls at while the WSP works (wheels only)
W_ANCHOR_V = 3  # m/s, reference at the last anchor (NaN: none yet)
W_ANCHOR_T = 4  # s, time of the last anchor
W_AGE = 5  # s since the last anchor, counted once the WSP has acted since it
W_WORKED = 6  # 1.0: the WSP has acted since the last anchor
W_DECEL = 7  # m/s^2, the measured deceleration the watchdog supervises (filtered)
W_LOW_FOR = 8  # s the measured deceleration has stayed below the floor
W_OVERRIDE = 9  # 1.0 once the minimum-deceleration supervision has overridden the releases;
# 2.0 once that override has given way (every axle locked under it; no second trip)
W_SPEED_F = 10  # m/s, the fastest wheel's speed, filtered (the supervision's input)
W_LOCKED_FOR = 11  # s every axle has been locked while the override stands
W_ACC_CORR = 12  # m/s^2, the accelerometer offset the estimator has learned (added to W_ACC)
W_VACC = 13  # m/s, the speed dead-reckoned on the corrected accelerometer since the last anchor
N_W = 14

# per-axle sensor, estimator and watchdog state (``axle_wsp``)
AW_WHEEL = 0  # m/s, the measured wheel speed
AW_SCALE = 1  # the wheel-speed sensor's scale (1 + error, drawn per stop)
AW_RELEASED_FOR = 2  # s the cylinder has been below OP_FREE_ROLL_BAR
AW_WD_RELEASED_FOR = 3  # s the axle has been released (watchdog)
AW_WD_RESTORED = 4  # 1.0 once the watchdog has given the axle its demand back
AW_VENT_FOR = 5  # s the axle's valve has vented without a break
AW_VENT_MIN = 6  # m/s, the lowest reading since this vent began
AW_ACC_FILT = 7  # m/s^2, the wheel's acceleration, filtered over OP_FREE_ROLL_FILTER_S
N_AW = 8

OBS_CLIP = 5.0
# m/s^2, the largest accelerometer offset the estimator learns: the benchmark's bias (0.3) and
# gradient (25 per mille, 0.25) together reach 0.55; more is a fault, not an offset
ACC_CORR_MAX = 1.0
# the aided reference learns its offset only at an anchor this long (s) after the last: the
# sensor's lag at the brakes' onset is noise (``update_reference``)
ACC_LEARN_MIN_SPAN_S = 2.0
MODE_CONTINUOUS = 0
MODE_DISCRETE = 1

# flags (``flags``): terminated, truncated, number of clipped action components, bad action
F_TERMINATED = 0
F_TRUNCATED = 1
F_CLIPPED = 2
F_NAN = 3
N_F = 4

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_ONE = np.uint64(1)


def obs_size(n_axles: int, n_valves: int, privileged: bool, accelerometer: bool = False) -> int:
    """Length of one observation (see ``write_obs``)."""
    extra = (1 + 2 * n_axles) if privileged else 0
    return 4 * n_axles + 2 + n_valves + extra + (1 if accelerometer else 0) + 1


@njit(**INLINE_FLAGS)
def damage_cost(sliding_energy_J, reward_par):
    """Cost in metres of one axle's cumulative sliding energy: superlinear, so that a slide
    concentrated on one wheel (a flat) costs more than the same energy spread over several."""
    e_mj = sliding_energy_J * 1e-6
    return reward_par[RP_DAMAGE_M_PER_MJ] * e_mj * (1.0 + e_mj / reward_par[RP_DAMAGE_REF_MJ])


@njit(**INLINE_FLAGS)
def _clip(x):
    return min(OBS_CLIP, max(-OBS_CLIP, x))


@njit(**INLINE_FLAGS)
def uniform(rng, e):
    """A uniform number in (0, 1] from env ``e``'s sensor generator (splitmix64: a counter-based
    stream per env, seeded at reset from the env's seeded generator; no shared state, so the
    parallel step draws the same numbers as the serial one)."""
    s = rng[e] + _GOLDEN
    rng[e] = s
    z = (s ^ (s >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    z = z ^ (z >> _S31)
    return float((z >> _S11) + _ONE) * (1.0 / 9007199254740992.0)


@njit(**INLINE_FLAGS)
def gaussian(rng, e):
    """A standard normal number (Box-Muller on two ``uniform`` draws)."""
    u1 = uniform(rng, e)
    u2 = uniform(rng, e)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@njit(**INLINE_FLAGS)
def measure_wheel(e, k, true_mps, sensor_par, axle_wsp, rng):
    """One wheel-speed reading: the sensor's scale error, Gaussian noise, and the phonic
    wheel's resolution (the reading is a multiple of it), never below zero."""
    v = true_mps * axle_wsp[e, k, AW_SCALE]
    sigma = sensor_par[e, SP_WHEEL_NOISE]
    if sigma > 0.0:
        v += sigma * gaussian(rng, e)
    q = sensor_par[e, SP_WHEEL_QUANTUM]
    if q > 0.0:
        v = q * math.floor(v / q + 0.5)
    return max(v, 0.0)


@njit(**INLINE_FLAGS)
def measure_acceleration(e, train_decel, env_par, sensor_par, wsp, rng, ctrl_dt):
    """The body accelerometer's deceleration reading over the last period: a specific-force
    sensor, so it misses the gradient's ``g sin(theta)`` (uphill it reads less deceleration than
    the train has), plus its bias and noise, through its first-order lag."""
    a = train_decel - env_par[e, EP_GRADE_ACC] + sensor_par[e, SP_ACC_BIAS]
    sigma = sensor_par[e, SP_ACC_NOISE]
    if sigma > 0.0:
        a += sigma * gaussian(rng, e)
    tau = sensor_par[e, SP_ACC_LAG]
    if tau > 0.0:
        a = wsp[e, W_ACC] + (a - wsp[e, W_ACC]) * (1.0 - math.exp(-ctrl_dt / tau))
    wsp[e, W_ACC] = a


@njit(**INLINE_FLAGS)
def update_reference(
    e, t, demand, active, cmd, axle_par, axle_state, prev_wheel, wsp, axle_wsp, obs_par, dt
):
    """The WSP's reference speed after one period — one estimator for every controller.

    The measured wheel speeds are ``AW_WHEEL`` (``prev_wheel``: at the period's start, for
    their decelerations), the cylinder pressures ``axle_state[..., AS_P]``, ``cmd`` the
    period's valve commands;
    ``pressure``: cylinder pressures (bar), ``free_bar``: per axle, the pressure below which its
    brake is off (``OP_FREE_ROLL_BAR``, or the brake's threshold where higher), ``vented``: the
    axle's valve vented in the period,
    ``demand``: the demand (bar), ``active``: the WSP works (a valve out of
    apply, or a wheel slipping more than ``OP_ACTIVE_SLIP`` / ``OP_ACTIVE_SLIP_REL``, at the
    period's start). It follows the fastest wheel; when every wheel may slide it must not
    follow them down: without an accelerometer it falls at most at ``OP_REF_DECEL_LIMIT``, and
    while the WSP works at an adaptive slope (``OP_REF_ADAPT_MARGIN`` x the deceleration between
    two anchors, within ``[OP_REF_DECEL_MIN, OP_REF_DECEL_LIMIT]``); with an accelerometer at
    the deceleration it reads (``W_ACC``: gradient, bias, noise and lag included) corrected by
    the offset it has learned (``W_ACC_CORR``: at each anchor at least 2 s after the last, the
    speed dead-reckoned on the corrected reading since then, ``W_VACC``, missed the anchor by
    some m/s a second; ``OP_ACC_OFFSET_GAIN`` of that is added, within ``ACC_CORR_MAX``: an
    integral observer of a constant offset). **Anchors**,
    both ways: a wheel whose cylinder has been below ``OP_FREE_ROLL_BAR`` for
    ``OP_FREE_ROLL_S`` and which no longer spins up (its acceleration filtered over
    ``OP_FREE_ROLL_FILTER_S`` below ``OP_FREE_ROLL_ACCEL``) rolls with the train, and the
    reference is set to it, up or down (the periodic release is how a WSP makes one). A wheel
    slowing faster than ``OP_REF_DECEL_LIMIT`` (faster than any train) is not free."""
    n_axles = axle_wsp.shape[1]
    fastest = 0.0
    for k in range(n_axles):
        fastest = max(fastest, axle_wsp[e, k, AW_WHEEL])
    v_ref = wsp[e, W_VREF]
    aided = obs_par[OP_ACCELEROMETER] > 0.0
    if aided:
        acc = wsp[e, W_ACC] + wsp[e, W_ACC_CORR]
        wsp[e, W_VACC] = max(wsp[e, W_VACC] - acc * dt, 0.0)
        fall = min(max(acc, 0.0), 2.0 * obs_par[OP_REF_DECEL_LIMIT])
    elif active:
        fall = wsp[e, W_SLOPE]
    else:
        fall = obs_par[OP_REF_DECEL_LIMIT]
    v_ref = max(fastest, v_ref - fall * dt)
    # anchors: a wheel rolling freely with the train
    anchor = -1.0
    v_ref_old = wsp[e, W_VREF]
    band = max(obs_par[OP_ACTIVE_SLIP], obs_par[OP_ACTIVE_SLIP_REL] * v_ref_old)
    for k in range(n_axles):
        wheel = axle_wsp[e, k, AW_WHEEL]
        decel = (prev_wheel[e, k] - wheel) / dt
        # the brake is off below its threshold (or 0.1 bar); a vent targets a pressure there
        # (a hold, CMD_HOLD < 0, is none)
        free_bar = max(obs_par[OP_FREE_ROLL_BAR], axle_par[e, k, AP_P_THRESH])
        vented = cmd[e, k] >= 0.0 and demand > free_bar and cmd[e, k] * demand < free_bar
        if axle_state[e, k, AS_P] < free_bar:
            axle_wsp[e, k, AW_RELEASED_FOR] += dt
        else:
            axle_wsp[e, k, AW_RELEASED_FOR] = 0.0
        if vented:
            if axle_wsp[e, k, AW_VENT_FOR] == 0.0:  # a vent begins
                axle_wsp[e, k, AW_VENT_MIN] = wheel
            axle_wsp[e, k, AW_VENT_FOR] += dt
            axle_wsp[e, k, AW_VENT_MIN] = min(axle_wsp[e, k, AW_VENT_MIN], wheel)
        else:
            axle_wsp[e, k, AW_VENT_FOR] = 0.0
        # spun up: risen by more than the working band above its lowest reading of the vent
        # (lasting evidence: a wheel-speed sensor's noise is far below the band)
        spun_up = wheel - axle_wsp[e, k, AW_VENT_MIN] > band
        off = axle_wsp[e, k, AW_RELEASED_FOR] >= obs_par[OP_FREE_ROLL_S] - 1e-9 or (
            axle_wsp[e, k, AW_VENT_FOR] >= obs_par[OP_FREE_ROLL_S] - 1e-9 and spun_up
        )
        # no longer spinning up (its acceleration filtered over OP_FREE_ROLL_FILTER_S: one
        # 20 ms reading of a wheel spinning up slowly on leaves can pass), nor slowing faster
        # than any train decelerates
        tau = obs_par[OP_FREE_ROLL_FILTER_S]
        if tau <= dt:  # one reading, exactly (-v1, -v2)
            axle_wsp[e, k, AW_ACC_FILT] = -decel
        else:
            axle_wsp[e, k, AW_ACC_FILT] += (-decel - axle_wsp[e, k, AW_ACC_FILT]) * (dt / tau)
        free = (
            off
            and axle_wsp[e, k, AW_ACC_FILT] < obs_par[OP_FREE_ROLL_ACCEL]
            and decel < obs_par[OP_REF_DECEL_LIMIT]
        )
        if free:
            anchor = max(anchor, wheel)
    if anchor >= 0.0 and active and demand > 0.0:
        span = t - wsp[e, W_ANCHOR_T]
        if not math.isnan(wsp[e, W_ANCHOR_V]) and span > 1.0:
            est = (wsp[e, W_ANCHOR_V] - anchor) / span
            wsp[e, W_SLOPE] = min(
                max(obs_par[OP_REF_ADAPT_MARGIN] * est, obs_par[OP_REF_DECEL_MIN]),
                obs_par[OP_REF_DECEL_LIMIT],
            )
        if aided:
            # the accelerometer's offset (bias, and the gradient a specific-force sensor reads)
            # made the dead-reckoned speed miss the anchor by this much a second; a share of it
            # is learned (over at least 2 s: the sensor's lag at the brakes' onset is noise)
            # (``span``: since the last anchor, or the stop's start before the first)
            if span >= ACC_LEARN_MIN_SPAN_S and obs_par[OP_ACC_OFFSET_GAIN] > 0.0:
                miss = (wsp[e, W_VACC] - anchor) / span
                corr = wsp[e, W_ACC_CORR] + obs_par[OP_ACC_OFFSET_GAIN] * miss
                wsp[e, W_ACC_CORR] = min(max(corr, -ACC_CORR_MAX), ACC_CORR_MAX)
            wsp[e, W_VACC] = anchor
        v_ref = anchor
        wsp[e, W_ANCHOR_V] = anchor
        wsp[e, W_ANCHOR_T] = t
        wsp[e, W_AGE] = 0.0
        wsp[e, W_WORKED] = 0.0
    else:
        if active:
            wsp[e, W_WORKED] = 1.0
        if wsp[e, W_WORKED] > 0.0:
            wsp[e, W_AGE] += dt
        else:
            wsp[e, W_AGE] = 0.0
    wsp[e, W_VREF] = v_ref


@njit(**INLINE_FLAGS)
def watchdog_commands(e, cmd, wsp, axle_wsp, obs_par):
    """The safety watchdog's say over this period's valve commands: an axle it has restored,
    or every axle while the minimum-deceleration supervision's override stands, gets the full
    demand (until standstill, or until the override gives way), whatever the controller
    asked."""
    if obs_par[OP_WD_ON] <= 0.0:
        return
    for k in range(cmd.shape[1]):
        if axle_wsp[e, k, AW_WD_RESTORED] > 0.0 or wsp[e, W_OVERRIDE] == 1.0:
            cmd[e, k] = 1.0


@njit(**INLINE_FLAGS)
def watchdog_update(e, cmd, axle_state, demand, full_demand, env_par, wsp, axle_wsp, obs_par, dt):
    """Advance the watchdog's timers after a period (EN 15595's WSP watchdog and a
    minimum-deceleration supervision, outside the controller).

    **Safety time**: an axle released — its valve asking for less than
    ``OP_WD_RELEASE_FRACTION`` of the demand (a vent), or its cylinder below that fraction of the
    full pressure (its brake off, however the valve got it there) — for longer than
    ``OP_WD_SAFETY_S`` is restored. A hold at a pressure that brakes is no release.
    **Minimum deceleration**: the deceleration of the fastest wheel, filtered twice (speed,
    then its derivative, ``OP_WD_DECEL_TAU`` each: a wheel-speed sensor's noise is gone, a trend
    of 0.1 m/s^2 is not), less the gradient's part (``EP_GRADE_ACC``: the supervision judges
    what the brakes do, so a steep downhill on leaves does not trip it), below
    ``OP_WD_MIN_DECEL`` for ``OP_WD_MIN_DECEL_S`` while the full demand stands and every wheel
    grips (all within the estimator's working band of the fastest, so the fastest wheel is the
    train) overrides every release: the brakes are being withheld, not the rail giving out.
    **Giving way** (``OP_WD_GIVE_WAY_S``): once every axle's measured speed has been locked
    (``integrator.is_locked``) against the shared reference for that long while the override
    stands (long enough that the wheels' last readings at standstill, under a reference that
    lags them, are not taken for a lock), the full demand has shown that the rail, not the
    controller, was the limit — every axle sliding together at a rail's limit looks like grip
    on the wheels alone — and on such a rail locked wheels brake worse than any WSP (on a steep
    downhill they run away). The override ends and does not trip again in the stop; the safety
    time still stands."""
    if obs_par[OP_WD_ON] <= 0.0:
        return
    n_axles = axle_wsp.shape[1]
    low = obs_par[OP_WD_RELEASE_FRACTION]
    for k in range(n_axles):
        vent = 0.0 <= cmd[e, k] < low
        off = axle_state[e, k, AS_P] < low * env_par[e, EP_P_MAX]
        if demand > 0.0 and (vent or off):
            axle_wsp[e, k, AW_WD_RELEASED_FOR] += dt
        else:
            axle_wsp[e, k, AW_WD_RELEASED_FOR] = 0.0
        if axle_wsp[e, k, AW_WD_RELEASED_FOR] > obs_par[OP_WD_SAFETY_S]:
            axle_wsp[e, k, AW_WD_RESTORED] = 1.0
    floor = obs_par[OP_WD_MIN_DECEL]
    if floor <= 0.0:
        return
    fastest = 0.0
    for k in range(n_axles):
        fastest = max(fastest, axle_wsp[e, k, AW_WHEEL])
    gain = min(1.0, dt / obs_par[OP_WD_DECEL_TAU])
    speed_old = wsp[e, W_SPEED_F]
    wsp[e, W_SPEED_F] += (fastest - speed_old) * gain
    measured = (speed_old - wsp[e, W_SPEED_F]) / dt
    wsp[e, W_DECEL] += (measured - wsp[e, W_DECEL]) * gain
    # every wheel grips: all within the working band of the fastest (judged on the wheels
    # alone: a reference drifted above the train would make gripping wheels look slipping)
    band = max(obs_par[OP_ACTIVE_SLIP], obs_par[OP_ACTIVE_SLIP_REL] * fastest)
    grip = True
    for k in range(n_axles):
        if fastest - axle_wsp[e, k, AW_WHEEL] > band:
            grip = False
    braking = wsp[e, W_DECEL] - env_par[e, EP_GRADE_ACC]  # what the brakes (and drag) do
    if full_demand and grip and fastest > 1.5 and braking < floor:
        wsp[e, W_LOW_FOR] += dt
    else:
        wsp[e, W_LOW_FOR] = 0.0
    if wsp[e, W_LOW_FOR] > obs_par[OP_WD_MIN_DECEL_S] and wsp[e, W_OVERRIDE] == 0.0:
        wsp[e, W_OVERRIDE] = 1.0
    elif wsp[e, W_OVERRIDE] == 1.0 and obs_par[OP_WD_GIVE_WAY_S] > 0.0:
        v_ref = wsp[e, W_VREF]
        every_axle_locked = True
        for k in range(n_axles):
            if not is_locked(axle_wsp[e, k, AW_WHEEL], v_ref):
                every_axle_locked = False
        wsp[e, W_LOCKED_FOR] = wsp[e, W_LOCKED_FOR] + dt if every_axle_locked else 0.0
        if wsp[e, W_LOCKED_FOR] > obs_par[OP_WD_GIVE_WAY_S]:
            wsp[e, W_OVERRIDE] = 2.0


@njit(**KERNEL_FLAGS)
def write_obs(
    e,
    env_par,
    axle_par,
    env_state,
    axle_state,
    wsp,
    axle_wsp,
    prev_wheel,
    prev_action,
    obs_par,
    ctrl_dt,
    obs,
):
    """Observation of env ``e``: what a WSP measures, normalised to about [-1, 1].

    ``[v_axle_i / v_s]``, ``[axle deceleration_i / a_s]``, ``[(v_ref - v_axle_i) / max(v_ref, 1)]``,
    ``[p_i / p_max]``, ``p_demand / p_max``, ``v_ref / v_s``, ``[previous action]``, with
    ``privileged``: ``V / v_s``, ``[friction level_i]``, ``[(V - v_axle_i) / max(V, 1)]``, with
    ``accelerometer``: the body accelerometer's deceleration reading ``/ a_s``, and last the
    reference's age (s since its last anchor) ``/ OP_AGE_SCALE``. Wheel speeds are the sensors'
    readings (``measure_wheel``), ``v_ref`` the shared estimator's (``update_reference``).
    """
    n_axles = axle_par.shape[1]
    n_valves = prev_action.shape[1]
    v_s = obs_par[OP_SPEED_SCALE]
    a_s = obs_par[OP_DECEL_SCALE]
    p_max = env_par[e, EP_P_MAX]
    v_ref = wsp[e, W_VREF]
    inv_ref = 1.0 / max(v_ref, 1.0)
    for k in range(n_axles):
        wheel = axle_wsp[e, k, AW_WHEEL]
        obs[e, k] = wheel / v_s
        obs[e, n_axles + k] = _clip((prev_wheel[e, k] - wheel) / ctrl_dt / a_s)
        obs[e, 2 * n_axles + k] = _clip((v_ref - wheel) * inv_ref)
        obs[e, 3 * n_axles + k] = axle_state[e, k, AS_P] / p_max
    base = 4 * n_axles
    obs[e, base] = demand_bar(env_par, e, env_state[e, ES_T]) / p_max
    obs[e, base + 1] = v_ref / v_s
    for j in range(n_valves):
        obs[e, base + 2 + j] = prev_action[e, j]
    if obs_par[OP_PRIVILEGED] > 0.0:
        base = base + 2 + n_valves
        v = env_state[e, ES_V]
        obs[e, base] = v / v_s
        inv_v = 1.0 / max(v, 1.0)
        for k in range(n_axles):
            true_wheel = axle_state[e, k, AS_OMEGA] * axle_par[e, k, AP_RADIUS]
            obs[e, base + 1 + k] = axle_state[e, k, AS_MU_LEVEL]
            obs[e, base + 1 + n_axles + k] = _clip((v - true_wheel) * inv_v)
    last = obs.shape[1] - 1
    if obs_par[OP_ACCELEROMETER] > 0.0:
        obs[e, last - 1] = _clip(wsp[e, W_ACC] / a_s)
    obs[e, last] = _clip(wsp[e, W_AGE] / obs_par[OP_AGE_SCALE])


@njit(**KERNEL_FLAGS)
def reset_obs(
    e,
    env_par,
    axle_par,
    env_state,
    axle_state,
    wsp,
    axle_wsp,
    prev_wheel,
    prev_action,
    obs_par,
    ctrl_dt,
    obs,
    sensor_par,
    rng,
):
    """Reset the WSP-side state of env ``e`` after ``TrainSim.reset`` (its sensor parameters
    and generator set by the caller) and write its observation: the sensors' first readings,
    the reference at the fastest wheel, the watchdog's timers at zero."""
    for k in range(axle_par.shape[1]):
        true_wheel = axle_state[e, k, AS_OMEGA] * axle_par[e, k, AP_RADIUS]
        axle_wsp[e, k, AW_WHEEL] = measure_wheel(e, k, true_wheel, sensor_par, axle_wsp, rng)
        prev_wheel[e, k] = axle_wsp[e, k, AW_WHEEL]
        axle_wsp[e, k, AW_RELEASED_FOR] = 0.0
        axle_wsp[e, k, AW_WD_RELEASED_FOR] = 0.0
        axle_wsp[e, k, AW_WD_RESTORED] = 0.0
        axle_wsp[e, k, AW_VENT_FOR] = 0.0
        axle_wsp[e, k, AW_VENT_MIN] = 0.0
        axle_wsp[e, k, AW_ACC_FILT] = 0.0
    fastest = 0.0
    for k in range(axle_par.shape[1]):
        fastest = max(fastest, axle_wsp[e, k, AW_WHEEL])
    wsp[e, W_VREF] = fastest
    wsp[e, W_ACC] = 0.0
    wsp[e, W_SLOPE] = obs_par[OP_REF_DECEL_ACTIVE]
    wsp[e, W_ANCHOR_V] = np.nan
    wsp[e, W_ANCHOR_T] = 0.0
    wsp[e, W_AGE] = 0.0
    wsp[e, W_WORKED] = 0.0
    wsp[e, W_DECEL] = 0.0
    wsp[e, W_LOW_FOR] = 0.0
    wsp[e, W_OVERRIDE] = 0.0
    wsp[e, W_LOCKED_FOR] = 0.0
    wsp[e, W_SPEED_F] = fastest
    wsp[e, W_ACC_CORR] = 0.0
    wsp[e, W_VACC] = fastest
    for j in range(prev_action.shape[1]):
        prev_action[e, j] = 1.0
    write_obs(
        e, env_par, axle_par, env_state, axle_state, wsp, axle_wsp, prev_wheel, prev_action,
        obs_par, ctrl_dt, obs,
    )  # fmt: skip


@njit(**KERNEL_FLAGS)
def estimate_and_supervise(
    e,
    t,
    cmd,
    env_par,
    axle_par,
    axle_state,
    wsp,
    axle_wsp,
    prev_wheel,
    prev_action,
    obs_par,
    ctrl_dt,
    mode,
):
    """After a period, from the sensors' readings (``AW_WHEEL``, ``W_ACC``) and the cylinder
    pressures (``axle_state[..., AS_P]``): the reference speed and the watchdog's timers. One
    implementation for the kernel and for a vehicle outside it (the rig,
    ``BrakingCore.observe_external``); ``cmd``: the valve commands of the period. Nothing is
    allocated: it runs per env and period in the hot path."""
    # the WSP works: a valve was out of apply in the period, or a wheel slipped at its start
    active = False
    for j in range(prev_action.shape[1]):
        if prev_action[e, j] < (1.0 if mode == MODE_DISCRETE else 1.0 - 1e-6):
            active = True
    v_ref_old = wsp[e, W_VREF]
    slip_min = max(obs_par[OP_ACTIVE_SLIP], obs_par[OP_ACTIVE_SLIP_REL] * v_ref_old)
    for k in range(axle_wsp.shape[1]):
        if v_ref_old - prev_wheel[e, k] > slip_min:
            active = True
    demand = demand_bar(env_par, e, t)
    update_reference(
        e, t, demand, active, cmd, axle_par, axle_state, prev_wheel, wsp, axle_wsp, obs_par,
        ctrl_dt,
    )  # fmt: skip
    full = t >= env_par[e, EP_DEMAND_DELAY] + env_par[e, EP_DEMAND_RISE]
    watchdog_update(e, cmd, axle_state, demand, full, env_par, wsp, axle_wsp, obs_par, ctrl_dt)


@njit(**KERNEL_FLAGS)
def sense_and_estimate(
    e,
    t,
    train_decel,
    cmd,
    env_par,
    axle_par,
    axle_state,
    wsp,
    axle_wsp,
    prev_wheel,
    prev_action,
    obs_par,
    sensor_par,
    rng,
    ctrl_dt,
    mode,
):
    """After a period of physics: the sensors read the simulated vehicle, then
    ``estimate_and_supervise``."""
    for k in range(axle_par.shape[1]):
        true_wheel = axle_state[e, k, AS_OMEGA] * axle_par[e, k, AP_RADIUS]
        axle_wsp[e, k, AW_WHEEL] = measure_wheel(e, k, true_wheel, sensor_par, axle_wsp, rng)
    if obs_par[OP_ACCELEROMETER] > 0.0:
        measure_acceleration(e, train_decel, env_par, sensor_par, wsp, rng, ctrl_dt)
    estimate_and_supervise(
        e, t, cmd, env_par, axle_par, axle_state, wsp, axle_wsp, prev_wheel, prev_action,
        obs_par, ctrl_dt, mode,
    )  # fmt: skip


@njit(**KERNEL_FLAGS)
def env_step_one(
    e,
    mode,
    actions,
    valve_of_axle,
    n_sub,
    dt,
    ctrl_dt,
    cmd,
    env_par,
    axle_par,
    sections,
    env_state,
    axle_state,
    field,
    env_acc,
    axle_acc,
    wsp,
    axle_wsp,
    sensor_par,
    rng,
    prev_wheel,
    prev_action,
    obs_par,
    reward_par,
    obs,
    terms,
    flags,
):
    n_axles = axle_par.shape[1]
    n_valves = actions.shape[1]
    clipped = 0
    bad = 0
    for j in range(n_valves):
        a = actions[e, j]
        if mode == MODE_CONTINUOUS:
            if math.isnan(a):
                bad += 1
                a = 1.0
            elif a > 1.0 or a < -1.0:
                clipped += 1
                a = min(1.0, max(-1.0, a))
        elif not (a == 0.0 or a == 1.0 or a == 2.0):
            bad += 1
            a = 2.0
        prev_action[e, j] = a if mode == MODE_CONTINUOUS else a - 1.0
    for k in range(n_axles):
        a = actions[e, valve_of_axle[k]]
        axle_state[e, k, AS_CMD] = cmd[e, k]  # acts during the valve dead time
        if mode == MODE_CONTINUOUS:
            a = 1.0 if math.isnan(a) else min(1.0, max(-1.0, a))
            cmd[e, k] = 0.5 * (a + 1.0)
        else:
            cmd[e, k] = 0.0 if a == 0.0 else (CMD_HOLD if a == 1.0 else 1.0)
    watchdog_commands(e, cmd, wsp, axle_wsp, obs_par)
    flags[e, F_CLIPPED] = clipped
    flags[e, F_NAN] = bad
    x0 = env_state[e, ES_X]
    v0 = env_state[e, ES_V]
    damage0 = 0.0
    air0 = 0.0
    slide0 = 0.0
    for k in range(n_axles):
        prev_wheel[e, k] = axle_wsp[e, k, AW_WHEEL]
        damage0 += damage_cost(axle_acc[e, k, AA_SLIDE_E], reward_par)
        air0 += axle_acc[e, k, AA_AIR_L]
        slide0 += axle_acc[e, k, AA_SLIDE_T]
    step_env(
        e,
        n_sub,
        dt,
        cmd,
        env_par,
        axle_par,
        sections,
        env_state,
        axle_state,
        field,
        env_acc,
        axle_acc,
    )
    # --- sensors, the shared reference speed, the watchdog ----------------------------------
    train_decel = (v0 - env_state[e, ES_V]) / ctrl_dt
    sense_and_estimate(
        e, env_state[e, ES_T], train_decel, cmd, env_par, axle_par, axle_state, wsp, axle_wsp,
        prev_wheel, prev_action, obs_par, sensor_par, rng, ctrl_dt, mode,
    )  # fmt: skip
    # --- reward terms (costs in metres of stopping distance) -------------------------------------
    v = env_state[e, ES_V]
    locked = 0.0
    damage1 = 0.0
    air1 = 0.0
    slide1 = 0.0
    for k in range(n_axles):
        if is_locked(axle_state[e, k, AS_OMEGA] * axle_par[e, k, AP_RADIUS], v):
            locked += 1.0
        damage1 += damage_cost(axle_acc[e, k, AA_SLIDE_E], reward_par)
        air1 += axle_acc[e, k, AA_AIR_L]
        slide1 += axle_acc[e, k, AA_SLIDE_T]
    inv_scale = 1.0 / reward_par[RP_DISTANCE_SCALE]
    terms[e, R_DISTANCE] = -(env_state[e, ES_X] - x0) * inv_scale
    terms[e, R_DAMAGE] = -(damage1 - damage0) * inv_scale
    terms[e, R_LOCK] = -reward_par[RP_LOCK_M_PER_S] * locked * ctrl_dt * inv_scale
    terms[e, R_AIR] = -reward_par[RP_AIR_M_PER_100L] * (air1 - air0) * 0.01 * inv_scale
    terms[e, R_SLIDE] = -reward_par[RP_SLIDE_M_PER_S] * (slide1 - slide0) * inv_scale
    a0 = reward_par[RP_SHAPING_DECEL]
    if a0 > 0.0:
        phi0 = -v0 * v0 / (2.0 * a0)
        phi1 = -v * v / (2.0 * a0) if env_state[e, ES_STOPPED] == 0.0 else 0.0
        terms[e, R_SHAPING] = (reward_par[RP_SHAPING_GAMMA] * phi1 - phi0) * inv_scale
    else:
        terms[e, R_SHAPING] = 0.0
    flags[e, F_TERMINATED] = 1 if env_state[e, ES_STOPPED] > 0.0 else 0
    flags[e, F_TRUNCATED] = (
        1 if flags[e, F_TERMINATED] == 0 and env_state[e, ES_T] >= obs_par[OP_MAX_TIME] else 0
    )
    write_obs(
        e, env_par, axle_par, env_state, axle_state, wsp, axle_wsp, prev_wheel, prev_action,
        obs_par, ctrl_dt, obs,
    )  # fmt: skip


ARG_ENV_PAR = 7  # position of env_par in the entry points' arguments


# One signature for both entry points (the arguments of ``env_step_one`` after ``e``); the
# serial and ``prange`` variants are separate functions so that each gets its own cache entry.
@njit(**KERNEL_FLAGS)
def env_step_serial(*args):
    for e in range(args[ARG_ENV_PAR].shape[0]):
        env_step_one(e, *args)


@njit(parallel=True, **KERNEL_FLAGS)
def env_step_parallel(*args):
    for e in prange(args[ARG_ENV_PAR].shape[0]):
        # prange's index is unsigned: as int64 the callees' compiled code is the serial
        # path's, not a second specialisation of the whole call tree
        env_step_one(np.int64(e), *args)


def step_args(
    n_sub: int, dt_s: float, control_period_s: float, p: Params, s: State
) -> tuple[Any, ...]:
    """The compiled entry points' arguments after ``(mode, actions)``, in their order: built
    once per core (the arrays are updated in place), so that a step unpacks one tuple."""
    return (
        p.valve_of_axle, n_sub, dt_s, control_period_s, s.cmd, p.env_par, p.axle_par,
        p.sections, s.env_state, s.axle_state, s.field, s.env_acc, s.axle_acc, s.wsp,
        s.axle_wsp, p.sensor_par, s.rng, s.prev_wheel, s.prev_action, p.obs_par, p.reward_par,
        s.obs, s.terms, s.flags,
    )  # fmt: skip


def reset_observation(e: int, p: Params, s: State, control_period_s: float) -> None:
    """``reset_obs`` on the bundles: env ``e``'s WSP state after ``TrainSim.reset``."""
    reset_obs(
        e, p.env_par, p.axle_par, s.env_state, s.axle_state, s.wsp, s.axle_wsp, s.prev_wheel,
        s.prev_action, p.obs_par, control_period_s, s.obs, p.sensor_par, s.rng,
    )  # fmt: skip


def write_observation(e: int, p: Params, s: State, control_period_s: float) -> None:
    """``write_obs`` on the bundles: env ``e``'s observation from its state."""
    write_obs(
        e, p.env_par, p.axle_par, s.env_state, s.axle_state, s.wsp, s.axle_wsp, s.prev_wheel,
        s.prev_action, p.obs_par, control_period_s, s.obs,
    )  # fmt: skip


def estimate_external(
    e: int, t_s: float, p: Params, s: State, control_period_s: float, mode: int
) -> None:
    """``estimate_and_supervise`` on the bundles, for readings written from outside the kernel
    (``AW_WHEEL`` and ``axle_state``'s pressures: a rig's)."""
    estimate_and_supervise(
        e, t_s, s.cmd, p.env_par, p.axle_par, s.axle_state, s.wsp, s.axle_wsp, s.prev_wheel,
        s.prev_action, p.obs_par, control_period_s, mode,
    )  # fmt: skip

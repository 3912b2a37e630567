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
    AP_RADIUS,
    AS_CMD,
    AS_MU_LEVEL,
    AS_OMEGA,
    AS_P,
    CMD_HOLD,
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
    obs_par: np.ndarray  # (N_OP,): observation scales and options
    reward_par: np.ndarray  # (N_RP,): the reward's exchange rates


class State(NamedTuple):
    """What evolves (``physics.layout`` columns; the ``W_``, ``R_`` and ``F_`` indices below)."""

    cmd: np.ndarray  # (n_envs, n_axles): valve commands, fraction of demand or CMD_HOLD
    env_state: np.ndarray  # (n_envs, N_ES): time, position, speed, deceleration, stopped
    axle_state: np.ndarray  # (n_envs, n_axles, N_AS): wheel speed, pressure, forces, levels
    field: np.ndarray  # (n_envs, n_cells): the rail's contamination along the track
    env_acc: np.ndarray  # (n_envs, N_EA): accumulated energies
    axle_acc: np.ndarray  # (n_envs, n_axles, N_AA): sliding energy, air, slide times
    wsp: np.ndarray  # (n_envs, N_W): reference speed, accelerometer reading and bias
    prev_wheel: np.ndarray  # (n_envs, n_axles) m/s: wheel speeds at the last period's start
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

# observation parameters (``obs_par``)
OP_SPEED_SCALE = 0  # m/s
OP_DECEL_SCALE = 1  # m/s^2
OP_REF_DECEL_LIMIT = 2  # m/s^2: the reference speed may fall at most this fast
OP_REF_RISE_LIMIT = 3  # m/s^2: ... and rise at most this fast
OP_MAX_TIME = 4  # s: truncation
OP_PRIVILEGED = 5  # 1.0: append true speed, friction level and true creepage
OP_ACCELEROMETER = 6  # 1.0: a body accelerometer aids the reference speed and is observed
N_OP = 7

# per-env WSP-side state (``wsp``)
W_VREF = 0  # m/s, reference speed estimate
W_ACC = 1  # m/s^2, the accelerometer's deceleration reading over the last period
W_ACC_BIAS = 2  # m/s^2, its bias (drawn per episode)
N_W = 3

OBS_CLIP = 5.0
MODE_CONTINUOUS = 0
MODE_DISCRETE = 1

# flags (``flags``): terminated, truncated, number of clipped action components, bad action
F_TERMINATED = 0
F_TRUNCATED = 1
F_CLIPPED = 2
F_NAN = 3
N_F = 4


def obs_size(n_axles: int, n_valves: int, privileged: bool, accelerometer: bool = False) -> int:
    """Length of one observation (see ``write_obs``)."""
    extra = (1 + 2 * n_axles) if privileged else 0
    return 4 * n_axles + 2 + n_valves + extra + (1 if accelerometer else 0)


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
def update_reference(e, wsp, fastest, train_decel, env_par, obs_par, ctrl_dt):
    """The WSP's reference speed after one period: the fastest wheel, falling at most at the
    deceleration limit, or with a body accelerometer at the deceleration it reads
    (``train_decel`` as a specific force: the gradient's ``g sin(theta)`` is not seen, plus the
    sensor's bias), as accelerometer-aided WSPs do; rising at most at the rise limit."""
    v_ref = wsp[e, W_VREF]
    if obs_par[OP_ACCELEROMETER] > 0.0:
        a_read = train_decel - env_par[e, EP_GRADE_ACC] + wsp[e, W_ACC_BIAS]
        wsp[e, W_ACC] = a_read
        v_ref = max(fastest, v_ref - max(a_read, 0.0) * ctrl_dt)
    else:
        v_ref = max(fastest, v_ref - obs_par[OP_REF_DECEL_LIMIT] * ctrl_dt)
    wsp[e, W_VREF] = min(v_ref, wsp[e, W_VREF] + obs_par[OP_REF_RISE_LIMIT] * ctrl_dt)


@njit(**KERNEL_FLAGS)
def write_obs(
    e, env_par, axle_par, env_state, axle_state, wsp, prev_wheel, prev_action, obs_par, ctrl_dt, obs
):
    """Observation of env ``e``: what a WSP measures, normalised to about [-1, 1].

    ``[v_axle_i / v_s]``, ``[axle deceleration_i / a_s]``, ``[(v_ref - v_axle_i) / max(v_ref, 1)]``,
    ``[p_i / p_max]``, ``p_demand / p_max``, ``v_ref / v_s``, ``[previous action]``, with
    ``privileged``: ``V / v_s``, ``[friction level_i]``, ``[(V - v_axle_i) / max(V, 1)]``, and
    with ``accelerometer`` last: the body accelerometer's deceleration reading ``/ a_s``.
    """
    n_axles = axle_par.shape[1]
    n_valves = prev_action.shape[1]
    v_s = obs_par[OP_SPEED_SCALE]
    a_s = obs_par[OP_DECEL_SCALE]
    p_max = env_par[e, EP_P_MAX]
    v_ref = wsp[e, W_VREF]
    inv_ref = 1.0 / max(v_ref, 1.0)
    for k in range(n_axles):
        wheel = axle_state[e, k, AS_OMEGA] * axle_par[e, k, AP_RADIUS]
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
            wheel = axle_state[e, k, AS_OMEGA] * axle_par[e, k, AP_RADIUS]
            obs[e, base + 1 + k] = axle_state[e, k, AS_MU_LEVEL]
            obs[e, base + 1 + n_axles + k] = _clip((v - wheel) * inv_v)
    if obs_par[OP_ACCELEROMETER] > 0.0:
        obs[e, obs.shape[1] - 1] = _clip(wsp[e, W_ACC] / a_s)


@njit(**KERNEL_FLAGS)
def reset_obs(
    e, env_par, axle_par, env_state, axle_state, wsp, prev_wheel, prev_action, obs_par, ctrl_dt, obs
):
    """Reset the WSP-side state of env ``e`` after ``TrainSim.reset`` and write its observation."""
    wsp[e, W_VREF] = env_state[e, ES_V]
    wsp[e, W_ACC] = 0.0  # the bias (W_ACC_BIAS) is drawn by the caller
    for k in range(axle_par.shape[1]):
        prev_wheel[e, k] = axle_state[e, k, AS_OMEGA] * axle_par[e, k, AP_RADIUS]
    for j in range(prev_action.shape[1]):
        prev_action[e, j] = 1.0
    write_obs(
        e,
        env_par,
        axle_par,
        env_state,
        axle_state,
        wsp,
        prev_wheel,
        prev_action,
        obs_par,
        ctrl_dt,
        obs,
    )


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
    flags[e, F_CLIPPED] = clipped
    flags[e, F_NAN] = bad
    x0 = env_state[e, ES_X]
    v0 = env_state[e, ES_V]
    damage0 = 0.0
    air0 = 0.0
    slide0 = 0.0
    for k in range(n_axles):
        prev_wheel[e, k] = axle_state[e, k, AS_OMEGA] * axle_par[e, k, AP_RADIUS]
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
    # --- WSP reference speed (``update_reference``) -----------------------------------------
    fastest = 0.0
    for k in range(n_axles):
        fastest = max(fastest, axle_state[e, k, AS_OMEGA] * axle_par[e, k, AP_RADIUS])
    train_decel = (v0 - env_state[e, ES_V]) / ctrl_dt
    update_reference(e, wsp, fastest, train_decel, env_par, obs_par, ctrl_dt)
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
        e,
        env_par,
        axle_par,
        env_state,
        axle_state,
        wsp,
        prev_wheel,
        prev_action,
        obs_par,
        ctrl_dt,
        obs,
    )


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
        env_step_one(e, *args)


def step_args(
    n_sub: int, dt_s: float, control_period_s: float, p: Params, s: State
) -> tuple[Any, ...]:
    """The compiled entry points' arguments after ``(mode, actions)``, in their order: built
    once per core (the arrays are updated in place), so that a step unpacks one tuple."""
    return (
        p.valve_of_axle, n_sub, dt_s, control_period_s, s.cmd, p.env_par, p.axle_par,
        p.sections, s.env_state, s.axle_state, s.field, s.env_acc, s.axle_acc, s.wsp,
        s.prev_wheel, s.prev_action, p.obs_par, p.reward_par, s.obs, s.terms, s.flags,
    )  # fmt: skip


def reset_observation(e: int, p: Params, s: State, control_period_s: float) -> None:
    """``reset_obs`` on the bundles: env ``e``'s WSP state after ``TrainSim.reset``."""
    reset_obs(
        e, p.env_par, p.axle_par, s.env_state, s.axle_state, s.wsp, s.prev_wheel, s.prev_action,
        p.obs_par, control_period_s, s.obs,
    )  # fmt: skip


def write_observation(e: int, p: Params, s: State, control_period_s: float) -> None:
    """``write_obs`` on the bundles: env ``e``'s observation from its state."""
    write_obs(
        e, p.env_par, p.axle_par, s.env_state, s.axle_state, s.wsp, s.prev_wheel, s.prev_action,
        p.obs_par, control_period_s, s.obs,
    )  # fmt: skip

"""One control period of the coupled train / wheelset / brake / rail system, batched and compiled.

Equations (per environment ``e``, axle ``k``, substep ``dt``):

* demand  ``p_d(t) = p_max clip((t - t_delay) / t_rise, 0, 1)`` (``brake.demand_fraction``);
* valve   target ``u p_d`` (``u`` in [0, 1]) or *hold*; the command of the previous control period
  acts for the valve dead time; the cylinder follows a first-order law integrated exactly
  (``p <- target + (p - target) exp(-dt/tau)``) with a rate limit, faster when venting;
* brake   ``T_b = gain (p - p_th)^+ * pad(V)`` (seed 000 Eqs. 3–6, linear form;
  ``brake.brake_torque``, ``brake.pad_factor``);
* wheel   ``J domega/dt = F r - T_b`` with ``F = mu N`` from ``adhesion.adhesion``;
  integrated **linearly-implicitly**: ``domega = dt (F r - T_b) / (J + dt r D)`` with
  ``D = r N max(0, dmu/dxi / V + dmu/dw) = -dF/domega`` (its stabilising part); the rising creep
  slope, which makes the problem stiff (time constant < 1 ms at low speed), is then
  unconditionally stable, while the physically unstable falling branch stays explicit.
  The brake is a friction element: it can hold a stopped wheel, never turn it backwards;
* train   ``M dV/dt = -sum F - (A + B V + C V^2) - M g sin(gradient) - F_extra p_d/p_max``
  (``F_extra``: a brake force not through the wheels, e.g. a track brake), explicit (M >> J/r^2),
  with the *same* linearised forces as the wheels, so the discrete energy balance
  (kinetic energy = brake + sliding + resistance work) holds to round-off;
* load    ``N_k = N_static,k + k_transfer,k * decel`` (quasi-static load transfer);
  Kalker stiffness scales as ``N^(2/3)`` (Hertz);
* rail    each axle reads the contamination ``c`` of the rail cell under it (``rail.py``) and
  removes ``dc = -c (E_slide / E_clean + pass_removal ds) / dx`` (implicit Euler): trailing
  axles see the rail the leading ones cleaned.

``step_batch`` advances all environments by ``n_sub`` substeps; environments at standstill are
left untouched. Serial and ``prange`` (two-core) variants share ``step_env``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from wsp_env.physics.adhesion import (
    REC_BASIS_RAIL_METRE,
    REC_BASIS_WHEEL_METRE,
    adhesion,
)
from wsp_env.physics.brake import (
    brake_torque,
    cylinder_step,
    demand_fraction,
    pad_factor,
    valve_target,
)
from wsp_env.physics.layout import (
    AA_ADH_INT,
    AA_AIR_L,
    AA_AVAIL_INT,
    AA_BRAKE_E,
    AA_BRAKE_T,
    AA_LEVEL_INT,
    AA_LOCK_CUR,
    AA_LOCK_MAX,
    AA_MAX_SLIDE,
    AA_SLIDE_CUR,
    AA_SLIDE_E,
    AA_SLIDE_INT,
    AA_SLIDE_MAX,
    AA_SLIDE_SQ_INT,
    AA_SLIDE_T,
    AA_VALVE_CYCLES,
    AA_VENT_CUR,
    AA_VENT_MAX,
    AA_VENT_T,
    AP_CYL_VOLUME_L,
    AP_INERTIA,
    AP_K_TRANSFER,
    AP_MU_FACTOR,
    AP_N_STATIC,
    AP_OFFSET,
    AP_RADIUS,
    AS_CELL,
    AS_CMD,
    AS_CONT,
    AS_DOMEGA,
    AS_EXT_TORQUE,
    AS_F,
    AS_INV_STIFF,
    AS_KW,
    AS_MU,
    AS_MU_LEVEL,
    AS_N,
    AS_OMEGA,
    AS_P,
    AS_RF_S1,
    AS_RF_S2,
    AS_STIFF,
    AS_TORQUE,
    AS_VENTING,
    EA_EXTRA_E,
    EA_GRADE_E,
    EA_RESIST_E,
    EP_CELL_DX,
    EP_DAVIS_A,
    EP_DAVIS_B,
    EP_DAVIS_C,
    EP_E_CLEAN,
    EP_EXT_TORQUE,
    EP_EXTRA_BRAKE_N,
    EP_FILL_DECAY,
    EP_FILL_RATE,
    EP_GRADE_ACC,
    EP_LAW,
    EP_LP0,
    EP_LP1,
    EP_LP2,
    EP_LP3,
    EP_MASS,
    EP_P_MAX,
    EP_PASS_REMOVAL,
    EP_REC_BASIS,
    EP_RF_A1,
    EP_RF_A2,
    EP_RF_B0,
    EP_RF_B1,
    EP_RF_B2,
    EP_SLIDE_REL,
    EP_SLIDE_THRESH,
    EP_V_EPS,
    EP_VALVE_DEAD,
    EP_VENT_DECAY,
    EP_VENT_RATE,
    EP_W_LIM,
    EP_W_MAX,
    ES_DECEL,
    ES_HEAD,
    ES_STOPPED,
    ES_T,
    ES_T_STOP,
    ES_V,
    ES_X,
)
from wsp_env.physics.rail import (
    advance_field,
    available_level,
    creep_stiffness,
    effective_removal,
    friction_level,
    recovered_level,
    recovers,
)

P_ATM_BAR = 1.01325
INV_P_ATM = 1.0 / P_ATM_BAR
LOCK_WHEEL_SPEED = 0.1  # m/s: a wheel slower than this while the train moves is "locked"
LOCK_TRAIN_SPEED = 1.0  # m/s
VENT_MARGIN_BAR = 0.005  # a valve is "venting" when its target lies this far below the pressure
# IEEE arithmetic (no fastmath: batch and single runs must agree to the bit); error_model
# "numpy" drops the ZeroDivisionError checks on every division (~1.7x faster here).
KERNEL_FLAGS = {"cache": True, "error_model": "numpy"}
INLINE_FLAGS = {"cache": True, "error_model": "numpy", "inline": "always"}


@njit(**INLINE_FLAGS)
def is_locked(wheel_speed, train_speed):
    """A wheel turning slower than ``LOCK_WHEEL_SPEED`` while the train still moves is locked
    (the one definition: metrics, reward and policies use it)."""
    return wheel_speed < LOCK_WHEEL_SPEED and train_speed > LOCK_TRAIN_SPEED


@njit(**INLINE_FLAGS)
def _spell(axle_acc, e, k, current, longest, on, span):
    """Extend the current spell of a condition by ``span`` (or end it) and keep the longest."""
    if on:
        axle_acc[e, k, current] += span
        axle_acc[e, k, longest] = max(axle_acc[e, k, longest], axle_acc[e, k, current])
    else:
        axle_acc[e, k, current] = 0.0


@njit(**KERNEL_FLAGS)
def step_env(
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
):
    if env_state[e, ES_STOPPED] > 0.0:
        return
    n_axles = axle_par.shape[1]
    n_cells = field.shape[1]
    mass = env_par[e, EP_MASS]
    p_max = env_par[e, EP_P_MAX]
    fill_decay = env_par[e, EP_FILL_DECAY]
    fill_step = env_par[e, EP_FILL_RATE] * dt
    vent_decay = env_par[e, EP_VENT_DECAY]
    vent_step = env_par[e, EP_VENT_RATE] * dt
    dead = env_par[e, EP_VALVE_DEAD]
    law = int(env_par[e, EP_LAW])
    lp0 = env_par[e, EP_LP0]
    lp1 = env_par[e, EP_LP1]
    lp2 = env_par[e, EP_LP2]
    lp3 = env_par[e, EP_LP3]
    w_lim = env_par[e, EP_W_LIM]
    w_span = env_par[e, EP_W_MAX] - w_lim
    recovery_on = recovers(env_par, e)
    inv_w_span = 1.0 / w_span if recovery_on else 0.0
    basis = int(env_par[e, EP_REC_BASIS])
    b0 = env_par[e, EP_RF_B0]
    b1 = env_par[e, EP_RF_B1]
    b2 = env_par[e, EP_RF_B2]
    a1 = env_par[e, EP_RF_A1]
    a2 = env_par[e, EP_RF_A2]
    inv_clean = 1.0 / env_par[e, EP_E_CLEAN]
    pass_removal = env_par[e, EP_PASS_REMOVAL]
    dx = env_par[e, EP_CELL_DX]
    inv_dx = 1.0 / dx
    inv_dt = 1.0 / dt
    v_eps = env_par[e, EP_V_EPS]
    grade = mass * env_par[e, EP_GRADE_ACC]
    external = env_par[e, EP_EXT_TORQUE] > 0.0
    # Once per control period: the quasi-static normal load (load transfer from the
    # deceleration, 20 ms behind it, far quicker than body pitch) and the Hertz/Kalker
    # stiffness that goes with it (~ N^(2/3)).
    decel0 = env_state[e, ES_DECEL]
    for k in range(n_axles):
        n_static = axle_par[e, k, AP_N_STATIC]
        normal = max(0.05 * n_static, n_static + axle_par[e, k, AP_K_TRANSFER] * decel0)
        stiff = creep_stiffness(env_par, axle_par, e, k, normal)
        axle_state[e, k, AS_N] = normal
        axle_state[e, k, AS_STIFF] = stiff / normal  # creep stiffness per unit load
        axle_state[e, k, AS_INV_STIFF] = normal / stiff
    t_start = env_state[e, ES_T]
    stopped = False
    for j in range(n_sub):
        v = env_state[e, ES_V]
        t = env_state[e, ES_T]
        x = env_state[e, ES_X]
        if x * inv_dx >= env_state[e, ES_HEAD] + 1.0:  # the leading axle entered new rail
            advance_field(env_par, sections, env_state, field, e)
        frac = demand_fraction(env_par, e, t)
        p_d = p_max * frac
        decel = env_state[e, ES_DECEL]
        # creep is evaluated at the predicted end-of-substep train speed, so that the wheel
        # update (implicit in omega) tracks the speed the train will have, not the one it had:
        # otherwise wheels lag by decel*dt and show a spurious overspeed near standstill
        v_c = max(v - decel * dt, 0.0)
        v_ref = max(v_c, v_eps)
        inv_v_ref = 1.0 / v_ref
        pad = pad_factor(env_par, e, v)
        use_prev = j * dt < dead
        force_sum = 0.0
        for k in range(n_axles):
            if external:  # torques from outside (a roller rig's estimates, a traction drive)
                torque = -axle_state[e, k, AS_EXT_TORQUE]
            else:
                # --- pneumatics: valve command -> cylinder pressure --------------------------
                u = axle_state[e, k, AS_CMD] if use_prev else cmd[e, k]
                p = axle_state[e, k, AS_P]
                target = valve_target(u, p, p_d)
                axle_state[e, k, AS_VENTING] = 1.0 if target < p - VENT_MARGIN_BAR else 0.0
                p_new = cylinder_step(p, target, fill_decay, fill_step, vent_decay, vent_step)
                if p_new < p:
                    axle_acc[e, k, AA_AIR_L] += (
                        axle_par[e, k, AP_CYL_VOLUME_L] * (p - p_new) * INV_P_ATM
                    )
                axle_state[e, k, AS_P] = p_new
                torque = brake_torque(axle_par, e, k, p_new, pad)
            # --- contact: rail under the axle -----------------------------------------------
            normal = axle_state[e, k, AS_N]
            k_n = axle_state[e, k, AS_STIFF]
            inv_k_n = axle_state[e, k, AS_INV_STIFF]
            # an axle sees the rail as the axles ahead of it left it: read a cell once, on entry
            cell = math.floor((x - axle_par[e, k, AP_OFFSET]) * inv_dx)
            if cell != axle_state[e, k, AS_CELL]:
                axle_state[e, k, AS_CELL] = cell
                axle_state[e, k, AS_CONT] = field[e, cell % n_cells]
            cont = axle_state[e, k, AS_CONT]
            factor = axle_par[e, k, AP_MU_FACTOR]
            level = friction_level(env_par, e, cont, factor)
            mu_rec = recovered_level(env_par, e, level, factor)
            # --- creep ----------------------------------------------------------------------
            r = axle_par[e, k, AP_RADIUS]
            omega = axle_state[e, k, AS_OMEGA]
            dv = v_c - omega * r
            w = abs(dv)
            axi = w * inv_v_ref
            kw_eff = 0.0
            if recovery_on:
                if basis == REC_BASIS_RAIL_METRE:
                    q = axi
                elif basis == REC_BASIS_WHEEL_METRE:
                    q = w / max(omega * r, v_eps)
                else:
                    q = w
                power = abs(axle_state[e, k, AS_MU]) * normal * q
                kw_in = min(1.0, max(0.0, (power - w_lim) * inv_w_span))
                kw = b0 * kw_in + axle_state[e, k, AS_RF_S1]
                axle_state[e, k, AS_RF_S1] = b1 * kw_in - a1 * kw + axle_state[e, k, AS_RF_S2]
                axle_state[e, k, AS_RF_S2] = b2 * kw_in - a2 * kw
                axle_state[e, k, AS_KW] = kw
                kw_eff = effective_removal(kw, cont)
            m, m_xi, m_w = adhesion(
                law, axi, w, level, mu_rec, kw_eff, k_n, inv_k_n, lp0, lp1, lp2, lp3
            )
            force = m * normal if dv >= 0.0 else -m * normal
            damping = r * normal * max(0.0, m_xi * inv_v_ref + m_w)
            # --- linearly-implicit wheelset update --------------------------------------------
            inertia = axle_par[e, k, AP_INERTIA]
            d_omega = dt * (force * r - torque) / (inertia + dt * r * damping)
            force_used = force - damping * d_omega
            if (v_c - (omega + d_omega) * r) * dv < 0.0:
                # The step crossed zero creepage, where the creep slope is steepest and the
                # slope of the starting point (often saturated) says nothing: re-linearise at
                # zero creepage (F = kappa * slip) and solve the implicit step there. Without
                # this a wheel near standstill chatters between lock and overspeed.
                _, s0, _ = adhesion(
                    law, 0.0, 0.0, level, mu_rec, kw_eff, k_n, inv_k_n, lp0, lp1, lp2, lp3
                )
                kappa = normal * s0 * inv_v_ref
                omega_new = (inertia * omega / dt + kappa * v_c * r - torque) / (
                    inertia / dt + kappa * r * r
                )
                d_omega = omega_new - omega
                force_used = kappa * (v_c - omega_new * r)
            # The linearised force may ask more of the rail than it can give (a step toward zero
            # creepage, a steep slope at low speed): then the wheel stays on the saturated force
            # and moves only as far as that force takes it — never past the friction limit.
            cap = max(level, mu_rec) * normal
            if abs(force_used) > cap:
                force_used = cap if force_used > 0.0 else -cap
                d_omega = dt * (force_used * r - torque) / inertia
                if (v_c - (omega + d_omega) * r) * dv < 0.0:  # it would pass zero creepage:
                    # the force that stops it there, if the rail can give it; else the wheel
                    # goes on through zero creepage on the saturated force of the other sign
                    needed = (inertia * (v_c / r - omega) / dt + torque) / r
                    force_used = min(cap, max(-cap, needed))
                    d_omega = dt * (force_used * r - torque) / inertia
            if omega + d_omega < 0.0:
                d_omega = -omega  # the brake holds the wheel; it never turns it backwards
            axle_state[e, k, AS_OMEGA] = omega + d_omega
            axle_state[e, k, AS_DOMEGA] = d_omega
            axle_state[e, k, AS_F] = force_used
            axle_state[e, k, AS_TORQUE] = torque
            axle_state[e, k, AS_MU] = force_used / normal
            axle_state[e, k, AS_MU_LEVEL] = level
            force_sum += force_used
        # --- train --------------------------------------------------------------------------
        resist = 0.0
        if v > 0.0:
            resist = env_par[e, EP_DAVIS_A] + v * (
                env_par[e, EP_DAVIS_B] + v * env_par[e, EP_DAVIS_C]
            )
        extra = env_par[e, EP_EXTRA_BRAKE_N] * frac if v > 0.0 else 0.0
        v_new = v - dt * (force_sum + resist + grade + extra) / mass
        h = dt
        stopped = v_new <= 0.0
        if stopped:
            h = dt * v / (v - v_new) if v > v_new else 0.0
            v_new = 0.0
        if h > 0.0:
            env_state[e, ES_DECEL] = (v - v_new) / h
        v_mid = 0.5 * (v + v_new)
        env_state[e, ES_V] = v_new
        env_state[e, ES_X] = x + v_mid * h
        env_state[e, ES_T] = t + h
        env_acc[e, EA_RESIST_E] += resist * v_mid * h
        env_acc[e, EA_GRADE_E] += grade * v_mid * h
        env_acc[e, EA_EXTRA_E] += extra * v_mid * h
        # --- work, sliding statistics and rail cleaning ----------------------------------------
        for k in range(n_axles):
            r = axle_par[e, k, AP_RADIUS]
            inertia = axle_par[e, k, AP_INERTIA]
            d_omega = axle_state[e, k, AS_DOMEGA]
            omega_new = axle_state[e, k, AS_OMEGA]
            omega_mid = omega_new - 0.5 * d_omega
            force_used = axle_state[e, k, AS_F]
            slide = v_mid - r * omega_mid
            # brake work from the torque that actually acted (less than T_b on a held wheel);
            # the substep is cut at standstill: scale its work to the travelled fraction h
            acting_torque = force_used * r - inertia * d_omega * inv_dt
            axle_acc[e, k, AA_BRAKE_E] += acting_torque * omega_mid * h
            slide_work = force_used * slide * h
            axle_acc[e, k, AA_SLIDE_E] += slide_work
            axle_acc[e, k, AA_SLIDE_INT] += slide * h
            axle_acc[e, k, AA_SLIDE_SQ_INT] += slide * slide * h
            axle_acc[e, k, AA_MAX_SLIDE] = max(axle_acc[e, k, AA_MAX_SLIDE], slide)
            # cleaning, dc/ds = -c (e_slide / E_clean + pass_removal) / dx, implicit Euler
            removal = (max(slide_work, 0.0) * inv_clean + pass_removal * v_mid * h) * inv_dx
            slot = int(axle_state[e, k, AS_CELL]) % n_cells
            field[e, slot] /= 1.0 + removal
            if stopped:
                # the brakes absorb what the wheels still spin with; everything comes to rest
                axle_acc[e, k, AA_BRAKE_E] += 0.5 * inertia * omega_new * omega_new
                axle_state[e, k, AS_OMEGA] = 0.0
        if stopped:
            break
    # --- once per control period: time-based metrics, sampled at the period's end -------------
    span = env_state[e, ES_T] - t_start
    v_end = env_state[e, ES_V]
    slide_threshold = max(env_par[e, EP_SLIDE_THRESH], env_par[e, EP_SLIDE_REL] * v_end)
    for k in range(n_axles):
        if axle_state[e, k, AS_TORQUE] > 0.0:
            level = axle_state[e, k, AS_MU_LEVEL]
            axle_acc[e, k, AA_ADH_INT] += abs(axle_state[e, k, AS_MU]) * span
            axle_acc[e, k, AA_LEVEL_INT] += level * span
            avail = available_level(env_par, e, level, axle_par[e, k, AP_MU_FACTOR])
            axle_acc[e, k, AA_AVAIL_INT] += avail * span
            axle_acc[e, k, AA_BRAKE_T] += span
        wheel = axle_state[e, k, AS_OMEGA] * axle_par[e, k, AP_RADIUS]
        _spell(axle_acc, e, k, AA_LOCK_CUR, AA_LOCK_MAX, is_locked(wheel, v_end), span)
        _spell(axle_acc, e, k, AA_SLIDE_CUR, AA_SLIDE_MAX, v_end - wheel > slide_threshold, span)
        if v_end - wheel > slide_threshold:
            axle_acc[e, k, AA_SLIDE_T] += span
        venting = axle_state[e, k, AS_VENTING] > 0.0
        if venting:
            axle_acc[e, k, AA_VENT_T] += span
            if axle_acc[e, k, AA_VENT_CUR] == 0.0:
                axle_acc[e, k, AA_VALVE_CYCLES] += 1.0
        _spell(axle_acc, e, k, AA_VENT_CUR, AA_VENT_MAX, venting, span)
    if stopped:
        env_state[e, ES_STOPPED] = 1.0
        env_state[e, ES_T_STOP] = env_state[e, ES_T]


ARG_ENV_PAR = 3  # position of env_par in the arguments of _step_serial / _step_parallel


# The arguments of ``step_env`` after ``e``; serial and ``prange`` variants are separate
# functions so that each gets its own cache entry.
@njit(**KERNEL_FLAGS)
def _step_serial(*args):
    for e in range(args[ARG_ENV_PAR].shape[0]):
        step_env(e, *args)


@njit(parallel=True, **KERNEL_FLAGS)
def _step_parallel(*args):
    for e in prange(args[ARG_ENV_PAR].shape[0]):
        # prange's index is unsigned: as int64 the callees' compiled code is the serial
        # path's, not a second specialisation of the whole call tree
        step_env(np.int64(e), *args)


PARALLEL_MIN_ENVS = 64  # below this, thread start-up costs more than it saves


def step_batch(
    n_sub: int,
    dt: float,
    cmd: np.ndarray,
    env_par: np.ndarray,
    axle_par: np.ndarray,
    sections: np.ndarray,
    env_state: np.ndarray,
    axle_state: np.ndarray,
    field: np.ndarray,
    env_acc: np.ndarray,
    axle_acc: np.ndarray,
) -> None:
    """Advance every environment by ``n_sub`` substeps of ``dt`` seconds, in place."""
    fn = _step_parallel if env_par.shape[0] >= PARALLEL_MIN_ENVS else _step_serial
    fn(n_sub, dt, cmd, env_par, axle_par, sections, env_state, axle_state, field, env_acc, axle_acc)

"""Reference stopping distance: what the rail's available adhesion would allow.

For a run's scenario (vehicle, demand build-up, rail adhesion along the track, resistance,
gradient) integrate the stop of an ideal controller that uses, at every instant, all the
adhesion the rail *as laid* offers under each axle — the peak of each axle's creep curve at the
contamination of its position, without the cleaning and recovery that sliding itself would
bring — but never more than the brake demand gives:

* brake-limited: ``M_eff a = sum T_i(p_d(t)) / r_i + R(V) + M g sin(theta)``
  with ``M_eff = M + sum J_i / r_i^2`` (the wheels roll);
* adhesion-limited when the rail force that needs exceeds ``sum mu*_i N_i``:
  ``M a = sum mu*_i N_i + R(V) + M g sin(theta)``.

``adhesion_utilisation = reference_distance / stopping_distance`` then reads like the
EN 15595 / UIC 541-05 evaluation of WSP tests against a calculated stopping distance (1.0 = all
the available adhesion used; above 1 when cleaning and recovery made more available).
"""

from __future__ import annotations

from numba import njit

from wsp_env.physics import layout as L
from wsp_env.physics.adhesion import peak_adhesion
from wsp_env.physics.integrator import contamination_at

G = 9.80665


@njit(cache=True, error_model="numpy")
def reference_distance(env_par, axle_par, sections, e, v0, dt=0.02, max_time=900.0):
    """Stopping distance (m) of the ideal adhesion-limited stop of run ``e`` from ``v0`` m/s."""
    n_axles = axle_par.shape[1]
    mass = env_par[e, L.EP_MASS]
    m_eff = mass
    for k in range(n_axles):
        m_eff += axle_par[e, k, L.AP_INERTIA] / axle_par[e, k, L.AP_RADIUS] ** 2
    mu_clean = env_par[e, L.EP_MU_CLEAN]
    mu_cont = env_par[e, L.EP_MU_CONT]
    law = int(env_par[e, L.EP_LAW])
    v, x, t = v0, 0.0, 0.0
    while v > 0.0 and t < max_time:
        rise = env_par[e, L.EP_DEMAND_RISE]
        frac = (t - env_par[e, L.EP_DEMAND_DELAY]) / rise if rise > 0.0 else 1.0
        p_d = env_par[e, L.EP_P_MAX] * min(1.0, max(0.0, frac))
        if t < env_par[e, L.EP_DEMAND_DELAY]:
            p_d = 0.0
        pad = env_par[e, L.EP_PAD_SCALE] * max(
            0.2, 1.0 + env_par[e, L.EP_PAD_SLOPE] * (v - env_par[e, L.EP_PAD_VREF])
        )
        brake_force = 0.0
        adhesion_force = 0.0
        for k in range(n_axles):
            r = axle_par[e, k, L.AP_RADIUS]
            torque = axle_par[e, k, L.AP_BRAKE_GAIN] * max(0.0, p_d - axle_par[e, k, L.AP_P_THRESH])
            brake_force += torque * pad / r
            c = contamination_at(env_par, sections, e, x - axle_par[e, k, L.AP_OFFSET])
            level = (mu_clean - (mu_clean - mu_cont) * c) * axle_par[e, k, L.AP_MU_FACTOR]
            n = axle_par[e, k, L.AP_N_STATIC]
            k_n = axle_par[e, k, L.AP_STIFF] / n
            _, mu = peak_adhesion(
                law, level, level, 0.0, k_n, 1.0 / k_n, max(v, 0.1),
                env_par[e, L.EP_LP0], env_par[e, L.EP_LP1], env_par[e, L.EP_LP2],
                env_par[e, L.EP_LP3],
            )  # fmt: skip
            adhesion_force += mu * n
        resist = env_par[e, L.EP_DAVIS_A] + v * (
            env_par[e, L.EP_DAVIS_B] + v * env_par[e, L.EP_DAVIS_C]
        )
        grade = mass * env_par[e, L.EP_GRADE_ACC]
        a = (brake_force + resist + grade) / m_eff
        if mass * a - resist - grade > adhesion_force:  # the rail cannot carry it
            a = (adhesion_force + resist + grade) / mass
        v_new = v - a * dt
        if v_new <= 0.0:
            x += 0.5 * v * (v / a) if a > 0.0 else 0.0
            return x
        x += 0.5 * (v + v_new) * dt
        v = v_new
        t += dt
    return x

"""Reference distances a run is judged against (EN 15595-style).

**Dry reference** (``dry_reference_distances``): the same stop — vehicle, speed, demand, load,
pads, gradient — on dry rail with no WSP, run by the simulator itself. EN 15595's headline figure
compares *deceleration distances*: the stopping distance minus the distance covered during the
equivalent build-up time ``t_e`` (``deceleration_distance``), with ``t_e = t_delay + t_rise / 2``,
the EN 14531 / CEN/TR 17315 equivalent time of a linear build-up (the brake counted as absent
for ``t_e`` and fully applied after it). The increase
``100 (s_dec / s_dec,dry - 1)`` % is the percentage by which reduced adhesion lengthened the stop.

**Available-adhesion reference** (``reference_distance``): for a run's scenario (vehicle,
demand build-up, rail adhesion along the track, resistance,
gradient) integrate the stop of an ideal controller that uses, at every instant, all the
adhesion the rail *as laid* offers under each axle — the peak of each axle's creep curve at the
contamination of its position, without the cleaning and recovery that sliding itself would
bring — but never more than the brake demand gives:

* brake-limited: ``M_eff a = sum T_i(p_d(t)) / r_i + R(V) + M g sin(theta)``
  with ``M_eff = M + sum J_i / r_i^2`` (the wheels roll);
* adhesion-limited when the rail force that needs exceeds ``sum mu*_i N_i``:
  ``M a = sum mu*_i N_i + R(V) + M g sin(theta)``.

``extension_pct = 100 (stopping_distance / reference_distance - 1)`` then reads like the
EN 15595 / UIC 541-05 evaluation of WSP tests against a stopping distance calculated for the
adhesion present (negative when cleaning and recovery made more adhesion available).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit

from wsp_env.core.config import RailConfig, VehicleConfig
from wsp_env.physics import layout as L
from wsp_env.physics.adhesion import peak_adhesion
from wsp_env.physics.brake import brake_torque, demand_bar, pad_factor
from wsp_env.physics.rail import contamination_at, creep_stiffness, friction_level

G = 9.80665


@njit(cache=True, error_model="numpy")
def reference_distance(env_par, axle_par, sections, e, v0, dt=0.02, max_time=900.0):
    """Stopping distance (m) of the ideal adhesion-limited stop of run ``e`` from ``v0`` m/s."""
    n_axles = axle_par.shape[1]
    mass = env_par[e, L.EP_MASS]
    m_eff = mass
    for k in range(n_axles):
        m_eff += axle_par[e, k, L.AP_INERTIA] / axle_par[e, k, L.AP_RADIUS] ** 2
    law = int(env_par[e, L.EP_LAW])
    v, x, t = v0, 0.0, 0.0
    while v > 0.0 and t < max_time:
        p_d = demand_bar(env_par, e, t)
        pad = pad_factor(env_par, e, v)
        brake_force = 0.0
        adhesion_force = 0.0
        for k in range(n_axles):
            brake_force += brake_torque(axle_par, e, k, p_d, pad) / axle_par[e, k, L.AP_RADIUS]
            c = contamination_at(env_par, sections, e, x - axle_par[e, k, L.AP_OFFSET])
            level = friction_level(env_par, e, c, axle_par[e, k, L.AP_MU_FACTOR])
            n = axle_par[e, k, L.AP_N_STATIC]
            k_n = creep_stiffness(env_par, axle_par, e, k, n) / n
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


def equivalent_build_up_time_s(env_par: np.ndarray) -> np.ndarray:
    """EN 14531 equivalent build-up time per run: ``t_delay + t_rise / 2`` (linear rise)."""
    return env_par[:, L.EP_DEMAND_DELAY] + 0.5 * env_par[:, L.EP_DEMAND_RISE]


def deceleration_distance(stop_m: float, speed_mps: float, t_e_s: float) -> float:
    """Stopping distance less the distance run at the initial speed during ``t_e``."""
    return stop_m - speed_mps * t_e_s


def dry_reference_distances(
    vehicle: VehicleConfig,
    setups: list,
    dry_rail: RailConfig,
    dt_s: float = 1e-3,
    control_period_s: float = 0.02,
    max_time_s: float = 600.0,
) -> np.ndarray:
    """Stopping distance (m) of each run's stop on dry rail, full demand on every axle."""
    from wsp_env.core.simulator import TrainSim

    sim = TrainSim(vehicle, n_envs=len(setups), dt_s=dt_s, control_period_s=control_period_s)
    for e, setup in enumerate(setups):
        dry = dataclasses.replace(
            setup, rail=dry_rail, rail_name="dry", mu_contaminated=None, background=None,
            sections=(), injection_level=0.0, injection_until_s=-1.0, axle_mu_factor=None,
            recovery_basis=None,
        )  # fmt: skip
        sim.configure(e, dry)
    sim.reset()
    full = np.ones((sim.n_envs, sim.n_axles))
    for _ in range(math.ceil(max_time_s / control_period_s)):
        if sim.stopped.all():
            break
        sim.step(full)
    return sim.position_m.copy()

"""Oracle: privileged controller that holds every axle at the peak of its current adhesion curve.

It reads the simulator's true state (train speed, each axle's friction level, recovery state
and contact stiffness) — no real WSP can — finds the creepage ``xi*`` where the axle's current
curve ``mu(xi, DV = xi V)`` peaks (a 64-point log grid refined by a parabola), and commands the
brake torque that holds the wheel there:
``T* = mu(xi*) N r + J a (1 - xi*) / r + K (v_wheel - (1 - xi*) V)``
(adhesion at the peak, the torque that decelerates the wheelset with the train, and a
proportional correction on the wheel-speed error), converted to a pressure request through the
brake's torque law. It is the upper reference showing how much any controller could still gain.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from wsp_env.physics import layout as L
from wsp_env.physics.adhesion import peak_adhesion


@njit(cache=True, error_model="numpy")
def oracle_pressures(env_par, axle_par, env_state, axle_state, gain_k, out):
    """Requested cylinder pressure (bar) per axle for every environment."""
    for e in range(env_par.shape[0]):
        v = env_state[e, L.ES_V]
        decel = env_state[e, L.ES_DECEL]
        law = int(env_par[e, L.EP_LAW])
        mu_clean = env_par[e, L.EP_MU_CLEAN]
        pad = env_par[e, L.EP_PAD_SCALE] * max(
            0.2, 1.0 + env_par[e, L.EP_PAD_SLOPE] * (v - env_par[e, L.EP_PAD_VREF])
        )
        for k in range(axle_par.shape[1]):
            level = axle_state[e, k, L.AS_MU_LEVEL]
            factor = axle_par[e, k, L.AP_MU_FACTOR]
            mu_rec = max(level, min(env_par[e, L.EP_REC_GAIN] * level, mu_clean * factor))
            kw = min(1.0, max(0.0, axle_state[e, k, L.AS_KW])) * axle_state[e, k, L.AS_CONT]
            n = axle_state[e, k, L.AS_N]
            k_n = axle_state[e, k, L.AS_STIFF]
            if k_n <= 0.0:  # before the first step: static load
                n = axle_par[e, k, L.AP_N_STATIC]
                k_n = axle_par[e, k, L.AP_STIFF] / n
            xi, mu = peak_adhesion(
                law, level, mu_rec, kw, k_n, 1.0 / k_n, max(v, 0.1),
                env_par[e, L.EP_LP0], env_par[e, L.EP_LP1], env_par[e, L.EP_LP2],
                env_par[e, L.EP_LP3],
            )  # fmt: skip
            r = axle_par[e, k, L.AP_RADIUS]
            wheel = axle_state[e, k, L.AS_OMEGA] * r
            target_wheel = (1.0 - xi) * v
            torque = (
                mu * n * r
                + axle_par[e, k, L.AP_INERTIA] * decel * (1.0 - xi) / r
                + gain_k * n * r * (wheel - target_wheel) / max(v, 1.0)
            )
            out[e, k] = (
                torque / (axle_par[e, k, L.AP_BRAKE_GAIN] * pad) + axle_par[e, k, L.AP_P_THRESH]
            )


class OraclePolicy:
    """Holds every axle at its adhesion peak using the simulator's true state (privileged)."""

    name = "oracle"
    privileged = True

    def __init__(self, feedback_gain: float = 2.0) -> None:
        self.feedback_gain = feedback_gain

    def bind(self, core: Any) -> None:
        self.core = core
        self._p = np.zeros((core.n_envs, core.n_axles))
        self.valve_starts = np.flatnonzero(np.r_[True, np.diff(core.valve_of_axle) != 0])

    def reset(self, env_ids: np.ndarray) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        sim = self.core.sim
        oracle_pressures(
            sim.env_par, sim.axle_par, sim.env_state, sim.axle_state, self.feedback_gain, self._p
        )
        demand = sim.demand_bar()[:, None]
        frac = np.where(demand > 1e-6, self._p / np.maximum(demand, 1e-6), 1.0)
        frac = np.minimum.reduceat(frac, self.valve_starts, axis=1)
        return np.clip(2.0 * frac - 1.0, -1.0, 1.0).astype(np.float32)

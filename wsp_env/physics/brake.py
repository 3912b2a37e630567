"""Brake: from cylinder pressure to brake torque, and the pneumatic time constants.

The disc-brake chain of seed 000:

* Eq. 4  actuator force ``F_z = [(A_BK p 10 - F_PRF) R mu_C] - F_SARF - F_RNR``
  (``A_BK`` in cm^2, ``p`` in bar: ``cm^2 * bar * 10 = N``);
* Eq. 3  clamp force ``F_B = F_z U eta``;
* Eq. 6  force at the wheel ``F_tx = F_B mu_pad n_KS (2 r_B / d_w) U_B``, i.e. the brake torque
  ``T = F_tx d_w / 2 = F_B mu_pad n_KS r_B U_B``. We take Eq. 6 as printed: ``F_B`` is the clamp
  force of one disc's caliper and each disc contributes ``F_B mu_pad r_B`` (the seed has no
  factor 2 for the two pad faces, so ``F_B`` must be the sum over both pads).

The chain is affine in ``p``, so it reduces to ``T = gain (p - p_threshold)^+`` — the form the
kernel uses and the linear form of ``docs/trace_format.md`` (seed 000 Eq. 5,
``F_B[kN] = (p - 0.174) / 0.1565``, is that reduction for the ETR 1000 caliper).

The compiled helpers at the end (demand ramp, pad factor, brake torque) are the one definition
of those formulas: the kernel, the reference distance, the oracle and the read-outs call them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from wsp_env.physics.layout import (
    AP_BRAKE_GAIN,
    AP_P_THRESH,
    EP_DEMAND_DELAY,
    EP_DEMAND_RISE,
    EP_P_MAX,
    EP_PAD_SCALE,
    EP_PAD_SLOPE,
    EP_PAD_VREF,
)

INLINE = {"cache": True, "error_model": "numpy", "inline": "always"}
PAD_FACTOR_MIN = 0.2  # the speed-dependent pad friction never falls below this share


@dataclass(frozen=True)
class DiscBrakeChain:
    """Parameters of seed 000 Eqs. 3–6 for one axle."""

    thrust_area_cm2: float  # A_BK
    cylinder_spring_N: float  # F_PRF
    cylinder_ratio: float  # R
    cylinder_efficiency: float  # mu_C
    slack_adjuster_spring_N: float  # F_SARF
    rear_nut_spring_N: float  # F_RNR
    caliper_ratio: float  # U (Ü)
    caliper_efficiency: float  # eta
    pad_friction: float  # mu_pad
    discs_per_axle: int  # n_KS
    friction_radius_m: float  # r_B
    transmission_ratio: float = 1.0  # U_B

    def clamp_force_N(self, p_bar: float) -> float:
        """Seed 000 Eqs. 3–4 (no clamping below the threshold)."""
        f_z = (
            (self.thrust_area_cm2 * p_bar * 10.0 - self.cylinder_spring_N)
            * self.cylinder_ratio
            * self.cylinder_efficiency
            - self.slack_adjuster_spring_N
            - self.rear_nut_spring_N
        )
        return max(0.0, f_z * self.caliper_ratio * self.caliper_efficiency)

    def torque_Nm(self, p_bar: float) -> float:
        """Seed 000 Eq. 6 times the wheel radius."""
        return (
            self.clamp_force_N(p_bar)
            * self.pad_friction
            * self.discs_per_axle
            * self.friction_radius_m
            * self.transmission_ratio
        )

    def linear_form(self) -> tuple[float, float]:
        """``(gain_Nm_per_bar, p_threshold_bar)`` with ``T = gain (p - p_threshold)^+``."""
        slope_clamp = (
            self.thrust_area_cm2
            * 10.0
            * self.cylinder_ratio
            * self.cylinder_efficiency
            * self.caliper_ratio
            * self.caliper_efficiency
        )
        offset_clamp = (
            self.cylinder_spring_N * self.cylinder_ratio * self.cylinder_efficiency
            + self.slack_adjuster_spring_N
            + self.rear_nut_spring_N
        ) * (self.caliper_ratio * self.caliper_efficiency)
        torque_per_clamp = (
            self.pad_friction
            * self.discs_per_axle
            * self.friction_radius_m
            * self.transmission_ratio
        )
        return slope_clamp * torque_per_clamp, offset_clamp / slope_clamp


def decay_factor(tau_s: float, dt_s: float) -> float:
    """``exp(-dt / tau)``: exact one-step solution of a first-order lag (0 for tau = 0)."""
    return 0.0 if tau_s <= 0 else math.exp(-dt_s / tau_s)


# ---- compiled helpers: the one definition of each formula -----------------------------------


@njit(**INLINE)
def demand_fraction(env_par, e, t):
    """Share of ``p_max`` the brake demands ``t`` s after the command: a dead time, then a linear
    rise (``rise = 0``: a step at the end of the dead time)."""
    since = t - env_par[e, EP_DEMAND_DELAY]
    if since < 0.0:
        return 0.0
    rise = env_par[e, EP_DEMAND_RISE]
    if rise <= 0.0:
        return 1.0
    return min(1.0, since / rise)


@njit(**INLINE)
def demand_bar(env_par, e, t):
    """Demand pressure (bar) at time ``t`` since the brake command."""
    return env_par[e, EP_P_MAX] * demand_fraction(env_par, e, t)


@njit(cache=True, error_model="numpy")
def demand_bars(env_par, times, out):
    """``demand_bar`` for every environment (``times[e]`` s since its brake command)."""
    for e in range(env_par.shape[0]):
        out[e] = demand_bar(env_par, e, times[e])
    return out


@njit(**INLINE)
def valve_target(cmd, p, p_demand):
    """The pressure a valve command drives the cylinder toward: a fraction of the demand, or
    (``cmd < 0``, ``layout.CMD_HOLD``) the pressure it holds, never above the demand."""
    if cmd < 0.0:
        return min(p, p_demand)
    return min(cmd, 1.0) * p_demand


@njit(**INLINE)
def cylinder_step(p, target, fill_decay, fill_step, vent_decay, vent_step):
    """Cylinder pressure after one substep toward ``target``: a first-order lag (``*_decay`` =
    ``exp(-dt / tau)``) capped at the valve's rate (``*_step`` = rate dt), fill or vent."""
    if target > p:
        return min(target + (p - target) * fill_decay, p + fill_step)
    return max(target + (p - target) * vent_decay, p - vent_step)


@njit(**INLINE)
def pad_factor(env_par, e, v):
    """Pad friction relative to nominal at train speed ``v`` m/s: the run's scale times a linear
    speed dependence about ``EP_PAD_VREF``, never below ``PAD_FACTOR_MIN``."""
    slope = env_par[e, EP_PAD_SLOPE] * (v - env_par[e, EP_PAD_VREF])
    return env_par[e, EP_PAD_SCALE] * max(PAD_FACTOR_MIN, 1.0 + slope)


@njit(**INLINE)
def brake_torque(axle_par, e, k, p_bar, pad):
    """Brake torque (N m) of axle ``k`` at pressure ``p_bar``: ``gain (p - p_th)^+ pad``."""
    return axle_par[e, k, AP_BRAKE_GAIN] * max(0.0, p_bar - axle_par[e, k, AP_P_THRESH]) * pad


@njit(**INLINE)
def pressure_for_torque(axle_par, e, k, torque, pad):
    """The cylinder pressure (bar) at which ``brake_torque`` gives ``torque`` (its inverse)."""
    return torque / (axle_par[e, k, AP_BRAKE_GAIN] * pad) + axle_par[e, k, AP_P_THRESH]


def demand_pressures(env_par: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Demand pressure (bar) of every environment at its time ``times[e]``."""
    return demand_bars(env_par, np.ascontiguousarray(times, dtype=float), np.empty(len(times)))

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
kernel uses and the linear form of ``TRACE_FORMAT.md`` (seed 000 Eq. 5,
``F_B[kN] = (p - 0.174) / 0.1565``, is that reduction for the ETR 1000 caliper).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


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

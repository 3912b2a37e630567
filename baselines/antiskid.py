"""Anti-skid device for the traction phase (seed 002 §3.1.4, Fig. 5), batched over environments.

The three tasks of seed 002 Fig. 5, on the four axle speeds and the driver's torque ``C``:

1. **Reference evaluation**: the reference speed follows the *slowest* wheel (in traction a
   wheel that slips turns faster than the train), rising at most at ``ref_accel_limit_mps2``
   (above the vehicle's best acceleration, so that while no wheel slips the reference is the
   slowest wheel); the reference acceleration is its slope.
2. **Sliding state** per axle, ``state_AS = 1`` when a speed criterion
   ``v_i - v_ref > max(slip_abs_kmh, slip_rel v_ref)`` or an acceleration criterion
   ``dv_i/dt - a_ref > accel_slip_mps2`` holds; it is cleared when both have fallen below
   ``release_ratio`` of their thresholds.
3. **Torque modulation**: while an axle slips its torque factor falls at ``reduce_per_s``
   (down to ``min_factor``); once it has stopped slipping the factor is held for ``hold_s``
   and then restored at ``restore_per_s`` up to the driver's demand (factor 1).

The thresholds are the device's documented settings (``AntiSkidConfig``); the seed gives none
(its logic follows the E402B documentation, its ref. [11]). The values were chosen as a
traction engineer would for a 5-20 km/h start on a contaminated rail — a slip threshold of
about 1 km/h (the creep of the adhesion peak at these speeds), reduction fast against restoring
— and are the same for every test; they are not fitted to Tables 9-10.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class AntiSkidConfig:
    ref_accel_limit_mps2: float = field(default=1.2, metadata={"gt": 0.0})
    slip_abs_kmh: float = field(default=1.0, metadata={"gt": 0.0})
    slip_rel: float = field(default=0.05, metadata={"ge": 0.0})
    accel_slip_mps2: float = field(default=1.0, metadata={"gt": 0.0})
    release_ratio: float = field(default=0.5, metadata={"gt": 0.0, "le": 1.0})
    reduce_per_s: float = field(default=2.0, metadata={"gt": 0.0})
    min_factor: float = field(default=0.3, metadata={"ge": 0.0, "le": 1.0})
    hold_s: float = field(default=0.3, metadata={"ge": 0.0})
    restore_per_s: float = field(default=0.3, metadata={"gt": 0.0})


class AntiSkid:
    """Torque factors in [0, 1] per axle for every environment (module docstring)."""

    name = "antiskid"

    def __init__(self, config: AntiSkidConfig | None = None) -> None:
        self.cfg = config or AntiSkidConfig()

    def reset(self, n_envs: int, n_axles: int, wheel_mps: np.ndarray) -> None:
        self.v_ref = np.asarray(wheel_mps, dtype=float).min(axis=1)
        self.prev = np.asarray(wheel_mps, dtype=float).copy()
        self.factor = np.ones((n_envs, n_axles))
        self.slipping = np.zeros((n_envs, n_axles), dtype=bool)
        self.held_for = np.zeros((n_envs, n_axles))

    def act(self, wheel_mps: np.ndarray, dt: float) -> np.ndarray:
        """Torque factors for the next period from the wheel speeds now (m/s)."""
        cfg = self.cfg
        v = np.asarray(wheel_mps, dtype=float)
        accel = (v - self.prev) / dt
        self.prev = v.copy()
        v_ref_old = self.v_ref
        self.v_ref = np.minimum(v.min(axis=1), v_ref_old + cfg.ref_accel_limit_mps2 * dt)
        a_ref = (self.v_ref - v_ref_old) / dt
        slip = v - self.v_ref[:, None]
        threshold = np.maximum(cfg.slip_abs_kmh / 3.6, cfg.slip_rel * self.v_ref[:, None])
        excess_accel = accel - a_ref[:, None]
        on = (slip > threshold) | (excess_accel > cfg.accel_slip_mps2)
        off = (slip < cfg.release_ratio * threshold) & (
            excess_accel < cfg.release_ratio * cfg.accel_slip_mps2
        )
        self.slipping = np.where(on, True, np.where(off, False, self.slipping))
        self.held_for = np.where(self.slipping, 0.0, self.held_for + dt)
        down = np.maximum(self.factor - cfg.reduce_per_s * dt, cfg.min_factor)
        up = np.minimum(self.factor + cfg.restore_per_s * dt, 1.0)
        self.factor = np.where(
            self.slipping, down, np.where(self.held_for >= cfg.hold_s, up, self.factor)
        )
        return self.factor.copy()

"""Train layout: axle positions, static loads and quasi-static load transfer under braking.

A train is a list of car bodies resting on bogies (a bogie may carry two bodies: Jakobs bogies);
each bogie has its axles. Under a deceleration ``a`` (> 0 when braking) the inertial forces act
forward at the centres of gravity and the adhesion forces backward at rail level, so load moves
to the front of each body and of each bogie (seed 002 §3.2.1, seed 000 §3):

* body of mass ``m`` and CoG height ``h`` on pivots at height ``h_p`` spaced ``L``:
  ``dN_front_pivot = -dN_rear_pivot = m a (h - h_p) / L``;
* bogie of wheelbase ``b``: the longitudinal pivot forces (``m_body a / 2`` per body half, at
  ``h_p``), its frame (``m_f a`` at ``h_f``) and the wheelsets (``m_w a`` at the wheel radius)
  pitch it about rail level: ``dN_front_axle = -dN_rear_axle = a (sum m h) / b``; the pivot's
  vertical change is shared by the two axles.

Coupler and buffer forces between cars are neglected (every car is assumed to decelerate with
its own brakes); that is the usual single-vehicle braking assumption. Everything is linear in
``a``, so each axle gets ``N = N_static + k_transfer a`` with constant ``k_transfer`` (N per
m/s^2), and the transfers sum to zero over the train.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

G = 9.80665


@dataclass(frozen=True)
class Bogie:
    """A bogie: ``position_m`` of its centre behind the front of the train."""

    position_m: float
    wheelbase_m: float
    frame_mass_kg: float
    frame_cog_height_m: float
    pivot_height_m: float
    n_axles: int = 2


@dataclass(frozen=True)
class Car:
    """A car body on two bogies (indices into the train's bogie list)."""

    body_mass_kg: float
    cog_height_m: float
    front_bogie: int
    rear_bogie: int


@dataclass(frozen=True)
class TrainLayout:
    cars: tuple[Car, ...]
    bogies: tuple[Bogie, ...]
    wheelset_mass_kg: float
    wheel_radius_m: float

    @property
    def n_axles(self) -> int:
        return sum(b.n_axles for b in self.bogies)

    @property
    def mass_kg(self) -> float:
        """Whole train: bodies, bogie frames and wheelsets."""
        return (
            sum(c.body_mass_kg for c in self.cars)
            + sum(b.frame_mass_kg for b in self.bogies)
            + self.n_axles * self.wheelset_mass_kg
        )

    def axle_offsets_m(self) -> np.ndarray:
        """Distance of each axle behind the leading axle, in running order."""
        pos = []
        for b in self.bogies:
            span = b.wheelbase_m * (b.n_axles - 1)
            pos.extend(b.position_m - span / 2 + b.wheelbase_m * i for i in range(b.n_axles))
        pos_arr = np.asarray(pos, dtype=float)
        return pos_arr - pos_arr[0]

    def axle_loads(self) -> tuple[np.ndarray, np.ndarray]:
        """Static axle loads (N) and load-transfer coefficients (N per m/s^2), running order."""
        n_bogies = len(self.bogies)
        pivot_static = np.zeros(n_bogies)  # N on each bogie from the bodies
        pivot_transfer = np.zeros(n_bogies)  # N per m/s^2
        pivot_long_mass = np.zeros(n_bogies)  # kg of body whose inertia passes the pivot
        pivot_height = np.array([b.pivot_height_m for b in self.bogies])
        for car in self.cars:
            f, r = car.front_bogie, car.rear_bogie
            span = self.bogies[r].position_m - self.bogies[f].position_m
            half = 0.5 * car.body_mass_kg
            pivot_static[[f, r]] += half * G
            pivot_long_mass[[f, r]] += half
            # pivots of one body are at one height (the mean of the two bogies')
            lever = car.cog_height_m - 0.5 * (pivot_height[f] + pivot_height[r])
            dn = car.body_mass_kg * lever / span
            pivot_transfer[f] += dn
            pivot_transfer[r] -= dn
        static, transfer = [], []
        for i, b in enumerate(self.bogies):
            frame_and_wheels = b.frame_mass_kg + b.n_axles * self.wheelset_mass_kg
            per_axle_static = (pivot_static[i] + frame_and_wheels * G) / b.n_axles
            moment = (
                pivot_long_mass[i] * b.pivot_height_m
                + b.frame_mass_kg * b.frame_cog_height_m
                + b.n_axles * self.wheelset_mass_kg * self.wheel_radius_m
            )
            # pitch of a bogie: linear distribution over its axles about the centre
            rel = np.arange(b.n_axles) - (b.n_axles - 1) / 2.0  # front axle has lowest index
            lever_sq = np.sum((rel * b.wheelbase_m) ** 2)
            for j in range(b.n_axles):
                pitch = -moment * (rel[j] * b.wheelbase_m) / lever_sq if lever_sq > 0 else 0.0
                static.append(per_axle_static)
                transfer.append(pivot_transfer[i] / b.n_axles + pitch)
        return np.asarray(static), np.asarray(transfer)


def davis_resistance_N(
    speed_mps: np.ndarray | float, a_N: float, b_Ns_per_m: float, c_Ns2_per_m2: float
) -> np.ndarray | float:
    """Running resistance ``A + B v + C v^2`` (Davis form), N."""
    return a_N + speed_mps * (b_Ns_per_m + speed_mps * c_Ns2_per_m2)

"""The brake's lag behind the logged pressure, measured on the wheels.

A brake force that follows the logged cylinder pressure ``tau`` late (a sensor upstream of
the cylinder, a long pipe) and a ground speed logged ``tau`` late are twins on the
train-speed balance: either makes the predicted speed fall ``tau a`` ahead of the logged one
(``discovery``). The wheelset equation tells them apart, because the ground speed is not in
it (seed 000 Eq. 3–6, ``adhesion_estimate``)::

    F_i(t) r = J domega_i/dt + T_i(t - tau)      T_i = gain_i (p_i - p_th)^+

While a wheel slides, its adhesion force ``F_i`` changes with the creep and the sliding speed
— smoothly — while the torque jumps with every valve command (a vent drops the pressure within
a few tenths of a second). At the wrong ``tau`` the estimate ``F_i`` carries the torque's jumps
uncompensated (the wheel answers the torque ``tau`` after the log shows it), so ``tau`` is the
lag that makes ``F_i`` smoothest: the sum of its squared sample-to-sample changes over the
samples where the wheel slides is least.

What makes this robust on logged data: a logger that averages, or stamps late, shifts the
wheel speeds and the pressures alike, which leaves the relative timing this measures alone;
the ground speed's hold between fixes, its lag and its scale do not enter (a slide is judged
against the fastest axle, not the ground speed); a pad-friction scale multiplies the torque
and leaves the smoothest ``tau`` where it is.

The lag's shape: a sensor upstream of the cylinder, or a long pipe, is a dead time; a cylinder
filling through a restriction is a first-order lag (``residuals.first_order``). Both are
scored the same way, the dead time on ``TAU_GRID_S``, the time constant on ``TC_GRID_S``; the
shape is the one whose best score is lower (on independent traces the dead time's shape won on
6 of 6 traces with a 0.2 s dead time, the first order's on 6 of 6 with a 0.3 s constant), and the
lag is that shape's parameter.

Both at once (a dead time, then a first-order lag: a sensor upstream of a cylinder that fills
through a restriction) is a third shape with two parameters, scored on the grid
``BOTH_DEAD_GRID_S`` x ``TC_GRID_S`` (``both_shapes``). It must earn each parameter:

* its smoothest point has a dead time and a constant of at least ``RESOLUTION_S`` each (the
  wheels' resolution: on clean traces they read -0.04 to +0.04 s) and lies inside the grid;
* its score beats the best of each single shape by ``BOTH_Z`` standard errors of the paired
  per-episode difference (the episodes are the independent pieces of evidence).

The second test is optimistic (its point is the best of some 1,000 on the same episodes: on a
pure first-order trace the best two-parameter point can pass it with a dead time under the
resolution); the resolution is what keeps a single shape single. Counts on independent traces:
``scripts/lag_shapes.py``.

Uncertainty: the slides fall into separate episodes (a contiguous run of sliding samples of
one axle, with a few samples either side); the lag's standard error is the jackknife over
episodes (each left out in turn, the lag re-found from the other episodes' sums). For both
shapes it is the dead time's, on its 0.02 s grid without refinement: a rough figure.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from wsp_env.calibration.residuals import first_order
from wsp_env.calibration.traces import Trace

# the lag grid (s): from a lead (an estimate that reads early says the timing is off, not
# that the brake is fast) to well beyond a brake pipe's plausible delay
TAU_GRID_S = np.arange(-0.3, 1.001, 0.02)
# the first-order time constant's grid (s): none to well beyond a restricted cylinder's filling
TC_GRID_S = np.arange(0.0, 1.001, 0.02)
# both shapes together: the dead time's grid (s); the constant's is TC_GRID_S
BOTH_DEAD_GRID_S = np.arange(0.0, 0.401, 0.02)
SHAPES = ("dead_time", "first_order", "both")
RESOLUTION_S = 0.1  # the wheels' resolution: a lag (or each part of both) below it is not read
BOTH_Z = 3.0  # standard errors by which both shapes must beat each shape alone
SLIDE_KMH = 2.0  # a wheel this much slower than the fastest axle slides (beyond sensor noise)
# an episode carries timing only if the valve acted in it: the torque moved by this share of
# the axle's largest (a wheel rolling under a steady brake has nothing to answer)
VALVE_ACTION = 0.2
MARGIN_SAMPLES = 3  # samples either side of a slide that belong to its episode
MIN_SPEED_KMH = 10.0  # below this the wheel speeds' resolution is too coarse a clock
MIN_EPISODES = 4  # fewer: no lag is measured (and no standard error could be)


@dataclass
class WheelLag:
    """The lag (s) at which the wheels' adhesion force is smoothest — a dead time, or a
    first-order time constant where ``shape`` is ``"first_order"``, or the dead time where it
    is ``"both"`` (then the constant is ``time_constant_s``) —, its jackknife standard error
    (s; for both, the dead time's, rough: module docstring), the number of slide episodes it
    rests on, and the shape's score curve over its grid (``TAU_GRID_S`` or ``TC_GRID_S``: mean
    squared change of the force, N^2, per sample pair; for both, over ``TC_GRID_S`` at the dead
    time found)."""

    lag_s: float
    se_s: float
    episodes: int
    score: np.ndarray
    shape: str = "dead_time"
    time_constant_s: float = 0.0  # the first-order part where ``shape`` is ``"both"``

    @property
    def params(self) -> dict[str, float]:
        """The pressure-lag effect's parameters this lag stands for."""
        if self.shape == "both":
            return {"lag_s": self.lag_s, "time_constant_s": self.time_constant_s}
        key = "time_constant_s" if self.shape == "first_order" else "lag_s"
        return {key: self.lag_s}

    def late_text(self) -> str:
        """How late the brake is, in words (a first-order lag's mean delay is its constant)."""
        if self.shape == "both":
            return (f"{self.lag_s:.2f} s late, then through a {self.time_constant_s:.2f} s "
                    "first-order lag")  # fmt: skip
        if self.shape == "first_order":
            return f"late through a {self.lag_s:.2f} s first-order lag"
        return f"{self.lag_s:.2f} s late"

    def confidence(self) -> dict[str, float | str]:
        """What a pressure-lag step records of the wheels' reading (``Step.confidence``)."""
        out: dict[str, float | str] = {"wheel_lag_s": self.lag_s, "wheel_lag_se_s": self.se_s,
                                       "wheel_lag_shape": self.shape}  # fmt: skip
        if self.shape == "both":
            out["wheel_time_constant_s"] = self.time_constant_s
        return out

    def as_dict(self) -> dict[str, float | str]:
        out: dict[str, float | str] = {
            "lag_s": self.lag_s,
            "se_s": self.se_s,
            "episodes": float(self.episodes),
            "shape": self.shape,
        }
        if self.shape == "both":
            out["time_constant_s"] = self.time_constant_s
        return out


def _refined_min(score: np.ndarray, grid: np.ndarray = TAU_GRID_S) -> float:
    """The grid's minimum refined by a parabola through it and its neighbours (s)."""
    k = int(np.argmin(score))
    if 0 < k < len(score) - 1:
        a, b, c = score[k - 1], score[k], score[k + 1]
        den = a - 2.0 * b + c
        if den > 0.0:
            step = float(grid[1] - grid[0])
            return float(grid[k] + 0.5 * step * (a - c) / den)
    return float(grid[k])


def wheel_lag(trace: Trace) -> WheelLag | None:
    """The brake's lag behind the logged pressure from the sliding wheels (module docstring);
    ``None`` where fewer than ``MIN_EPISODES`` slide episodes exist (a stop on which no wheel
    slid says nothing about it) or the metadata gives no wheelset inertia."""

    veh = trace.vehicle
    inertia = float(veh.get("wheelset_inertia_kgm2", 0.0) or 0.0)
    r = float(veh["wheel_radius_m"])
    if inertia <= 0.0 or trace.n_axles < 2:
        return None
    t = trace.time_s
    wheels = trace.v_axle_kmh
    fastest = wheels.max(axis=1)
    torque = trace.brake_torque_Nm()
    per_episode: list[np.ndarray] = []
    kernel = np.ones(2 * MARGIN_SAMPLES + 1)
    for i in range(trace.n_axles):
        v_kmh = wheels[:, i]
        sliding = (fastest - v_kmh) > SLIDE_KMH
        active = (np.convolve(sliding.astype(float), kernel, "same") > 0) & (
            fastest > MIN_SPEED_KMH
        )
        pair = active[1:] & active[:-1]
        if not pair.any():
            continue
        # episodes: contiguous runs of active sample pairs; one carries timing only where
        # the valve acted in it
        edges = np.diff(np.concatenate([[0], pair.astype(int), [0]]))
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        big = float(torque[:, i].max())
        episodes = [(a, b) for a, b in zip(starts, ends, strict=True)
                    if b - a >= 2 and big > 0.0
                    and np.ptp(torque[a : b + 1, i]) >= VALVE_ACTION * big]  # fmt: skip
        if not episodes:
            continue
        accel = np.gradient(v_kmh / 3.6, t)  # m/s^2 at the rim
        inertial = inertia * accel / (r * r)  # N
        sums = np.concatenate([_episode_sums(block, inertial, r, episodes)
                               for block in _lagged_torques(t, torque[:, i])], axis=1)  # fmt: skip
        counts = np.array([[b - a] for a, b in episodes], dtype=float)
        per_episode.extend(np.concatenate([sums, counts], axis=1))
    if len(per_episode) < MIN_EPISODES:
        return None
    table = np.stack(per_episode, axis=0)  # (episodes, columns + 1): sums, pair counts
    sums, counts = table[:, :-1], table[:, -1]
    total = sums.sum(axis=0) / counts.sum()
    n_tau, n_tc = len(TAU_GRID_S), len(TC_GRID_S)
    both = both_shapes(sums, total, n_tau, n_tc)
    if both is not None:
        return both
    first = bool(total[n_tau : n_tau + n_tc].min() < total[:n_tau].min())
    cols = slice(n_tau, n_tau + n_tc) if first else slice(0, n_tau)
    grid = TC_GRID_S if first else TAU_GRID_S
    lag = _refined_min(total[cols], grid)
    m = len(table)
    leave_one_out = np.array([
        _refined_min((sums[:, cols].sum(axis=0) - sums[j, cols]) / (counts.sum() - counts[j]),
                     grid)
        for j in range(m)
    ])  # fmt: skip
    se = float(np.sqrt((m - 1) / m * np.sum((leave_one_out - leave_one_out.mean()) ** 2)))
    return WheelLag(lag, se, m, total[cols], "first_order" if first else "dead_time")


BLOCK_ELEMENTS = 2_000_000  # lagged-torque samples held at once (memory on long logs)


def _lagged_torques(t: np.ndarray, torque: np.ndarray) -> Iterator[np.ndarray]:
    """One axle's torque through every lag the wheels score, in blocks of columns (each
    ``(columns, T)``), in the order of the table: the dead times of ``TAU_GRID_S``, the time
    constants of ``TC_GRID_S``, then both shapes dead-time-major (``BOTH_DEAD_GRID_S`` x
    ``TC_GRID_S``), a few dead times per block so that a long log's block stays near
    ``BLOCK_ELEMENTS`` samples."""
    yield np.stack([np.interp(t - tau, t, torque, left=0.0) for tau in TAU_GRID_S], axis=0)
    n_tc = len(TC_GRID_S)
    yield first_order(t, np.repeat(torque[:, None], n_tc, axis=1), TC_GRID_S).T
    per_block = max(1, BLOCK_ELEMENTS // (n_tc * len(t)))
    for k in range(0, len(BOTH_DEAD_GRID_S), per_block):
        dead = np.stack([np.interp(t - d, t, torque, left=0.0)
                         for d in BOTH_DEAD_GRID_S[k : k + per_block]], axis=1)  # fmt: skip
        yield first_order(t, np.repeat(dead, n_tc, axis=1),
                          np.tile(TC_GRID_S, dead.shape[1])).T  # fmt: skip


def _episode_sums(
    lagged: np.ndarray, inertial: np.ndarray, r: float, episodes: list[tuple[int, int]]
) -> np.ndarray:
    """``(episodes, columns)``: each episode's sum of squared sample-to-sample changes of the
    adhesion force ``inertial + lagged / r`` (N), one column per lag of ``lagged``."""
    change2 = np.diff(inertial[None, :] + lagged / r, axis=1) ** 2
    return np.stack([change2[:, a:b].sum(axis=1) for a, b in episodes], axis=0)


def both_shapes(sums: np.ndarray, total: np.ndarray, n_tau: int, n_tc: int) -> WheelLag | None:
    """Both shapes at once where they earn both parameters (module docstring), else ``None``.
    ``sums``: per-episode sums of squared force changes over the columns dead time, first
    order, both (dead-time-major); ``total`` their means per sample pair."""
    two = total[n_tau + n_tc :].reshape(len(BOTH_DEAD_GRID_S), n_tc)
    k, j = np.unravel_index(int(np.argmin(two)), two.shape)
    dead_s, tc_s = float(BOTH_DEAD_GRID_S[k]), float(TC_GRID_S[j])
    if dead_s < RESOLUTION_S or tc_s < RESOLUTION_S:
        return None
    if k == two.shape[0] - 1 or j == two.shape[1] - 1:  # at the grid's end: not identified
        return None
    col = n_tau + n_tc + k * n_tc + j
    m = len(sums)
    for alone in (
        int(np.argmin(total[:n_tau])),
        n_tau + int(np.argmin(total[n_tau : n_tau + n_tc])),
    ):
        diff = sums[:, alone] - sums[:, col]  # per episode: how much smoother both are
        spread = float(np.std(diff, ddof=1)) if m > 1 else 0.0
        if not (diff.sum() > BOTH_Z * np.sqrt(m) * spread and spread > 0.0):
            return None
    block = sums[:, n_tau + n_tc :].reshape(m, len(BOTH_DEAD_GRID_S), n_tc)
    leave_one_out = np.array([
        BOTH_DEAD_GRID_S[np.unravel_index(int(np.argmin(block.sum(axis=0) - block[e])),
                                          block.shape[1:])[0]]
        for e in range(m)
    ])  # fmt: skip
    se = float(np.sqrt((m - 1) / m * np.sum((leave_one_out - leave_one_out.mean()) ** 2)))
    return WheelLag(dead_s, se, m, two[k], "both", tc_s)


__all__ = [
    "BOTH_DEAD_GRID_S",
    "BOTH_Z",
    "RESOLUTION_S",
    "SHAPES",
    "TAU_GRID_S",
    "TC_GRID_S",
    "WheelLag",
    "both_shapes",
    "wheel_lag",
]

"""A friction change along the rail, read plainly from the slides.

The loop's adhesion model carries a friction step as one of its extensions
(``adhesion_model.fit_adhesion_step``): a factor on the whole Eq. 9 law beyond a position,
judged against the law with a train-speed trend. On independent traces it hardly ever
qualifies (5 % of +-50 % changes in the power study of issue 11): the law's shape, its recovery
and the cleaning along the train absorb what a step would explain. This reading asks less of
the data. At the critical points where a wheel slides (sliding by ``SLIDE_KMH`` or more, past
the friction curve's peak: the points that carry the rail's level, not the creep curve's
initial slope, ``adhesion_estimate.pooled_points``), it fits::

    log mu = a_axle + b V + c [x >= x_s]

one level per axle (the rail each axle meets, cleaned by the axles ahead), a linear
train-speed trend (a rail's adhesion falls with speed: without it a step at one end of the
stop stands in for the trend) and a step ``c`` at a rail position ``x_s`` under the axle
(``adhesion_model.axle_offsets_m``), on a grid of the points' position quantiles with
``MIN_SIDE`` points or more on each side. The best step's factor ``exp(c)`` and its z
(ordinary least squares; the points are one per slide turning point, far apart in time)
decide: a change is reported when ``|log factor| >= MIN_LOG_FACTOR`` and ``|z| >= MIN_Z``.

The thresholds are set on clean traces of the independent generator's development set
(``scripts/friction_step_null.py``, seed 0: 100 clean traces on sliding rails), where a clean
rail's own variation along a stop (its roughness, its cleaning by the slides ahead) reads as
steps too; they are checked on clean sets never used to set them (docs/calibration.md).

A rail that gets better and stops the slides leaves no slide point beyond the change: there
this reading has one side only and says nothing (``None``); what is left there is the censored
evidence the adhesion model carries (``adhesion_estimate.censored_points``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wsp_env.calibration.adhesion_estimate import pooled_points
from wsp_env.calibration.adhesion_model import axle_offsets_m
from wsp_env.calibration.residuals import MIN_SPEED_KMH
from wsp_env.calibration.selection import Step
from wsp_env.calibration.traces import Trace

SLIDE_KMH = 1.0  # a critical point this much slower than the train is at a slide
STEP_GRID = 60  # candidate positions: quantiles of the slide points' rail positions
MIN_SIDE = 6  # slide points on each side of a step
MIN_POINTS = 12  # fewer slide points: no reading
# decision thresholds (module docstring: set on the development set's clean traces)
MIN_LOG_FACTOR = 0.40
MIN_Z = 6.5
# the reading's own channel: log mu at the slide points, about the fit without / with the step
CHANNEL = "slide_friction_log"


@dataclass
class StepReading:
    """The best step in ``log mu`` at a trace's slide points: how many points, the rail
    position (m, under the axle, from axle 1's position at the record's start), the factor
    beyond it, its z, and the RMS of ``log mu`` about the fit without and with the step."""

    points: int
    position_m: float
    factor: float
    z: float
    rms_without: float
    rms_with: float

    @property
    def significant(self) -> bool:
        """Over both thresholds (``MIN_LOG_FACTOR``, ``MIN_Z``)."""
        return abs(np.log(self.factor)) >= MIN_LOG_FACTOR and abs(self.z) >= MIN_Z


def step_reading(trace: Trace) -> StepReading | None:
    """The reading of the module docstring, or ``None`` where there are fewer than
    ``MIN_POINTS`` slide points or no position leaves ``MIN_SIDE`` on each side."""
    pts = pooled_points(trace, MIN_SPEED_KMH)
    at_slide = (pts.sliding_kmh >= SLIDE_KMH) & (pts.mu > 0.0)
    if at_slide.sum() < MIN_POINTS:
        return None
    axle = pts.axle[at_slide]
    rail_m = (pts.position_m - axle_offsets_m(trace)[pts.axle])[at_slide]
    speed = trace.v_train_kmh[pts.sample][at_slide] / 100.0
    y = np.log(pts.mu[at_slide])
    base = np.column_stack([(axle == a).astype(float) for a in np.unique(axle)] + [speed])
    coef0, *_ = np.linalg.lstsq(base, y, rcond=None)
    rms0 = float(np.sqrt(np.mean((y - base @ coef0) ** 2)))
    best: tuple[float, float, float, float] | None = None
    for x_s in np.unique(np.quantile(rail_m, np.linspace(0.05, 0.95, STEP_GRID))):
        beyond = (rail_m >= x_s).astype(float)
        if beyond.sum() < MIN_SIDE or (1.0 - beyond).sum() < MIN_SIDE:
            continue
        design = np.column_stack([base, beyond])
        coef, *_ = np.linalg.lstsq(design, y, rcond=None)
        e = y - design @ coef
        rss = float(e @ e)
        if best is None or rss < best[0]:
            dof = max(len(y) - design.shape[1], 1)
            se = float(np.sqrt(np.linalg.pinv(design.T @ design)[-1, -1] * rss / dof))
            best = (rss, float(x_s), float(coef[-1]), se)
    if best is None:
        return None
    rss, x_s, c, se = best
    return StepReading(int(at_slide.sum()), x_s, float(np.exp(c)), c / se if se > 0 else 0.0,
                       rms0, float(np.sqrt(rss / len(y))))  # fmt: skip


def friction_change_step(trace: Trace) -> Step | None:
    """A ``adhesion_position`` effect where the reading is significant, else ``None``. Its
    channel's error is the RMS of ``log mu`` at the slide points about the fit (without and
    with the step)."""
    reading = step_reading(trace)
    if reading is None or not reading.significant:
        return None
    step = Step(
        "friction change along the rail (slide points)",
        "adhesion_position",
        CHANNEL,
        {"step_position_m": reading.position_m, "factor_beyond_step": reading.factor},
        reading.rms_without,
        reading.rms_with,
        float("nan"),
    )
    step.confidence.update(z=reading.z, slide_points=float(reading.points))
    return step


__all__ = [
    "CHANNEL",
    "MIN_LOG_FACTOR",
    "MIN_Z",
    "StepReading",
    "friction_change_step",
    "step_reading",
]

"""What the effect-discovery loop (``discovery``) judges candidates by and records.

The Bayesian information criterion ``BIC = n ln(RSS / n) + k ln(n)`` (``bic``) and the two
gates every stage shares: a candidate must lower the BIC by more than ``MIN_DELTA_BIC`` and cut
its channel's RMSE by at least ``MIN_REDUCTION``. A ``Candidate`` is one effect's fit on one
channel; a ``Step`` an effect added, with its confidence and the alternatives that explained the
channel as well; a ``Result`` the loop's whole answer for one trace.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wsp_env.calibration.traces import Trace

MIN_DELTA_BIC = 10.0
MIN_REDUCTION = 0.2

# A qualified candidate, as the loop's stages pass it on: (relative cut, the candidate, its
# parameters, the channel's new residual, RMSE before, RMSE after, BIC gain, parameters
# counted). The candidate is a ``Candidate`` (one balance or coasting effect), a pair of balance
# force effects ``((category, parameters, RMSE after), ...)``, or an adhesion extension's key
# (its "residual" then the fit's chi2 and the recovery it re-chose).
Qualified = tuple[float, Any, dict[str, float] | None, Any, float, float, float, int]


def bic(rss: float, n: int, k: int) -> float:
    """``BIC = n ln(RSS / n) + k ln(n)`` for ``n`` samples and ``k`` parameters."""
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


@dataclass
class Candidate:
    name: str
    category: str
    channel: str
    n_params: int
    fit: Callable[[Trace, np.ndarray, np.ndarray], tuple[dict[str, float], np.ndarray]]


@dataclass
class Step:
    name: str
    category: str
    channel: str
    parameters: dict[str, float]
    before: float
    after: float
    delta_bic: float
    # how sure: the BIC gain when added, the cut against the channel's noise floor, and the BIC
    # gain of keeping it once every other effect is in (the re-test, ``retest``)
    confidence: dict[str, float] = field(default_factory=dict)
    # other effects that explained the channel as well (within the tie margin): the data alone
    # cannot tell them apart (pads and an unmeasured brake force on a stop without WSP action)
    alternatives: list[str] = field(default_factory=list)
    # declared ambiguity: the runner-up (an effect or a pair) inside the tie margin; each
    # alternative's fit (``effect``, ``parameters``, ``delta_bic``, ``after``) and, in one line,
    # the measurement that would separate them (``separating_measurement``)
    alternative_fits: list[dict[str, Any]] = field(default_factory=list)
    separate_by: str = ""

    @property
    def ambiguous(self) -> bool:
        """The trace does not decide between this effect and its ``alternatives`` (other
        categories) or another form of it (``alternative_fits`` also lists those: a dead time
        against a time constant)."""
        return bool(self.alternatives or self.alternative_fits)

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "category": self.category,
            "parameters": self.parameters,
            "channel": self.channel,
            "before": self.before,
            "after": self.after,
            "delta_bic": self.delta_bic,
            "confidence": self.confidence,
            "alternatives": self.alternatives,
            "ambiguous": self.ambiguous,
            "alternative_fits": self.alternative_fits,
            "separate_by": self.separate_by,
        }


# What separates two effects that explained a trace equally well: keyed by the pair of
# categories (either order); ``separating_measurement`` picks the line for the chosen effect
# and the runner-up. The physics of each line: where the two
# signatures differ (a force in proportion to the cylinders' vs to the demand; a constant force
# vs one growing with speed; a force present with the brake off vs one that needs it; a late
# brake vs a late ground speed).
SEPARATING: list[tuple[frozenset[str], str]] = [
    (
        frozenset({"pad_friction", "unmeasured_brake_force"}),
        "a stop on which the WSP vents (cylinders modulated against a steady demand), or one at a "
        "lower demand: pads scale the cylinders' force, an unmeasured brake follows the demand",
    ),
    (
        frozenset({"gradient", "running_resistance"}),
        "a coasting run over the same track at another speed, or the stop in the other direction: "
        "a gradient is constant and changes sign with direction, a resistance grows with speed",
    ),
    (
        frozenset({"gradient", "unmeasured_brake_force"}),
        "a coasting segment with the brake released: a gradient acts without the brake, an "
        "unmeasured brake force does not",
    ),
    (
        frozenset({"gradient", "pad_friction"}),
        "a coasting segment with the brake released, or a stop at a lower demand: a gradient acts "
        "without the brake, pads only with it",
    ),
    (
        frozenset({"running_resistance", "unmeasured_brake_force"}),
        "a coasting run from the same speed with the brake released: resistance acts without the "
        "brake, an unmeasured brake force does not",
    ),
    (
        frozenset({"running_resistance", "pad_friction"}),
        "a coasting run from the same speed with the brake released: resistance acts without the "
        "brake, pads only with it",
    ),
    (
        frozenset({"pressure_lag", "sensor"}),
        "the ground speed against a wheel left unbraked (or the receiver's latency from its data "
        "sheet): a late ground speed trails a rolling wheel, a late brake does not",
    ),
    (
        frozenset({"pressure_lag"}),
        "a step in the brake demand held for some seconds, logged at 50 Hz or faster: a dead time "
        "shifts the cylinder's answer, a first-order lag rounds it",
    ),
    (
        frozenset({"adhesion_per_axle", "load_transfer"}),
        "a stop at a different deceleration: a load transfer changes with it, an axle's own "
        "friction does not",
    ),
    (
        frozenset({"adhesion_position", "adhesion_per_axle"}),
        "a second stop over the same rail from another starting point: a change on the rail stays "
        "at its place, an axle's factor moves with the train",
    ),
]
SEPARATING_DEFAULT = (
    "a stop with another speed profile or brake demand: the candidates' signatures differ "
    "where the demand, the speed or the WSP's action change"
)


def separating_measurement(chosen: set[str], runner_up: set[str]) -> str:
    """One line naming the measurement that would separate the chosen effect's categories from
    the runner-up's (the alternative that came nearest; ``SEPARATING``): the first key with a
    category of each (one category: the same effect in two shapes)."""
    both = chosen | runner_up
    for key, line in SEPARATING:
        if len(key) == 1 and key == both:
            return line
        if len(key) > 1 and key <= both and key & chosen and key & runner_up:
            return line
    return SEPARATING_DEFAULT


@dataclass
class Result:
    errors_before: dict[str, float]
    errors_after: dict[str, float]
    added: list[Step] = field(default_factory=list)
    considered: list[dict[str, Any]] = field(default_factory=list)
    # channels still well above their noise floor once nothing more qualifies: an effect the
    # library does not hold ("other"), reported rather than forced onto a wrong category
    unexplained: list[dict[str, float | str]] = field(default_factory=list)
    # the adhesion law in the end: mu0, K, K_rozv, recovery (W_lim / W_max in kW, gain) if any
    adhesion_law: dict[str, float] = field(default_factory=dict)
    # per channel: rmse, samples, usable, reason (``plausibility.channel_health``)
    channel_health: dict[str, dict[str, Any]] = field(default_factory=dict)
    # effects added and then dropped by the re-test, with the reason
    dropped: list[dict[str, Any]] = field(default_factory=list)
    n_axles: int = 0
    # the brake's lag behind the logged pressure as the sliding wheels show it (``wheel_lag``):
    # lag_s, se_s, episodes, shape (dead_time / first_order / both; for both, time_constant_s
    # beside the dead time lag_s), verdict (late / on_time / unknown); empty where no wheel slid
    wheel_lag: dict[str, Any] = field(default_factory=dict)

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
        }


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
    # lag_s, se_s, episodes, verdict (late / on_time / unknown); empty where no wheel slid
    wheel_lag: dict[str, Any] = field(default_factory=dict)

"""Per-axle slip targets on the slip-target loop, for probes: the first N axles at a higher
target (they slide more and clean the rail for the axles behind them, seed 000 Table 4's
better-gripping rear bogie), the rest at the base target. A policy factory for
``module:callable`` (``wsp-env benchmark --policy``, ``scripts/fresh_stops.py --policy``), with
the policy's numbers in its name: ``axle_profile:pBBB_LLL_N`` is a base target of BBB/10 km/h
and LLL/10 km/h on the first N axles (``p35_100_4``: 3.5 km/h, 10 km/h on axles 1-4), on the
environment's default loop of the bound core's tier.

    PYTHONPATH=scripts .venv/bin/python scripts/fresh_stops.py --vehicle regiolis \\
        --tier wheels+accel --rail soap --draw 1200 --policy target:3.5 \\
        --policy axle_profile:p35_100_4 --policy classical
"""

from __future__ import annotations

from typing import Any

from wsp_env.baselines.slip_target import SlipTargetLoop, SlipTargetPolicy


class AxleProfile(SlipTargetPolicy):
    """``base_kmh`` on every valve but the first ``n_lead``, which hold ``lead_kmh``."""

    def __init__(self, base_kmh: float, lead_kmh: float, n_lead: int) -> None:
        super().__init__(base_kmh, SlipTargetLoop())
        self.lead_kmh, self.n_lead = float(lead_kmh), int(n_lead)
        self.name = f"axle_profile_{base_kmh:g}_{lead_kmh:g}x{n_lead}"

    def bind(self, core: Any) -> None:
        super().bind(core)
        if not 0 < self.n_lead < core.n_valves:
            raise ValueError(f"{self.name}: {self.n_lead} leading valves of {core.n_valves}")
        self.target[:, : self.n_lead] = self.lead_kmh


def __getattr__(name: str) -> Any:
    """``pBBB_LLL_N`` -> a factory of ``AxleProfile(BBB / 10, LLL / 10, N)``."""
    parts = name[1:].split("_") if name.startswith("p") else []
    if len(parts) != 3 or not all(p.isdigit() for p in parts):
        raise AttributeError(f"axle_profile has no {name!r} (pBBB_LLL_N: tenths of km/h, N axles)")
    base, lead, n = (int(p) for p in parts)
    return lambda: AxleProfile(base / 10, lead / 10, n)

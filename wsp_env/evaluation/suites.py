"""Scenario suites: cases x speeds x seeds (``configs/scenarios/*.yaml``), their pass/fail
criteria, and the runs they expand to (``expand``). ``runner.run_suite`` runs them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wsp_env.core.braking import OPTION_KEYS
from wsp_env.core.config import (
    ConfigError,
    VehicleConfig,
    configs_root,
    from_dict,
    load_vehicle,
    read_yaml,
)

# Pass/fail criteria (configurable per suite and case; EN 15595-style defaults, not normative):
# distance against the reference for the adhesion present and against dry rail, and wheel damage
# (lock found by wheel-rotation monitoring, sliding energy per axle, the longest slide) and air.
CRITERIA_KEYS = (
    "max_extension_pct",
    "max_deceleration_distance_increase_pct",
    "min_adhesion_utilisation",
    "max_lock_s",
    "max_axle_sliding_energy_kJ",
    "max_axle_sliding_energy_pct",
    "max_slide_s",
    "max_air_litres",
)
# load cases (body masses x): tare and laden at the ends of the scenario distribution (+-15 %)
LOAD_FACTORS = {"tare": 0.85, "nominal": 1.0, "laden": 1.15}


@dataclass(frozen=True)
class CaseConfig:
    name: str
    rail: str
    speeds_kmh: tuple[str, ...] = field(metadata={"nonempty": True})
    vehicle: str | None = None  # a vehicle id or file; None: the suite run's vehicle
    mu_contaminated: float | None = field(default=None, metadata={"gt": 0.0})
    pattern: str | None = field(
        default=None, metadata={"choices": ("uniform", "step_up", "step_down", "patches")}
    )
    demand: str = field(default="emergency", metadata={"choices": ("emergency", "service")})
    load: str | None = field(default=None, metadata={"choices": tuple(LOAD_FACTORS)})
    load_factor: float | None = field(default=None, metadata={"gt": 0.0})
    gradient_permille: float | None = None
    recovery_basis: str | None = field(
        default=None, metadata={"choices": ("rail_metre", "wheel_metre", "sliding_power")}
    )
    axle_mu_factor: tuple[float, ...] | None = field(default=None, metadata={"gt": 0.0})
    extra_brake_force_N: float | None = field(default=None, metadata={"ge": 0.0})
    sections: tuple[tuple[float, ...], ...] | None = None
    criteria: dict[str, float] = field(default_factory=dict)

    def validate(self, where: str) -> None:
        if self.load is not None and self.load_factor is not None:
            raise ConfigError(f"{where}.load: give load or load_factor, not both")


@dataclass(frozen=True)
class SuiteConfig:
    name: str
    description: str
    seeds: tuple[int, ...] = field(metadata={"nonempty": True})
    cases: tuple[CaseConfig, ...] = field(metadata={"nonempty": True})
    criteria: dict[str, float] = field(default_factory=dict)

    def validate(self, where: str) -> None:
        prefix = f"{where}." if where else ""
        for key in self.criteria:
            if key not in CRITERIA_KEYS:
                raise ConfigError(
                    f"{prefix}criteria.{key}: unknown (one of {', '.join(CRITERIA_KEYS)})"
                )
        for i, case in enumerate(self.cases):
            for key in case.criteria:
                if key not in CRITERIA_KEYS:
                    raise ConfigError(f"{prefix}cases[{i}].criteria.{key}: unknown criterion")
            for s in case.speeds_kmh:
                if s != "max":
                    try:
                        ok = float(s) > 0
                    except ValueError:
                        ok = False
                    if not ok:
                        raise ConfigError(
                            f"{prefix}cases[{i}].speeds_kmh: {s!r} is not a speed or 'max'"
                        )


def load_suite(name_or_path: str) -> SuiteConfig:
    """A suite by name (``quick``, ``en15595``, ``heldout``) or YAML path."""
    p = Path(name_or_path)
    if p.suffix not in (".yaml", ".yml"):
        p = configs_root() / "scenarios" / f"{name_or_path}.yaml"
        if not p.exists():
            known = sorted(q.stem for q in (configs_root() / "scenarios").glob("*.yaml"))
            raise ConfigError(f"suite: unknown suite {name_or_path!r} (known: {', '.join(known)})")
    elif not p.exists():
        raise ConfigError(f"{p}: no such file")
    data = read_yaml(p)
    if isinstance(data, dict):  # YAML reads bare numbers in speeds_kmh as numbers
        for case in data.get("cases", []) or []:
            if isinstance(case, dict) and isinstance(case.get("speeds_kmh"), list):
                case["speeds_kmh"] = [str(s) for s in case["speeds_kmh"]]
    try:
        return from_dict(SuiteConfig, data)
    except ConfigError as err:
        raise ConfigError(f"{p}: {err}") from None


@dataclass(frozen=True)
class Run:
    scenario: str
    seed: int
    options: dict[str, Any]
    criteria: dict[str, float]
    vehicle: VehicleConfig


def expand(suite: SuiteConfig, vehicle: VehicleConfig) -> list[Run]:
    """Cases x speeds x seeds, in a fixed order (a case may name its own vehicle)."""
    runs = []
    vehicles: dict[str, VehicleConfig] = {}
    for case in suite.cases:
        veh = vehicle
        if case.vehicle is not None:
            veh = vehicles.setdefault(case.vehicle, load_vehicle(case.vehicle))
        for s in case.speeds_kmh:
            speed = veh.max_speed_kmh if s == "max" else float(s)
            name = f"{case.name}_{round(speed)}"
            options: dict[str, Any] = {"rail": case.rail, "speed_kmh": speed, "demand": case.demand}
            if case.load is not None:
                options["load_factor"] = LOAD_FACTORS[case.load]
            for key in (
                "mu_contaminated", "pattern", "load_factor", "gradient_permille",
                "recovery_basis", "axle_mu_factor", "extra_brake_force_N", "sections",
            ):  # fmt: skip
                value = getattr(case, key)
                if value is not None:
                    options[key] = value
            assert set(options) <= set(OPTION_KEYS)
            criteria = {**suite.criteria, **case.criteria}
            runs.extend(Run(name, seed, options, criteria, veh) for seed in suite.seeds)
    return runs


def with_option(suite: SuiteConfig, **changes: Any) -> SuiteConfig:
    """A copy of ``suite`` with every case changed (e.g. ``mu_contaminated``)."""
    cases = tuple(dataclasses.replace(c, **changes) for c in suite.cases)
    return dataclasses.replace(suite, cases=cases)

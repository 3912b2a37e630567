"""Scenario suites: cases x speeds x seeds (``configs/scenarios/*.yaml``), their pass/fail
criteria, and the runs they expand to (``expand``). ``runner.run_suite`` runs them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wsp_env.core.braking import OPTION_KEYS
from wsp_env.core.config import (
    OPTION_SPECS,
    ConfigError,
    VehicleConfig,
    check_option,
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


def _option(name: str) -> Any:
    """An optional case field with the environment option's bounds (``config.OPTION_SPECS``)."""
    return field(default=None, metadata=dict(OPTION_SPECS[name].bounds))


# the case fields that are environment options of the same name (``expand`` passes them on)
CASE_OPTIONS = (
    "mu_contaminated", "pattern", "load_factor", "gradient_permille", "recovery_basis",
    "axle_mu_factor", "extra_brake_force_N", "sections", "accelerometer_bias_mps2",
    "wheel_speed_noise_kmh",
)  # fmt: skip


@dataclass(frozen=True)
class CaseConfig:
    name: str
    rail: str
    speeds_kmh: tuple[str, ...] = field(metadata={"nonempty": True})
    vehicle: str | None = None  # a vehicle id or file; None: the suite run's vehicle
    mu_contaminated: float | None = _option("mu_contaminated")
    pattern: str | None = _option("pattern")
    demand: str = field(default="emergency", metadata=OPTION_SPECS["demand"].bounds)
    load: str | None = field(default=None, metadata={"choices": tuple(LOAD_FACTORS)})
    load_factor: float | None = _option("load_factor")
    gradient_permille: float | None = _option("gradient_permille")
    recovery_basis: str | None = _option("recovery_basis")
    axle_mu_factor: tuple[float, ...] | None = _option("axle_mu_factor")
    extra_brake_force_N: float | None = _option("extra_brake_force_N")
    sections: tuple[tuple[float, ...], ...] | None = None  # checked whole in ``validate``
    # the stop's sensor errors (core.sensors); the bias needs an accelerometer to act on
    accelerometer_bias_mps2: float | None = _option("accelerometer_bias_mps2")
    wheel_speed_noise_kmh: float | None = _option("wheel_speed_noise_kmh")
    criteria: dict[str, float] = field(default_factory=dict)

    def validate(self, where: str) -> None:
        if self.load is not None and self.load_factor is not None:
            raise ConfigError(f"{where}.load: give load or load_factor, not both")
        prefix = f"{where}." if where else ""
        for key in CASE_OPTIONS:  # the options' own checks (a section's shape, ...)
            value = getattr(self, key)
            if value is not None:
                check_option(key, value, where=prefix + key)


def _speed(s: str, veh: VehicleConfig | None, where: str) -> float:
    """A case's speed entry (a number or ``max``) in km/h; with ``veh`` at most its maximum."""
    if s == "max" and veh is not None:
        return veh.max_speed_kmh
    try:
        v = check_option("speed_kmh", s, where=where)
    except ConfigError:
        raise ConfigError(f"{where}: {s!r} is not a speed (a finite number > 0) or 'max'") from None
    if veh is not None and v > veh.max_speed_kmh:
        raise ConfigError(
            f"{where} {v:g} km/h exceeds {veh.id}'s maximum {veh.max_speed_kmh:g} km/h"
        )
    return v


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
        for i, seed in enumerate(self.seeds):
            if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
                raise ConfigError(f"{prefix}seeds[{i}]: must be a whole number >= 0, got {seed!r}")
        if len(set(self.seeds)) < len(self.seeds):  # their runs would merge in the results
            raise ConfigError(f"{prefix}seeds: {list(self.seeds)} repeats a seed")
        first: dict[str, int] = {}
        for i, case in enumerate(self.cases):
            if case.name in first:  # their runs would merge in the results
                raise ConfigError(
                    f"{prefix}cases[{i}].name: {case.name!r} repeats cases[{first[case.name]}]'s "
                    "(case names must be unique)"
                )
            first[case.name] = i
            for key in case.criteria:
                if key not in CRITERIA_KEYS:
                    raise ConfigError(f"{prefix}cases[{i}].criteria.{key}: unknown criterion")
            for s in case.speeds_kmh:
                if s != "max":
                    _speed(s, None, f"{prefix}cases[{i}].speeds_kmh")


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
    """Cases x speeds x seeds, in a fixed order (a case may name its own vehicle).

    Each case is checked against the vehicle it runs on (speeds at most its maximum, one
    ``axle_mu_factor`` per axle, the options' bounds: ``config.OPTION_SPECS``), and no two
    runs may share a name (their results would merge): a ``ConfigError`` naming the suite,
    the case and the problem, e.g. ``suite quick: case soap_low: speed 1e+09 km/h exceeds
    uic_z1's maximum 200 km/h``."""
    runs = []
    vehicles: dict[str, VehicleConfig] = {}
    made: dict[str, tuple[str, str, float]] = {}  # run name -> (case, speed entry, km/h)
    for case in suite.cases:
        veh = vehicle
        if case.vehicle is not None:
            veh = vehicles.setdefault(case.vehicle, load_vehicle(case.vehicle))
        here = f"suite {suite.name}: case {case.name}"
        for key in CASE_OPTIONS:
            value = getattr(case, key)
            if value is not None:
                try:
                    check_option(key, value, veh, where=key)
                except ConfigError as err:
                    raise ConfigError(f"{here}: {err}") from None
        for s in case.speeds_kmh:
            speed = _speed(s, veh, f"{here}: speed")
            name = f"{case.name}_{round(speed)}"
            if name in made:
                other, entry, km_h = made[name]
                if other == case.name and km_h == speed:  # 'max' is a listed speed: one run
                    continue
                raise ConfigError(
                    f"{here}: speed {s} makes run {name} on {veh.id}, as case {other} speed "
                    f"{entry} does (runs of one name would merge in the results)"
                )
            made[name] = (case.name, s, speed)
            options: dict[str, Any] = {"rail": case.rail, "speed_kmh": speed, "demand": case.demand}
            if case.load is not None:
                options["load_factor"] = LOAD_FACTORS[case.load]
            for key in CASE_OPTIONS:
                value = getattr(case, key)
                if value is not None:
                    options[key] = value
            assert set(options) <= set(OPTION_KEYS)
            criteria = {**suite.criteria, **case.criteria}
            runs.extend(Run(name, seed, options, criteria, veh) for seed in suite.seeds)
    return runs

"""Typed configuration: YAML files -> frozen dataclasses, validated on load.

Every problem raises :class:`ConfigError` with one line that names the file, the field (as a
dotted path) and what is wrong, e.g. ``configs/vehicles/x.yaml: brake.p_max_bar: must be > 0``.
Unknown fields are errors too (a typo must not silently fall back to a default).

Environment options (``reset(options=...)``, suite cases, CLI flags) are checked against one
table, ``OPTION_SPECS``, by :func:`check_option` / :func:`check_options`, with the bounds of the
YAML fields they share (``field_bounds``).

Built-in configs live in the repository's ``configs/`` folder, installed as the package
``wsp_env.configs``; a vehicle or rail can be given by id (``uic_z1``) or by a path to a file.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import numbers
import types
import typing
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from wsp_env.core.records import CONTAMINANTS  # the trace format's vocabulary of contaminants


class ConfigError(ValueError):
    """A configuration problem; ``str(err)`` is the one-line message for the user."""


# ---- generic dataclass loading --------------------------------------------------------------


def _check_number(value: Any, where: str, spec: dict[str, Any]) -> float:
    if isinstance(value, str):  # YAML 1.1 reads "5.0e7" (no exponent sign) as a string
        try:
            value = float(value)
        except ValueError:
            raise ConfigError(f"{where}: expected a number, got {value!r}") from None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{where}: expected a number, got {value!r}")
    v = float(value)
    if math.isnan(v):
        raise ConfigError(f"{where}: is NaN")
    if math.isinf(v) and not spec.get("inf", False):
        raise ConfigError(f"{where}: must be finite")
    if "gt" in spec and not v > spec["gt"]:
        raise ConfigError(f"{where}: must be > {spec['gt']}, got {v:g}")
    if "ge" in spec and not v >= spec["ge"]:
        raise ConfigError(f"{where}: must be >= {spec['ge']}, got {v:g}")
    if "le" in spec and not v <= spec["le"]:
        raise ConfigError(f"{where}: must be <= {spec['le']}, got {v:g}")
    return v


def _convert(tp: Any, value: Any, where: str, spec: dict[str, Any]) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        return _convert(args[0], value, where, spec)
    if dataclasses.is_dataclass(tp):
        return from_dict(tp, value, where)
    if origin is tuple:
        item_tp = typing.get_args(tp)[0]
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if "len" in spec and len(value) != spec["len"]:
            raise ConfigError(f"{where}: expected {spec['len']} items, got {len(value)}")
        if spec.get("nonempty") and not value:
            raise ConfigError(f"{where}: must not be empty")
        return tuple(_convert(item_tp, v, f"{where}[{i}]", spec) for i, v in enumerate(value))
    if origin is dict:
        val_tp = typing.get_args(tp)[1]
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: expected a mapping, got {value!r}")
        return {str(k): _convert(val_tp, v, f"{where}.{k}", spec) for k, v in value.items()}
    if tp is float:
        return _check_number(value, where, spec)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        _check_number(value, where, spec)
        return int(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        if "choices" in spec and value not in spec["choices"]:
            raise ConfigError(f"{where}: {value!r} is not one of {', '.join(spec['choices'])}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    raise TypeError(f"unsupported config type {tp!r} at {where}")


def from_dict(cls: type, data: Any, where: str = "") -> Any:
    """Build dataclass ``cls`` from a mapping, checking names, types and ``metadata`` bounds."""
    prefix = f"{where}." if where else ""
    if not isinstance(data, dict):
        raise ConfigError(f"{where or '(top level)'}: expected a mapping, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ConfigError(
            f"{prefix}{unknown[0]}: unknown field (allowed: {', '.join(sorted(names))})"
        )
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name not in data:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise ConfigError(f"{prefix}{f.name}: missing required field")
            continue
        kwargs[f.name] = _convert(hints[f.name], data[f.name], prefix + f.name, dict(f.metadata))
    obj = cls(**kwargs)
    check = getattr(obj, "validate", None)
    if check is not None:
        check(where)
    return obj


def _pos(default: Any = dataclasses.MISSING, **extra: Any) -> Any:
    return field(default=default, metadata={"gt": 0.0, **extra})


def _nonneg(default: Any = dataclasses.MISSING, **extra: Any) -> Any:
    return field(default=default, metadata={"ge": 0.0, **extra})


# ---- vehicle --------------------------------------------------------------------------------


@dataclass(frozen=True)
class CarConfig:
    body_mass_kg: float = _pos()
    cog_height_m: float = _pos()
    bogies: tuple[int, ...] = field(metadata={"len": 2, "ge": 0})


@dataclass(frozen=True)
class BogieConfig:
    position_m: float = _nonneg()
    wheelbase_m: float = _pos()
    frame_mass_kg: float = _pos()
    frame_cog_height_m: float = _pos()
    pivot_height_m: float = _pos()
    n_axles: int = field(default=2, metadata={"ge": 1})
    # electrodynamic brake force at the wheel per axle of a motor bogie at full demand (kN);
    # blended: it follows the axle's friction brake (the WSP valve modulates both together)
    ed_brake_force_kN: float = _nonneg(default=0.0)


@dataclass(frozen=True)
class DiscChainConfig:
    """Seed 000 Eqs. 3–6 (see ``physics.brake.DiscBrakeChain``)."""

    thrust_area_cm2: float = _pos()
    cylinder_spring_N: float = _nonneg()
    cylinder_ratio: float = _pos()
    cylinder_efficiency: float = _pos(le=1.0)
    slack_adjuster_spring_N: float = _nonneg()
    rear_nut_spring_N: float = _nonneg()
    caliper_ratio: float = _pos()
    caliper_efficiency: float = _pos(le=1.0)
    pad_friction: float = _pos(le=1.0)
    discs_per_axle: int = field(metadata={"ge": 1})
    friction_radius_m: float = _pos()
    transmission_ratio: float = _pos(default=1.0)


@dataclass(frozen=True)
class BrakeConfig:
    p_max_bar: float = _pos()
    cylinder_volume_l: float = _pos()
    fill_tau_s: float = _nonneg()
    fill_rate_bar_per_s: float = _pos()
    vent_tau_s: float = _nonneg()
    vent_rate_bar_per_s: float = _pos()
    valve_dead_time_s: float = _nonneg()
    demand_delay_s: float = _nonneg()
    demand_rise_s: float = _nonneg()
    torque_gain_Nm_per_bar: float | None = field(default=None, metadata={"gt": 0.0})
    p_threshold_bar: float | None = field(default=None, metadata={"ge": 0.0})
    disc_chain: DiscChainConfig | None = None
    valve_group: str = field(default="axle", metadata={"choices": ("axle", "bogie")})
    pad_speed_coeff_per_kmh: float = 0.0
    pad_ref_speed_kmh: float = _nonneg(default=100.0)

    def validate(self, where: str) -> None:
        linear = self.torque_gain_Nm_per_bar is not None
        if linear == (self.disc_chain is not None):
            raise ConfigError(
                f"{where}.torque_gain_Nm_per_bar: give either torque_gain_Nm_per_bar "
                "(+ p_threshold_bar) or disc_chain, not both or neither"
            )
        if linear and self.p_threshold_bar is None:
            raise ConfigError(
                f"{where}.p_threshold_bar: missing (needed with torque_gain_Nm_per_bar)"
            )

    def linear_torque(self) -> tuple[float, float]:
        """``(gain_Nm_per_bar, p_threshold_bar)`` of the brake torque."""
        if self.disc_chain is not None:
            from wsp_env.physics.brake import DiscBrakeChain

            return DiscBrakeChain(**dataclasses.asdict(self.disc_chain)).linear_form()
        assert self.torque_gain_Nm_per_bar is not None and self.p_threshold_bar is not None
        return self.torque_gain_Nm_per_bar, self.p_threshold_bar


@dataclass(frozen=True)
class ResistanceConfig:
    """Davis running resistance ``A + B v + C v^2`` of the whole train (v in m/s)."""

    a_N: float = _nonneg()
    b_N_per_mps: float = _nonneg()
    c_N_per_mps2: float = _nonneg()


@dataclass(frozen=True)
class ContactConfig:
    rail_crown_radius_m: float = _pos(default=0.3)
    wheel_transverse_radius_m: float = field(default=math.inf, metadata={"gt": 0.0, "inf": True})
    youngs_modulus_Pa: float = _pos(default=2.1e11)
    poisson: float = field(default=0.3, metadata={"gt": 0.0, "le": 0.49})


@dataclass(frozen=True)
class VehicleConfig:
    id: str
    name: str
    source: str
    max_speed_kmh: float = _pos()
    wheel_radius_m: float = _pos()
    wheelset_inertia_kgm2: float = _pos()
    wheelset_mass_kg: float = _pos()
    cars: tuple[CarConfig, ...] = field(metadata={"nonempty": True})
    bogies: tuple[BogieConfig, ...] = field(metadata={"nonempty": True})
    brake: BrakeConfig
    resistance: ResistanceConfig
    contact: ContactConfig = field(default_factory=ContactConfig)

    def validate(self, where: str) -> None:
        prefix = f"{where}." if where else ""
        n = len(self.bogies)
        for i, car in enumerate(self.cars):
            f, r = car.bogies
            if f >= n or r >= n:
                raise ConfigError(f"{prefix}cars[{i}].bogies: index out of range (0..{n - 1})")
            if self.bogies[r].position_m <= self.bogies[f].position_m:
                raise ConfigError(f"{prefix}cars[{i}].bogies: rear bogie must stand behind front")
        pos = [b.position_m for b in self.bogies]
        if any(b <= a for a, b in itertools.pairwise(pos)):
            raise ConfigError(f"{prefix}bogies: positions must increase in running order")
        # each bogie's axles (wheelbase_m apart, centred on its position) behind the one's ahead
        for i, (ahead, behind) in enumerate(itertools.pairwise(self.bogies), start=1):
            last = ahead.position_m + ahead.wheelbase_m * (ahead.n_axles - 1) / 2
            first = behind.position_m - behind.wheelbase_m * (behind.n_axles - 1) / 2
            if first <= last:
                raise ConfigError(
                    f"{prefix}bogies[{i}]: its first axle ({first:g} m) is not behind the last "
                    f"axle of bogies[{i - 1}] ({last:g} m)"
                )
        carried = {b for car in self.cars for b in car.bogies}
        if carried != set(range(n)):
            missing = sorted(set(range(n)) - carried)
            raise ConfigError(f"{prefix}bogies[{missing[0]}]: carries no car body")

    @property
    def n_axles(self) -> int:
        return sum(b.n_axles for b in self.bogies)


# ---- rail / contaminant ---------------------------------------------------------------------

LAWS = ("polach", "polach_simple", "seed002")

PATTERNS = ("uniform", "step_up", "step_down", "patches")

# The lowest friction level a rail may have: leaf films, the slipperiest rail measured, give
# about 0.01-0.03; near zero the creep-force laws lose all precision (a level of 1e-20 gives
# NaN forces), so levels below 0.001 are refused as no rail at all.
MU_MIN = 0.001


@dataclass(frozen=True)
class RecoveryConfig:
    """Seed 002 Eqs. 9–14. ``w_lim = inf`` disables recovery."""

    w_lim: float = field(metadata={"ge": 0.0, "inf": True})
    w_max: float = field(metadata={"gt": 0.0, "inf": True})
    gain: float = field(default=1.25, metadata={"ge": 1.0})
    tau_s: float = _pos(default=0.1)
    zeta: float = _pos(default=1.0)
    basis: str = field(
        default="sliding_power",
        metadata={"choices": ("rail_metre", "wheel_metre", "sliding_power")},
    )

    def validate(self, where: str) -> None:
        if math.isfinite(self.w_lim) and not self.w_max > self.w_lim:
            raise ConfigError(f"{where}.w_max: must exceed w_lim ({self.w_lim:g})")


@dataclass(frozen=True)
class RailConfig:
    """One rail condition: creep law, friction levels, cleaning, recovery and its randomisation."""

    law: str = field(metadata={"choices": LAWS})
    law_params: dict[str, float]
    mu_clean: float = field(metadata={"ge": MU_MIN, "le": 1.0})
    mu_contaminated: float = field(metadata={"ge": MU_MIN, "le": 1.0})
    mu_contaminated_range: tuple[float, ...] = field(metadata={"len": 2, "ge": MU_MIN, "le": 1.0})
    contamination: float = field(metadata={"ge": 0.0, "le": 1.0})
    clean_energy_J_per_m: float = field(metadata={"gt": 0.0, "inf": True})
    pass_removal: float = field(default=0.0, metadata={"ge": 0.0, "le": 1.0})
    recovery: RecoveryConfig = field(
        default_factory=lambda: RecoveryConfig(w_lim=math.inf, w_max=math.inf)
    )
    patterns: dict[str, float] = field(default_factory=lambda: {"uniform": 1.0})
    # creep stiffness of the contaminated contact / Kalker's (physics/rail.py)
    creep_stiffness_factor: float = field(default=1.0, metadata={"gt": 0.0, "le": 1.0})
    # the trace format's name for this rail's contaminant; None: the rail's own name if it is one
    contaminant: str | None = field(default=None, metadata={"choices": CONTAMINANTS})

    _LAW_KEYS: typing.ClassVar[dict[str, tuple[str, ...]]] = {
        "polach": ("kA", "kS", "A", "B"),
        "polach_simple": ("K", "K_rozv_per_kmh"),
        "seed002": ("K_red", "lambda", "A", "B"),
    }
    # optional law parameters and their defaults (seed002: no sliding-speed fall-off)
    _LAW_DEFAULTS: typing.ClassVar[dict[str, dict[str, float]]] = {"seed002": {"A": 1.0, "B": 0.0}}

    def validate(self, where: str) -> None:
        prefix = f"{where}." if where else ""
        need = self._LAW_KEYS[self.law]
        optional = self._LAW_DEFAULTS.get(self.law, {})
        for key in need:
            if key not in self.law_params and key not in optional:
                raise ConfigError(f"{prefix}law_params.{key}: missing for law {self.law}")
        for key in self.law_params:
            if key not in need:
                raise ConfigError(f"{prefix}law_params.{key}: unknown for law {self.law}")
            if not self.law_params[key] >= 0:
                raise ConfigError(f"{prefix}law_params.{key}: must be >= 0")
            if key == "A" and self.law_params[key] > 1:
                raise ConfigError(f"{prefix}law_params.A: must be <= 1 (a fraction of mu0)")
        lo, hi = self.mu_contaminated_range
        if lo > hi:
            raise ConfigError(f"{prefix}mu_contaminated_range: low end exceeds high end")
        for name, weight in self.patterns.items():
            if name not in PATTERNS:
                raise ConfigError(
                    f"{prefix}patterns.{name}: unknown (one of {', '.join(PATTERNS)})"
                )
            if weight < 0:
                raise ConfigError(f"{prefix}patterns.{name}: weight must be >= 0")
        if not sum(self.patterns.values()) > 0:
            raise ConfigError(f"{prefix}patterns: weights must not all be zero")

    def contaminant_name(self, rail_name: str) -> str:
        """The contaminant of rail ``rail_name`` as a trace's metadata names it."""
        if self.contaminant is not None:
            return self.contaminant
        return rail_name if rail_name in CONTAMINANTS else "unknown"

    def law_vector(self) -> tuple[float, float, float, float]:
        defaults = self._LAW_DEFAULTS.get(self.law, {})
        vals = [self.law_params.get(k, defaults.get(k)) for k in self._LAW_KEYS[self.law]]
        return tuple(vals + [0.0] * (4 - len(vals)))  # type: ignore[return-value]


# ---- environment options: one table of bounds -----------------------------------------------
#
# What ``reset(options=...)`` may fix (``core.braking.BrakingCore.draw_setup``), what a
# ``core.simulator.RunSetup`` holds, what a scenario suite's case sets (``evaluation.suites``)
# and what the CLI's flags give are all checked against ``OPTION_SPECS``; where the YAML schema
# has the same quantity (a rail's adhesion level, its contamination level, the recovery basis)
# the bounds are that field's metadata, so the two cannot drift apart.


def field_bounds(cls: type, name: str) -> dict[str, Any]:
    """The ``metadata`` (bounds, choices) of dataclass field ``name`` of ``cls`` (a copy)."""
    for f in dataclasses.fields(cls):
        if f.name == name:
            return dict(f.metadata)
    raise KeyError(f"{cls.__name__} has no field {name!r}")


# Gradients: the steepest adhesion-worked lines run at 70-90 per mille (Bernina 70, Uetliberg
# 79); steeper lines are rack railways, where the rack, not the wheel-rail adhesion a WSP
# manages, holds the train, so adhesion braking is meaningless there. |g| <= 100 per mille
# keeps every adhesion railway and refuses typos (a gradient in per cent or in degrees x 1000).
GRADIENT_LIMIT_PERMILLE = 100.0
# Per-axle adhesion factors R_i (seed 002 Fig. 8: cleaning raises the level of trailing axles
# by tens of per cent): a factor above 2 would more than double an axle's friction level, one
# below 0.01 would take it to nothing (and the level times R_i below MU_MIN's precision).
AXLE_MU_FACTOR_MIN = 0.01
AXLE_MU_FACTOR_MAX = 2.0
# Body masses x load_factor: crush-laden multiple units reach about 1.5 x their nominal body
# mass; 3 is beyond any vehicle. Pad friction x pad_factor: new or wet pads differ from the
# nominal coefficient by tens of per cent; 3 would triple it.
LOAD_FACTOR_MAX = 3.0
PAD_FACTOR_MAX = 3.0
DEMANDS = ("emergency", "service")
_LEVEL = field_bounds(RailConfig, "contamination")  # a contamination level, [0, 1]


@dataclass(frozen=True)
class OptionSpec:
    """How one environment option is checked: ``kind`` is ``number``, ``choice`` (a string of
    ``bounds["choices"]``), ``name`` (a non-empty string), ``factors`` (one number per axle)
    or ``sections`` (``(start_m, end_m, level)`` rows); ``bounds`` as dataclass field metadata
    (``gt`` / ``ge`` / ``le`` / ``choices``); ``nullable``: None is a value (the rail's or the
    draw's own)."""

    kind: str
    bounds: dict[str, Any] = field(default_factory=dict)
    nullable: bool = False
    help: str = ""


OPTION_SPECS: dict[str, OptionSpec] = {
    "speed_kmh": OptionSpec(  # below 1 km/h a stop is over before the first record
        "number", {"ge": 1.0}, help="initial speed (km/h), 1 to the vehicle's maximum"
    ),
    "rail": OptionSpec("name", help="a rail condition of the rail table in use"),
    "mu_contaminated": OptionSpec(
        "number", field_bounds(RailConfig, "mu_contaminated"), nullable=True,
        help="the contaminated adhesion level (None: the rail's nominal one)",
    ),
    "pattern": OptionSpec(
        "choice", {"choices": PATTERNS}, nullable=True, help="spatial pattern (None: drawn)"
    ),
    "load_factor": OptionSpec(
        "number", {"gt": 0.0, "le": LOAD_FACTOR_MAX}, help="body masses x this"
    ),
    "pad_factor": OptionSpec(
        "number", {"gt": 0.0, "le": PAD_FACTOR_MAX}, help="actual / nominal pad friction"
    ),
    "gradient_permille": OptionSpec(
        "number", {"ge": -GRADIENT_LIMIT_PERMILLE, "le": GRADIENT_LIMIT_PERMILLE},
        help="gradient (per mille, > 0 uphill)",
    ),
    "demand": OptionSpec("choice", {"choices": DEMANDS}, help="brake demand"),
    "sections": OptionSpec(
        "sections", _LEVEL, help="contaminated stretches (start_m, end_m, level in [0, 1])"
    ),
    "axle_mu_factor": OptionSpec(
        "factors", {"ge": AXLE_MU_FACTOR_MIN, "le": AXLE_MU_FACTOR_MAX}, nullable=True,
        help="per-axle adhesion factors R_i, one per axle (None: all 1)",
    ),
    "recovery_basis": OptionSpec(
        "choice", {"choices": field_bounds(RecoveryConfig, "basis")["choices"]}, nullable=True,
        help="override the rail's recovery basis (None: the rail's)",
    ),
    "background": OptionSpec(
        "number", _LEVEL, nullable=True,
        help="contamination level outside the sections (None: the rail's)",
    ),
    # the stop's sensor errors (core.sensors): fixed exactly instead of drawn
    "accelerometer_bias_mps2": OptionSpec(
        "number", {"ge": -2.0, "le": 2.0},
        help="the accelerometer's bias (m/s^2, > 0 reads more deceleration), within +-2",
    ),
    "wheel_speed_noise_kmh": OptionSpec(
        "number", {"ge": 0.0, "le": 10.0},
        help="standard deviation of a wheel-speed reading (km/h), 0 to 10",
    ),
    "extra_brake_force_N": OptionSpec(  # a magnetic track brake gives ~80 kN per bogie
        "number", {"ge": 0.0, "le": 1e6}, help="brake force not through the wheels at full "
        "demand (N), at most 1 MN"
    ),
}  # fmt: skip


def _interval(spec: dict[str, Any]) -> str:
    lo = f"({spec['gt']:g}" if "gt" in spec else f"[{spec['ge']:g}" if "ge" in spec else "(-inf"
    hi = f"{spec['le']:g}]" if "le" in spec else "inf)"
    return f"{lo}, {hi}"


def check_number(value: Any, where: str, **bounds: Any) -> float:
    """``value`` as a finite float within ``bounds`` (``gt`` / ``ge`` / ``le``, as field
    metadata; ``inf=True`` lets it be infinite), or :class:`ConfigError` naming ``where``.
    Numbers of any type (numpy's too, 0-d arrays included) and numeric strings are accepted;
    booleans are not."""
    if getattr(value, "ndim", None) == 0 and hasattr(value, "item"):  # a 0-d numpy array
        value = value.item()
    if isinstance(value, bool) or not isinstance(value, str | numbers.Real):
        raise ConfigError(f"{where}: expected a number, got {value!r}")
    try:
        v = float(value)
    except ValueError:  # a string that is not a number
        raise ConfigError(f"{where}: expected a number, got {value!r}") from None
    except OverflowError:  # an integer beyond float's range
        v = math.inf if value > 0 else -math.inf
    ok = (
        not math.isnan(v)
        and (math.isfinite(v) or bool(bounds.get("inf", False)))
        and ("gt" not in bounds or v > bounds["gt"])
        and ("ge" not in bounds or v >= bounds["ge"])
        and ("le" not in bounds or v <= bounds["le"])
    )
    if not ok:
        if "le" in bounds:
            need = f"in {_interval(bounds)}"
        else:
            need = "a number" if bounds.get("inf", False) else "a finite number"
            if "gt" in bounds or "ge" in bounds:
                op = ">" if "gt" in bounds else ">="
                need += f" {op} {bounds.get('gt', bounds.get('ge')):g}"
        raise ConfigError(f"{where}: must be {need}, got {v:g}")
    return v


def _check_sequence(value: Any, where: str) -> list[Any]:
    if isinstance(value, str | bytes | Mapping) or not isinstance(value, Iterable):
        raise ConfigError(f"{where}: expected a list, got {value!r}")
    return list(value)


def check_option(
    name: str, value: Any, vehicle: VehicleConfig | None = None, where: str | None = None
) -> Any:
    """Check one environment option (``OPTION_SPECS``) and return its converted value.

    ``name`` is an option of ``reset(options=...)``; ``value`` its value; with ``vehicle`` the
    checks that need one are made too (``speed_kmh`` at most its maximum, ``axle_mu_factor``
    one entry per axle). Returns a float for numbers (numeric strings too), the string for
    choices and names, a tuple of floats for ``axle_mu_factor``, a tuple of
    ``(start_m, end_m, level)`` float tuples for ``sections``, None where None is a value.
    Raises :class:`ConfigError` (a ``ValueError``) with one line naming ``where`` (default
    ``options.<name>``), e.g. ``options.mu_contaminated: must be in [0.001, 1], got nan``.
    """
    where = f"options.{name}" if where is None else where
    spec = OPTION_SPECS.get(name)
    if spec is None:
        raise ConfigError(f"{where}: unknown option (allowed: {', '.join(OPTION_SPECS)})")
    if value is None and spec.nullable:
        return None
    b = spec.bounds
    if spec.kind == "number":
        v = check_number(value, where, **b)
        if name == "speed_kmh" and vehicle is not None and v > vehicle.max_speed_kmh:
            raise ConfigError(
                f"{where}: {v:g} km/h exceeds {vehicle.id}'s maximum {vehicle.max_speed_kmh:g} km/h"
            )
        return v
    if spec.kind in ("choice", "name"):
        if not isinstance(value, str) or not value:
            raise ConfigError(f"{where}: expected a name, got {value!r}")
        if spec.kind == "choice" and value not in b["choices"]:
            raise ConfigError(f"{where}: {value!r} is not one of {', '.join(b['choices'])}")
        return value
    items = _check_sequence(value, where)
    if spec.kind == "factors":
        if not items:
            raise ConfigError(f"{where}: must not be empty")
        if vehicle is not None and len(items) != vehicle.n_axles:
            raise ConfigError(
                f"{where}: expected {vehicle.n_axles} entries (one per axle of {vehicle.id}), "
                f"got {len(items)}"
            )
        return tuple(check_number(x, f"{where}[{i}]", **b) for i, x in enumerate(items))
    assert spec.kind == "sections"
    # imported here, not at the top: loading a YAML config needs no physics (its JIT cache)
    from wsp_env.physics.layout import MAX_SECTIONS

    if len(items) > MAX_SECTIONS:
        raise ConfigError(f"{where}: at most {MAX_SECTIONS} sections, got {len(items)}")
    out = []
    for i, row in enumerate(items):
        here = f"{where}[{i}]"
        cells = _check_sequence(row, here)
        if len(cells) != 3:
            raise ConfigError(f"{here}: expected (start_m, end_m, level), got {row!r}")
        start = check_number(cells[0], f"{here}[0]", inf=True)  # may be open-ended
        end = check_number(cells[1], f"{here}[1]", inf=True)
        if not end > start:
            raise ConfigError(f"{here}: end_m must exceed start_m, got {start:g} .. {end:g}")
        out.append((start, end, check_number(cells[2], f"{here}[2]", **b)))
    return tuple(out)


def check_options(
    options: Mapping[str, Any] | None, vehicle: VehicleConfig | None = None, where: str = "options"
) -> dict[str, Any]:
    """Every entry of ``options`` through :func:`check_option` (names as ``where.<name>``);
    unknown names are refused. Returns the converted options (a new dict, same order)."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise ConfigError(f"{where}: expected a mapping, got {options!r}")
    return {str(k): check_option(str(k), v, vehicle, f"{where}.{k}") for k, v in options.items()}


# ---- file loading ---------------------------------------------------------------------------


def configs_root() -> Path:
    """The built-in configs folder (``wsp_env.configs`` package, or ./configs in a checkout)."""
    try:
        return Path(str(resources.files("wsp_env.configs")))
    except ModuleNotFoundError:  # running from a source tree without installing
        return Path(__file__).resolve().parent.parent / "configs"


def read_yaml(path: Path) -> Any:
    try:
        text = path.read_text()
    except OSError as err:
        raise ConfigError(f"{path}: cannot read ({err.strerror})") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        line = f"line {mark.line + 1}: " if mark is not None else ""
        raise ConfigError(f"{path}: {line}invalid YAML") from None


def _resolve(name_or_path: str | Path, folder: str) -> Path:
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.exists():
        if not p.exists():
            raise ConfigError(f"{p}: no such file")
        return p
    builtin = configs_root() / folder / f"{name_or_path}.yaml"
    if not builtin.exists():
        known = sorted(q.stem for q in (configs_root() / folder).glob("*.yaml"))
        raise ConfigError(f"{folder}: unknown id {str(name_or_path)!r} (known: {', '.join(known)})")
    return builtin


def load_vehicle(name_or_path: str | Path) -> VehicleConfig:
    """Load and validate a vehicle config by id (``uic_z1``) or YAML path."""
    path = _resolve(name_or_path, "vehicles")
    data = read_yaml(path)  # a file it cannot read is named once, there
    try:
        return from_dict(VehicleConfig, data)
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from None


def load_rails(path: str | Path | None = None) -> dict[str, RailConfig]:
    """Load the rail-condition table (``configs/rails.yaml`` unless a path is given)."""
    p = Path(path) if path is not None else configs_root() / "rails.yaml"
    data = read_yaml(p)
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: expected a mapping of rail conditions")
    out = {}
    for name, body in data.items():
        try:
            out[str(name)] = from_dict(RailConfig, body, str(name))
        except ConfigError as err:
            raise ConfigError(f"{p}: {err}") from None
    return out


def load_rail(name: str, path: str | Path | None = None) -> RailConfig:
    rails = load_rails(path)
    if name not in rails:
        raise ConfigError(f"rail: unknown condition {name!r} (known: {', '.join(sorted(rails))})")
    return rails[name]

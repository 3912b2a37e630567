"""The benchmark's registered environments: one id per vehicle and sensor tier, each fixing every
setting a benchmark score depends on (``wsp-env benchmark``; docs/benchmark.md).

Two **sensor tiers**, each with its own frozen classical WSP (``baselines.classical``
``TIER_CONFIGS``); a controller is only ever compared with the classical WSP of its tier:

* ``wheels`` — wheel-speed sensors only (``WSPBraking-UICZ1-v3``);
* ``wheels+accel`` — plus a body accelerometer (``WSPBraking-UICZ1-Accel-v3``).

Every earlier version stays registered and reproduces its results (``VERSION_SETTINGS``:
``-v2`` is ``-v3`` with the shared estimator's spin-up test on one 20 ms
reading and no accelerometer offset learned; ``-v1`` is ``-v2`` with the watchdog's
minimum-deceleration override standing until standstill).

What an id fixes (``benchmark_env_kwargs``): the vehicle; the sensor errors of the tier
(``TIER_SENSORS``: wheel-speed resolution 0.02 km/h, noise sigma drawn per stop in 0-0.05 km/h
— period measurement of a ~100-tooth phonic wheel over the 20 ms cycle; its derivative, the
wheel deceleration a WSP reads, then carries up to ~1 m/s^2 of noise —, per-axle scale error
within +-0.5 %; the accelerometer's bias within +-0.3 m/s^2, noise sigma
0.05 m/s^2 per reading, 0.1 s lag); the shared estimator and the safety watchdog at their
defaults; the scenario distribution of the real world's range (``BENCHMARK_SCENARIO``: every rail
of ``configs/rails.yaml`` including ``soap_etr1000``, their patterns and levels, speeds from
40 km/h to the vehicle's maximum, gradients within +-25 per mille, loads tare to laden, pad
friction +-15 %, 70 % emergency and 30 % service demand); the default reward; a 20 ms control
period, 1 ms substeps and a 600 s time limit.
"""

from __future__ import annotations

import copy
import dataclasses
from typing import Any

from wsp_env import BENCHMARK_VEHICLES
from wsp_env.core.braking import ScenarioConfig
from wsp_env.core.sensors import SensorConfig
from wsp_env.envs.wsp_braking import WSPBrakingEnv, WSPBrakingVectorEnv

TIERS = ("wheels", "wheels+accel")
VERSION = "v3"  # the ids the benchmark scores; every earlier version stays registered
# what each registered version sets apart from the current one (the environment docstring's
# version history): v2 is v3 with the shared estimator's spin-up test on one reading and no
# accelerometer offset learned; v1 is v2 with the watchdog's minimum-deceleration override
# standing until standstill however the axles lock under it
ESTIMATOR_BEFORE_V3: dict[str, Any] = {"free_roll_filter_s": 0.0, "accel_offset_gain": 0.0}
VERSION_SETTINGS: dict[str, dict[str, dict[str, Any]]] = {
    "v1": {"estimator": ESTIMATOR_BEFORE_V3, "watchdog": {"give_way_locked_s": 0.0}},
    "v2": {"estimator": ESTIMATOR_BEFORE_V3},
    "v3": {},
}
VERSIONS = tuple(VERSION_SETTINGS)

_WHEELS = SensorConfig(
    wheel_speed_noise_kmh=(0.0, 0.05),
    wheel_speed_quantum_kmh=0.02,
    wheel_speed_scale_error=0.005,
    accelerometer_bias_mps2=0.0,
)
TIER_SENSORS: dict[str, SensorConfig] = {
    "wheels": _WHEELS,
    "wheels+accel": dataclasses.replace(
        _WHEELS,
        accelerometer_bias_mps2=0.3,
        accelerometer_noise_mps2=0.05,
        accelerometer_lag_s=0.1,
    ),
}
BENCHMARK_SCENARIO = ScenarioConfig(
    speed_kmh=None,  # 40 km/h to the vehicle's maximum
    rails={
        "dry": 0.1,
        "wet": 0.15,
        "soap": 0.25,
        "soap_etr1000": 0.1,
        "oil": 0.15,
        "leaves": 0.25,
    },
    load_factor=(0.85, 1.15),
    pad_factor=(0.85, 1.15),
    gradient_permille=(-25.0, 25.0),
    emergency_probability=0.7,
    service_demand_fraction=0.85,
)
MAX_TIME_S = 600.0


def check_tier(tier: str) -> str:
    if tier not in TIERS:
        raise ValueError(f"tier: {tier!r} is not one of {', '.join(TIERS)}")
    return tier


def check_version(version: str) -> str:
    if version not in VERSIONS:
        raise ValueError(f"version: {version!r} is not one of {', '.join(VERSIONS)}")
    return version


def benchmark_env_kwargs(vehicle: str, tier: str, version: str = VERSION) -> dict[str, Any]:
    """Every environment argument of the benchmark id of ``vehicle``, ``tier`` and ``version``
    (the current one by default)."""
    check_tier(tier)
    check_version(version)
    if vehicle not in BENCHMARK_VEHICLES:
        raise ValueError(
            f"vehicle: {vehicle!r} has no benchmark id (known: {', '.join(BENCHMARK_VEHICLES)})"
        )
    return {
        "vehicle": vehicle,
        "accelerometer": tier == "wheels+accel",
        "sensors": dataclasses.asdict(TIER_SENSORS[tier]),
        "estimator": copy.deepcopy(VERSION_SETTINGS[version].get("estimator")),
        "watchdog": copy.deepcopy(VERSION_SETTINGS[version].get("watchdog")),
        "reward": None,
        "scenario": dataclasses.asdict(BENCHMARK_SCENARIO),
        "control_period_s": 0.02,
        "substep_s": 1e-3,
        "max_time_s": MAX_TIME_S,
    }


def env_id(vehicle: str, tier: str, version: str = VERSION) -> str:
    """``WSPBraking-UICZ1-v3`` (tier ``wheels``), ``-Accel-v3`` (tier ``wheels+accel``); an
    earlier ``version`` names its id (``-v1``, ``-v2``)."""
    check_tier(tier)
    check_version(version)
    accel = "-Accel" if tier == "wheels+accel" else ""
    return f"WSPBraking-{BENCHMARK_VEHICLES[vehicle]}{accel}-{version}"


# what gymnasium itself may pass to an entry point (the spec's own settings, ignored: the id's
# settings hold)
_GYM_KEYS = ("max_episode_steps", "autoreset", "disable_env_checker", "apply_api_compatibility")


def ids() -> dict[str, tuple[str, str, str]]:
    """Every registered benchmark id, every version, and its ``(vehicle, tier, version)``."""
    return {env_id(v, t, n): (v, t, n) for n in VERSIONS for v in BENCHMARK_VEHICLES for t in TIERS}


def _resolve(benchmark_id: str, kwargs: dict[str, Any]) -> tuple[str, str, str]:
    """The vehicle, tier and version of a registered id; any setting given besides gymnasium's
    own is refused in one line (the id fixes them all)."""
    table = ids()
    if benchmark_id not in table:
        raise ValueError(f"benchmark_id: {benchmark_id!r} is not registered")
    extra = sorted(k for k in kwargs if k not in _GYM_KEYS)
    if extra:
        raise ValueError(
            f"{benchmark_id}: fixes every setting, so {', '.join(extra)} cannot be given (use "
            "WSPBraking-v0 to choose them)"
        )
    return table[benchmark_id]


def make_benchmark_env(
    benchmark_id: str, render_mode: str | None = None, **kwargs: Any
) -> WSPBrakingEnv:
    """The registered single environment ``benchmark_id`` (``WSPBraking-UICZ1-v3``, ...)."""
    vehicle, tier, version = _resolve(benchmark_id, kwargs)
    return WSPBrakingEnv(render_mode=render_mode, **benchmark_env_kwargs(vehicle, tier, version))


def make_benchmark_vector_env(
    num_envs: int, benchmark_id: str, render_mode: str | None = None, **kwargs: Any
) -> WSPBrakingVectorEnv:
    """The registered native vector environment ``benchmark_id`` (gymnasium's
    ``max_episode_steps`` is ignored: the id's time limit holds)."""
    vehicle, tier, version = _resolve(benchmark_id, kwargs)
    return WSPBrakingVectorEnv(
        num_envs=num_envs,
        render_mode=render_mode,
        **benchmark_env_kwargs(vehicle, tier, version),
    )

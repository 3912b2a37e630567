"""wsp-env: railway wheel slide protection braking — physics core and Gymnasium environment.

Importing the package registers ``WSPBraking-v0`` (every argument free) and the benchmark's ids,
one per vehicle and sensor tier (``WSPBraking-UICZ1-v3``, ``WSPBraking-UICZ1-Accel-v3``, ...:
``wsp_env.envs.tiers``), single and native vector entry points; the compiled physics is imported
lazily, when an environment is made.
"""

from gymnasium.envs.registration import register, registry

__version__ = "0.1.0"

# the vehicles of configs/vehicles with a benchmark id, and the name each id carries
BENCHMARK_VEHICLES = {"uic_z1": "UICZ1", "etr1000": "ETR1000", "regiolis": "Regiolis",
                      "e402b": "E402B"}  # fmt: skip

if "WSPBraking-v0" not in registry:
    register(
        id="WSPBraking-v0",
        entry_point="wsp_env.envs:WSPBrakingEnv",
        vector_entry_point="wsp_env.envs:WSPBrakingVectorEnv",
    )
# every version of the ids (``wsp_env.envs.tiers.VERSIONS``; the latest is the benchmark's)
for _version in ("v1", "v2", "v3"):
    for _vehicle, _name in BENCHMARK_VEHICLES.items():
        for _tier, _suffix in (("wheels", ""), ("wheels+accel", "-Accel")):
            _id = f"WSPBraking-{_name}{_suffix}-{_version}"
            if _id not in registry:
                register(
                    id=_id,
                    entry_point="wsp_env.envs.tiers:make_benchmark_env",
                    vector_entry_point="wsp_env.envs.tiers:make_benchmark_vector_env",
                    kwargs={"benchmark_id": _id},
                )

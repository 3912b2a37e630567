"""wsp-env: railway wheel slide protection braking — physics core and Gymnasium environment.

Importing the package registers ``WSPBraking-v0`` (single and native vector entry points); the
compiled physics is imported lazily, when an environment is made.
"""

from gymnasium.envs.registration import register, registry

__version__ = "0.1.0"

if "WSPBraking-v0" not in registry:
    register(
        id="WSPBraking-v0",
        entry_point="wsp_env.envs:WSPBrakingEnv",
        vector_entry_point="wsp_env.envs:WSPBrakingVectorEnv",
    )

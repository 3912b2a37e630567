"""The Gymnasium environments over the braking core: ``WSPBraking-v0`` single and native vector
(``wsp_braking``), and their ``rgb_array`` frames (``rendering``)."""

from wsp_env.envs.wsp_braking import WSPBrakingEnv, WSPBrakingVectorEnv

__all__ = ["WSPBrakingEnv", "WSPBrakingVectorEnv"]

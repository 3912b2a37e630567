"""The Gymnasium environments over the braking core: ``WSPBraking-v0`` single and native vector
(``wsp_braking``), their ``rgb_array`` / ``human`` frames (``rendering``), and ``make_core``, the
core as the environments build it (what evaluation, training and the rig build too)."""

from wsp_env.core.braking import RewardConfig, ScenarioConfig
from wsp_env.envs.wsp_braking import (
    WSPBrakingEnv,
    WSPBrakingVectorEnv,
    check_action_repeat,
    check_stagger_reset_steps,
    make_core,
)

__all__ = [
    "RewardConfig", "ScenarioConfig", "WSPBrakingEnv", "WSPBrakingVectorEnv",
    "check_action_repeat", "check_stagger_reset_steps", "make_core",
]  # fmt: skip

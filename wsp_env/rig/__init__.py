"""Seed 002's own system: the virtual full-scale roller rig (``roller_rig``) and the traction
phase with the anti-skid device (``traction``)."""

from wsp_env.rig.roller_rig import RigConfig, RigResult, RollerRig, plot_rig, rig_test
from wsp_env.rig.traction import plot_traction, run_traction

__all__ = ["RigConfig", "RigResult", "RollerRig", "plot_rig", "plot_traction", "rig_test",
           "run_traction"]  # fmt: skip

"""Seed 002's own system: the virtual full-scale roller rig (``roller_rig``) and the traction
phase with the anti-skid device (``traction``)."""

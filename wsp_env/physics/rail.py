"""The rail under the train: contamination laid along the track, the field sliding wheels clean,
and the friction levels an axle sees there.

The rail is a 1-D field of remaining contamination ``c`` (1 = as laid, 0 = clean) in cells of
``EP_CELL_DX`` metres, kept as a ring buffer that moves with the train: a cell is laid (from the
background level, the contaminated sections and, at the start, the injection at the leading
axle) when the leading axle reaches it, and every axle removes contamination from the cell it
stands on (``integrator.py``). The compiled helpers here are the one definition of the friction
level and the recovered level; the kernel, the reference distance and the oracle call them.

Friction level seen by an axle (seed 000 Table 4 / seed 002 Fig. 8):
``level = (mu_clean - (mu_clean - mu_contaminated) c) R_i``. Recovered level (seed 002 Table 5,
``mu_rec / mu_c = 0.10 / 0.08``): ``min(gain level, mu_clean R_i)``, never below ``level``.

Creep stiffness: Kalker's (``contact.py``, Hertz ellipse at the current load, ~ ``N^(2/3)``)
times the rail's ``creep_stiffness_factor``: a contaminant layer makes the contact more
compliant (Polach 2005 reduces the slope by kA, kS < 1 on wet rail; seed 000 Table 4's soap
curves rise with K = 30 per unit creep, several times below Kalker's slope).
"""

from __future__ import annotations

import math

from numba import njit

from wsp_env.physics.layout import (
    AP_N_STATIC,
    AP_STIFF,
    EP_C_BACKGROUND,
    EP_CELL_DX,
    EP_INJ_LEVEL,
    EP_INJ_UNTIL,
    EP_MU_CLEAN,
    EP_MU_CONT,
    EP_N_SECTIONS,
    EP_REC_GAIN,
    EP_STIFF_FACTOR,
    EP_W_LIM,
    EP_W_MAX,
    ES_HEAD,
    ES_T,
    ES_X,
)

KERNEL = {"cache": True, "error_model": "numpy"}
INLINE = {"cache": True, "error_model": "numpy", "inline": "always"}
NO_RECOVERY_W = 1e300  # EP_W_LIM at or above this: the rail does not recover


@njit(**INLINE)
def friction_level(env_par, e, contamination, mu_factor):
    """Friction level of rail with remaining contamination ``contamination`` (0..1), times R_i."""
    mu_clean = env_par[e, EP_MU_CLEAN]
    return (mu_clean - (mu_clean - env_par[e, EP_MU_CONT]) * contamination) * mu_factor


@njit(**INLINE)
def creep_stiffness(env_par, axle_par, e, k, normal):
    """Longitudinal creep stiffness (N per unit creep) of axle ``k`` under load ``normal``."""
    ratio = normal / axle_par[e, k, AP_N_STATIC]
    return env_par[e, EP_STIFF_FACTOR] * axle_par[e, k, AP_STIFF] * ratio ** (2.0 / 3.0)


@njit(**INLINE)
def recovers(env_par, e):
    """Whether the rail's adhesion recovers under sliding (seed 002 Eqs. 9-14 switched on)."""
    return env_par[e, EP_W_MAX] > env_par[e, EP_W_LIM] and env_par[e, EP_W_LIM] < NO_RECOVERY_W


@njit(**INLINE)
def recovered_level(env_par, e, level, mu_factor):
    """The level recovery raises ``level`` toward: ``gain level``, at most the clean rail's."""
    return max(level, min(env_par[e, EP_REC_GAIN] * level, env_par[e, EP_MU_CLEAN] * mu_factor))


@njit(**INLINE)
def available_level(env_par, e, level, mu_factor):
    """The most friction the axle's curve can give: the recovered level where the rail
    recovers, else ``level`` (the upper bound of every creep law at that level)."""
    if recovers(env_par, e):
        return recovered_level(env_par, e, level, mu_factor)
    return level


@njit(**INLINE)
def effective_removal(k_w_filtered, contamination):
    """Removed fraction acting on the curve: the filtered K_W (clipped to [0, 1]) of the
    contamination that is still there (a clean rail has nothing left to recover)."""
    return min(1.0, max(0.0, k_w_filtered)) * contamination


@njit(**KERNEL)
def contamination_at(env_par, sections, e, x):
    """Initial contamination level of the rail at position ``x`` (sections override background)."""
    c = env_par[e, EP_C_BACKGROUND]
    for s in range(int(env_par[e, EP_N_SECTIONS])):
        if sections[e, s, 0] <= x < sections[e, s, 1]:
            c = sections[e, s, 2]
    return c


@njit(**KERNEL)
def _lay_cell(env_par, sections, env_state, field, e, cell):
    dx = env_par[e, EP_CELL_DX]
    c = contamination_at(env_par, sections, e, (cell + 0.5) * dx)
    if env_state[e, ES_T] < env_par[e, EP_INJ_UNTIL]:
        c = max(c, env_par[e, EP_INJ_LEVEL])
    field[e, cell % field.shape[1]] = c


@njit(**KERNEL)
def reset_field(env_par, sections, env_state, field, e):
    """Lay the rail under a train whose leading axle stands at ``env_state[e, ES_X]``."""
    head = math.floor(env_state[e, ES_X] / env_par[e, EP_CELL_DX])
    for cell in range(head - field.shape[1] + 1, head + 1):
        _lay_cell(env_par, sections, env_state, field, e, cell)
    env_state[e, ES_HEAD] = head


@njit(**KERNEL)
def advance_field(env_par, sections, env_state, field, e):
    """Lay the cells the leading axle has reached since the last call."""
    head = int(env_state[e, ES_HEAD])
    front = math.floor(env_state[e, ES_X] / env_par[e, EP_CELL_DX])
    while head < front:
        head += 1
        _lay_cell(env_par, sections, env_state, field, e, head)
    env_state[e, ES_HEAD] = head

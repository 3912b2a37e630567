"""Per-run metrics, read from the kernel's accumulators (no per-step bookkeeping in Python).

Sliding statistics follow seed 002 Eqs. 22–24: ``dv_i = V - omega_i r`` (Eq. 22), its time mean
over the stop ``(1/T) int dv_i dt`` (Eq. 23) and standard deviation
``sqrt((1/T) int (dv_i - mean)^2 dt)`` (Eq. 24), reported in km/h.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wsp_env.physics import layout as L


def axle_metrics(axle_acc: np.ndarray, duration_s: float) -> list[dict[str, float]]:
    """Per-axle metrics of one run from its ``(n_axles, N_AA)`` accumulators."""
    out = []
    T = max(duration_s, 1e-9)
    for a in axle_acc:
        mean = a[L.AA_SLIDE_INT] / T
        var = max(a[L.AA_SLIDE_SQ_INT] / T - mean * mean, 0.0)
        brake_t = a[L.AA_BRAKE_T]
        out.append(
            {
                "mean_sliding_kmh": 3.6 * mean,
                "std_sliding_kmh": 3.6 * math.sqrt(var),
                "mean_adhesion_used": a[L.AA_ADH_INT] / brake_t if brake_t > 0 else 0.0,
                "mean_adhesion_level": a[L.AA_LEVEL_INT] / brake_t if brake_t > 0 else 0.0,
                "sliding_energy_kJ": a[L.AA_SLIDE_E] / 1e3,
                "brake_energy_kJ": a[L.AA_BRAKE_E] / 1e3,
                "max_lock_s": a[L.AA_LOCK_MAX],
                "longest_vent_s": a[L.AA_VENT_MAX],
                "air_litres": a[L.AA_AIR_L],
            }
        )
    return out


def run_metrics(sim: Any, env: int = 0) -> dict[str, Any]:
    """Metrics of run ``env`` of a ``TrainSim`` (stopped or not: ``stopped`` says which)."""
    es = sim.env_state[env]
    stopped = bool(es[L.ES_STOPPED] > 0)
    duration = es[L.ES_T_STOP] if stopped else es[L.ES_T]
    axles = axle_metrics(sim.axle_acc[env], duration)
    e0 = float(sim.initial_energy_J[env])
    dissipated = (
        sim.axle_acc[env, :, L.AA_SLIDE_E].sum()
        + sim.axle_acc[env, :, L.AA_BRAKE_E].sum()
        + sim.env_acc[env].sum()
    )
    ke = float(sim.kinetic_energy_J()[env])
    return {
        "stopped": stopped,
        "stopping_distance_m": float(es[L.ES_X]),
        "stopping_time_s": float(duration),
        "initial_speed_kmh": float(sim.setups[env].speed_kmh) if sim.setups[env] else None,
        "air_litres": float(sum(a["air_litres"] for a in axles)),
        "sliding_energy_kJ": float(sum(a["sliding_energy_kJ"] for a in axles)),
        "max_lock_s": float(max(a["max_lock_s"] for a in axles)),
        "longest_vent_s": float(max(a["longest_vent_s"] for a in axles)),
        "energy_balance_rel_error": float((e0 - ke - dissipated) / e0) if e0 > 0 else 0.0,
        "axles": axles,
    }

"""The environment's ``rgb_array`` frames, and the axle colours every plot of a run shares.

Uses :class:`matplotlib.figure.Figure` with the Agg canvas directly: no pyplot, no global
backend state, safe in worker processes and headless CI. matplotlib is imported when a frame is
drawn, not with the environment (it would add a tenth of a second to every command's start).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wsp_env.core.braking import BrakingCore
from wsp_env.physics.layout import EP_P_MAX


def axle_colours(n_axles: int) -> list[Any]:
    """One colour per axle: the ten default cycle colours, a ``turbo`` ramp beyond."""
    if n_axles <= 10:
        return [f"C{i}" for i in range(n_axles)]
    from matplotlib import colormaps

    cmap = colormaps["turbo"]
    return [cmap(x) for x in np.linspace(0.05, 0.95, n_axles)]


def render_state(
    wheel_kmh: np.ndarray,
    train_kmh: float,
    ref_kmh: float,
    pressure_bar: np.ndarray,
    demand_bar: float,
    p_max_bar: float,
    time_s: float,
    distance_m: float,
    v_max_kmh: float,
) -> np.ndarray:
    """An RGB image (H, W, 3) of the current state: axle speeds against the train speed and the
    WSP reference, and cylinder pressures against the demand (the environment's ``render``)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    n = len(wheel_kmh)
    fig = Figure(figsize=(6.4, 4.0), dpi=100)
    canvas = FigureCanvasAgg(fig)
    ax_v, ax_p = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    axles = np.arange(1, n + 1)
    colours = axle_colours(n)
    ax_v.bar(axles, wheel_kmh, color=colours, label="axle speed")
    ax_v.axhline(train_kmh, color="black", lw=2.5, label=f"train {train_kmh:.1f} km/h")
    ax_v.axhline(ref_kmh, color="grey", ls=":", lw=1.5, label="WSP reference")
    ax_v.set_ylim(0, max(v_max_kmh, train_kmh) * 1.05)
    ax_v.set_ylabel("speed [km/h]")
    ax_v.set_title(f"t = {time_s:5.2f} s, s = {distance_m:6.1f} m")
    ax_v.legend(loc="upper right", fontsize=7)
    ax_p.bar(axles, pressure_bar, color=colours)
    ax_p.axhline(demand_bar, color="black", ls="--", label="demand")
    ax_p.set_ylim(0, p_max_bar * 1.1)
    ax_p.set_ylabel("cylinder [bar]")
    ax_p.set_xlabel("axle")
    ax_p.legend(loc="upper right", fontsize=7)
    if n <= 16:
        ax_p.set_xticks(axles)
    fig.tight_layout()
    canvas.draw()
    image = np.asarray(canvas.buffer_rgba())[:, :, :3].copy()
    fig.clear()
    return image


def render_core(core: BrakingCore, e: int = 0) -> np.ndarray:
    """``render_state`` of env ``e`` of ``core``."""
    sim = core.sim
    return render_state(
        wheel_kmh=3.6 * sim.wheel_speed_mps[e],
        train_kmh=3.6 * sim.speed_mps[e],
        ref_kmh=3.6 * core.reference_speed_mps[e],
        pressure_bar=sim.pressure_bar[e],
        demand_bar=float(sim.demand_bar()[e]),
        p_max_bar=float(core.params.env_par[e, EP_P_MAX]),
        time_s=float(sim.time_s[e]),
        distance_m=float(sim.position_m[e]),
        v_max_kmh=core.vehicle.max_speed_kmh,
    )

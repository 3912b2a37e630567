"""PNG plots of simulated braking runs.

Uses :class:`matplotlib.figure.Figure` with the Agg canvas directly: no pyplot, no global
backend state, safe in worker processes and headless CI.
"""

from __future__ import annotations

from pathlib import Path
from typing import IO, Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from wsp_env.trace_io import RunRecord, write_atomically


def _axle_colours(n_axles: int) -> list[Any]:
    if n_axles <= 10:
        return [f"C{i}" for i in range(n_axles)]
    from matplotlib import colormaps

    cmap = colormaps["turbo"]
    return [cmap(x) for x in np.linspace(0.05, 0.95, n_axles)]


def plot_run(record: RunRecord, path: str | Path, title: str = "") -> Path:
    """Plot a run as a PNG (10x7 in, 120 dpi) and return its path.

    Top: vehicle speed (thick black) and each axle's peripheral speed (coloured, "axle i"), and
    the WSP reference speed (dotted grey) if recorded, in km/h; bottom: each axle's cylinder
    pressure and the demand pressure (dashed black) in bar; shared time axis. The style follows
    seed 002 Fig. 11 / seed 000 Fig. 4. Written atomically (temp file + ``os.replace``).
    """
    path = Path(path)
    t = record.time_s
    colours = _axle_colours(record.n_axles)

    fig = Figure(figsize=(10, 7), dpi=120, layout="constrained")
    FigureCanvasAgg(fig)
    try:
        ax_v, ax_p = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2]})
        for i in range(record.n_axles):
            ax_v.plot(t, record.v_axle_kmh[:, i], color=colours[i], lw=1.1, label=f"axle {i + 1}")
        ax_v.plot(t, record.v_train_kmh, color="black", lw=2.6, label="vehicle", zorder=5)
        if record.v_ref_kmh is not None:
            ax_v.plot(
                t, record.v_ref_kmh, color="0.6", lw=1.2, ls=":", label="v_ref (WSP)", zorder=6
            )
        ax_v.set_ylabel("speed [km/h]")
        ax_v.set_ylim(bottom=0)
        ax_v.grid(True, alpha=0.4)
        ax_v.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9)

        for i in range(record.n_axles):
            ax_p.plot(t, record.p_cyl_bar[:, i], color=colours[i], lw=1.1, label=f"axle {i + 1}")
        ax_p.plot(t, record.p_demand_bar, color="black", lw=1.6, ls="--", label="demand")
        ax_p.set_ylabel("cylinder pressure [bar]")
        ax_p.set_xlabel("time [s]")
        ax_p.set_ylim(bottom=0)
        ax_p.set_xlim(t[0], t[-1])
        ax_p.grid(True, alpha=0.4)
        ax_p.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9)

        if title:
            fig.suptitle(title)

        def write(fh: IO[bytes]) -> None:
            fig.savefig(fh, format="png", dpi=120)

        path.parent.mkdir(parents=True, exist_ok=True)
        return write_atomically(path, write, binary=True)
    finally:
        fig.clear()


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
    n = len(wheel_kmh)
    fig = Figure(figsize=(6.4, 4.0), dpi=100)
    canvas = FigureCanvasAgg(fig)
    ax_v, ax_p = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    axles = np.arange(1, n + 1)
    colours = _axle_colours(n)
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

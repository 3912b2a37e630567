"""PNG plots of simulated braking runs.

Uses :class:`matplotlib.figure.Figure` with the Agg canvas directly: no pyplot, no global
backend state, safe in worker processes and headless CI.
"""

from __future__ import annotations

from pathlib import Path
from typing import IO

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from wsp_env.core.records import RunRecord
from wsp_env.envs.rendering import axle_colours
from wsp_env.files import write_atomically


def plot_run(record: RunRecord, path: str | Path, title: str = "") -> Path:
    """Plot a run as a PNG (10x7 in, 120 dpi) and return its path.

    Top: vehicle speed (thick black) and each axle's peripheral speed (coloured, "axle i"), and
    the WSP reference speed (dotted grey) if recorded, in km/h; bottom: each axle's cylinder
    pressure and the demand pressure (dashed black) in bar; shared time axis. The style follows
    seed 002 Fig. 11 / seed 000 Fig. 4. Written atomically (temp file + ``os.replace``).
    """
    path = Path(path)
    t = record.time_s
    colours = axle_colours(record.n_axles)

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

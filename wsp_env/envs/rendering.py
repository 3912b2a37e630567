"""The environment's frames (``render_mode`` ``"rgb_array"`` and ``"human"``), the recent history
they show, and the axle colours every plot of a run shares.

A frame shows the last ``HISTORY_S`` (10 s) of the stop against the time before now: each
axle's wheel speed against the train's true speed and the shared WSP reference, each axle's slip
against the train, and each cylinder's pressure against the demand. The environment keeps that
history in a ring buffer (:class:`RenderHistory`), filled after every reset and step only when a
``render_mode`` is set: without one, nothing is recorded and matplotlib is never imported.

One figure per :class:`FrameRenderer` (one per environment object), made at the first frame and
updated in place: the axes, ticks, labels and legend are drawn once (``canvas.draw()``) and kept
as a background; each frame restores that background, sets the lines' data and draws only them
and the time stamp (matplotlib's blitting), then reads the canvas's RGBA buffer. The axes'
limits are fixed (the vehicle's maximum speed, 0-100 % slip, the brake's maximum pressure, the
window), so the background never goes stale; a full redraw (a resized window) takes a new one.

``rgb_array`` uses :class:`matplotlib.figure.Figure` with the Agg canvas directly: no pyplot, no
global backend state, safe in worker processes and headless CI. ``human`` opens the figure
through pyplot in the backend matplotlib chose and updates its window at every step; where that
backend is not interactive (``MPLBACKEND=Agg``, or no display: matplotlib then falls back to
Agg) it draws the same frames on an Agg canvas without showing them, and raises nothing.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wsp_env.core.braking import BrakingCore

HISTORY_S = 10.0  # s: the window a frame shows
FIGSIZE_IN = (6.4, 4.8)  # 640 x 480 pixels at DPI
DPI = 100

# the history's columns: time, train speed, reference, demand, then per axle wheel speed, pressure
_T, _V, _REF, _DEMAND, _AXLES = 0, 1, 2, 3, 4


def axle_colours(n_axles: int) -> list[Any]:
    """One colour per axle: the ten default cycle colours, a ``turbo`` ramp beyond."""
    if n_axles <= 10:
        return [f"C{i}" for i in range(n_axles)]
    from matplotlib import colormaps

    cmap = colormaps["turbo"]
    return [cmap(x) for x in np.linspace(0.05, 0.95, n_axles)]


class RenderHistory:
    """The last ``window_s`` of every environment of ``core`` at the control period, in a ring
    buffer of fixed size: time, train speed, WSP reference, demand, wheel speeds and cylinder
    pressures (SI units). Call :meth:`clear` for an environment that starts a new stop, then
    :meth:`record` after its reset and after every step."""

    def __init__(self, core: BrakingCore, window_s: float = HISTORY_S) -> None:
        self.core = core
        self.window_s = float(window_s)
        # the states at both ends of the window: window / period + 1 rows
        self.capacity = round(self.window_s / core.sim.control_period_s) + 1
        self.rows = np.zeros((core.n_envs, self.capacity, _AXLES + 2 * core.n_axles))
        self.next_row = np.zeros(core.n_envs, dtype=np.int64)
        self.length = np.zeros(core.n_envs, dtype=np.int64)
        self._envs = np.arange(core.n_envs)

    def clear(self, envs: int | slice | np.ndarray | list[int]) -> None:
        """Forget the history of ``envs`` (a new stop starts there)."""
        self.length[envs] = 0
        self.next_row[envs] = 0

    def record(self) -> None:
        """Append every environment's current state (the oldest row goes once the buffer holds
        ``capacity`` rows)."""
        core, sim, n = self.core, self.core.sim, self.core.n_axles
        envs, k, rows = self._envs, self.next_row, self.rows
        rows[envs, k, _T] = sim.time_s
        rows[envs, k, _V] = sim.speed_mps
        rows[envs, k, _REF] = core.reference_speed_mps
        rows[envs, k, _DEMAND] = sim.demand_bar()
        rows[envs, k, _AXLES : _AXLES + n] = sim.wheel_speed_mps
        rows[envs, k, _AXLES + n :] = sim.pressure_bar
        self.next_row = (k + 1) % self.capacity
        np.minimum(self.length + 1, self.capacity, out=self.length)

    def window(self, e: int) -> np.ndarray:
        """Env ``e``'s rows, oldest first: ``(length, 4 + 2 n_axles)``."""
        length, k = int(self.length[e]), int(self.next_row[e])
        if length < self.capacity:
            return self.rows[e, :length]
        return np.concatenate([self.rows[e, k:], self.rows[e, :k]])


def _interactive_backend() -> bool:
    """Whether pyplot's backend (resolved now: without a display matplotlib falls back to Agg)
    can show a window."""
    import matplotlib.pyplot as plt
    from matplotlib.backends import BackendFilter, backend_registry

    name = plt.get_backend().lower()
    return name not in backend_registry.list_builtin(BackendFilter.NON_INTERACTIVE)


def _window_open(figure: Any) -> bool:
    """Whether pyplot still holds ``figure`` (its window was not closed)."""
    import matplotlib.pyplot as plt

    return plt.fignum_exists(figure.number)


class FrameRenderer:
    """Frames of the environments of ``core`` from ``history``, on one figure made at the first
    frame and updated in place (module docstring). ``human``: the figure is a window where the
    backend can show one."""

    def __init__(self, core: BrakingCore, history: RenderHistory, human: bool = False) -> None:
        self.core = core
        self.history = history
        self.human = human
        self.figure: Any = None
        self._pyplot = False  # the figure is pyplot's (a window): close it through pyplot
        self._background: Any = None
        self._blit = True
        self._dynamic: list[Any] = []

    # ---- the figure, made once --------------------------------------------------------------

    def _make_figure(self) -> None:
        if self.human and _interactive_backend():
            import matplotlib.pyplot as plt

            fig = plt.figure(figsize=FIGSIZE_IN, dpi=DPI)
            self._pyplot = True
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            fig = Figure(figsize=FIGSIZE_IN, dpi=DPI)
            FigureCanvasAgg(fig)
        core, n = self.core, self.core.n_axles
        colours = axle_colours(n)
        ax_v, ax_s, ax_p = fig.subplots(3, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2, 2]})
        fig.subplots_adjust(left=0.11, right=0.98, top=0.93, bottom=0.09, hspace=0.12)
        none: list[float] = []
        self._wheel = [ax_v.plot(none, none, color=c, lw=1.0)[0] for c in colours]
        (self._train,) = ax_v.plot(none, none, color="black", lw=2.0, label="train")
        (self._ref,) = ax_v.plot(none, none, color="grey", ls=":", lw=1.5, label="WSP reference")
        self._slip = [ax_s.plot(none, none, color=c, lw=1.0)[0] for c in colours]
        self._pressure = [ax_p.plot(none, none, color=c, lw=1.0)[0] for c in colours]
        (self._demand,) = ax_p.plot(none, none, color="black", ls="--", lw=1.2, label="demand")
        self._stamp = fig.text(0.11, 0.955, "", fontsize=9, family="monospace")
        v_max_kmh = core.vehicle.max_speed_kmh
        ax_v.set_ylim(0.0, 1.05 * v_max_kmh)
        ax_v.set_ylabel("speed [km/h]")
        ax_s.set_ylim(-5.0, 100.0)
        ax_s.set_ylabel("slip [%]")
        ax_p.set_ylim(0.0, 1.1 * core.vehicle.brake.p_max_bar)
        ax_p.set_ylabel("cylinder [bar]")
        ax_p.set_xlim(-self.history.window_s, 0.0)
        ax_p.set_xlabel("time before now [s]")
        handles = [self._train, self._ref]
        if n <= 8:  # one legend entry per axle while it stays legible
            for i, line in enumerate(self._wheel):
                line.set_label(f"axle {i + 1}")
            handles += self._wheel
        ax_v.legend(handles=handles, loc="lower left", fontsize=6, ncol=2, framealpha=0.6)
        ax_p.legend(loc="lower left", fontsize=6, framealpha=0.6)
        for ax in (ax_v, ax_s, ax_p):
            ax.grid(True, lw=0.4, alpha=0.5)
        self._dynamic = [*self._wheel, self._train, self._ref, *self._slip, *self._pressure]
        self._dynamic += [self._demand, self._stamp]
        self._blit = fig.canvas.supports_blit  # every Agg canvas; otherwise a full draw a frame
        for artist in self._dynamic:  # drawn per frame, not into the background
            artist.set_animated(self._blit)
        self.figure = fig
        # every full draw (the first one here, a resized window) takes a new background
        fig.canvas.mpl_connect("draw_event", self._on_draw)
        if self._pyplot:
            fig.show()
        fig.canvas.draw()

    def _on_draw(self, event: Any) -> None:
        if self._blit:
            self._background = self.figure.canvas.copy_from_bbox(self.figure.bbox)

    # ---- a frame -----------------------------------------------------------------------------

    def _update(self, e: int) -> None:
        """Set the lines' data and the stamp to env ``e``'s history."""
        rows = self.history.window(e)  # empty before the first reset: empty lines
        n = self.core.n_axles
        t = rows[:, _T] - (rows[-1, _T] if len(rows) else 0.0)
        train = rows[:, _V]
        wheels = rows[:, _AXLES : _AXLES + n]
        slip = 100.0 * (train[:, None] - wheels) / np.maximum(train, 1.0)[:, None]
        pressure = rows[:, _AXLES + n :]
        for i in range(n):
            self._wheel[i].set_data(t, 3.6 * wheels[:, i])
            self._slip[i].set_data(t, slip[:, i])
            self._pressure[i].set_data(t, pressure[:, i])
        self._train.set_data(t, 3.6 * train)
        self._ref.set_data(t, 3.6 * rows[:, _REF])
        self._demand.set_data(t, rows[:, _DEMAND])
        stamp = ""
        if len(rows):
            x_m = float(self.core.sim.position_m[e])
            stamp = (
                f"t = {rows[-1, _T]:6.2f} s   V = {3.6 * train[-1]:5.1f} km/h   s = {x_m:6.1f} m"
            )
        self._stamp.set_text(stamp)

    def draw(self, e: int = 0) -> None:
        """Draw env ``e``'s frame into the figure (and its window, in human mode; a window the
        user closed opens again)."""
        if self._pyplot and not _window_open(self.figure):
            self.close()
        if self.figure is None:
            self._make_figure()
        fig = self.figure
        canvas = fig.canvas
        self._update(e)
        if not self._blit:
            canvas.draw()
        else:
            canvas.restore_region(self._background)
            for artist in self._dynamic:
                fig.draw_artist(artist)
            if self._pyplot:
                canvas.blit(fig.bbox)
        if self._pyplot:
            canvas.flush_events()

    def frame(self, e: int = 0) -> np.ndarray:
        """Env ``e``'s frame as an RGB image ``(480, 640, 3)`` uint8 (a copy)."""
        self.draw(e)
        return np.asarray(self.figure.canvas.buffer_rgba())[:, :, :3].copy()

    def close(self) -> None:
        """Close the figure (its window, in human mode); a later frame makes a new one."""
        if self.figure is not None and self._pyplot:
            import matplotlib.pyplot as plt

            plt.close(self.figure)
        self.figure = None
        self._background = None
        self._dynamic = []

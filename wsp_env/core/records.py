"""What a simulated run records, and the trace format's names for it.

:class:`RunRecord` is a run at the control period, as ``braking.Recorder.record`` builds it; the
trace writer (``evaluation.trace_writer``) turns it into logger-like samples, and ``FORMAT`` and
``CONTAMINANTS`` are the ``wsp-trace/1`` vocabulary (``docs/trace_format.md``) that configs and
the calibration's reader share.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FORMAT = "wsp-trace/1"
CONTAMINANTS = ("dry", "wet", "soap", "oil", "leaves", "unknown")


@dataclass
class RunRecord:
    """A simulated run recorded at the control period (uniform time grid).

    Speeds in km/h (axle speed is the peripheral speed ``omega * r_nominal``), pressures in bar
    (gauge), ``a_train_mps2`` positive when slowing; see ``docs/trace_format.md`` for the channels.
    """

    time_s: np.ndarray  # (T,)
    v_train_kmh: np.ndarray  # (T,)
    v_axle_kmh: np.ndarray  # (T, n_axles)
    p_cyl_bar: np.ndarray  # (T, n_axles)
    p_demand_bar: np.ndarray  # (T,)
    a_train_mps2: np.ndarray  # (T,)
    v_ref_kmh: np.ndarray | None = None  # (T,)
    wsp_active: np.ndarray | None = None  # (T, n_axles) bool
    f_adhesion_N: np.ndarray | None = None  # (T, n_axles) the simulator's own adhesion forces

    def __post_init__(self) -> None:
        self.time_s = np.asarray(self.time_s, dtype=float)
        if self.time_s.ndim != 1 or self.time_s.size < 2:
            raise ValueError("time_s: must be a 1-D array with at least 2 samples")
        if not np.all(np.isfinite(self.time_s)) or np.any(np.diff(self.time_s) <= 0):
            raise ValueError("time_s: must be finite and strictly increasing")
        T = self.time_s.size
        for name in ("v_train_kmh", "p_demand_bar", "a_train_mps2", "v_ref_kmh"):
            value = getattr(self, name)
            if value is None:
                if name != "v_ref_kmh":
                    raise ValueError(f"{name}: required")
                continue
            arr = np.asarray(value, dtype=float)
            if arr.shape != (T,):
                raise ValueError(f"{name}: shape {arr.shape}, expected ({T},)")
            setattr(self, name, arr)
        v_axle = np.asarray(self.v_axle_kmh, dtype=float)
        if v_axle.ndim != 2 or v_axle.shape[0] != T or v_axle.shape[1] < 1:
            raise ValueError(f"v_axle_kmh: shape {v_axle.shape}, expected ({T}, n_axles)")
        self.v_axle_kmh = v_axle
        n = v_axle.shape[1]
        p_cyl = np.asarray(self.p_cyl_bar, dtype=float)
        if p_cyl.shape != (T, n):
            raise ValueError(f"p_cyl_bar: shape {p_cyl.shape}, expected ({T}, {n})")
        self.p_cyl_bar = p_cyl
        if self.wsp_active is not None:
            active = np.asarray(self.wsp_active)
            if active.shape != (T, n):
                raise ValueError(f"wsp_active: shape {active.shape}, expected ({T}, {n})")
            self.wsp_active = active.astype(bool)
        if self.f_adhesion_N is not None:
            force = np.asarray(self.f_adhesion_N, dtype=float)
            if force.shape != (T, n):
                raise ValueError(f"f_adhesion_N: shape {force.shape}, expected ({T}, {n})")
            self.f_adhesion_N = force

    @property
    def n_axles(self) -> int:
        """Number of axles (columns of ``v_axle_kmh``)."""
        return int(self.v_axle_kmh.shape[1])

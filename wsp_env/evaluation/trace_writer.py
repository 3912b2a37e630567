"""Writing ``wsp-trace/1`` braking traces.

A trace is ``STEM.csv`` (samples, header line first) plus ``STEM.meta.json`` (test and nominal
vehicle data); the format is specified in ``docs/trace_format.md``. This module turns a
simulated run (:class:`RunRecord`, recorded at the control period) into logger-like samples
(:func:`sample_run`, with a :class:`SensorModel` for period, jitter, noise and quantisation) and
writes them atomically (:func:`write_trace`). The one reader is the calibration's
(``calibration.traces.read_trace``).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np

from wsp_env.core.records import CONTAMINANTS, FORMAT, RunRecord
from wsp_env.files import json_default, write_all_atomically

_AXLE_SPEED = re.compile(r"^v_axle_(\d+)_kmh$")
_AXLE_PRESSURE = re.compile(r"^p_cyl_(\d+)_bar$")
_BAD_NAME_CHARS = re.compile(r"[,\"\r\n]")

# Jitter offsets are truncated at this fraction of the period, so consecutive stamps stay at
# least (1 - 2 * 0.45) = 0.1 periods apart and can never swap.
_JITTER_CLIP = 0.45
# Largest allowed jitter std as a fraction of the period (the truncation then sits >= 1.8 sigma).
_JITTER_MAX = 0.25


# --------------------------------------------------------------------------------------------
# Records and sensors
# --------------------------------------------------------------------------------------------


@dataclass
class SensorModel:
    """How a data logger samples a run (``docs/trace_format.md``: logger 0.1 s, BCU cycle 0.02 s).

    ``jitter_s`` is the std of a per-sample timestamp offset (truncated at 0.45 periods so the
    stamps stay strictly increasing; at most a quarter period). Noise values are Gaussian
    standard deviations; ``speed_noise_kmh`` applies to the vehicle speed and to every axle
    speed, ``pressure_noise_bar`` to every cylinder pressure and the demand pressure. Quanta of
    0 switch quantisation off.
    """

    sample_period_s: float = 0.1
    jitter_s: float = 0.0
    speed_noise_kmh: float = 0.0
    pressure_noise_bar: float = 0.0
    accel_noise_mps2: float = 0.0
    speed_quantum_kmh: float = 0.0
    pressure_quantum_bar: float = 0.0

    def __post_init__(self) -> None:
        for name in (
            "sample_period_s",
            "jitter_s",
            "speed_noise_kmh",
            "pressure_noise_bar",
            "accel_noise_mps2",
            "speed_quantum_kmh",
            "pressure_quantum_bar",
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float | np.number):
                raise ValueError(f"{name}: must be a number, got {value!r}")
            value = float(value)
            if not math.isfinite(value) or value < 0:
                raise ValueError(f"{name}: must be finite and >= 0, got {value}")
            setattr(self, name, value)
        if self.sample_period_s <= 0:
            raise ValueError(f"sample_period_s: must be > 0, got {self.sample_period_s}")
        if self.jitter_s > _JITTER_MAX * self.sample_period_s:
            raise ValueError(
                f"jitter_s: {self.jitter_s} exceeds a quarter of sample_period_s "
                f"({self.sample_period_s}); timestamps could not stay strictly increasing"
            )


# --------------------------------------------------------------------------------------------
# Sampling
# --------------------------------------------------------------------------------------------


def _quantise(x: np.ndarray, quantum: float) -> np.ndarray:
    return np.round(x / quantum) * quantum if quantum > 0 else x


def sample_run(
    record: RunRecord, sensors: SensorModel, rng: np.random.Generator
) -> dict[str, np.ndarray]:
    """Sample ``record`` like a data logger and return ``wsp-trace/1`` columns, in order.

    Instants are ``t_k = t_0 + k * period`` plus truncated Gaussian jitter, clipped to the
    record span (strictly increasing). Analogue channels are linearly interpolated, then get
    Gaussian noise, then quantisation, then are clipped physically (speeds and pressures
    ``>= 0``; the deceleration is not clipped). ``v_ref_kmh`` is the WSP's own digital estimate:
    it is quantised but gets no sensor noise. ``wsp_active_<i>`` is 1 if the valve was active
    at any record sample in ``(t_{k-1}, t_k]`` (the nearest earlier sample if none falls there).

    Column order: ``time_s, v_train_kmh, v_axle_<i>_kmh..., p_cyl_<i>_bar...``, then
    ``v_ref_kmh`` (if recorded), ``a_train_mps2, p_demand_bar``, ``wsp_active_<i>...`` (if
    recorded). All randomness comes from ``rng``; every noise stream is always drawn (scaled by
    its std, possibly 0) so a channel's noise does not depend on the other settings.
    """
    t_rec = record.time_s
    t0, t_end = float(t_rec[0]), float(t_rec[-1])
    period = sensors.sample_period_s
    n_samples = math.floor((t_end - t0) / period + 1e-9) + 1
    n_axles = record.n_axles

    # Fixed draw order: jitter, speeds (train + axles), pressures (axles + demand), accel.
    z_jitter = rng.standard_normal(n_samples)
    z_speed = rng.standard_normal((n_samples, 1 + n_axles))
    z_pressure = rng.standard_normal((n_samples, n_axles + 1))
    z_accel = rng.standard_normal(n_samples)

    clip = _JITTER_CLIP * period
    offset = np.clip(sensors.jitter_s * z_jitter, -clip, clip)
    t = np.clip(t0 + np.arange(n_samples) * period + offset, t0, t_end)

    def interp(y: np.ndarray) -> np.ndarray:
        return np.interp(t, t_rec, y)

    v_train = interp(record.v_train_kmh) + sensors.speed_noise_kmh * z_speed[:, 0]
    v_axle = np.column_stack([interp(record.v_axle_kmh[:, i]) for i in range(n_axles)])
    v_axle = v_axle + sensors.speed_noise_kmh * z_speed[:, 1:]
    p_cyl = np.column_stack([interp(record.p_cyl_bar[:, i]) for i in range(n_axles)])
    p_cyl = p_cyl + sensors.pressure_noise_bar * z_pressure[:, :n_axles]
    p_demand = interp(record.p_demand_bar) + sensors.pressure_noise_bar * z_pressure[:, n_axles]
    a_train = interp(record.a_train_mps2) + sensors.accel_noise_mps2 * z_accel

    def speed(x: np.ndarray) -> np.ndarray:
        return np.maximum(_quantise(x, sensors.speed_quantum_kmh), 0.0) + 0.0

    def pressure(x: np.ndarray) -> np.ndarray:
        return np.maximum(_quantise(x, sensors.pressure_quantum_bar), 0.0) + 0.0

    columns: dict[str, np.ndarray] = {"time_s": t, "v_train_kmh": speed(v_train)}
    v_axle, p_cyl = speed(v_axle), pressure(p_cyl)
    for i in range(n_axles):
        columns[f"v_axle_{i + 1}_kmh"] = v_axle[:, i]
    for i in range(n_axles):
        columns[f"p_cyl_{i + 1}_bar"] = p_cyl[:, i]
    if record.v_ref_kmh is not None:
        columns["v_ref_kmh"] = speed(interp(record.v_ref_kmh))
    columns["a_train_mps2"] = a_train
    columns["p_demand_bar"] = pressure(p_demand)
    if record.wsp_active is not None:
        # Tolerance so that a sample instant equal to a record instant up to rounding counts it.
        tol = 1e-9 * max(1.0, abs(t_end))
        hi = np.searchsorted(t_rec, t + tol, side="right") - 1  # last record sample <= t_k
        t_prev = np.concatenate(([-np.inf], t[:-1]))
        lo = np.minimum(np.searchsorted(t_rec, t_prev + tol, side="right"), hi)
        counts = np.concatenate(
            (np.zeros((1, n_axles), dtype=np.int64), np.cumsum(record.wsp_active, axis=0))
        )
        active = (counts[hi + 1] - counts[lo]) > 0
        for i in range(n_axles):
            columns[f"wsp_active_{i + 1}"] = active[:, i]
    return columns


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------


def stem_path(stem: str | Path) -> Path:
    """``STEM`` from ``STEM``, ``STEM.csv`` or ``STEM.meta.json``."""
    path = Path(stem)
    for suffix in (".meta.json", ".csv"):
        if path.name.endswith(suffix) and len(path.name) > len(suffix):
            return path.with_name(path.name[: -len(suffix)])
    return path


def _positive_number(meta: dict, key: str, label: str) -> None:
    if key not in meta:
        raise ValueError(f"{label}: required field missing from the metadata")
    value = meta[key]
    if isinstance(value, bool) or not isinstance(value, int | float | np.number):
        raise ValueError(f"{label}: must be a number, got {value!r}")
    if not math.isfinite(float(value)) or float(value) <= 0:
        raise ValueError(f"{label}: must be finite and > 0, got {value!r}")


def _validate_meta(meta: dict) -> int:
    """Check the required ``wsp-trace/1`` metadata; return ``vehicle.n_axles``."""
    if meta.get("format") != FORMAT:
        raise ValueError(f"format: must be {FORMAT!r}, got {meta.get('format')!r}")
    _positive_number(meta, "sample_period_s", "sample_period_s")
    vehicle = meta.get("vehicle")
    if vehicle is None:
        raise ValueError("vehicle: required field missing from the metadata")
    if not isinstance(vehicle, dict):
        raise ValueError(f"vehicle: must be an object, got {type(vehicle).__name__}")
    if "n_axles" not in vehicle:
        raise ValueError("vehicle.n_axles: required field missing from the metadata")
    n_axles = vehicle["n_axles"]
    if isinstance(n_axles, bool) or not isinstance(n_axles, int | np.integer) or n_axles < 1:
        raise ValueError(f"vehicle.n_axles: must be an integer >= 1, got {n_axles!r}")
    _positive_number(vehicle, "wheel_radius_m", "vehicle.wheel_radius_m")
    _positive_number(vehicle, "mass_kg", "vehicle.mass_kg")
    contaminant = meta.get("contaminant")
    if contaminant is not None and contaminant not in CONTAMINANTS:
        raise ValueError(
            f"contaminant: must be one of {', '.join(CONTAMINANTS)}, got {contaminant!r}"
        )
    return int(n_axles)


def _check_axle_columns(
    names: list[str], pattern: re.Pattern[str], n_axles: int, what: str
) -> None:
    found = sorted(int(m.group(1)) for name in names if (m := pattern.match(name)))
    if found != list(range(1, n_axles + 1)):
        got = ", ".join(n for n in names if pattern.match(n)) or "none"
        raise ValueError(
            f"vehicle.n_axles: {n_axles} axles but the {what} columns are: {got} "
            f"(expected axles 1..{n_axles})"
        )


def _validate_columns(columns: dict[str, np.ndarray], n_axles: int) -> dict[str, np.ndarray]:
    names = list(columns)
    for name in names:
        if not isinstance(name, str) or not name or _BAD_NAME_CHARS.search(name):
            raise ValueError(f'{name!r}: column names must be non-empty, without , " or newlines')
    for required in ("time_s", "v_train_kmh"):
        if required not in columns:
            raise ValueError(f"{required}: required column missing")
    _check_axle_columns(names, _AXLE_SPEED, n_axles, "axle speed")
    _check_axle_columns(names, _AXLE_PRESSURE, n_axles, "cylinder pressure")

    arrays = {name: np.asarray(col) for name, col in columns.items()}
    length = arrays["time_s"].shape
    for name, arr in arrays.items():
        if arr.ndim != 1:
            raise ValueError(f"{name}: must be 1-D, got shape {arr.shape}")
        if arr.shape != length:
            raise ValueError(f"{name}: {arr.shape[0]} rows but time_s has {length[0]}")
        if arr.dtype.kind not in "biuf":
            raise ValueError(f"{name}: must be numeric or boolean, got dtype {arr.dtype}")
        if arr.dtype.kind == "f" and np.any(np.isinf(arr)):
            raise ValueError(f"{name}: contains infinite values")
    t = arrays["time_s"].astype(float)
    if t.size == 0:
        raise ValueError("time_s: no samples")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise ValueError("time_s: must be finite and strictly increasing")
    return arrays


def _format_time(t: np.ndarray) -> np.ndarray:
    """``%.4f`` unless that collapses neighbouring stamps; then more decimals (up to 9)."""
    for decimals in range(4, 10):
        text = np.char.mod(f"%.{decimals}f", t + 0.0)
        if np.all(np.diff(text.astype(float)) > 0):
            return text
    raise ValueError("time_s: neighbouring stamps closer than 1 ns cannot be written distinctly")


def _format_column(arr: np.ndarray) -> np.ndarray:
    if arr.dtype.kind in "biu":
        return np.char.mod("%d", arr.astype(np.int64))
    values = arr.astype(float) + 0.0  # no "-0"
    text = np.char.mod("%.6g", values)
    text[np.isnan(values)] = ""  # missing values are empty cells
    return text


def write_trace(stem: str | Path, columns: dict[str, np.ndarray], meta: dict) -> tuple[Path, Path]:
    """Write ``STEM.csv`` and ``STEM.meta.json`` (``docs/trace_format.md``); return their paths.

    ``meta`` gets ``format: "wsp-trace/1"`` if missing (the caller's dict is not modified).
    Required metadata (``sample_period_s``, ``vehicle.n_axles``, ``vehicle.wheel_radius_m``,
    ``vehicle.mass_kg``) and the columns (``time_s``, ``v_train_kmh``, one ``v_axle_<i>_kmh``
    and one ``p_cyl_<i>_bar`` per axle, equal lengths, time strictly increasing) are checked
    first; problems raise ``ValueError`` with one line naming the field or column. Columns are
    written in the given order (extra columns kept): time ``%.4f`` (more decimals only if needed
    to keep stamps distinct), floats ``%.6g``, booleans/integers ``%d``, NaN as an empty cell.
    Both files go through temp files and ``os.replace``; on any failure neither is left behind.
    ``stem`` may also be given as ``STEM.csv``; missing parent directories are created.
    """
    stem = stem_path(stem)
    meta = {"format": FORMAT, **meta}  # "format" first in the file; a given value is kept
    n_axles = _validate_meta(meta)
    arrays = _validate_columns(columns, n_axles)
    try:  # fail before writing anything
        json.dumps(meta, default=json_default, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"meta: {exc}") from None

    names = list(arrays)
    cells = [
        _format_time(arrays["time_s"].astype(float)) if n == "time_s" else _format_column(arrays[n])
        for n in names
    ]
    rows = np.stack(cells, axis=1) if cells else np.empty((0, 0), dtype=str)

    def write_csv(fh: IO[str]) -> None:
        fh.write(",".join(names) + "\n")
        fh.writelines(",".join(row) + "\n" for row in rows.tolist())

    def write_meta(fh: IO[str]) -> None:
        json.dump(meta, fh, indent=2, default=json_default, allow_nan=False)
        fh.write("\n")

    csv_path = stem.with_name(stem.name + ".csv")
    meta_path = stem.with_name(stem.name + ".meta.json")
    csv_path.parent.mkdir(parents=True, exist_ok=True)

    write_all_atomically([(csv_path, write_csv), (meta_path, write_meta)])
    return csv_path, meta_path

"""Reading measured braking traces (``docs/trace_format.md``, ``wsp-trace/1``) for calibration.

``read_trace(csv_path)`` reads ``NAME.csv`` and ``NAME.meta.json``, accepts the BCU's vendor
channel names (converting units), validates, fills short gaps and returns a :class:`Trace`.
Every problem raises :class:`TraceError` with one line naming the file, the column or field and
what is wrong. Input files are only read, never modified.

Checks: metadata present, valid JSON, ``format`` and required fields; axle count of the metadata
against the columns; required columns present, numeric and not mostly empty; time strictly
increasing; gaps of more than ``MAX_GAP`` samples in a required column; physically implausible
values for the stated unit (a speed column in m/s or a pressure column in kPa, negative speeds);
what one braking test can be (``MAX_ROWS`` rows, ``MAX_DURATION_S``, no ground-speed step of
``MAX_STEP_KMH`` faster than ``MAX_STEP_MPS2``).
Gaps of up to ``MAX_GAP`` samples are interpolated linearly in time and listed in
``Trace.notes``.
"""

from __future__ import annotations

import csv
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sparse
from scipy.integrate import cumulative_trapezoid
from scipy.sparse.linalg import spsolve

from wsp_env.core.records import CONTAMINANTS, FORMAT

MAX_GAP = 3  # samples: longer runs of missing values in a required column are an error
MAX_SPEED_KMH = 500.0
MAX_PRESSURE_BAR = 12.0
# What a braking trace can be: a stop from 350 km/h at 0.3 m/s^2 takes ~330 s, so 30 minutes
# leaves room for coasting lead-ins; 100,000 rows hold 1,000 s at 100 Hz (loggers log at 10-100
# Hz). A larger file is another kind of record (a whole journey): cut or resample it first.
MAX_ROWS = 100_000
MAX_DURATION_S = 1800.0
# A ground-speed step no train makes between two samples: 20 km/h at more than 3 g (sensor
# noise at 1 kHz reaches ~30 m/s^2 on its own, but never 20 km/h in one sample)
MAX_STEP_KMH = 20.0
MAX_STEP_MPS2 = 30.0


class TraceError(ValueError):
    """A malformed trace; ``str(err)`` is one line naming file, column or field."""


@dataclass
class Trace:
    """A validated trace in the canonical units of ``docs/trace_format.md``."""

    path: Path
    meta: dict[str, Any]
    time_s: np.ndarray
    v_train_kmh: np.ndarray
    v_axle_kmh: np.ndarray  # (T, n_axles)
    p_cyl_bar: np.ndarray  # (T, n_axles)
    optional: dict[str, np.ndarray] = field(default_factory=dict)  # v_ref_kmh, a_train_mps2, ...
    extra: dict[str, np.ndarray] = field(default_factory=dict)  # unknown columns, kept
    notes: list[str] = field(default_factory=list)
    # the ground-speed sensor's noise (km/h) where the reader measured it on held updates;
    # None: measure it on the samples (``ground_speed_noise_kmh``)
    v_train_noise_kmh: float | None = None
    # the interval (s) between the ground speed's updates where the reader found them held or
    # averaged (``unhold``, ``averaged_updates``); None: every sample is an update
    v_train_update_s: float | None = None
    # how far (s) the column as read trails the train by its logging alone: half an update
    # interval where updates were averaged over the log period and left as logged
    # (``averaged_updates``), else 0 (held updates are put back on time by ``unhold``)
    v_train_logger_lag_s: float = 0.0
    # the noise (km/h) of one update where the reader found updates (held: as
    # ``v_train_noise_kmh``; averaged: measured on the fitted levels, while the samples' own
    # noise stays what the channels are judged by); None: every sample is an update
    v_train_update_noise_kmh: float | None = None

    @property
    def ground_speed_noise_kmh(self) -> float:
        """The ground-speed sensor's noise (km/h): on its updates where it was held (an
        interpolated record has no sample noise left to see), else on the samples."""
        if self.v_train_noise_kmh is not None:
            return self.v_train_noise_kmh
        return noise_std(self.v_train_kmh)

    @property
    def n_axles(self) -> int:
        return self.v_axle_kmh.shape[1]

    @property
    def vehicle(self) -> dict[str, Any]:
        return self.meta["vehicle"]

    def distance_m(self) -> np.ndarray:
        """(T,) the distance the train has run (m), the ground speed integrated from the first
        sample (trapezoidal): where critical points, censored bounds and slides sit on the rail."""
        return cumulative_trapezoid(self.v_train_kmh / 3.6, self.time_s, initial=0.0)

    def axle_torque_gains(self) -> np.ndarray:
        """Nominal brake torque gain (N m / bar) per axle: ``brake.axle_torque_gain_Nm_per_bar``
        where the metadata lists them (motor axles with a blended ED brake), else
        ``brake.torque_gain_Nm_per_bar`` for every axle."""
        brake = self.vehicle.get("brake", {})
        gains = brake.get("axle_torque_gain_Nm_per_bar")
        if gains is None:
            gains = [float(brake.get("torque_gain_Nm_per_bar", 0.0))] * self.n_axles
        return np.asarray(gains, dtype=float)

    def brake_torque_Nm(self) -> np.ndarray:
        """(T, n_axles) nominal brake torque ``gain_i (p_i - p_th)^+`` from the metadata."""
        p_th = p_threshold_bar(self)
        return self.axle_torque_gains()[None, :] * np.maximum(0.0, self.p_cyl_bar - p_th)


def noise_std(y: np.ndarray) -> float:
    """Std of white noise on a smooth signal, from the median absolute second difference
    (robust to the signal's own curvature and to outliers)."""
    d2 = np.diff(np.asarray(y, dtype=float), 2, axis=0).ravel()
    return float(np.median(np.abs(d2)) / 0.6745 / np.sqrt(6.0)) if d2.size else 0.0


def _updates_noise_kmh(levels: np.ndarray) -> float | None:
    """One update's noise (km/h, ``noise_std``) on the values of the moving updates; None
    with fewer than 7 of them (5 second differences)."""
    moving = levels[levels > 1.0]
    return noise_std(moving) if moving.size >= 7 else None


BRAKED_MARGIN_BAR = 0.05  # above the brake's threshold: a pressure sensor's offset is no brake


def p_threshold_bar(trace: Any) -> float:
    """The metadata's brake threshold (bar; 0 where it gives none)."""
    return float(trace.vehicle.get("brake", {}).get("p_threshold_bar", 0.0))


def braked(trace: Any) -> np.ndarray:
    """(T, n_axles): the axle's cylinder at least ``BRAKED_MARGIN_BAR`` above the brake's
    threshold. One definition for "the brake is on": the coasting channel (no axle braked)
    and the stop a force is judged over (from the first braked sample) both use it."""
    return trace.p_cyl_bar >= p_threshold_bar(trace) + BRAKED_MARGIN_BAR


# vendor name -> (canonical name, factor) ; see docs/trace_format.md "Vendor channel names"
_VENDOR_FIXED = {
    "time": ("time_s", 1.0),
    "vtrain": ("v_train_kmh", 3.6),
    "vref": ("v_ref_kmh", 3.6),
    "dec_train": ("a_train_mps2", 1.0),
    "ed": ("ed_force_kN", 1e-3),
}
_VENDOR_AXLE = [
    (re.compile(r"^vites_fc_ax(\d+)$"), "v_axle_{}_kmh", 1.0),
    (re.compile(r"^p_cyl(\d+)$"), "p_cyl_{}_bar", 1.0),
]
_OPTIONAL = ("v_ref_kmh", "a_train_mps2", "p_demand_bar")


def _fail(path: Path, what: str) -> TraceError:
    return TraceError(f"{path}: {what}")


def _read_meta(csv_path: Path) -> tuple[Path, dict[str, Any]]:
    name = csv_path.name[:-4] if csv_path.name.endswith(".csv") else csv_path.stem
    meta_path = csv_path.with_name(f"{name}.meta.json")
    if not meta_path.exists():
        raise _fail(meta_path, "metadata file missing (expected next to the CSV)")
    try:
        meta = json.loads(meta_path.read_text())
    except json.JSONDecodeError as err:
        raise _fail(meta_path, f"invalid JSON (line {err.lineno}: {err.msg})") from None
    if not isinstance(meta, dict):
        raise _fail(meta_path, "expected a JSON object")
    if meta.get("format") != FORMAT:
        raise _fail(meta_path, f"format: expected {FORMAT!r}, got {meta.get('format')!r}")
    veh = meta.get("vehicle")
    if not isinstance(veh, dict):
        raise _fail(meta_path, "vehicle: missing or not an object")
    for key in ("mass_kg", "wheel_radius_m", "n_axles"):
        value = veh.get(key)
        if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
            raise _fail(meta_path, f"vehicle.{key}: missing or not a positive number")
    if int(veh["n_axles"]) != veh["n_axles"]:
        raise _fail(meta_path, "vehicle.n_axles: must be a whole number")
    period = meta.get("sample_period_s")
    if isinstance(period, bool) or not isinstance(period, int | float) or not period > 0:
        raise _fail(meta_path, "sample_period_s: missing or not a positive number")
    if meta.get("contaminant", "unknown") not in CONTAMINANTS:
        raise _fail(meta_path, f"contaminant: {meta['contaminant']!r} not one of {CONTAMINANTS}")
    for key in ("axle_static_load_kN", "axle_load_transfer_kN_per_mps2"):
        per_axle = veh.get(key)
        if per_axle is None:
            continue
        problem = _per_axle_problem(per_axle, int(veh["n_axles"]))
        if problem:
            raise _fail(meta_path, f"vehicle.{key}: must list one number per axle ({problem})")
    _check_geometry(meta_path, veh)
    _check_axle_offsets(meta_path, veh)
    brake = veh.get("brake", {})
    gains = brake.get("axle_torque_gain_Nm_per_bar") if isinstance(brake, dict) else None
    problem = None if gains is None else _per_axle_problem(gains, int(veh["n_axles"]), True)
    if problem:
        raise _fail(
            meta_path, "vehicle.brake.axle_torque_gain_Nm_per_bar: must list one positive "
            f"number per axle ({problem})"
        )  # fmt: skip
    return meta_path, meta


def _finite(x: Any) -> bool:
    """A JSON number (not a boolean) that is finite; an integer too large for a float is not."""
    if isinstance(x, bool) or not isinstance(x, int | float):
        return False
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


def _per_axle_problem(values: Any, n_axles: int, positive: bool = False) -> str | None:
    """What is wrong with a per-axle list of the metadata, in a few words, or ``None``."""
    if not isinstance(values, list):
        return f"got {type(values).__name__}"
    if len(values) != n_axles:
        return f"{len(values)} numbers for {n_axles} axles"
    for i, x in enumerate(values, start=1):
        if not _finite(x) or (positive and not x > 0):
            return f"axle {i}: {str(x)[:20]!r}"
    return None


# Optional vehicle geometry (one car; ``docs/trace_format.md``): name -> (low, high) bounds,
# each the range of a railway vehicle that has one (a value outside is a typo or a unit error)
GEOMETRY_BOUNDS: dict[str, tuple[float, float]] = {
    "cog_height_m": (0.3, 4.0),  # body centre of gravity above the rail
    "bogie_centre_distance_m": (2.0, 40.0),
    "bogie_wheelbase_m": (1.0, 5.0),
    "bogie_pivot_height_m": (0.1, 2.0),  # where the body's braking force enters the bogie
    "bogie_cog_height_m": (0.2, 1.5),  # bogie frame and wheelsets
    "bogie_mass_kg": (500.0, 30000.0),
}


def _check_geometry(meta_path: Path, veh: dict[str, Any]) -> None:
    """One line for the first optional geometry field that is not a number within its bounds,
    or that contradicts another (a bogie longer than the distance between bogies, bogies
    heavier than their car, a bogie's centre of gravity without its mass)."""
    for key, (low, high) in GEOMETRY_BOUNDS.items():
        value = veh.get(key)
        if value is None:
            continue
        number = isinstance(value, int | float) and not isinstance(value, bool)
        if not number or not low <= value <= high:
            raise _fail(meta_path, f"vehicle.{key}: must be a number in [{low:g}, {high:g}], "
                        f"got {value!r}")  # fmt: skip
    wb, dist = veh.get("bogie_wheelbase_m"), veh.get("bogie_centre_distance_m")
    if wb is not None and dist is not None and wb >= dist:
        raise _fail(meta_path, f"vehicle.bogie_wheelbase_m: {wb:g} m is not shorter than "
                    f"bogie_centre_distance_m {dist:g} m")  # fmt: skip
    mb = veh.get("bogie_mass_kg")
    n = int(veh["n_axles"])
    if mb is not None and n % 2 == 0 and mb * (n // 2) >= veh["mass_kg"]:
        raise _fail(meta_path, f"vehicle.bogie_mass_kg: {n // 2} bogies of {mb:g} kg weigh as "
                    f"much as the vehicle ({veh['mass_kg']:g} kg)")  # fmt: skip
    if (veh.get("bogie_cog_height_m") is None) != (mb is None):
        raise _fail(meta_path, "vehicle.bogie_cog_height_m and bogie_mass_kg: give both or "
                    "neither (the bogie's own pitch needs its mass and its height)")  # fmt: skip


# the optional per-axle positions along the train (m behind axle 1): a train up to this long
MAX_TRAIN_LENGTH_M = 1000.0


def _check_axle_offsets(meta_path: Path, veh: dict[str, Any]) -> None:
    """One line where the optional ``vehicle.axle_offsets_m`` is not each axle's distance behind
    axle 1 in running order: one number per axle, the first 0, each behind the one before
    (all zeros would read as unknown places, ``adhesion_model.axle_offsets_m``), within
    ``MAX_TRAIN_LENGTH_M``."""
    off = veh.get("axle_offsets_m")
    if off is None:
        return
    field = "vehicle.axle_offsets_m"
    problem = _per_axle_problem(off, int(veh["n_axles"]))
    if problem:
        raise _fail(meta_path, f"{field}: must list one number per axle ({problem})")
    if off[0] != 0:
        raise _fail(meta_path, f"{field}: axle 1's must be 0 (distances behind axle 1, axle 1 "
                    f"first), got {off[0]!r}")  # fmt: skip
    for i in range(1, len(off)):
        if off[i] < off[i - 1]:
            raise _fail(meta_path, f"{field}: axle {i + 1} ({off[i]:g} m) is ahead of axle {i} "
                        f"({off[i - 1]:g} m): list the axles in running order")  # fmt: skip
        if off[i] == off[i - 1]:  # two wheelsets cannot share a place (all zeros: unknown)
            raise _fail(meta_path, f"{field}: axle {i + 1} at the place of axle {i} "
                        f"({off[i]:g} m)")  # fmt: skip
    if off[-1] > MAX_TRAIN_LENGTH_M:
        raise _fail(meta_path, f"{field}: the last axle {off[-1]:g} m behind the first: more "
                    f"than a {MAX_TRAIN_LENGTH_M:g} m train (metres?)")  # fmt: skip


def _read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    try:
        with path.open(newline="") as fh:
            rows = []
            for row in csv.reader(fh):
                rows.append(row)
                if len(rows) > MAX_ROWS + 1:
                    raise _fail(
                        path, f"more than {MAX_ROWS:,} data rows: not one braking test (cut or "
                        "resample it)"
                    )  # fmt: skip
    except FileNotFoundError:
        raise _fail(path, "no such file") from None
    except csv.Error as err:  # e.g. a field over the csv module's 128 KiB limit
        raise _fail(path, f"not a readable CSV ({err})") from None
    except (OSError, UnicodeDecodeError) as err:
        raise _fail(path, f"cannot read ({err})") from None
    if not rows or not any(h.strip() for h in rows[0]):
        raise _fail(path, "empty file (no header line)")
    header = [h.strip() for h in rows[0]]
    seen = set()
    for h in header:
        if h in seen:
            raise _fail(path, f"column {h!r}: appears twice in the header")
        seen.add(h)
    body = [r for r in rows[1:] if any(c.strip() for c in r)]
    for i, r in enumerate(body, start=2):
        if len(r) != len(header):
            raise _fail(path, f"line {i}: {len(r)} fields, header has {len(header)}")
    if len(body) < 3:
        raise _fail(path, f"only {len(body)} data rows (need at least 3)")
    return header, body


def _column(path: Path, name: str, cells: list[str]) -> np.ndarray:
    out = np.empty(len(cells))
    for i, c in enumerate(cells):
        c = c.strip()
        if c == "":
            out[i] = np.nan
            continue
        try:
            out[i] = float(c)
        except ValueError:
            raise _fail(path, f"column {name!r}: non-numeric value {c!r} on line {i + 2}") from None
        if math.isinf(out[i]):
            raise _fail(path, f"column {name!r}: infinite value on line {i + 2}")
    return out


def _canonical(path: Path, header: list[str], body: list[list[str]]) -> tuple[dict, list[str]]:
    """Columns under canonical names, in canonical units; vendor aliases converted."""
    notes: list[str] = []
    raw = {h: _column(path, h, [r[j] for r in body]) for j, h in enumerate(header)}
    cols: dict[str, np.ndarray] = {}
    for name, values in raw.items():
        target, factor = name, 1.0
        if name in _VENDOR_FIXED:
            target, factor = _VENDOR_FIXED[name]
        for pattern, template, f in _VENDOR_AXLE:
            m = pattern.match(name)
            if m:
                target, factor = template.format(int(m.group(1))), f
        if target != name:
            if target in raw:
                raise _fail(
                    path, f"column {name!r}: vendor alias of {target!r}, which is also present"
                )
            notes.append(
                f"column {name!r} read as {target!r}" + (f" (x {factor:g})" if factor != 1 else "")
            )
        cols[target] = values * factor
    if "time_camp" in raw and "time_s" not in cols:
        period = raw["time_camp"]
        if np.isnan(period).any() or (period <= 0).any():
            raise _fail(path, "column 'time_camp': sample periods must be positive, without gaps")
        cols["time_s"] = np.concatenate([[0.0], np.cumsum(period[:-1])])
        notes.append("column 'time_camp' (sample period) integrated into 'time_s'")
    return cols, notes


def _fill_gaps(
    path: Path, name: str, values: np.ndarray, t: np.ndarray, notes: list[str]
) -> np.ndarray:
    missing = np.isnan(values)
    if not missing.any():
        return values
    if missing.mean() > 0.5:
        raise _fail(path, f"column {name!r}: mostly empty ({missing.mean():.0%} missing)")
    # runs of missing samples
    edges = np.diff(np.concatenate([[0], missing.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    longest = int((ends - starts).max())
    if longest > MAX_GAP:
        i = int(starts[np.argmax(ends - starts)])
        raise _fail(
            path,
            f"column {name!r}: {longest} missing samples in a row from t = {t[i]:.3f} s "
            f"(at most {MAX_GAP} are interpolated)",
        )
    if missing[0] or missing[-1]:
        raise _fail(path, f"column {name!r}: missing value at the start or end of the record")
    filled = values.copy()
    filled[missing] = np.interp(t[missing], t[~missing], values[~missing])
    notes.append(f"column {name!r}: {int(missing.sum())} missing samples interpolated")
    return filled


def _check_jumps(path: Path, v_kmh: np.ndarray, t: np.ndarray) -> None:
    """A ground speed that steps by more than a train can between two samples."""
    dv = np.abs(np.diff(v_kmh))
    rate = dv / 3.6 / np.diff(t)
    bad = np.flatnonzero((dv > MAX_STEP_KMH) & (rate > MAX_STEP_MPS2))
    if bad.size:
        i = int(bad[0])
        raise _fail(
            path, f"column 'v_train_kmh': jumps {v_kmh[i]:g} -> {v_kmh[i + 1]:g} km/h between "
            f"t = {t[i]:g} and {t[i + 1]:g} s (line {i + 2}): no train does that"
        )  # fmt: skip


def read_trace(csv_path: str | Path) -> Trace:
    """Read and validate ``NAME.csv`` + ``NAME.meta.json`` (see the module docstring)."""
    path = Path(csv_path)
    if not path.is_file():
        raise _fail(path, "no such file" if not path.exists() else "not a file")
    meta_path, meta = _read_meta(path)
    header, body = _read_csv(path)
    cols, notes = _canonical(path, header, body)
    n = int(meta["vehicle"]["n_axles"])
    axle_cols = sorted(
        {int(m.group(1)) for c in cols if (m := re.match(r"^v_axle_(\d+)_kmh$", c))}
        | {int(m.group(1)) for c in cols if (m := re.match(r"^p_cyl_(\d+)_bar$", c))}
    )
    if axle_cols and max(axle_cols) > n:
        raise _fail(
            meta_path,
            f"vehicle.n_axles: {n}, but the CSV has columns for axle {max(axle_cols)}",
        )
    required = ["time_s", "v_train_kmh"] + [f"v_axle_{i}_kmh" for i in range(1, n + 1)]
    required += [f"p_cyl_{i}_bar" for i in range(1, n + 1)]
    for name in required:
        if name not in cols:
            raise _fail(path, f"column {name!r}: required but missing")
    t = cols["time_s"]
    if np.isnan(t).any():
        raise _fail(
            path, f"column 'time_s': empty cell on line {int(np.flatnonzero(np.isnan(t))[0]) + 2}"
        )
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise _fail(
            path,
            f"column 'time_s': not strictly increasing at line {int(bad[0]) + 3} "
            f"({t[bad[0]]:g} -> {t[bad[0] + 1]:g})",
        )
    if t[-1] - t[0] > MAX_DURATION_S:
        raise _fail(
            path, f"column 'time_s': spans {t[-1] - t[0]:.0f} s, more than one braking test "
            f"({MAX_DURATION_S:.0f} s at most; cut it)"
        )  # fmt: skip
    gap_filled = np.isnan(cols["v_train_kmh"])  # filled samples are no GPS update (unhold)
    for name in required[1:]:
        cols[name] = _fill_gaps(path, name, cols[name], t, notes)
    for name in _OPTIONAL:
        if name in cols:
            if np.isnan(cols[name]).mean() > 0.5:
                notes.append(f"column {name!r}: mostly empty, ignored")
                del cols[name]
            else:
                cols[name] = _fill_gaps(path, name, cols[name], t, notes)
    _check_units(path, meta, cols, n)
    _check_jumps(path, cols["v_train_kmh"], t)
    cols["v_train_kmh"], v_noise, v_update = unhold(cols["v_train_kmh"], t, notes, gap_filled)
    v_logger_lag, v_update_noise = 0.0, v_noise
    if v_update is None:  # nothing held: perhaps updates averaged over the log period
        averaged = averaged_updates(cols["v_train_kmh"], t, notes, gap_filled)
        if averaged is not None:
            v_update, v_update_noise = averaged
            v_logger_lag = 0.5 * v_update
    elif not math.isfinite(v_update):  # held, but fewer than two updates to time
        v_update = None
    v_axle = np.stack([cols[f"v_axle_{i}_kmh"] for i in range(1, n + 1)], axis=1)
    p_cyl = np.stack([cols[f"p_cyl_{i}_bar"] for i in range(1, n + 1)], axis=1)
    optional = {k: cols[k] for k in _OPTIONAL if k in cols}
    known = set(required) | set(optional)
    extra = {k: v for k, v in cols.items() if k not in known}
    return Trace(
        path, meta, t, cols["v_train_kmh"], v_axle, p_cyl, optional, extra, notes, v_noise,
        v_update, v_logger_lag, v_update_noise,
    )  # fmt: skip


HELD_FRACTION = 0.3  # of the moving samples repeating the previous value exactly
# of the levels inside the record shown for a single sample: at or above, the singles are an
# averaging logger's blends (one at nearly every change of fix); below, a holding logger shows
# an occasional fix once because its clock jitters against the fixes (measured on the
# independent generator: holding loggers 0-25 %, averaging ones 33-100 %)
BLEND_SINGLES_FRACTION = 0.3


def unhold(
    v: np.ndarray, t: np.ndarray, notes: list[str], filled: np.ndarray | None = None
) -> tuple[np.ndarray, float | None, float | None]:
    """A ground speed held between updates (a GPS fix every 0.1-1 s, logged faster, or held
    through a dropout) lags the true speed by up to an update interval and has no sample noise
    to measure. Where more than ``HELD_FRACTION`` of the moving samples repeat the previous
    value exactly, each held level (a run of equal samples) is one update, and the speed is
    interpolated linearly between updates (noted).

    When an update became due: a holding logger shows a fix at the first sample after it
    arrived, so the fix is placed halfway between that sample and the one before. A logger
    that averages over its period shows the change first as a blend of the two fixes, a single
    sample (``BLEND_SINGLES_FRACTION`` tells the two loggers apart on the whole record): the
    blend is dropped and its value places the change inside its averaging window — a blend
    ``w v_prev + (1 - w) v_next`` says the previous fix filled the first ``w`` of the window.
    Samples the reader interpolated across a gap (``filled``) are no update either.
    Returns the speed, the noise measured on the updates (None where nothing was held or too
    few updates to measure it) and the median interval between updates (None where nothing
    was held, NaN where held with fewer than two updates)."""
    moving = v > 1.0
    repeats = np.concatenate([[False], np.diff(v) == 0.0])
    if moving.sum() < 10 or repeats[moving].mean() <= HELD_FRACTION:
        return v, None, None
    period = float(np.median(np.diff(t)))
    change = np.flatnonzero(np.diff(v) != 0.0) + 1  # first sample of every run
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [v.size]])  # exclusive
    inner = (ends - starts)[1:-1]
    blends = inner.size > 0 and float(np.mean(inner == 1)) >= BLEND_SINGLES_FRACTION
    fix_t, fix_v = [], []
    if filled is None:
        filled = np.zeros(v.size, dtype=bool)
    for j, (a, b) in enumerate(zip(starts, ends, strict=True)):
        single = b - a == 1 and 0 < a and b < v.size
        if (blends and single) or (0 < a and filled[a:b].all()):
            continue  # a blend (it times the next level, below) or a gap the reader filled
        if a == 0:
            fix_t.append(t[0])
        elif blends and ends[j - 1] - starts[j - 1] == 1 and not filled[a - 1]:
            # the level after a blend: the change fell inside the blend's averaging window
            prev, mix, nxt = fix_v[-1], v[a - 1], v[a]
            w = (mix - nxt) / (prev - nxt) if prev != nxt else 0.5
            fix_t.append(t[a - 1] - (1.0 - float(np.clip(w, 0.0, 1.0))) * period)
        else:  # due somewhere after the previous sample: the middle of that interval
            fix_t.append(0.5 * (t[a - 1] + t[a]))
        fix_v.append(v[a])
    fix_t_arr = np.asarray(fix_t)
    keep = np.concatenate([[True], np.diff(fix_t_arr) > 0.0])
    fix_v_arr = np.asarray(fix_v)[keep]
    out = np.interp(t, fix_t_arr[keep], fix_v_arr)
    noise = _updates_noise_kmh(fix_v_arr)
    kept_t = fix_t_arr[keep]
    interval = float(np.median(np.diff(kept_t))) if kept_t.size > 1 else float("nan")
    logger = "averaged (blends dropped)" if blends else "held"
    notes.append(
        f"column 'v_train_kmh': {logger} between updates (median interval {interval:.2f} s, "
        f"{100 * repeats[moving].mean():.0f} % of moving samples repeated): interpolated "
        "between the updates"
    )
    return out, noise, interval


# GPS update intervals (s) a logger may average without showing repeats (1.5-3.5 log periods:
# shorter ones are the log's own rate, longer ones leave held samples for ``unhold``)
GPS_INTERVALS_S = (0.1, 0.125, 0.2, 0.25, 0.5)
# the held-and-averaged model must leave at most this fraction of what a smooth curve with as
# many parameters leaves (measured on the independent generator: 5 Hz fixes averaged at 10 Hz
# 0.09-0.34, 10 Hz fixes 1.04-1.44)
HELD_MODEL_RATIO = 0.5
HELD_MODEL_PHASES = 20


def _levels_design(t: np.ndarray, period: float, knots: np.ndarray) -> sparse.csr_matrix:
    """Rows: each sample as the mean over its log period ``[t - period, t]`` of a signal held
    between ``knots`` (one column per level); at most two levels per row (knot spacing >= 1.5
    periods)."""
    lo = t - period
    m = knots.size - 1
    j0 = np.clip(np.searchsorted(knots, lo, side="right") - 1, 0, m - 1)
    j1 = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, m - 1)
    first = (np.minimum(t, knots[j0 + 1]) - lo) / period
    rows = np.arange(t.size)
    second = j1 > j0
    data = np.concatenate([np.where(second, first, 1.0), 1.0 - first[second]])
    return sparse.csr_matrix(
        (data, (np.concatenate([rows, rows[second]]), np.concatenate([j0, j1[second]]))),
        shape=(t.size, m),
    )


def _ls_rss(design: sparse.csr_matrix, v: np.ndarray) -> tuple[float, np.ndarray]:
    """Least squares of ``v`` on the used columns of ``design``: (residual sum, coefficients;
    NaN for unused columns)."""
    used = np.asarray(np.abs(design).sum(axis=0)).ravel() > 1e-9
    a = design[:, used].tocsc()
    ata = (a.T @ a).tocsc() + sparse.identity(int(used.sum()), format="csc") * 1e-9
    coef = np.full(design.shape[1], np.nan)
    coef[used] = spsolve(ata, a.T @ v)
    e = a @ coef[used] - v
    return float(e @ e), coef


def averaged_updates(
    v: np.ndarray, t: np.ndarray, notes: list[str], filled: np.ndarray | None = None
) -> tuple[float, float | None] | None:
    """The update interval and the noise of one update of a GPS speed updated every ``P`` (a
    few log periods, ``GPS_INTERVALS_S``) and averaged over each log period, or None. Such a
    column repeats no sample for ``unhold`` to find (a 5 Hz fix logged at 10 Hz: a blend of
    two fixes, then the new fix alone), yet it trails the train by half an update more than
    the other averaged columns (the pressures): ~0.1 s, a ground-speed lag in every trace that
    is the logger's, not the sensor's.

    Each sample is modelled as the mean over its log period of a level held from one update
    to the next (updates every ``P``, at a phase on a grid of ``HELD_MODEL_PHASES``), the
    levels by least squares. Where the best such model leaves under ``HELD_MODEL_RATIO`` of
    what a piecewise-linear curve with a knot every ``P`` leaves (as many parameters, no
    holding; the median over four placements of its knots), the column is taken as held and
    averaged (noted), and the noise of one update is measured on the fitted levels (the
    samples' own noise is lower: a blend averages two updates). The column itself is left as
    logged, and its samples' noise stays what the channels are judged by. Samples the reader
    filled across a gap are left out of the fit; a record with nothing to fit (a constant
    speed: both models leave nothing) has no update interval to find."""
    fit = np.ones(v.size, dtype=bool) if filled is None else ~filled
    if (fit & (v > 1.0)).sum() < 50:
        return None
    period = float(np.median(np.diff(t)))
    tf, vf = t[fit], v[fit]
    best: tuple[float, float, np.ndarray] | None = None
    for interval in GPS_INTERVALS_S:
        if not 1.5 * period <= interval <= 3.5 * period:
            continue
        held = min(
            (
                _ls_rss(
                    _levels_design(tf, period, np.arange(
                        t[0] - period - interval + phase, t[-1] + interval, interval)),
                    vf,
                )
                for phase in np.arange(HELD_MODEL_PHASES) * interval / HELD_MODEL_PHASES
            ),
            key=lambda fitted: fitted[0],
        )  # fmt: skip
        smooth = float(np.median([
            _ls_rss(_hat_design(tf, np.arange(t[0] - interval, t[-1] + 2 * interval, interval)
                                + shift), vf)[0]
            for shift in np.arange(4) * interval / 4
        ]))  # fmt: skip
        if smooth <= 1e-6 * vf.size:  # a straight line leaves nothing: no noise to tell by
            continue
        ratio = held[0] / smooth
        if ratio < HELD_MODEL_RATIO and (best is None or ratio < best[0]):
            best = (ratio, interval, held[1])
    if best is None:
        return None
    ratio, interval, levels = best
    noise = _updates_noise_kmh(levels[np.isfinite(levels)])
    notes.append(
        f"column 'v_train_kmh': updates every {interval:g} s averaged over the {period:g} s log "
        f"period (a held model leaves {100 * ratio:.0f} % of a smooth curve's residual): it "
        f"trails the train by ~{0.5 * interval:g} s more than the other columns, counted as the "
        "logger's timing"
    )
    return float(interval), noise


def _hat_design(t: np.ndarray, knots: np.ndarray) -> sparse.csr_matrix:
    """Piecewise-linear interpolation between ``knots`` (one column per knot)."""
    j = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, knots.size - 2)
    w = (t - knots[j]) / (knots[j + 1] - knots[j])
    rows = np.arange(t.size)
    return sparse.csr_matrix(
        (np.concatenate([1.0 - w, w]), (np.concatenate([rows, rows]), np.concatenate([j, j + 1]))),
        shape=(t.size, knots.size),
    )


def _check_units(path: Path, meta: dict, cols: dict[str, np.ndarray], n: int) -> None:
    """Values that cannot be in the stated unit (one line naming the column)."""
    v0 = meta.get("initial_speed_kmh")
    speeds = ["v_train_kmh"] + [f"v_axle_{i}_kmh" for i in range(1, n + 1)]
    for name in speeds:
        v = cols[name]
        if np.nanmin(v) < -5.0:
            raise _fail(path, f"column {name!r}: negative speed {np.nanmin(v):g} km/h")
        if np.nanmax(v) > MAX_SPEED_KMH:
            raise _fail(path, f"column {name!r}: {np.nanmax(v):g} km/h is not a plausible speed")
    if isinstance(v0, int | float) and v0 > 20:
        top = float(np.nanmax(cols["v_train_kmh"]))
        if abs(top * 3.6 - v0) < 0.15 * v0 and abs(top - v0) > 0.3 * v0:
            raise _fail(
                path,
                f"column 'v_train_kmh': peaks at {top:.1f}, initial_speed_kmh is {v0:g}: "
                "looks like m/s, not km/h",
            )
    for i in range(1, n + 1):
        name = f"p_cyl_{i}_bar"
        p = cols[name]
        if np.nanmax(p) > MAX_PRESSURE_BAR:
            raise _fail(
                path,
                f"column {name!r}: {np.nanmax(p):g} bar is not a plausible cylinder pressure "
                "(kPa or psi instead of bar?)",
            )
        if np.nanmin(p) < -0.5:
            raise _fail(path, f"column {name!r}: negative pressure {np.nanmin(p):g} bar")

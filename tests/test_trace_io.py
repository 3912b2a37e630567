"""Tests of the wsp-trace/1 writer (``evaluation.trace_writer``: sampling, writing) and plot_run.

Written files are read back by ``read_csv`` below, a plain ``csv``-module reader that shares no
code with the package; the package's own reader (``calibration.traces.read_trace``) is tested in
``test_traces.py``.
"""

from __future__ import annotations

import csv
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

import wsp_env.files
from wsp_env.calibration.traces import TraceError, read_trace
from wsp_env.core.records import RunRecord
from wsp_env.evaluation.plotting import plot_run
from wsp_env.evaluation.trace_writer import SensorModel, sample_run, write_trace

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def read_csv(csv_path: Path) -> tuple[dict[str, np.ndarray], dict]:
    """A written trace's columns (float, empty cells NaN, file order) and metadata."""
    with open(csv_path, encoding="utf-8", newline="") as fh:
        rows = list(csv.reader(fh))
    header, body = rows[0], rows[1:]
    columns = {
        name: np.array([float(r[j]) if r[j].strip() else np.nan for r in body])
        for j, name in enumerate(header)
    }
    meta_path = csv_path.with_name(csv_path.name[: -len(".csv")] + ".meta.json")
    return columns, json.loads(meta_path.read_text())


def make_meta(n_axles: int = 4) -> dict:
    return {
        "test_id": "unit test",
        "sample_period_s": 0.1,
        "initial_speed_kmh": 120.0,
        "contaminant": "soap",
        "brake_type": "emergency",
        "vehicle": {
            "name": "UIC-Z1 coach",
            "mass_kg": 45000.0,
            "n_axles": n_axles,
            "wheel_radius_m": 0.46,
            "wheelset_inertia_kgm2": 160.0,
            "brake": {"p_threshold_bar": 0.174, "torque_gain_Nm_per_bar": 2620.0, "p_max_bar": 3.8},
        },
    }


def braking_record(n_axles: int = 4, dt: float = 0.02, duration: float = 30.0) -> RunRecord:
    """A plausible braking run from 120 km/h with slide episodes and WSP dumps."""
    t = np.arange(0.0, duration + dt / 2, dt)
    decel = 0.9  # m/s^2
    v_train = np.maximum(120.0 - decel * 3.6 * t, 0.0)
    slide = np.zeros((t.size, n_axles))
    active = np.zeros((t.size, n_axles), dtype=bool)
    for i in range(n_axles):
        for start in (3.0 + 0.7 * i, 11.0 + 0.5 * i, 19.0 + 0.3 * i):
            bump = np.clip(1.0 - np.abs(t - start - 1.0) / 1.0, 0.0, None)
            slide[:, i] += (12.0 - 2.0 * i) * bump
            active[:, i] |= bump > 0.3
    v_axle = np.maximum(v_train[:, None] - slide * (v_train[:, None] > 0), 0.0)
    p_demand = np.minimum(t / 1.5, 1.0) * 3.8
    p_cyl = np.where(active, 0.8, p_demand[:, None]) + 0.05 * np.arange(n_axles)
    return RunRecord(
        time_s=t,
        v_train_kmh=v_train,
        v_axle_kmh=v_axle,
        p_cyl_bar=p_cyl,
        p_demand_bar=p_demand,
        a_train_mps2=np.where(v_train > 0, decel, 0.0),
        v_ref_kmh=v_train + 0.5,
        wsp_active=active,
    )


def constant_record(
    duration: float, dt: float = 0.02, v: float = 80.0, p: float = 2.0, a: float = 0.5
) -> RunRecord:
    t = np.arange(0.0, duration + dt / 2, dt)
    n = t.size
    return RunRecord(
        time_s=t,
        v_train_kmh=np.full(n, v),
        v_axle_kmh=np.full((n, 2), v),
        p_cyl_bar=np.full((n, 2), p),
        p_demand_bar=np.full(n, p),
        a_train_mps2=np.full(n, a),
    )


def ramp_record(dt: float = 0.02, duration: float = 10.0) -> RunRecord:
    t = np.arange(0.0, duration + dt / 2, dt)
    return RunRecord(
        time_s=t,
        v_train_kmh=100.0 - 5.0 * t,
        v_axle_kmh=np.column_stack([100.0 - 6.0 * t, 99.0 - 5.5 * t]),
        p_cyl_bar=np.column_stack([0.3 * t, 0.2 * t + 0.1]),
        p_demand_bar=0.35 * t,
        a_train_mps2=0.1 * t,
        v_ref_kmh=101.0 - 5.0 * t,
    )


# ------------------------------------------------------------------------------------------
# Round trip
# ------------------------------------------------------------------------------------------


def test_round_trip(tmp_path: Path) -> None:
    sensors = SensorModel(sample_period_s=0.1, jitter_s=0.005, speed_noise_kmh=0.3)
    columns = sample_run(braking_record(), sensors, np.random.default_rng(1))
    columns["ed_force_kN"] = np.full(columns["time_s"].size, np.nan)  # extra column, all empty
    columns["ed_force_kN"][::3] = 12.5
    meta = make_meta()
    csv_path, meta_path = write_trace(tmp_path / "run7", columns, meta)
    assert csv_path == tmp_path / "run7.csv"
    assert meta_path == tmp_path / "run7.meta.json"
    assert "format" not in meta  # the caller's dict is not modified

    read, read_meta = read_csv(csv_path)
    assert list(read) == list(columns)
    for name, col in columns.items():
        want = np.asarray(col, dtype=float)
        if name == "time_s":
            np.testing.assert_allclose(read[name], want, rtol=0, atol=5.1e-5)  # %.4f
        else:  # %.6g: relative error <= 5e-6
            np.testing.assert_allclose(read[name], want, rtol=1e-5, atol=1e-12, equal_nan=True)
    assert read_meta == {**meta, "format": "wsp-trace/1"}

    header = csv_path.read_text().splitlines()[0]
    assert header.startswith("time_s,v_train_kmh,v_axle_1_kmh,")
    assert "wsp_active_4" in header


def test_written_file_is_compact(tmp_path: Path) -> None:
    columns = sample_run(braking_record(), SensorModel(), np.random.default_rng(0))
    csv_path, _ = write_trace(tmp_path / "x.csv", columns, make_meta())  # ".csv" is stripped
    assert csv_path.name == "x.csv"
    row = csv_path.read_text().splitlines()[5].split(",")
    assert row[0] == "0.4000"  # time %.4f
    assert all(len(cell) <= 12 for cell in row)  # %.6g
    active = csv_path.read_text().splitlines()[1].split(",")[-4:]
    assert set(active) <= {"0", "1"}


# ------------------------------------------------------------------------------------------
# Sampling
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("jitter", [0.0, 0.02])
def test_linear_ramp_sampled_exactly(jitter: float) -> None:
    rec = ramp_record()
    cols = sample_run(
        rec, SensorModel(sample_period_s=0.1, jitter_s=jitter), np.random.default_rng(3)
    )
    t = cols["time_s"]
    assert t.size == 101
    if jitter == 0:
        np.testing.assert_allclose(t, 0.1 * np.arange(101), atol=1e-12)
    np.testing.assert_allclose(cols["v_train_kmh"], 100.0 - 5.0 * t, atol=1e-9)
    np.testing.assert_allclose(cols["v_axle_1_kmh"], 100.0 - 6.0 * t, atol=1e-9)
    np.testing.assert_allclose(cols["v_axle_2_kmh"], 99.0 - 5.5 * t, atol=1e-9)
    np.testing.assert_allclose(cols["p_cyl_1_bar"], 0.3 * t, atol=1e-9)
    np.testing.assert_allclose(cols["p_cyl_2_bar"], 0.2 * t + 0.1, atol=1e-9)
    np.testing.assert_allclose(cols["p_demand_bar"], 0.35 * t, atol=1e-9)
    np.testing.assert_allclose(cols["a_train_mps2"], 0.1 * t, atol=1e-9)
    np.testing.assert_allclose(cols["v_ref_kmh"], 101.0 - 5.0 * t, atol=1e-9)
    assert list(cols) == [
        "time_s",
        "v_train_kmh",
        "v_axle_1_kmh",
        "v_axle_2_kmh",
        "p_cyl_1_bar",
        "p_cyl_2_bar",
        "v_ref_kmh",
        "a_train_mps2",
        "p_demand_bar",
    ]


def test_noise_std_matches_configuration() -> None:
    # 4001 samples per channel: the relative standard error of a sample std is about
    # 1 / sqrt(2 * (N - 1)) = 1.1 %, so a 20 % band is ~18 standard errors wide: it can never
    # fail by chance for any seed, yet still catches real mistakes (variance used as std,
    # noise applied twice (x sqrt 2 = +41 %), a wrong channel scaled, noise missing). The
    # constant levels sit far above zero so the physical clipping at 0 cannot bias the spread.
    rec = constant_record(duration=400.0)
    sensors = SensorModel(
        sample_period_s=0.1, speed_noise_kmh=0.5, pressure_noise_bar=0.05, accel_noise_mps2=0.02
    )
    cols = sample_run(rec, sensors, np.random.default_rng(7))
    expected = {
        "v_train_kmh": 0.5,
        "v_axle_1_kmh": 0.5,
        "v_axle_2_kmh": 0.5,
        "p_cyl_1_bar": 0.05,
        "p_cyl_2_bar": 0.05,
        "p_demand_bar": 0.05,
        "a_train_mps2": 0.02,
    }
    assert cols["time_s"].size == 4001
    for name, std in expected.items():
        assert abs(np.std(cols[name], ddof=1) / std - 1.0) < 0.2, name
    np.testing.assert_allclose(np.mean(cols["v_train_kmh"]), 80.0, atol=0.05)


def test_quantisation_and_clipping() -> None:
    rec = constant_record(duration=20.0, v=0.2, p=0.01)
    sensors = SensorModel(
        speed_noise_kmh=1.0,
        pressure_noise_bar=0.1,
        speed_quantum_kmh=0.25,
        pressure_quantum_bar=0.02,
    )
    cols = sample_run(rec, sensors, np.random.default_rng(5))
    for name in ("v_train_kmh", "v_axle_1_kmh", "p_cyl_2_bar", "p_demand_bar"):
        assert np.all(cols[name] >= 0.0), name
        assert np.any(cols[name] == 0.0), name  # the clip did act
        assert not np.any(np.signbit(cols[name])), name  # no -0.0
    np.testing.assert_allclose(cols["v_train_kmh"] / 0.25, np.round(cols["v_train_kmh"] / 0.25))
    np.testing.assert_allclose(cols["p_cyl_1_bar"] / 0.02, np.round(cols["p_cyl_1_bar"] / 0.02))


def test_jittered_times_strictly_increasing_and_in_span() -> None:
    rec = braking_record(duration=60.0)
    for period in (0.1, 0.02):
        sensors = SensorModel(sample_period_s=period, jitter_s=0.25 * period)  # the maximum
        t = sample_run(rec, sensors, np.random.default_rng(11))["time_s"]
        assert np.all(np.diff(t) > 0)
        assert t[0] >= rec.time_s[0] and t[-1] <= rec.time_s[-1]
        nominal = period * np.arange(t.size)
        assert np.max(np.abs(t - nominal)) <= 0.45 * period + 1e-12
        assert np.std(t - nominal) > 0.1 * period  # jitter is really there


def test_wsp_active_any_within_preceding_period() -> None:
    t = np.arange(0.0, 2.0 + 1e-9, 0.02)
    n = t.size
    active = np.zeros((n, 1), dtype=bool)
    active[(t > 0.42) & (t < 0.47), 0] = True  # a 40 ms pulse between logger samples 0.4 and 0.5
    rec = RunRecord(
        time_s=t,
        v_train_kmh=np.full(n, 50.0),
        v_axle_kmh=np.full((n, 1), 50.0),
        p_cyl_bar=np.full((n, 1), 1.0),
        p_demand_bar=np.full(n, 1.0),
        a_train_mps2=np.zeros(n),
        wsp_active=active,
    )
    cols = sample_run(rec, SensorModel(sample_period_s=0.1), np.random.default_rng(0))
    flags = cols["wsp_active_1"]
    assert flags.dtype == bool
    assert np.flatnonzero(flags).tolist() == [5]  # reported at t = 0.5, nowhere else


def test_same_seed_byte_identical_csv(tmp_path: Path) -> None:
    rec = braking_record()
    sensors = SensorModel(
        sample_period_s=0.1, jitter_s=0.01, speed_noise_kmh=0.3, pressure_noise_bar=0.02
    )

    def write(stem: str, seed: int) -> bytes:
        cols = sample_run(rec, sensors, np.random.default_rng(seed))
        csv_path, _ = write_trace(tmp_path / stem, cols, make_meta())
        return csv_path.read_bytes()

    assert write("a", 42) == write("b", 42)
    assert write("a", 42) != write("c", 43)


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("sample_period_s", {"sample_period_s": 0.0}),
        ("jitter_s", {"jitter_s": -0.1}),
        ("jitter_s", {"sample_period_s": 0.1, "jitter_s": 0.05}),
        ("speed_noise_kmh", {"speed_noise_kmh": float("nan")}),
        ("pressure_quantum_bar", {"pressure_quantum_bar": "0.1"}),
    ],
)
def test_sensor_model_validation(field: str, kwargs: dict) -> None:
    with pytest.raises(ValueError, match=field):
        SensorModel(**kwargs)


# ------------------------------------------------------------------------------------------
# Validation and atomicity of write_trace
# ------------------------------------------------------------------------------------------


def sampled_columns() -> dict[str, np.ndarray]:
    return sample_run(braking_record(), SensorModel(), np.random.default_rng(0))


def test_axle_count_mismatch_raises(tmp_path: Path) -> None:
    meta = make_meta(n_axles=3)
    with pytest.raises(ValueError, match=r"vehicle\.n_axles") as info:
        write_trace(tmp_path / "bad", sampled_columns(), meta)
    assert "\n" not in str(info.value)
    cols = sampled_columns()
    del cols["p_cyl_3_bar"]
    with pytest.raises(ValueError, match=r"vehicle\.n_axles.*p_cyl"):
        write_trace(tmp_path / "bad", cols, make_meta())
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize(
    "field",
    ["sample_period_s", "vehicle", "vehicle.n_axles", "vehicle.wheel_radius_m", "vehicle.mass_kg"],
)
def test_missing_meta_field_raises(tmp_path: Path, field: str) -> None:
    meta = make_meta()
    parts = field.split(".")
    target = meta if len(parts) == 1 else meta["vehicle"]
    del target[parts[-1]]
    with pytest.raises(ValueError, match="^" + re.escape(field) + ":") as info:
        write_trace(tmp_path / "bad", sampled_columns(), meta)
    assert "\n" not in str(info.value)
    assert os.listdir(tmp_path) == []


def test_bad_meta_and_column_values_raise(tmp_path: Path) -> None:
    cols = sampled_columns()
    with pytest.raises(ValueError, match=r"^format:"):
        write_trace(tmp_path / "x", cols, {**make_meta(), "format": "wsp-trace/2"})
    with pytest.raises(ValueError, match=r"^vehicle\.mass_kg:"):
        meta = make_meta()
        meta["vehicle"]["mass_kg"] = -1.0
        write_trace(tmp_path / "x", cols, meta)
    with pytest.raises(ValueError, match=r"^contaminant:"):
        write_trace(tmp_path / "x", cols, {**make_meta(), "contaminant": "jam"})
    bad = dict(cols)
    bad["time_s"] = bad["time_s"][::-1].copy()
    with pytest.raises(ValueError, match=r"^time_s:"):
        write_trace(tmp_path / "x", bad, make_meta())
    bad = dict(cols)
    bad["v_train_kmh"] = bad["v_train_kmh"][:-1]
    with pytest.raises(ValueError, match=r"^v_train_kmh:"):
        write_trace(tmp_path / "x", bad, make_meta())
    assert os.listdir(tmp_path) == []


def test_failure_in_meta_write_leaves_nothing(tmp_path: Path, monkeypatch) -> None:
    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(json, "dump", boom)
    with pytest.raises(OSError, match="disk full"):
        write_trace(tmp_path / "run", sampled_columns(), make_meta())
    assert os.listdir(tmp_path) == []  # no STEM.* and no temp files


@pytest.mark.parametrize("fail_on_call", [1, 2])
def test_failure_in_replace_leaves_nothing(tmp_path: Path, monkeypatch, fail_on_call: int) -> None:
    real_replace = os.replace
    calls = {"n": 0}

    def flaky_replace(src, dst):
        calls["n"] += 1
        if calls["n"] == fail_on_call:
            raise OSError("replace failed")
        return real_replace(src, dst)

    monkeypatch.setattr(wsp_env.files.os, "replace", flaky_replace)
    with pytest.raises(OSError, match="replace failed"):
        write_trace(tmp_path / "run", sampled_columns(), make_meta())
    assert os.listdir(tmp_path) == []


def test_time_precision_grows_when_needed(tmp_path: Path) -> None:
    cols = sampled_columns()
    cols["time_s"] = 1e-5 * np.arange(cols["time_s"].size)  # would collapse at %.4f
    csv_path, _ = write_trace(tmp_path / "fast", cols, make_meta())
    read, _ = read_csv(csv_path)
    assert np.all(np.diff(read["time_s"]) > 0)


def test_written_malformed_is_one_line_from_the_reader(tmp_path: Path) -> None:
    """A written trace spoilt by hand: the package's one reader names the line or column."""
    csv_path, _ = write_trace(tmp_path / "r", sampled_columns(), make_meta())
    original = csv_path.read_text().splitlines()

    lines = list(original)
    lines[3] = lines[3].replace(",", ",0,", 1)  # one field too many on line 4
    csv_path.write_text("\n".join(lines) + "\n")
    with pytest.raises(TraceError, match="line 4: 18 fields, header has 17"):
        read_trace(csv_path)

    lines = list(original)
    fields = lines[5].split(",")
    fields[1] = "fast"
    lines[5] = ",".join(fields)
    csv_path.write_text("\n".join(lines) + "\n")
    with pytest.raises(
        TraceError, match="column 'v_train_kmh': non-numeric value 'fast' on line 6"
    ):
        read_trace(csv_path)

    (tmp_path / "r.meta.json").unlink()
    with pytest.raises(TraceError, match="metadata file missing"):
        read_trace(csv_path)


# ------------------------------------------------------------------------------------------
# Plot
# ------------------------------------------------------------------------------------------


def test_plot_run_writes_png(tmp_path: Path) -> None:
    out = plot_run(braking_record(), tmp_path / "plots" / "run.png", title="4-axle test run")
    assert out == tmp_path / "plots" / "run.png"
    data = out.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) > 10_000
    assert os.listdir(out.parent) == ["run.png"]  # no temp file left
    if os.environ.get("WSP_KEEP_PLOT"):  # for looking at the figure by eye
        Path(os.environ["WSP_KEEP_PLOT"]).write_bytes(data)


def test_written_files_get_the_usual_permissions(tmp_path):
    """Atomic writes go through mkstemp (mode 0600); the final files must be readable."""
    import os
    import stat

    from wsp_env.files import write_atomically

    target = write_atomically(tmp_path / "x.txt", lambda fh: fh.write("hi"))
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~mask

"""Reading wsp-trace/1 traces: vendor aliases, gap filling, and one clear line per problem."""

from __future__ import annotations

import csv
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from wsp_env.calibration.traces import TraceError, read_trace
from wsp_env.config import load_vehicle
from wsp_env.policy import NoWSP
from wsp_env.runner import run_one, trace_metadata
from wsp_env.trace_io import SensorModel, sample_run, write_trace


@pytest.fixture(scope="module")
def trace_dir(tmp_path_factory) -> Path:
    veh = load_vehicle("uic_z1")
    case = {"mu_contaminated": 0.08, "pattern": "uniform"}
    run, record = run_one(veh, "soap", 80.0, NoWSP(), 0, case)
    cols = sample_run(record, SensorModel(sample_period_s=0.1, speed_noise_kmh=0.1),
                      np.random.default_rng(0))  # fmt: skip
    meta = trace_metadata(veh, run["conditions"], "soap", 0.1, "fixture")
    d = tmp_path_factory.mktemp("traces")
    write_trace(d / "good", cols, meta)
    return d


def _load(d: Path) -> tuple[list[str], list[list[str]], dict]:
    with (d / "good.csv").open() as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:], json.loads((d / "good.meta.json").read_text())


def _write(d: Path, name: str, header, rows, meta) -> Path:
    with (d / f"{name}.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    if meta is not None:
        (d / f"{name}.meta.json").write_text(json.dumps(meta) if isinstance(meta, dict) else meta)
    return d / f"{name}.csv"


def test_good_trace_reads(trace_dir):
    tr = read_trace(trace_dir / "good.csv")
    assert tr.n_axles == 4 and tr.v_axle_kmh.shape == tr.p_cyl_bar.shape
    assert tr.v_train_kmh[0] == pytest.approx(80, abs=1)
    assert "a_train_mps2" in tr.optional and not tr.notes


def test_vendor_aliases_are_converted(trace_dir):
    header, rows, meta = _load(trace_dir)
    tr0 = read_trace(trace_dir / "good.csv")
    idx = {h: i for i, h in enumerate(header)}
    new_header, new_rows = [], [[] for _ in rows]
    t = np.array([float(r[idx["time_s"]]) for r in rows])
    period = np.append(np.diff(t), np.diff(t)[-1])
    new_header.append("time_camp")
    for r, p in zip(new_rows, period, strict=True):
        r.append(f"{p:.6f}")
    new_header.append("vtrain")
    for r, row in zip(new_rows, rows, strict=True):
        r.append(f"{float(row[idx['v_train_kmh']]) / 3.6:.6f}")
    for i in range(1, 5):
        new_header += [f"vites_fc_ax{i}", f"p_cyl{i}"]
        for r, row in zip(new_rows, rows, strict=True):
            r += [row[idx[f"v_axle_{i}_kmh"]], row[idx[f"p_cyl_{i}_bar"]]]
    tr = read_trace(_write(trace_dir, "vendor", new_header, new_rows, meta))
    np.testing.assert_allclose(tr.v_train_kmh, tr0.v_train_kmh, atol=1e-4)
    np.testing.assert_allclose(tr.time_s, tr0.time_s - tr0.time_s[0], atol=1e-5)
    np.testing.assert_array_equal(tr.p_cyl_bar, tr0.p_cyl_bar)
    assert any("vites_fc_ax1" in n for n in tr.notes)


def test_short_gaps_are_interpolated_and_said(trace_dir):
    header, rows, meta = _load(trace_dir)
    j = header.index("v_axle_2_kmh")
    for r in rows[50:53]:
        r[j] = ""
    tr = read_trace(_write(trace_dir, "gap", header, rows, meta))
    assert any("3 missing samples interpolated" in n for n in tr.notes)
    assert np.isfinite(tr.v_axle_kmh).all()


def _mutations():
    def drop_axle(h, rows, m):
        j = h.index("p_cyl_3_bar")
        return (
            [x for i, x in enumerate(h) if i != j],
            [[x for i, x in enumerate(r) if i != j] for r in rows],
            m,
        )

    def time_back(h, rows, m):
        rows[20][0] = rows[10][0]
        return h, rows, m

    def long_gap(h, rows, m):
        j = h.index("v_train_kmh")
        for r in rows[30:36]:
            r[j] = ""
        return h, rows, m

    def kpa(h, rows, m):
        j = h.index("p_cyl_1_bar")
        for r in rows:
            r[j] = str(float(r[j]) * 100)
        return h, rows, m

    def mps(h, rows, m):
        j = h.index("v_train_kmh")
        for r in rows:
            r[j] = str(float(r[j]) / 3.6)
        return h, rows, m

    def axle_count(h, rows, m):
        m["vehicle"]["n_axles"] = 2
        m["vehicle"].pop("axle_static_load_kN")
        m["vehicle"].pop("axle_load_transfer_kN_per_mps2")
        return h, rows, m

    def short_transfer(h, rows, m):
        m["vehicle"]["axle_load_transfer_kN_per_mps2"] = [1.0, -1.0]
        return h, rows, m

    def text_cell(h, rows, m):
        rows[5][h.index("p_cyl_2_bar")] = "n/a"
        return h, rows, m

    def bad_format(h, rows, m):
        m["format"] = "wsp-trace/0"
        return h, rows, m

    def duplicate(h, rows, m):
        return [*h, "v_train_kmh"], [[*r, r[1]] for r in rows], m

    def short_row(h, rows, m):
        rows[7] = rows[7][:-2]
        return h, rows, m

    def no_mass(h, rows, m):
        del m["vehicle"]["mass_kg"]
        return h, rows, m

    def negative_speed(h, rows, m):
        rows[12][h.index("v_axle_4_kmh")] = "-40"
        return h, rows, m

    return [
        (drop_axle, "'p_cyl_3_bar': required but missing"),
        (time_back, "'time_s': not strictly increasing"),
        (long_gap, "'v_train_kmh': 6 missing samples in a row"),
        (kpa, "'p_cyl_1_bar'"),
        (mps, "looks like m/s"),
        (axle_count, "vehicle.n_axles: 2"),
        (short_transfer, "vehicle.axle_load_transfer_kN_per_mps2: must list one number per axle"),
        (text_cell, "non-numeric value 'n/a'"),
        (bad_format, "format: expected"),
        (duplicate, "appears twice"),
        (short_row, "fields, header has"),
        (no_mass, "vehicle.mass_kg"),
        (negative_speed, "negative speed"),
    ]


@pytest.mark.parametrize("mutate,needle", _mutations(), ids=lambda x: getattr(x, "__name__", ""))
def test_malformed_traces_give_one_clear_line(trace_dir, mutate, needle):
    header, rows, meta = _load(trace_dir)
    header, rows, meta = mutate(header, rows, meta)
    path = _write(trace_dir, f"bad_{mutate.__name__}", header, rows, meta)
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    with pytest.raises(TraceError) as err:
        read_trace(path)
    msg = str(err.value)
    assert needle in msg and "\n" not in msg and "bad_" in msg
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest  # input untouched


def test_missing_or_broken_metadata(trace_dir):
    header, rows, _ = _load(trace_dir)
    with pytest.raises(TraceError, match="metadata file missing"):
        read_trace(_write(trace_dir, "nometa", header, rows, None))
    with pytest.raises(TraceError, match="invalid JSON"):
        read_trace(_write(trace_dir, "badjson", header, rows, "{not json"))
    (trace_dir / "empty.csv").write_text("")
    (trace_dir / "empty.meta.json").write_text((trace_dir / "good.meta.json").read_text())
    with pytest.raises(TraceError, match="empty file"):
        read_trace(trace_dir / "empty.csv")

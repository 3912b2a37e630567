"""Reading wsp-trace/1 traces: vendor aliases, gap filling, and one clear line per problem."""

from __future__ import annotations

import csv
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from wsp_env.calibration.traces import TraceError, averaged_updates, read_trace
from wsp_env.core.config import load_vehicle
from wsp_env.evaluation.runner import run_one, trace_metadata
from wsp_env.evaluation.trace_writer import SensorModel, sample_run, write_trace
from wsp_env.policy import NoWSP


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
        m["vehicle"].pop("axle_offsets_m")
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

    def pivot_in_mm(h, rows, m):  # optional geometry, a unit error
        m["vehicle"]["bogie_pivot_height_m"] = 650
        return h, rows, m

    def pivot_text(h, rows, m):
        m["vehicle"]["bogie_pivot_height_m"] = "0.65"
        return h, rows, m

    def bogie_longer_than_car(h, rows, m):
        m["vehicle"]["bogie_wheelbase_m"] = 3.0
        m["vehicle"]["bogie_centre_distance_m"] = 2.5
        return h, rows, m

    def bogie_height_without_mass(h, rows, m):
        m["vehicle"]["bogie_cog_height_m"] = 0.5
        return h, rows, m

    def heavy_bogies(h, rows, m):
        m["vehicle"]["bogie_cog_height_m"] = 0.5
        m["vehicle"]["bogie_mass_kg"] = 25000.0
        return h, rows, m

    def offsets_short(h, rows, m):
        m["vehicle"]["axle_offsets_m"] = [0.0, 2.5]
        return h, rows, m

    def offsets_not_from_axle_1(h, rows, m):
        m["vehicle"]["axle_offsets_m"] = [1.0, 3.5, 20.0, 22.5]
        return h, rows, m

    def offsets_out_of_order(h, rows, m):
        m["vehicle"]["axle_offsets_m"] = [0.0, 2.5, 1.0, 22.5]
        return h, rows, m

    def offsets_nan(h, rows, m):
        m["vehicle"]["axle_offsets_m"] = [0.0, float("nan"), 19.0, 21.5]
        return h, rows, m

    def offsets_bool(h, rows, m):
        m["vehicle"]["axle_offsets_m"] = [0.0, True, 19.0, 21.5]
        return h, rows, m

    def offsets_nested(h, rows, m):
        m["vehicle"]["axle_offsets_m"] = [0.0, [2.5], 19.0, 21.5]
        return h, rows, m

    def offsets_huge(h, rows, m):  # an integer no float holds
        m["vehicle"]["axle_offsets_m"] = [0, 2, 19, 10**400]
        return h, rows, m

    def offsets_text(h, rows, m):
        m["vehicle"]["axle_offsets_m"] = "0, 2.5, 19, 21.5"
        return h, rows, m

    def offsets_shared_place(h, rows, m):  # all zeros would read as unknown places
        m["vehicle"]["axle_offsets_m"] = [0.0, 0.0, 0.0, 0.0]
        return h, rows, m

    def offsets_in_mm(h, rows, m):
        m["vehicle"]["axle_offsets_m"] = [0.0, 2500.0, 19000.0, 21500.0]
        return h, rows, m

    return [
        (drop_axle, "'p_cyl_3_bar': required but missing"),
        (offsets_short, "vehicle.axle_offsets_m: must list one number per axle (2 numbers for 4"),
        (offsets_nan, "vehicle.axle_offsets_m: must list one number per axle (axle 2: 'nan')"),
        (offsets_bool, "vehicle.axle_offsets_m: must list one number per axle (axle 2: 'True')"),
        (offsets_nested, "vehicle.axle_offsets_m: must list one number per axle (axle 2:"),
        (offsets_huge, "vehicle.axle_offsets_m: must list one number per axle (axle 4:"),
        (offsets_text, "vehicle.axle_offsets_m: must list one number per axle (got str)"),
        (offsets_not_from_axle_1, "vehicle.axle_offsets_m: axle 1's must be 0"),
        (offsets_out_of_order, "vehicle.axle_offsets_m: axle 3 (1 m) is ahead of axle 2"),
        (offsets_shared_place, "vehicle.axle_offsets_m: axle 2 at the place of axle 1 (0 m)"),
        (offsets_in_mm, "vehicle.axle_offsets_m: the last axle 21500 m behind the first"),
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
        (pivot_in_mm, "vehicle.bogie_pivot_height_m: must be a number in [0.1, 2], got 650"),
        (pivot_text, "vehicle.bogie_pivot_height_m: must be a number in"),
        (bogie_longer_than_car, "vehicle.bogie_wheelbase_m: 3 m is not shorter than"),
        (bogie_height_without_mass, "vehicle.bogie_cog_height_m and bogie_mass_kg: give both"),
        (heavy_bogies, "vehicle.bogie_mass_kg: 2 bogies of 25000 kg"),
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


def _logged_gps(
    mode: str,
    fix_period_s: float,
    log_period_s: float,
    seed: int,
    noise_kmh: float = 0.0,
    jitter_s: float = 0.03,
):
    """A GPS-like ground speed on a train decelerating at 1 m/s^2 (the truth, km/h), fixed
    every ``fix_period_s`` (each fix off by Gaussian ``noise_kmh``) and logged every
    ``log_period_s`` (+-``jitter_s`` clock jitter) by a logger that holds the last value or
    averages over its period — built here on a 1 ms grid, apart from every simulator in the
    project."""
    rng = np.random.default_rng(seed)

    def truth(t):
        return np.maximum(120.0 - 3.6 * (t - 1.0).clip(0.0), 0.0)

    fine = np.arange(0.0, 30.0, 0.001)
    fix_t = np.arange(rng.uniform(0.0, fix_period_s), 30.0, fix_period_s)
    fixes = truth(fix_t) + rng.normal(0.0, noise_kmh, fix_t.size) * (truth(fix_t) > 0)
    held = fixes[np.clip(np.searchsorted(fix_t, fine, side="right") - 1, 0, None)]
    t_log = np.arange(1, int(29.0 / log_period_s)) * log_period_s
    t_log = t_log + rng.uniform(-jitter_s, jitter_s, t_log.size)
    k = np.round(t_log / 0.001).astype(int)
    if mode == "hold":
        v = held[k]
    else:
        w = round(log_period_s / 0.001)
        csum = np.concatenate([[0.0], np.cumsum(held)])
        v = (csum[k + 1] - csum[k + 1 - w]) / w
    return t_log, np.round(v, 2), truth


@pytest.mark.parametrize(
    ("mode", "fix_period_s", "log_period_s"),
    [("hold", 0.2, 0.1), ("hold", 1.0, 0.1), ("mean", 0.5, 0.1), ("mean", 0.25, 0.05)],
)
def test_a_held_or_averaged_gps_is_put_back_on_time(mode, fix_period_s, log_period_s):
    """The reader places every fix where it became due: a holding logger that shows some
    fixes once (its clock jitters against a 5 Hz receiver) keeps them as fixes; an averaging
    logger's blends time the change inside their window. Left on the log's timestamps the
    held speed lags by half a fix period (0.1-0.5 s). Put back, an averaging logger's lag is
    within 20 ms on each of six draws of the receiver's phase and the clock's jitter; a
    holding logger cannot place a fix better than the log interval it showed up in (+-half a
    period on one draw), so there the mean over the six draws is within 20 ms (the reader
    before this change dropped the holding logger's single fixes as blends: -22 ms mean,
    -48 ms on one draw, at 5 Hz logged at 10 Hz)."""
    from wsp_env.calibration.traces import unhold

    lags = np.arange(-0.3, 0.6, 0.001)
    found = []
    for seed in range(6):
        t, v, truth = _logged_gps(mode, fix_period_s, log_period_s, seed)
        notes: list[str] = []
        out, _, _ = unhold(v, t, notes)
        assert notes and ("averaged" in notes[0]) == (mode == "mean")
        moving = (t > 2.0) & (out > 5.0)
        err = [np.mean((out[moving] - truth(t[moving] - lag)) ** 2) for lag in lags]
        raw = [np.mean((v[moving] - truth(t[moving] - lag)) ** 2) for lag in lags]
        found.append(lags[int(np.argmin(err))])
        assert abs(found[-1]) < (0.02 if mode == "mean" else 0.5 * log_period_s), seed
        assert lags[int(np.argmin(raw))] > 0.3 * fix_period_s  # there was a lag to take out
    assert abs(np.mean(found)) < 0.02


@pytest.mark.parametrize(("fix_period_s", "log_period_s"), [(0.2, 0.1), (0.125, 0.05)])
def test_an_averaged_gps_without_repeats_is_told_by_its_update_interval(fix_period_s, log_period_s):
    """A 5 Hz fix averaged at 10 Hz (8 Hz at 20 Hz) shows no repeated samples, only blends,
    and trails the truth by half a fix period and half a log period. The reader finds the
    update interval on each of six draws of phase, noise (0.1 km/h per fix) and +-2 ms clock
    jitter (the held and averaged model leaves well under half of what a smooth curve with as
    many parameters leaves) and says how much of the column's lag is the logger's: half an
    update beyond the log period's own half, which the pressures share — the column lags the
    truth by that sum within 30 ms."""
    lags = np.arange(-0.3, 0.6, 0.001)
    for seed in range(6):
        t, v, truth = _logged_gps("mean", fix_period_s, log_period_s, seed, 0.1, 0.002)
        notes: list[str] = []
        found = averaged_updates(v, t, notes)
        assert found is not None and found[0] == pytest.approx(fix_period_s), seed
        assert found[1] == pytest.approx(0.1, rel=0.35), seed  # one update's noise
        assert notes and "averaged" in notes[0]
        moving = (t > 2.0) & (v > 5.0)
        raw = [np.mean((v[moving] - truth(t[moving] - lag)) ** 2) for lag in lags]
        lag_found = lags[int(np.argmin(raw))]  # the premise: the lag the reader puts down
        assert abs(lag_found - 0.5 * (fix_period_s + log_period_s)) < 0.03, seed


@pytest.mark.parametrize("seed", range(3))
def test_a_speed_updated_every_sample_is_no_averaged_update(seed):
    """A 10 Hz fix averaged at 10 Hz, and a smooth speed with independent noise on every
    sample, are no held signal: the reader finds no update interval and notes nothing."""
    t, v, _ = _logged_gps("mean", 0.1, 0.1, seed, 0.1, 0.002)
    assert averaged_updates(v, t, []) is None
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 30.0, 0.1)
    v = np.round(120.0 - 3.6 * t + 0.02 * t**2 + rng.normal(0.0, 0.1, t.size), 2)
    notes: list[str] = []
    assert averaged_updates(v, t, notes) is None and not notes


def test_a_ground_speed_lag_is_judged_beyond_the_loggers_part(trace_dir):
    """A lag the column shows is reported only beyond what the reader put down to the logger's
    averaging of held updates: 0.2 s with 0.1 s of it the logger's is inside the logging's
    0.15 s resolution, 0.3 s is not."""
    from wsp_env.calibration.plausibility import negligible

    trace = read_trace(trace_dir / "good.csv")
    assert negligible("sensor", {"speed_lag_s": 0.2}, trace) is None
    trace.v_train_logger_lag_s, trace.v_train_update_s = 0.1, 0.2
    why = negligible("sensor", {"speed_lag_s": 0.2}, trace)
    assert why and "0.10 s of it the logger's" in why and "0.2 s updates" in why
    assert negligible("sensor", {"speed_lag_s": 0.3}, trace) is None


def test_a_constant_or_held_speed_is_no_averaged_update(trace_dir):
    """A record whose ground speed never changes (a single held value: no interval to time)
    and a held GPS read from a file get no averaged-update interval and no logger lag: the
    first is too little to tell, the second is put back on time between its updates."""
    notes: list[str] = []
    t = np.arange(0.0, 20.0, 0.1)
    v = np.full(t.size, 80.0)
    assert averaged_updates(v, t, notes) is None and not notes
    from wsp_env.calibration.traces import unhold

    _, noise, interval = unhold(v, t, notes)
    assert noise is None and interval is not None and not np.isfinite(interval)
    header, rows, meta = _load(trace_dir)
    col = header.index("v_train_kmh")
    for k, row in enumerate(rows):  # a 1 Hz fix held at 10 Hz
        row[col] = rows[k - k % 10][col]
    trace = read_trace(_write(trace_dir, "held_1hz", header, rows, meta))
    assert trace.v_train_update_s == pytest.approx(1.0, rel=0.1)
    assert trace.v_train_logger_lag_s == 0.0
    assert not any("updates every" in n for n in trace.notes)


def test_a_record_larger_than_a_braking_test_is_refused(trace_dir, tmp_path, monkeypatch):
    """Rows, duration and ground-speed steps are bounded (a 10^6-row file took 466 s and
    3.1 GB before): one line each, before any fitting."""
    import wsp_env.calibration.traces as traces

    header, rows, meta = _load(trace_dir)
    monkeypatch.setattr(traces, "MAX_ROWS", len(rows) - 1)
    with pytest.raises(TraceError, match=f"more than {len(rows) - 1:,} data rows"):
        read_trace(_write(tmp_path, "long", header, rows, meta))
    monkeypatch.undo()

    t = header.index("time_s")
    slow = [[*r[:t], f"{float(r[t]) * 60:.3f}", *r[t + 1 :]] for r in rows]  # minutes for seconds
    with pytest.raises(TraceError, match=r"column 'time_s': spans .* s, more than one braking"):
        read_trace(_write(tmp_path, "slow", header, slow, meta))

    v = header.index("v_train_kmh")
    jumpy = [list(r) for r in rows]
    jumpy[10][v] = f"{float(jumpy[10][v]) + 40:.3f}"  # 40 km/h up and down within 0.2 s
    with pytest.raises(TraceError, match=r"column 'v_train_kmh': jumps .* \(line 11\)"):
        read_trace(_write(tmp_path, "jumpy", header, jumpy, meta))

"""The detection-power study (``scripts/calibration_power.py``, docs/calibration.md "Calibration on
independent traces") runs end to end on a tiny grid and reports what the README quotes from it:
detection, the adhesion candidates' readings against the generator's truth, false positives."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from conftest import script


def _study(tmp_path: Path, category: str, clean: int, demand_drop: int = 0) -> dict:
    """The study on one scenario per magnitude of ``category``, ``clean`` clean traces and
    ``demand_drop`` clean traces whose demand falls part-way, as its JSON gives it."""
    cp = script("calibration_power")
    out = tmp_path / "power.json"
    args = ["--scenarios", "1", "--clean", str(clean), "--pairs", "0", "--jobs", "1",
            "--categories", category, "--demand-drop", str(demand_drop),
            "--json", str(out)]  # fmt: skip
    assert cp.main(args) == 0
    return json.loads(out.read_text())


def test_the_power_study_reports_the_adhesion_readings(tmp_path):
    data = _study(tmp_path, "load_transfer", clean=2)
    summary, results = data["summary"], data["results"]
    assert summary["traces"] == 2 + 3 and not summary["errors"]
    rows = summary["categories"]["load_transfer"]["rows"]
    assert [r["magnitude"] for r in rows] == [1.5, 2.0, 3.0]
    assert all(0.0 <= r["tried_rate"] <= 1.0 for r in rows)
    for r in results:
        # the generator's bogie pitch (36-68 t cars, pivot 0.5-0.8 m over a 2.2-3 m wheelbase),
        # times the injected load-transfer factor
        # times the injected load-transfer factor, less the nominal pitch where the metadata
        # declares it (the pivot height given)
        factor = math.prod(p.get("factor", 1.0) for p in r["effect_params"])
        beyond = factor - 1.0 if r["pivot_in_metadata"] else factor
        if beyond == 0.0:
            assert r["true_bogie_pitch_kN_per_mps2"] == 0.0
        else:
            assert 1.5 <= r["true_bogie_pitch_kN_per_mps2"] / beyond <= 13.0
        for fitted in r["adhesion_fits"].values():
            assert all(np.isfinite(v) for v in fitted.values())
    assert 0.0 <= summary["clean"]["false_positive_rate"] <= 1.0
    assert all(0.0 <= r["pitch_threshold"]["detection"] <= 1.0 for r in rows)


def test_a_threshold_on_the_fitted_pitch_keeps_the_clean_traces_false_positives():
    """``pitch_threshold``: the lowest threshold at most 2 % of the clean traces reach (a clean
    trace without a fit reaches none) and the share of effect traces over it."""
    cp = script("calibration_power")

    def rows(pitches):
        return [{"adhesion_fits": {} if p is None else {"load_transfer": {
            "bogie_pitch_kN_per_mps2": p}}} for p in pitches]  # fmt: skip

    clean = rows([float(k % 10) for k in range(49)] + [30.0])  # one clean trace reads 30
    effect = rows([5.0, 12.0, 31.0, None])
    best = cp.pitch_threshold(clean, effect)
    assert best == {"detection": 0.5, "threshold": 12.0, "clean": 50}  # 30: the 2 % let in
    assert cp.pitch_threshold(clean + rows([29.0]), effect)["detection"] == 0.25


def test_the_clean_traces_pitch_readings_per_rail():
    """``clean_pitch_readings``: the fitted pitch less the generator's on clean traces where one
    was fitted (other kinds and unfitted traces left out), overall and per rail."""
    cp = script("calibration_power")

    def row(rail, fitted, true=2.0, kind="clean"):
        fits = {} if fitted is None else {"load_transfer": {"bogie_pitch_kN_per_mps2": fitted}}
        return {"kind": kind, "contaminant": rail, "adhesion_fits": fits,
                "true_bogie_pitch_kN_per_mps2": true}  # fmt: skip

    rows = [row("soap", -20.0), row("soap", 4.0), row("soap", 2.0), row("oil", 1.0),
            row("oil", None), row("soap", 50.0, kind="clean_demand_drop")]  # fmt: skip
    out = cp.clean_pitch_readings(rows)
    assert out["n"] == 4 and out["median"] == -0.5
    assert out["by_rail"] == {
        "oil": {"n": 1, "min": -1.0, "median": -1.0, "max": -1.0},
        "soap": {"n": 3, "min": -22.0, "median": 0.0, "max": 2.0},
    }
    assert cp.clean_pitch_readings([row("oil", None)]) == {"n": 0}


def test_the_power_study_says_what_a_friction_step_leaves_to_see(tmp_path):
    """A friction change along the rail: the generator's seconds past the curve's peak on
    each side of it and the loop's critical points there, per trace and summarised."""
    data = _study(tmp_path, "adhesion_position", clean=0)
    for r in data["results"]:
        ev = r["step_evidence"]
        assert ev["past_peak_s_before"] >= 0.0 and ev["past_peak_s_after"] >= 0.0
        # both sides of one stop: no more than the stop lasted, and a sliding rail slides
        assert 1.0 < ev["past_peak_s_before"] + ev["past_peak_s_after"] < 200.0
        assert ev["points_before"] >= 0 and ev["points_after"] >= 0
    for row in data["summary"]["categories"]["adhesion_position"]["rows"]:
        assert 0.0 <= row["past_peak_both_sides_rate"] <= 1.0
        assert 0.0 <= row["points_both_sides_rate"] <= 1.0


def test_the_power_study_says_which_choices_were_ties(tmp_path):
    """Pads and a brake force that follows the demand are one regressor where the WSP seldom
    vents: the study says how often the loop chose inside the tie margin and with what. Its
    first 3 kN trace (seed 41000, soap, 4 axles) is such a tie, lost to the pads."""
    summary = _study(tmp_path, "unmeasured_brake_force", 0)["summary"]
    row = next(
        r
        for r in summary["categories"]["unmeasured_brake_force"]["rows"]
        if r["magnitude"] == 3000.0
    )
    assert row["n"] == 1 and row["detection_rate"] == 0.0
    assert row["tied_rate"] == 1.0 and (row["tied"], row["tied_won"]) == (1, 0)
    assert row["tied_with"].get("pad_friction") == 1


def _null_script():
    fsn = script("friction_step_null")
    return fsn


def test_a_simple_step_reading_finds_a_friction_change_on_a_power_study_trace():
    """``friction_step_null.step_reading`` on trace 101011
    (soap, 4 axles, the rail x1.3 from 133 m after the brake application): a step up by more
    than 20 % at |z| > 3, within 60 m of the change (placed from the record's start: the
    coasting lead-in added)."""
    from scipy.integrate import cumulative_trapezoid

    from wsp_env.calibration import independent as ind

    fsn = _null_script()
    seed = 101011
    row = fsn.run_job({"kind": "step", "effects": [("adhesion_position", 0.3)], "seed": seed})
    reading = row["reading"]
    assert row["true_factor"] == 1.3 and reading is not None
    assert reading["factor"] > 1.2 and reading["z"] > 3.0
    rng = np.random.default_rng(seed)
    scenario = ind.random_scenario(rng, contaminant=row["rail"])
    effect = fsn.cp.scaled_effect(ind, "adhesion_position", 0.3, rng, scenario)
    columns, _ = ind.generate(scenario, [effect], seed=seed)
    t, v = columns["time_s"], np.nan_to_num(columns["v_train_kmh"])
    x_brake = float(np.interp(scenario.lead_in_s, t, cumulative_trapezoid(v / 3.6, t, initial=0)))
    assert abs(reading["position_m"] - (x_brake + effect.params["position_m"])) < 60.0


def test_the_best_threshold_search_keeps_the_clean_traces_false_positives():
    """``best_detection``: thresholds that let at most the allowed share of clean readings
    through; a step read with the wrong sign never counts."""
    fsn = _null_script()

    def rows(factors, zs, truth=None):
        return [{"reading": {"factor": f, "z": z}, "true_factor": truth}
                for f, z in zip(factors, zs, strict=True)]  # fmt: skip

    clean = rows([1.1] * 49 + [1.6], [2.0] * 49 + [9.0])
    steps = rows([1.5, 1.45, 0.7, 1.2], [8.0, 7.0, -6.0, 1.0], truth=1.3)
    best = fsn.best_detection(clean, steps, 0.02)
    # the one large clean reading may pass (1 of 50): every step read up counts, 0.7 never
    assert best["false_positive"] <= 0.02 and best["detection"] == 0.75
    # none may pass: over 1.6 or z 9 nothing of the steps is left
    assert fsn.best_detection(clean, steps, 0.0)["detection"] == 0.0


def test_the_power_study_reports_the_censored_rail_and_a_falling_demand(tmp_path):
    """The rail-gets-better row carries its rate on the traces where only censored evidence
    can show it (judged there: ``target_rate``), and the clean traces whose demand falls
    part-way their own false-positive rate."""
    data = _study(tmp_path, "rail_gets_better", clean=0, demand_drop=1)
    summary, results = data["summary"], data["results"]
    assert summary["traces"] == 3 + 1 and not summary["errors"]
    info = summary["categories"]["rail_gets_better"]
    assert info["target_rate"] == ["censored_rate", 0.9]
    for row in info["rows"]:
        assert 0 <= row["censored_n"] <= row["n"]
        rate = row["censored_rate"]
        assert (row["censored_n"] == 0 and math.isnan(rate)) or 0.0 <= rate <= 1.0
    dropped = summary["clean_demand_drop"]
    assert dropped["n"] == 1 and 0.0 <= dropped["false_positive_rate"] <= 1.0
    (job,) = [r for r in results if r["kind"] == "clean_demand_drop"]
    drop = job["demand_drop"]
    assert 0.2 <= drop["fraction"] <= 0.6 and 0.3 <= drop["factor"] <= 0.6

"""Classical WSP, oracle, suites, EN 15595-style metrics and criteria, `wsp-env evaluate`."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from wsp_env.baselines.classical import load_wsp_config
from wsp_env.cli import main
from wsp_env.core.config import ConfigError, load_vehicle
from wsp_env.evaluation import CaseConfig, SuiteConfig, load_suite, run_suite, summarise
from wsp_env.policy import NoWSP, make_policy


@pytest.fixture(scope="module")
def quick_results():
    suite = load_suite("quick")
    out = {}
    for name in ("classical", "none", "oracle"):
        out[name] = run_suite("uic_z1", suite, make_policy(name), record="none")[0]
    return out


def test_classical_wsp_cuts_sliding_and_locks_far_below_none(quick_results):
    for c, n in zip(quick_results["classical"], quick_results["none"], strict=True):
        assert c["scenario"] == n["scenario"] and c["seed"] == n["seed"]
        assert c["conditions"] == n["conditions"]  # same scenario, same draws: one code path
        assert c["sliding_energy_kJ"] < 0.25 * n["sliding_energy_kJ"]
        assert c["max_lock_s"] < 0.25 * n["max_lock_s"]


def test_classical_stops_within_the_extension_criterion_on_low_adhesion(quick_results):
    soap = [r for r in quick_results["classical"] if r["scenario"].startswith("soap_low")]
    assert soap and all(r["checks"]["extension"] for r in soap)
    assert all(r["stopped"] for r in quick_results["classical"])


def test_oracle_is_the_best_constant_slip_under_the_damage_criteria(quick_results):
    """The oracle sweep meets the damage criteria everywhere and stops no longer than the
    classical WSP (it may pick the classical WSP's own kind of slip)."""
    for o, c in zip(quick_results["oracle"], quick_results["classical"], strict=True):
        assert all(o["checks"][k] for k in ("lock", "sliding_energy", "slide_duration"))
        assert o["stopping_distance_m"] <= 1.01 * c["stopping_distance_m"], o["scenario"]
        assert o["oracle_variant"].startswith("oracle_")


def test_peak_tracking_meets_the_available_adhesion_reference():
    """Holding every axle at its curve's peak (no sliding: no recovery) is the ideal the
    available-adhesion reference integrates: the two stops agree within 5 % (the tracker is a
    little shorter: rolling passes clean 1 % of the soap per axle, and load transfer)."""
    from wsp_env.baselines.oracle import SlipTracker

    suite = load_suite("quick")
    cases = tuple(c for c in suite.cases if c.rail in ("soap", "leaves") and c.pattern == "uniform")
    res, _ = run_suite("uic_z1", dataclasses.replace(suite, cases=cases), SlipTracker(None))
    for r in res:
        assert r["stopping_distance_m"] == pytest.approx(r["reference_distance_m"], rel=0.05)
        assert r["max_sliding_kmh"] < 5.0 and r["max_lock_s"] == 0.0


def test_dry_reference_and_deceleration_distance():
    """On dry rail without WSP the run *is* its dry reference: increase 0; the equivalent
    build-up time is the demand's delay plus half its rise (EN 14531)."""
    veh = load_vehicle("uic_z1")
    suite = SuiteConfig(name="d", description="", seeds=(3,), cases=(
        CaseConfig(name="dry", rail="dry", speeds_kmh=("120",), pattern="uniform"),
        CaseConfig(name="soap", rail="soap", speeds_kmh=("120",), mu_contaminated=0.07),
    ))  # fmt: skip
    (dry, soap), _ = run_suite(veh, suite, NoWSP(), record="none")
    assert dry["stopping_distance_m"] == pytest.approx(dry["dry_reference_distance_m"], rel=1e-9)
    assert abs(dry["deceleration_distance_increase_pct"]) < 1e-6
    t_e = veh.brake.demand_delay_s + veh.brake.demand_rise_s / 2
    assert dry["equivalent_build_up_time_s"] == pytest.approx(t_e)
    v0 = 120 / 3.6
    assert dry["deceleration_distance_m"] == pytest.approx(
        dry["stopping_distance_m"] - v0 * t_e, rel=1e-9
    )
    assert soap["deceleration_distance_increase_pct"] > 50.0  # locked wheels on soap
    assert soap["dry_reference_distance_m"] == pytest.approx(dry["dry_reference_distance_m"],
                                                              rel=0.05)  # fmt: skip


def test_damage_criteria_fail_locked_wheels_not_the_wsp(quick_results):
    """Locked wheels fail the lock criterion on every run; the classical WSP's longest lock
    (a wheel stopping just before the train as it hands back the full demand below 3 km/h)
    is a small fraction of theirs, its worst axle's sliding energy a third at most."""
    for c, n in zip(quick_results["classical"], quick_results["none"], strict=True):
        assert not n["checks"]["lock"] and not n["passed"]
        assert c["max_lock_s"] < 0.1 * n["max_lock_s"] and c["checks"]["sliding_energy"]
        assert n["max_axle_sliding_energy_pct"] > 3 * c["max_axle_sliding_energy_pct"]
        for key in ("max_sliding_kmh", "longest_slide_s", "valve_cycles", "vent_time_s"):
            assert key in c and all(key in a for a in c["axles"])
        assert 0.0 < c["adhesion_utilisation"] <= 1.0 and 0.0 < n["adhesion_utilisation"] <= 1.0


def test_reference_speed_error_is_reported_for_every_policy(quick_results):
    """The shared estimator's error against the train, whoever controls the valves; with
    locked wheels (nothing anchors it) it is far worse than under the classical WSP."""
    for c, n in zip(quick_results["classical"], quick_results["none"], strict=True):
        for r in (c, n):
            assert 0.0 <= r["reference_speed_error_rms_kmh"] <= r["reference_speed_error_max_kmh"]
        assert c["reference_speed_error_rms_kmh"] < 5.0
    worse = [n["reference_speed_error_rms_kmh"] > c["reference_speed_error_rms_kmh"]
             for c, n in zip(quick_results["classical"], quick_results["none"], strict=True)
             if c["conditions"]["rail"] in ("soap", "leaves")]  # fmt: skip
    assert worse and all(worse)


def test_suite_cases_carry_their_vehicle_and_load():
    suite = SuiteConfig(name="m", description="", seeds=(0,), cases=(
        CaseConfig(name="coach", rail="soap", speeds_kmh=("80",), load="laden"),
        CaseConfig(name="train", rail="soap", speeds_kmh=("80",), vehicle="regiolis",
                   load="tare"),
    ))  # fmt: skip
    (coach, train), _ = run_suite("uic_z1", suite, NoWSP(), record="none")
    assert coach["vehicle"] == "uic_z1" and train["vehicle"] == "regiolis"
    assert coach["conditions"]["load_factor"] == 1.15
    assert train["conditions"]["load_factor"] == 0.85
    assert len(train["axles"]) == 16


def test_results_are_reproducible():
    suite = load_suite("quick")
    a = run_suite("uic_z1", suite, make_policy("classical"), record="none")[0]
    b = run_suite("uic_z1", suite, make_policy("classical"), record="none")[0]
    assert a == b


def test_summary_reports_spread(quick_results):
    summary = summarise(quick_results["classical"] + quick_results["none"])
    s = summary["classical"]["scenarios"]["soap_low_120"]["stopping_distance_m"]
    assert set(s) == {"mean", "std", "min", "max"} and s["min"] <= s["mean"] <= s["max"]
    assert summary["none"]["runs"] == len(quick_results["none"])


def test_evaluate_cli_json_and_report(tmp_path):
    out, report = tmp_path / "ev.json", tmp_path / "report"
    code = main(["evaluate", "--policy", "classical", "--policy", "none", "--suite", "quick",
                 "--json", str(out), "--report", str(report), "--no-progress"])  # fmt: skip
    assert code == 0
    data = json.loads(out.read_text())
    run = data["runs"][0]
    keys = ("scenario", "seed", "stopping_distance_m", "reference_distance_m")
    keys += ("adhesion_utilisation", "sliding_energy_kJ", "air_litres", "max_lock_s")
    keys += ("dry_reference_distance_m", "deceleration_distance_increase_pct")
    keys += ("max_sliding_kmh", "passed")
    for key in keys:
        assert key in run
    assert set(data["summary"]) == {"classical", "none"}
    text = (report / "report.md").read_text()
    assert "soap_low_120" in text and "comparison.png" in text
    assert (report / "plots" / "comparison.png").stat().st_size > 1000


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--policy", "models/missing.zip"], "missing.zip"),
        (["--policy", "classical", "--suite", "nope"], "unknown suite 'nope'"),
        (["--policy", "telepathy"], "telepathy"),
    ],
)
def test_evaluate_bad_input_one_line(tmp_path, capsys, args, needle):
    out = tmp_path / "x.json"
    code = main(["evaluate", *args, "--json", str(out), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and needle in err and len(err.splitlines()) == 1
    assert not out.exists()


def test_wsp_config_errors_name_file_and_field(tmp_path):
    bad = tmp_path / "wsp.yaml"
    bad.write_text("slip_rel: -1\n")
    with pytest.raises(ConfigError, match=r"wsp\.yaml: slip_rel: must be >= 0"):
        load_wsp_config(bad)


def test_no_wsp_policy_is_full_demand():
    class Core:
        n_envs, n_valves = 3, 4

    p = NoWSP()
    p.bind(Core())
    assert (p.act(np.zeros((3, 10))) == 1.0).all()


def test_classical_wsp_reapplies_in_steps_and_stays_silent_on_dry_rail():
    """After a vent the WSP fills in pulses (apply, hold, apply, ...) below the demand; on dry
    rail it never leaves apply (its reference follows the train: no false slide)."""
    from wsp_env.baselines.classical import ClassicalWSP
    from wsp_env.envs import WSPBrakingVectorEnv

    def actions(rail):
        venv = WSPBrakingVectorEnv(num_envs=1, vehicle="uic_z1")
        venv.reset(seed=0, options={"rail": rail, "speed_kmh": 100.0, "pattern": "uniform"})
        wsp = ClassicalWSP(load_wsp_config())
        wsp.bind(venv.core)
        wsp.reset(np.arange(1))
        seen = []
        while True:
            a = wsp.act(venv.core.obs)
            seen.append(a[0, 0])
            _, _, term, trunc, _ = venv.step(a)
            if term[0] or trunc[0]:
                return np.array(seen)

    assert np.all(actions("dry") == 1.0)
    soap = actions("soap")
    apply_, hold = soap == 1.0, (soap > -1.0) & (soap < 1.0)
    # pulses: a hold directly after an apply and an apply directly after a hold, many times
    assert np.sum(apply_[:-1] & hold[1:]) > 10 and np.sum(hold[:-1] & apply_[1:]) > 10
    assert np.any(soap == -1.0)


@pytest.mark.parametrize(
    "chosen_on,judged_on",
    [("tuning", "en15595"), ("tuning", "heldout"), ("validation", "heldout"),
     ("validation", "en15595"), ("validation", "tuning")],
)  # fmt: skip
def test_selection_suites_share_nothing_with_the_judging_suites(chosen_on, judged_on):
    """The classical WSP is tuned on `tuning`, learned controllers are selected on
    `validation`, both are judged on `en15595` and `heldout`: no seed, case name or (rail,
    adhesion level) may be shared, or the judging suites would reward tuning on themselves."""

    def levels(suite):
        return {(c.rail, c.mu_contaminated) for c in suite.cases if c.mu_contaminated is not None}

    chosen, judged = load_suite(chosen_on), load_suite(judged_on)
    assert not set(chosen.seeds) & set(judged.seeds)
    assert not {c.name for c in chosen.cases} & {c.name for c in judged.cases}
    assert not levels(chosen) & levels(judged)


def test_references_of_a_repeated_run_are_its_own_alone():
    """A run repeated in one batch (the fine-tune runs each stop once a member) has its
    references computed once; every copy gets what the run gets alone, exactly."""
    from wsp_env.evaluation.runner import run_runs
    from wsp_env.evaluation.suites import expand

    veh = load_vehicle("uic_z1")
    runs = expand(load_suite("quick"), veh)
    a, b = runs[0], runs[-1]
    keys = ("reference_distance_m", "dry_reference_distance_m", "equivalent_build_up_time_s")

    def refs(batch):
        res, _ = run_runs(veh, batch, NoWSP(), max_time_s=2.0)
        return [tuple(r[k] for k in keys) for r in res]

    alone = refs([a]) + refs([b])
    assert alone[0] != alone[1]
    assert refs([a, b, a, b, a]) == [alone[0], alone[1], alone[0], alone[1], alone[0]]


def test_references_kept_for_another_policy_are_the_ones_computed_again():
    """A stop's references (the available-adhesion and dry-rail distances) are kept for the
    process by the inputs that make them: another policy on the same stops finds every one
    kept, and what it reports is bit for bit what computing them again gives."""
    from wsp_env.evaluation import runner

    suite = dataclasses.replace(load_suite("quick"), seeds=(0,))
    suite = dataclasses.replace(suite, cases=suite.cases[:3])
    runner.clear_reference_cache()
    first, _ = run_suite("uic_z1", suite, make_policy("none"), record="none")
    kept = runner.reference_cache_size()
    assert kept == (len(first), 1)
    reused, _ = run_suite("uic_z1", suite, make_policy("classical"), record="none")
    assert runner.reference_cache_size() == kept  # every one found, none added
    runner.clear_reference_cache()
    again, _ = run_suite("uic_z1", suite, make_policy("classical"), record="none")
    assert json.dumps(reused, sort_keys=True) == json.dumps(again, sort_keys=True)
    for r in reused:
        assert r["reference_distance_m"] > 0 and r["dry_reference_distance_m"] > 0


def test_a_reference_key_changes_with_each_input_it_hashes():
    """A key that left out an input would hand one stop's reference to another: change one
    input at a time and only the references that read it are computed again, each equal to a
    computation from a cold cache. The run's time limit reaches only the dry-rail run (20 s cuts
    its stops short); one case's initial speed only its own available-adhesion reference (and
    the batch's dry run, whose setups carry it)."""
    from wsp_env.evaluation import runner

    suite = dataclasses.replace(load_suite("quick"), seeds=(0,))
    suite = dataclasses.replace(suite, cases=suite.cases[:2])
    case = suite.cases[0]
    # rail sections that do not move with the speed: the available key changes through v0 alone
    assert case.pattern == "uniform"
    faster = dataclasses.replace(case, speeds_kmh=(str(float(case.speeds_kmh[0]) + 7.0),))
    moved = dataclasses.replace(suite, cases=(faster, *suite.cases[1:]))

    def refs(s, max_time_s=600.0):
        res, _ = run_suite("uic_z1", s, make_policy("none"), record="none", max_time_s=max_time_s)
        return [(r["reference_distance_m"], r["dry_reference_distance_m"]) for r in res]

    cold = {}
    for name, s, limit in (("short", suite, 20.0), ("moved", moved, 600.0)):
        runner.clear_reference_cache()
        cold[name] = refs(s, limit)
    runner.clear_reference_cache()
    first = refs(suite)
    assert runner.reference_cache_size() == (2, 1)
    # 20 s cuts the dry stops short, so a dry key without the time limit would return the
    # first run's (longer) distances
    shorter = refs(suite, 20.0)
    assert runner.reference_cache_size() == (2, 2)  # a new dry run, the same available ones
    assert shorter == cold["short"]
    assert [r[1] for r in shorter] != [r[1] for r in first]
    res = refs(moved)
    assert runner.reference_cache_size() == (3, 3)  # that case's available one, a dry run
    assert res == cold["moved"]
    assert res[0] != first[0] and res[1:] == first[1:]
    runner.clear_reference_cache()

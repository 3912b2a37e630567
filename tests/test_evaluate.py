"""Classical WSP, suites, metrics and `wsp-env evaluate`; the seed 002 braking-test reproduction."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wsp_env.baselines.classical import ClassicalWSP, load_wsp_config
from wsp_env.cli import main
from wsp_env.config import ConfigError, _configs_root
from wsp_env.evaluation import load_suite, run_suite, summarise
from wsp_env.policy import NoWSP, make_policy

TABLE6 = 0.5 * (np.array([13.08, 13.36, 13.09, 13.52]) + np.array([12.78, 12.06, 13.20, 13.43]))


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


def test_oracle_uses_the_available_adhesion(quick_results):
    """The privileged peak-holder stops within a few % of the reference distance, no sliding."""
    for r in quick_results["oracle"]:
        if r["conditions"]["rail"] in ("soap", "leaves") and not r["conditions"]["sections"]:
            assert abs(r["adhesion_utilisation"] - 1.0) < 0.05
        assert r["max_lock_s"] == 0.0


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


def test_seed002_braking_test_reproduction():
    """Seed 002 §5.2: stop within 5 % of 725 m (Table 7), each axle's mean sliding within
    2 km/h of Table 6 (mean of tests B1, B2), Table 5 held fixed; WSP thresholds and R_i tuned
    (configs/wsp/seed002_uic_z1.yaml, configs/scenarios/seed002_braking.yaml)."""
    wsp = load_wsp_config(_configs_root() / "wsp" / "seed002_uic_z1.yaml")
    result = run_suite("uic_z1", load_suite("seed002_braking"), ClassicalWSP(wsp), record="none")[
        0
    ][0]
    assert result["stopping_distance_m"] == pytest.approx(725.0, rel=0.05)
    slide = np.array([a["mean_sliding_kmh"] for a in result["axles"]])
    assert np.all(np.abs(slide - TABLE6) <= 2.0), slide

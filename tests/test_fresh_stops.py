"""scripts/fresh_stops.py: policies on fresh stops of one rail (seeds no set or pool uses)."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import fresh_stops

from wsp_env.evaluation.benchmark import SEALED_SEED_BASE, STOP_SETS
from wsp_env.training.es import MAX_POOL, TRAINING_SEED_BASE


def test_the_fresh_seeds_are_no_sets_or_pools():
    top = fresh_stops.FRESH_SEED_BASE + fresh_stops.MAX_DRAW
    for base in (SEALED_SEED_BASE, STOP_SETS["development"][0]):
        assert base + 300 <= fresh_stops.FRESH_SEED_BASE or base >= top
    assert TRAINING_SEED_BASE + MAX_POOL <= fresh_stops.FRESH_SEED_BASE


def test_stops_of_one_rail_run_under_every_policy(tmp_path, capsys):
    """The kept seeds are exactly the draw's stops on the rail; every policy runs them all, the
    file holds each run and the summary counts what the runs say."""
    seeds = fresh_stops.rail_seeds("uic_z1", "wheels+accel", "dry", 30)
    assert seeds and all(9_800_000 <= s < 9_800_030 for s in seeds)
    others = set(range(9_800_000, 9_800_030)) - set(seeds)
    assert others  # other rails were drawn and left out
    out = tmp_path / "f.json"
    argv = ["--rail", "dry", "--draw", "30", "--policy", "target:3", "--policy", "classical",
            "--json", str(out)]  # fmt: skip
    assert fresh_stops.main(argv) == 0
    data = json.loads(out.read_text())
    assert data["seeds"] == seeds and data["rail"] == "dry"
    for spec in ("target:3", "classical"):
        runs = data["run_results"][spec]
        assert [r["seed"] for r in runs] == seeds
        assert all(r["conditions"]["rail"] == "dry" and r["stopped"] for r in runs)
        s = data["summary"][spec]
        assert s["stops"] == len(seeds)
        assert s["longest_lock_s"] == max(r["max_lock_s"] for r in runs)
        for key, field in (("return_mean", "return"), ("air_litres_mean", "air_litres"),
                           ("sliding_energy_kJ_mean", "sliding_energy_kJ")):  # fmt: skip
            want = sum(r[field] for r in runs) / len(runs)
            assert s[key] == pytest.approx(want, rel=1e-12), key
    assert data["summary"]["target:3"]["air_litres_mean"] != s["air_litres_mean"]
    printed = capsys.readouterr().out
    assert f"{len(seeds)} dry stops among seeds" in printed
    assert f"air {s['air_litres_mean']:.0f} l" in printed
    # each policy's per-stop ratios to the classical WSP's runs of the same stops
    mine = [r["stopping_distance_m"] for r in data["run_results"]["target:3"]]
    base = [r["stopping_distance_m"] for r in data["run_results"]["classical"]]
    ratio = [m / b for m, b in zip(mine, base, strict=True)]
    s = data["summary"]["target:3"]
    assert s["stop_ratio_mean"] == pytest.approx(sum(ratio) / len(ratio), rel=1e-12)
    worst = ratio.index(max(ratio))
    assert s["stop_ratio_worst"] == ratio[worst]
    assert s["stop_ratio_worst_stop"] == data["run_results"]["target:3"][worst]["scenario"]


def test_a_supervision_floor_probe_runs_every_policy_under_it(tmp_path, capsys):
    """``--watchdog-floor``: the stops run under that minimum-deceleration floor. Dry stops
    brake at about 1 m/s^2 on gripping wheels, so a 5 m/s^2 floor trips the supervision on
    every one, which the benchmark's 0.2 m/s^2 never does there; the header and the file say
    it was a probe."""
    out = tmp_path / "f.json"
    argv = ["--rail", "dry", "--draw", "12", "--policy", "target:3", "--watchdog-floor", "5",
            "--json", str(out)]  # fmt: skip
    assert fresh_stops.main(argv) == 0
    data = json.loads(out.read_text())
    assert data["watchdog_floor_mps2"] == 5.0
    runs = data["run_results"]["target:3"]
    assert runs and all(r["watchdog"]["min_deceleration"] == 1 for r in runs)
    assert "supervision floor 5 m/s^2: a probe" in capsys.readouterr().out
    plain = fresh_stops.run("uic_z1", "wheels+accel", data["seeds"], ["target:3"])["target:3"]
    assert all(r["watchdog"]["min_deceleration"] == 0 for r in plain)


def test_a_target_with_the_drift_correction_runs_the_corrected_loop():
    """``target:X:drift`` is the tier's loop with the drift correction (named so); plain
    ``target:X`` is the environment's default loop."""
    drift = fresh_stops.build_policy("target:2:drift", "wheels+accel")
    plain = fresh_stops.build_policy("target:2", "wheels+accel")
    assert drift.loop.drift_correction and not plain.loop.drift_correction
    assert drift.name == "slip_target_2kmh_drift" and plain.name == "slip_target_2kmh"
    scaled = fresh_stops.build_policy("target:2:drift:0.8x0.25", "wheels+accel")
    assert scaled.loop.drift_correction
    assert (scaled.loop.gain_per_kmh, scaled.loop.gain_scale_floor) == (0.8, 0.25)
    assert scaled.name == "slip_target_2kmh_drift_pgain0.8x0.25"
    alone = fresh_stops.build_policy("target:2:0.4x0.5", "wheels")
    assert not alone.loop.drift_correction and alone.loop.gain_scale_floor == 0.5
    onset = fresh_stops.build_policy("target:2:drift:onset", "wheels+accel")
    assert onset.loop.onset_drift and onset.name == "slip_target_2kmh_drift_onset"
    cal = fresh_stops.build_policy("target:2:drift:onset:cal", "wheels+accel")
    assert cal.loop.onset_drift and cal.loop.scale_calibration
    assert cal.name == "slip_target_2kmh_drift_onset_cal"
    alone_cal = fresh_stops.build_policy("target:2:cal", "wheels")
    assert alone_cal.loop.scale_calibration and not alone_cal.loop.drift_correction
    assert not onset.loop.scale_calibration and not onset.loop.onset_two_sided
    two = fresh_stops.build_policy("target:2:drift:onset2:cal", "wheels+accel")
    assert two.loop.onset_two_sided and two.loop.onset_drift and two.loop.scale_calibration
    assert two.name == "slip_target_2kmh_drift_onset2_cal"
    # the creep cap and its floor (a schedule): before ``:cal``, after the gain
    sched = fresh_stops.build_policy("target:2:drift:onset2:creep0.02@0.5:cal", "wheels+accel")
    assert (sched.loop.max_creep, sched.loop.creep_floor_kmh) == (0.02, 0.5)
    assert sched.loop.onset_two_sided and sched.loop.scale_calibration
    assert sched.name == "slip_target_2kmh_creep0.02at0.5_drift_onset2_cal"
    assert not sched.loop.lock_guard
    guard = fresh_stops.build_policy("target:1:drift:onset2:cal:guard", "wheels+accel")
    assert guard.loop.lock_guard and guard.loop.scale_calibration
    assert guard.name == "slip_target_1kmh_drift_onset2_cal_guard"
    cap = fresh_stops.build_policy("target:2:0.8x0.25:creep0.1", "wheels")
    assert (cap.loop.max_creep, cap.loop.creep_floor_kmh, cap.loop.gain_scale_floor) == (
        0.1, 2.0, 0.25)  # fmt: skip
    assert cap.name == "slip_target_2kmh_creep0.1_pgain0.8x0.25"
    bad = (
        ("target:2:onset", "target:X[:drift[:onset|:onset2]][:GAINxFLOOR]"),
        ("target:2:drift:0.8", "target:X[:drift[:onset|:onset2]][:GAINxFLOOR]"),
        ("target:2:drift:ax0.25", "slip_target_gain_per_kmh: expected a number"),
        ("target:2:0.8x2", "slip_target_gain_scale_floor: must be in (0, 1]"),
        ("target:2:drift:0.8x0.25:x", "target:X[:drift[:onset|:onset2]][:GAINxFLOOR]"),
        ("target:2:cal:drift", "target:X[:drift[:onset|:onset2]][:GAINxFLOOR][:creepC[@F]][:cal]"),
        ("target:2:creep2", "creepC[@F], the loop's cap and floor (slip_target_max_creep"),
        ("target:2:creep0.1@", "creepC[@F], the loop's cap and floor (creep_floor_kmh"),
        ("target:2:creep0@0.5", "creep0 is no cap, so a floor means nothing"),
        ("target:2:creep0.1@40", "creep_floor_kmh: must be in [0, 30]"),
        ("target:2:creepx", "creepC[@F]"),
        ("target:2:creep0.1:drift", "target:X[:drift[:onset|:onset2]][:GAINxFLOOR]"),
    )
    for spec, words in bad:
        with pytest.raises(ValueError, match=re.escape(words)):
            fresh_stops.build_policy(spec, "wheels+accel")


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--rail", "mud", "--policy", "classical"], "--rail: 'mud' is not one of"),
        (["--rail", "dry", "--policy", "target:x"], "target:X needs a number"),
        (["--rail", "dry", "--policy", "target:40"], "a target in [0, 30] km/h"),
        (["--rail", "dry", "--draw", "0", "--policy", "classical"], "--draw: must be"),
        (["--rail", "dry", "--policy", "no_such_model.zip"], "no_such_model.zip"),
        (
            ["--rail", "dry", "--policy", "target:2:fast"],
            "target:X[:drift[:onset|:onset2]][:GAINxFLOOR]",
        ),
        (["--rail", "dry", "--tier", "wheels", "--policy", "target:2:drift"], "needs --tier"),
        (
            ["--rail", "dry", "--policy", "classical", "--watchdog-floor", "-1"],
            "--watchdog-floor: must be in [0, 5], got -1",
        ),
    ],
)
def test_bad_input_is_one_line_and_no_file(tmp_path, capsys, argv, words):
    out = tmp_path / "f.json"
    assert fresh_stops.main([*argv, "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err and err.startswith("fresh_stops: ")
    assert not out.exists() and not list(tmp_path.iterdir())


class _ConstantInMode:
    """A constant slip-target action given to the environment's slip-target mode (as a model
    file of that mode acts)."""

    name = "constant"

    def __init__(self, action: float) -> None:
        self.action = action
        self.env_kwargs = {"action_mode": "slip_target"}

    def bind(self, core):
        self.n = (core.n_envs, core.n_valves)

    def reset(self, env_ids):
        pass

    def act(self, obs):
        import numpy as np

        return np.full(self.n, self.action, dtype=np.float32)


def test_policy_targets_bins_every_decision_by_the_train_speed(capsys):
    """scripts/policy_targets.py: a policy asking for one target always has that target in
    every band of every rail, each stop counted in the bands its speed passed through (a stop
    from over 40 km/h passes all three), and a table cell is None where no stop was; the
    command's input errors are one line."""
    import numpy as np
    import policy_targets as pt

    from wsp_env.evaluation.benchmark import DAMAGE_CRITERIA, POLICY_KEYS
    from wsp_env.evaluation.runner import run_runs
    from wsp_env.evaluation.suites import Run

    veh, max_time_s, kw = fresh_stops.benchmark_setup("uic_z1", "wheels")
    rec = pt.TargetRecorder(_ConstantInMode(-0.6), np.array([20.0, 40.0]))  # 2 km/h of 0.5-8
    runs = [Run(f"s{s}", s, {"speed_kmh": v, "rail": r}, dict(DAMAGE_CRITERIA), veh)
            for s, v, r in ((1, 60.0, "wet"), (2, 30.0, "wet"), (3, 90.0, "dry"))]  # fmt: skip
    run_runs(veh, runs, rec, max_time_s=max_time_s, env_kwargs=kw, policy_keys=POLICY_KEYS)
    counts = rec.counts
    assert (counts[0] > 0).all() and (counts[2] > 0).all()  # 60 and 90 km/h: every band
    assert counts[1, 2] == 0 and (counts[1, :2] > 0).all()  # 30 km/h: never at 40 or more
    np.testing.assert_allclose(rec.sums[counts > 0] / counts[counts > 0], 2.0)
    rails = [s.rail_name for s in rec.core.sim.setups]
    out = pt.table(rails, rec.sums, rec.counts)
    assert out["wet"][2][0] == 1 and out["wet"][0][0] == 2
    assert out["dry"][1][1] == pytest.approx(2.0)
    assert pt.band_names(np.array([20.0, 40.0])) == ["<20", "20-40", ">=40"]
    capsys.readouterr()
    assert pt.main(["--policy", "target:3", "--draw", "2"]) == 2
    assert "not a model of the slip-target action mode" in capsys.readouterr().err
    assert pt.main(["--policy", "target:3", "--bands", "a,b"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--bands: expected km/h edges" in err
    # the teacher's table: a config's, checked as training checks it (one implementation,
    # ``config_teacher_table``, which slip_target_benchmark.py --teacher-table uses too)
    from wsp_env.training.config import config_teacher_table

    root = Path(__file__).resolve().parents[1] / "configs" / "train"
    table = config_teacher_table(root / "ppo_bc_slip_target_cal_accel_uic_z1.yaml")
    assert table["leaves"] == 2.0 and table["soap"] == 4.25
    assert pt.main(["--policy", "target:3", "--teacher", str(root / "ppo_uic_z1.yaml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no pretrain.teacher_targets_kmh" in err
    # a teacher whose leaves target is a creep schedule has no constant row to compare
    from wsp_env.training.config import config_teacher_creep

    guard = root / "ppo_bc_slip_target_guard_accel_regiolis.yaml"
    assert config_teacher_creep(guard) == ({"leaves": 0.015}, 0.5)
    assert config_teacher_creep(root / "ppo_bc_slip_target_cal_accel_uic_z1.yaml")[0] == {}
    assert pt.main(["--policy", "target:3", "--teacher", str(guard)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "rail leaves's target is a creep schedule" in err


def test_an_axle_profile_holds_its_leading_axles_higher():
    """``scripts/axle_profile.py``: ``pBBB_LLL_N`` through ``module:callable``; with the lead
    target equal to the base it is the constant target, run for run; otherwise the first N
    valves hold the lead target and the stops differ. A bad name is refused."""
    import axle_profile

    from wsp_env.policy import make_policy

    seeds = fresh_stops.rail_seeds("uic_z1", "wheels+accel", "soap", 12)[:3]
    specs = ["target:3.5", "axle_profile:p35_35_2", "axle_profile:p35_100_2"]
    got = fresh_stops.run("uic_z1", "wheels+accel", seeds, specs)
    runs = {spec: [{k: v for k, v in r.items() if k != "policy"} for r in got[spec]]
            for spec in specs}  # fmt: skip
    assert runs["axle_profile:p35_35_2"] == runs["target:3.5"]
    assert runs["axle_profile:p35_100_2"] != runs["target:3.5"]
    policy = make_policy("axle_profile:p35_100_2")
    assert policy.name == "axle_profile_3.5_10x2"
    with pytest.raises(AttributeError, match="pBBB_LLL_N"):
        axle_profile.p35_100  # noqa: B018
    with pytest.raises(ValueError, match="policy: axle_profile:q1: 'axle_profile' has no"):
        make_policy("axle_profile:q1")

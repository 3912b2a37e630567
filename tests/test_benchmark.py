"""The benchmark (``wsp-env benchmark``): the sealed set shares nothing with the other suites,
the score's ends are what they say, policies from anywhere load, bad input is one line."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from wsp_env import BENCHMARK_VEHICLES
from wsp_env.cli import main
from wsp_env.core.config import configs_root, load_vehicle
from wsp_env.envs.tiers import VERSION, VERSIONS, benchmark_env_kwargs, env_id, ids
from wsp_env.evaluation import expand, load_suite
from wsp_env.evaluation.benchmark import (
    SEALED_RUNS,
    STOP_SETS,
    iqm,
    paired_difference,
    run_benchmark,
    score,
    sealed_runs,
)
from wsp_env.policy import load_callable_policy, make_policy


def _suites():
    return [load_suite(p.stem) for p in sorted((configs_root() / "scenarios").glob("*.yaml"))]


@pytest.mark.parametrize("stop_set", ["sealed", "development"])
def test_the_sealed_set_shares_no_seed_case_or_level_with_any_suite(stop_set):
    """300 stops per vehicle; no seed, case name or adhesion level of tuning, validation,
    en15595, heldout (or any other suite) among them; its levels are drawn, every one distinct.
    The development set likewise, and it shares no seed, name or level with the sealed set."""
    from wsp_env.core.braking import BrakingCore

    veh = load_vehicle("uic_z1")
    sealed = sealed_runs(veh, stop_set=stop_set)
    assert len(sealed) == SEALED_RUNS == 300
    if stop_set != "sealed":
        test_set = sealed_runs(veh)
        assert not {r.seed for r in test_set} & {r.seed for r in sealed}
        assert not {r.scenario for r in test_set} & {r.scenario for r in sealed}
    suite_seeds, suite_cases, suite_levels = set(), set(), set()
    for suite in _suites():
        suite_seeds |= set(suite.seeds)
        suite_cases |= {c.name for c in suite.cases}
        for run in expand(suite, veh):
            suite_cases.add(run.scenario)
            if run.options.get("mu_contaminated") is not None:
                suite_levels.add(round(float(run.options["mu_contaminated"]), 6))
    assert not suite_seeds & {r.seed for r in sealed}
    assert not suite_cases & {r.scenario for r in sealed}
    assert {"tuning", "validation", "en15595", "heldout"} <= {s.name for s in _suites()}
    kwargs = benchmark_env_kwargs("uic_z1", "wheels")
    kwargs.pop("vehicle")
    core = BrakingCore(len(sealed), vehicle=veh, **kwargs)
    levels = []
    for e, run in enumerate(sealed):
        core.reset_env(e, run.options, seed=run.seed)
        levels.append(round(core.describe(e)["mu_contaminated"], 6))
    contaminated = [x for x, s in zip(levels, core.sim.setups, strict=True) if s.rail_name != "dry"]
    assert not suite_levels & set(contaminated)
    drawn = [core.describe(e) for e in range(len(sealed))]  # this set's stops, before any other
    rails = {d["rail"] for d in drawn}
    assert rails == {"dry", "wet", "soap", "soap_etr1000", "oil", "leaves"}
    grades = np.array([d["gradient_permille"] for d in drawn])
    assert grades.min() < -20.0 and grades.max() > 20.0 and np.abs(grades).max() <= 25.0
    if stop_set != "sealed":  # the sealed set's levels are not the development set's
        test_levels = set()
        for e, run in enumerate(test_set):
            core.reset_env(e, run.options, seed=run.seed)
            if core.sim.setups[e].rail_name != "dry":
                test_levels.add(round(core.describe(e)["mu_contaminated"], 6))
        assert not test_levels & set(contaminated)


def test_iqm_is_the_mean_of_the_middle_half():
    assert iqm(np.arange(8.0)) == pytest.approx(np.mean([2, 3, 4, 5]))
    assert iqm(np.array([0.0, 1.0, 1.0, 1.0, 100.0])) == pytest.approx(1.0)
    x = np.random.default_rng(0).normal(size=(3, 41))
    assert np.allclose(iqm(x, axis=1), [iqm(r) for r in x])


def test_score_ends_and_interval():
    """none scores 0, the classical WSP 1, exactly; a policy halfway scores 0.5 with a
    bootstrap interval around it; stops where the classical WSP gains nothing are left out."""
    rng = np.random.default_rng(1)
    r_none = -rng.uniform(5, 10, 200)
    r_cls = r_none + rng.uniform(0.5, 2.0, 200)
    r_cls[:20] = r_none[:20]  # dry: the classical WSP rightly does nothing
    assert score(r_none, r_none, r_cls)["score"] == 0.0
    assert score(r_cls, r_none, r_cls)["score"] == pytest.approx(1.0)
    half = r_none + 0.5 * (r_cls - r_none) + rng.normal(0, 0.02, 200)
    s = score(half, r_none, r_cls)
    assert s["scored_runs"] == 180
    assert s["score_ci95"][0] < s["score"] < s["score_ci95"][1]
    assert s["score"] == pytest.approx(0.5, abs=0.03)


def test_paired_difference_sees_a_small_gain_that_the_scores_intervals_hide():
    """Two policies whose normalised returns spread widely over stops but differ by a small
    constant on every stop: the paired interval of the difference lies above 0 and is far
    narrower than either score's own; a policy against itself differs by exactly 0."""
    rng = np.random.default_rng(2)
    r_none = -rng.uniform(5, 10, 300)
    gain = rng.uniform(0.5, 2.0, 300)
    r_cls = r_none + gain
    base = r_none + gain * rng.uniform(0.8, 1.2, 300)
    other = base + 0.003 * gain
    d = paired_difference(other, base, r_none, r_cls)
    assert d["difference"] == pytest.approx(0.003, abs=1e-9)
    lo, hi = d["difference_ci95"]
    assert 0 < lo <= 0.003 <= hi
    s_lo, s_hi = score(other, r_none, r_cls)["score_ci95"]
    assert s_lo < score(base, r_none, r_cls)["score"]  # unpaired: not clear of the base
    assert hi - lo < 0.1 * (s_hi - s_lo)
    same = paired_difference(base, base, r_none, r_cls)
    assert same["difference"] == 0.0 and same["difference_ci95"] == [0.0, 0.0]
    assert paired_difference(base, base, r_none, r_none)["difference"] is None


def test_registered_ids_fix_vehicle_tier_and_distribution():
    for vehicle in BENCHMARK_VEHICLES:
        load_vehicle(vehicle)  # every id names a vehicle of configs/vehicles
    assert {p.stem for p in (configs_root() / "vehicles").glob("*.yaml")} == set(BENCHMARK_VEHICLES)
    env = gym.make("WSPBraking-UICZ1-Accel-v3")
    core = env.unwrapped.core
    assert core.accelerometer and core.sensors.accelerometer_bias_mps2 == 0.3
    assert core.scenario.gradient_permille == (-25.0, 25.0) and core.watchdog.enabled
    assert env.observation_space.shape == (24,)
    venv = gym.make_vec("WSPBraking-ETR1000-v3", num_envs=3)
    assert not venv.unwrapped.core.accelerometer and venv.unwrapped.core.vehicle.id == "etr1000"
    assert env_id("regiolis", "wheels+accel") == "WSPBraking-Regiolis-Accel-v3"
    obs, _ = venv.reset(seed=0)
    assert obs.shape[0] == 3
    for bad in ({"vehicle": "etr1000"}, {"max_time_s": 5.0}, {"tier": "wheels"}):
        with pytest.raises(ValueError, match="fixes every setting"):
            gym.make("WSPBraking-UICZ1-v3", **bad)


def test_every_version_of_the_ids_stays_registered_and_differs_only_where_its_history_says():
    """The package registers exactly ``tiers.ids()`` (every vehicle, tier and version); ``-v2``
    is ``-v3`` with the estimator's spin-up test on one reading and no accelerometer offset
    learned, ``-v1`` is ``-v2`` with the watchdog's override standing to standstill
    (``give_way_locked_s`` 0), every other setting equal; the benchmark scores the current
    version."""
    from gymnasium.envs.registration import registry

    registered = {i for i in registry if i.startswith("WSPBraking-") and i != "WSPBraking-v0"}
    assert registered == set(ids()) and len(registered) == 3 * 2 * len(BENCHMARK_VEHICLES)
    assert VERSION == VERSIONS[-1] == "v3" and env_id("uic_z1", "wheels").endswith("-v3")
    v1, v2, v3 = (benchmark_env_kwargs("uic_z1", "wheels", v) for v in VERSIONS)
    assert v1.pop("watchdog") == {"give_way_locked_s": 0.0} and v2.pop("watchdog") is None
    assert v3.pop("watchdog") is None
    old_estimator = {"free_roll_filter_s": 0.0, "accel_offset_gain": 0.0}
    assert v1.pop("estimator") == v2.pop("estimator") == old_estimator
    assert v3.pop("estimator") is None
    assert v1 == v2 == v3
    with pytest.warns(Warning, match="out of date"):
        made = gym.make("WSPBraking-UICZ1-v1")
    assert made.unwrapped.core.watchdog.give_way_locked_s == 0.0
    with pytest.warns(Warning, match="out of date"):
        made = gym.make("WSPBraking-UICZ1-Accel-v2")
    est = made.unwrapped.core.estimator
    assert est.free_roll_filter_s == 0.0 and est.accel_offset_gain == 0.0
    assert made.unwrapped.core.watchdog.give_way_locked_s == 0.2
    est = gym.make("WSPBraking-UICZ1-Accel-v3").unwrapped.core.estimator
    assert est.free_roll_filter_s == 0.1 and est.accel_offset_gain == 0.5
    with pytest.raises(ValueError, match="version"):
        env_id("uic_z1", "wheels", "v4")


class _Half:
    """Half the demand on every valve: a policy from outside the project."""

    name = "half"

    def bind(self, core):
        self.shape = (core.n_envs, core.n_valves)

    def reset(self, env_ids):
        pass

    def act(self, obs):
        return np.zeros(self.shape, dtype=np.float32)


def make_half():
    return _Half()


def make_nothing():
    return 42


def test_module_callable_policies_load_and_bad_paths_are_one_line(monkeypatch):
    monkeypatch.syspath_prepend(str(Path(__file__).parent))
    policy = load_callable_policy("test_benchmark:make_half")
    assert policy.name == "half" and policy.privileged is False
    assert make_policy("test_benchmark:make_half").name == "half"
    for spec, needle in [
        ("no_such_module_xyz:make", "cannot import 'no_such_module_xyz'"),
        ("test_benchmark:missing", "has no attribute 'missing'"),
        ("test_benchmark:make_nothing", "without bind, reset, act"),
        ("test_benchmark:SEALED_RUNS", "is not callable"),
        (":make", "is not module:callable"),
    ]:
        with pytest.raises(ValueError) as err:
            make_policy(spec)
        assert needle in str(err.value) and "\n" not in str(err.value), str(err.value)


def test_benchmark_runs_policies_through_one_path_and_refuses_a_foreign_tier(
    monkeypatch, tmp_path, capsys
):
    """Twelve stops: none 0, classical 1, a module's policy scored in between or below; the
    JSON carries families and the watchdog; a policy trained with an accelerometer is refused
    in the wheels tier with one line."""
    monkeypatch.syspath_prepend(str(Path(__file__).parent))
    out = tmp_path / "b.json"
    rc = main(["benchmark", "--policy", "classical", "--policy", "test_benchmark:make_half",
               "--runs", "12", "--json", str(out), "--report", str(tmp_path / "rep"),
               "--no-progress"])  # fmt: skip
    assert rc == 0
    payload = json.loads(out.read_text())
    pols = payload["policies"]
    assert payload["runs"] == 12 and not payload["sealed"]
    assert pols["none"]["score"] == 0.0 and pols["classical"]["score"] == pytest.approx(1.0)
    assert pols["half"]["score"] < 1.0 and pols["half"]["stop_ratio_mean"] > 1.0
    assert set(pols["half"]["families"]) == {"rail", "gradient", "speed"}
    assert "watchdog_interventions" in pols["half"]
    assert 0 <= pols["half"]["watchdog_gave_way_runs"] <= pols["half"]["watchdog_runs"]
    assert (tmp_path / "rep" / "report.md").read_text().startswith("# WSPBraking-UICZ1-v3")

    accel = _Half()
    accel.env_kwargs = {"accelerometer": True}  # as a model trained with one says
    with pytest.raises(ValueError, match="belongs to tier wheels\\+accel"):
        run_benchmark([accel], "uic_z1", "wheels", runs=2)

    # the development set: other stops, said so in the JSON, the printout and the report
    out = tmp_path / "d.json"
    capsys.readouterr()
    rc = main(["benchmark", "--policy", "classical", "--runs", "3", "--stops", "development",
               "--json", str(out), "--report", str(tmp_path / "dev"), "--no-progress"])  # fmt: skip
    assert rc == 0
    dev = json.loads(out.read_text())
    assert dev["stops"] == "development" and not dev["sealed"] and payload["stops"] == "sealed"
    assert "development stops: not the sealed set" in capsys.readouterr().out
    assert "(development stops: not the sealed set" in (tmp_path / "dev" / "report.md").read_text()
    for name in ("none", "classical"):  # the development set's first three stops, not the sealed
        runs = dev["run_results"][name]
        assert [r["seed"] for r in runs] == [8_260_000, 8_260_001, 8_260_002]
        assert all(r["scenario"].startswith("dev_") for r in runs)
    assert [r["seed"] for r in payload["run_results"]["none"]][:2] == [7_340_000, 7_340_001]
    # each stop's figures are kept, and the summary's largest and mean are theirs
    for name, summ in dev["policies"].items():
        runs = dev["run_results"][name]
        assert summ["max_lock_s_max"] == max(r["max_lock_s"] for r in runs)
        assert summ["max_sliding_kmh_max"] == max(r["max_sliding_kmh"] for r in runs)
        assert summ["air_litres_mean"] == pytest.approx(np.mean([r["air_litres"] for r in runs]))
        assert summ["sliding_energy_kJ_mean"] == pytest.approx(
            np.mean([r["sliding_energy_kJ"] for r in runs])
        )
    with pytest.raises(ValueError, match="stops: 'test' is not one of sealed, development"):
        run_benchmark([make_policy("none")], "uic_z1", "wheels", runs=1, stop_set="test")
    with pytest.raises(ValueError, match="stops: 'test' is not one of"):
        sealed_runs(load_vehicle("uic_z1"), 1, stop_set="test")
    # the command line offers exactly the library's stop sets (written out there: the parser
    # does not import the evaluation package)
    from wsp_env.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    stops = next(a for a in sub.choices["benchmark"]._actions if a.dest == "stops")
    assert tuple(stops.choices) == tuple(STOP_SETS)
    version = next(a for a in sub.choices["benchmark"]._actions if a.dest == "version")
    assert tuple(version.choices) == VERSIONS and version.default == VERSION
    # an earlier version of the ids: named in the JSON, its watchdog (checked on the ids)
    out = tmp_path / "v1.json"
    rc = main(["benchmark", "--policy", "classical", "--runs", "2", "--version", "v1",
               "--json", str(out), "--no-progress"])  # fmt: skip
    assert rc == 0 and json.loads(out.read_text())["benchmark"] == "WSPBraking-UICZ1-v1"


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["benchmark", "--policy", "classical", "--vehicle", "nope"], "--vehicle"),
        (["benchmark", "--policy", "classical", "--runs", "0"], "--runs"),
        (["benchmark", "--policy", "classical", "--runs", "301"], "--runs"),
        (["benchmark", "--policy", "classical", "--tier", "eyes"], "--tier"),
        (["benchmark", "--policy", "classical", "--stops", "test"], "--stops"),
        (["benchmark", "--policy", "no.such:thing"], "cannot import"),
        (["simulate", "--gradient-permille", "200"], "--gradient-permille"),
        (["simulate", "--accelerometer-bias-mps2", "0.1"], "no accelerometer"),
        (["simulate", "--accelerometer", "--accelerometer-bias-mps2", "5"], "bias"),
        (["simulate", "--wheel-speed-noise-kmh", "-1"], "--wheel-speed-noise-kmh"),
        (["simulate", "--wheel-speed-noise-kmh", "x"], "--wheel-speed-noise-kmh"),
    ],
)
def test_bad_benchmark_and_simulate_arguments_are_one_line(argv, needle, capsys):
    with pytest.raises(SystemExit) as ex:
        sys.exit(main(argv))
    assert ex.value.code != 0
    err = capsys.readouterr().err.strip()
    assert needle in err and "\n" not in err and "Traceback" not in err, err


def test_simulate_fixes_gradient_accelerometer_bias_and_noise(tmp_path):
    """The new options reach the stop exactly; with no options the stop is as before
    (level, no accelerometer, exact wheel speeds)."""
    out = tmp_path / "s.json"
    rc = main(["simulate", "--policy", "classical", "--rail", "leaves", "--speed-kmh", "100",
               "--gradient-permille", "-20", "--accelerometer", "--accelerometer-bias-mps2",
               "0.3", "--wheel-speed-noise-kmh", "0.2", "--json", str(out)])  # fmt: skip
    assert rc == 0
    r = json.loads(out.read_text())
    assert r["tier"] == "wheels+accel" and r["gradient_permille"] == -20.0
    assert r["sensors"]["accelerometer_bias_mps2"] == 0.3
    assert r["sensors"]["wheel_speed_noise_kmh"] == pytest.approx(0.2)
    assert main(["simulate", "--json", str(tmp_path / "d.json")]) == 0
    d = json.loads((tmp_path / "d.json").read_text())
    assert d["tier"] == "wheels" and d["policy"] == "none" and d["gradient_permille"] == 0.0
    assert d["sensors"] == {"wheel_speed_noise_kmh": 0.0, "wheel_speed_scale": [1.0] * 4,
                            "accelerometer_bias_mps2": None}  # fmt: skip


def test_evaluate_runs_a_suite_with_a_tiers_sensors(tmp_path, capsys):
    """``evaluate --tier wheels+accel``: the tier's accelerometer and sensor errors, its classical
    WSP; a wheels-only tier refuses the accelerometer-trained shipped policy in one line."""
    out = tmp_path / "e.json"
    argv = ["evaluate", "--policy", "classical", "--suite", "quick", "--tier", "wheels+accel",
            "--no-progress", "--json", str(out)]  # fmt: skip
    assert main(argv) == 0
    runs = json.loads(out.read_text())["runs"]
    biases = [r["conditions"]["sensors"]["accelerometer_bias_mps2"] for r in runs]
    assert all(b is not None and abs(b) <= 0.3 for b in biases) and len(set(biases)) > 1
    noise = [r["conditions"]["sensors"]["wheel_speed_noise_kmh"] for r in runs]
    assert max(noise) > 0.0 and max(noise) <= 0.05 + 1e-12
    rc = main(["evaluate", "--policy", "ppo_bc_uic_z1", "--suite", "quick", "--tier", "wheels"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "belongs to tier wheels+accel" in err and "\n" not in err

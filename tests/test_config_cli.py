"""Configs load and validate; the simulate command works end to end and fails cleanly."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from test_trace_io import read_csv

from wsp_env.cli import main
from wsp_env.core.config import ConfigError, load_rails, load_vehicle

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize(
    "vid,n_axles", [("uic_z1", 4), ("e402b", 4), ("etr1000", 32), ("regiolis", 16)]
)
def test_shipped_vehicles_load(vid, n_axles):
    veh = load_vehicle(vid)
    assert veh.n_axles == n_axles
    gain, p_th = veh.brake.linear_torque()
    assert gain > 0 and 0 <= p_th < veh.brake.p_max_bar


def test_uic_z1_full_demand_torque_is_9500_nm():
    """Seed 002 Table 2: braking torque 9500 N m."""
    veh = load_vehicle("uic_z1")
    gain, p_th = veh.brake.linear_torque()
    assert gain * (veh.brake.p_max_bar - p_th) == pytest.approx(9500, rel=1e-3)


def test_shipped_rails_load():
    rails = load_rails()
    assert {"dry", "wet", "soap", "oil", "leaves"} <= set(rails)


def _broken_vehicle(tmp_path, mutate) -> Path:
    data = yaml.safe_load((ROOT / "configs/vehicles/uic_z1.yaml").read_text())
    mutate(data)
    path = tmp_path / "broken.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    "mutate,field",
    [
        (lambda d: d.pop("wheel_radius_m"), "wheel_radius_m: missing required field"),
        (lambda d: d["cars"][0].update(body_mass_kg=-5.0), "cars[0].body_mass_kg: must be > 0"),
        (lambda d: d["brake"].update(p_max_bar="high"), "brake.p_max_bar: expected a number"),
        (lambda d: d.update(wheel_radus_m=0.4), "wheel_radus_m: unknown field"),
        (lambda d: d["brake"].update(valve_group="train"), "brake.valve_group: 'train' is not one"),
        (lambda d: d["cars"][0].update(bogies=[0, 7]), "cars[0].bogies: index out of range"),
        # bogies 2 m apart with 2.56 m wheelbases: the second's first axle ahead of the first's last
        (
            lambda d: d["bogies"][1].update(position_m=d["bogies"][0]["position_m"] + 2.0),
            "bogies[1]: its first axle",
        ),
    ],
)
def test_bad_vehicle_config_names_file_and_field(tmp_path, mutate, field):
    path = _broken_vehicle(tmp_path, mutate)
    with pytest.raises(ConfigError) as err:
        load_vehicle(path)
    msg = str(err.value)
    assert msg.startswith(str(path)) and field in msg and "\n" not in msg


def test_cli_bad_config_exits_nonzero_with_one_line(tmp_path, capsys):
    path = _broken_vehicle(tmp_path, lambda d: d["cars"][0].update(body_mass_kg=-1))
    out = tmp_path / "out.json"
    code = main(["simulate", "--vehicle", str(path), "--json", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and "broken.yaml" in err and "body_mass_kg" in err
    assert not out.exists()


def test_cli_unknown_contaminant_in_rail_table(tmp_path, capsys):
    rails = yaml.safe_load((ROOT / "configs/rails.yaml").read_text())
    rails["soap"]["law"] = "magic"
    path = tmp_path / "rails.yaml"
    path.write_text(yaml.safe_dump(rails))
    code = main(["simulate", "--rails-config", str(path)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "rails.yaml" in err and "soap.law" in err and "magic" in err


def test_cli_unknown_rail_is_one_line_naming_the_known_ones():
    proc = subprocess.run(
        [sys.executable, "-m", "wsp_env.cli", "simulate", "--rail", "custard"],
        capture_output=True,
        text=True,
    )
    err = proc.stderr.strip()
    assert proc.returncode == 2 and "custard" in err and "soap_etr1000" in err
    assert len(err.splitlines()) == 1 and "Traceback" not in err


def test_simulate_takes_every_rail_of_the_table_in_use(tmp_path, capsys):
    """Beyond the five contaminants: a named rail of the shipped table and one of a table given
    by --rails-config; the trace names its contaminant in the format's vocabulary."""
    assert main(["simulate", "--rail", "soap_etr1000", "--speed-kmh", "60",
                 "--trace", str(tmp_path / "t")]) == 0  # fmt: skip
    assert json.loads((tmp_path / "t.meta.json").read_text())["contaminant"] == "soap"
    rails = yaml.safe_load((ROOT / "configs/rails.yaml").read_text())
    rails["grease"] = {**rails["oil"], "mu_contaminated": 0.07}
    path = tmp_path / "rails.yaml"
    path.write_text(yaml.safe_dump(rails))
    out = tmp_path / "g.json"
    code = main(["simulate", "--rails-config", str(path), "--rail", "grease", "--speed-kmh",
                 "60", "--json", str(out), "--trace", str(tmp_path / "g")])  # fmt: skip
    assert code == 0 and json.loads(out.read_text())["rail"] == "grease"
    assert json.loads((tmp_path / "g.meta.json").read_text())["contaminant"] == "unknown"
    capsys.readouterr()


def test_simulate_writes_json_plot_and_trace(tmp_path, capsys):
    out = tmp_path / "run.json"
    code = main(
        [
            "simulate",
            "--speed-kmh",
            "80",
            "--rail",
            "soap",
            "--seed",
            "3",
            "--json",
            str(out),
            "--plot",
            str(tmp_path / "run.png"),
            "--trace",
            str(tmp_path / "t"),
        ]
    )
    assert code == 0
    result = json.loads(out.read_text())
    for key in ("stopping_distance_m", "stopping_time_s", "air_litres"):
        assert result[key] >= 0
    assert len(result["axles"]) == 4
    for axle in result["axles"]:
        assert set(axle) >= {
            "mean_sliding_kmh",
            "std_sliding_kmh",
            "mean_adhesion_used",
            "sliding_energy_kJ",
        }
    assert (tmp_path / "run.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    cols, meta = read_csv(tmp_path / "t.csv")
    assert meta["format"] == "wsp-trace/1" and meta["vehicle"]["n_axles"] == 4
    assert cols["v_train_kmh"][0] == pytest.approx(80, abs=1.0)
    assert "stop" in capsys.readouterr().out


def test_simulate_same_seed_same_result(tmp_path):
    a, b, c = (tmp_path / f"{n}.json" for n in "abc")
    main(["simulate", "--seed", "5", "--json", str(a), "--speed-kmh", "60"])
    main(["simulate", "--seed", "5", "--json", str(b), "--speed-kmh", "60"])
    main(["simulate", "--seed", "6", "--json", str(c), "--speed-kmh", "60"])
    assert a.read_text() == b.read_text()
    assert (
        json.loads(a.read_text())["mu_contaminated"] != json.loads(c.read_text())["mu_contaminated"]
    )


def test_simulate_runs_the_wsp_policies_on_the_evaluation_path(tmp_path):
    """--policy takes the evaluation's policy names (DESIGN §8): on the same seed, the
    classical WSP and the oracle keep the wheels from locking that full demand locks, and the
    stop matches ``wsp-env evaluate``'s code path (one run of a suite)."""
    from wsp_env.evaluation.runner import run_one
    from wsp_env.policy import make_policy

    results = {}
    for policy in ("none", "classical", "oracle"):
        out = tmp_path / f"{policy}.json"
        args = ["simulate", "--policy", policy, "--seed", "2", "--speed-kmh", "100"]
        assert main([*args, "--mu-contaminated", "0.07", "--json", str(out)]) == 0
        results[policy] = json.loads(out.read_text())
    assert results["none"]["max_lock_s"] > 5.0
    for policy in ("classical", "oracle"):
        assert results[policy]["policy"] == policy
        assert results[policy]["max_lock_s"] < 1.0
        assert results[policy]["sliding_energy_kJ"] < 0.5 * results["none"]["sliding_energy_kJ"]
        assert abs(results[policy]["energy_balance_rel_error"]) < 1e-9  # every run metric
    run, _ = run_one(
        "uic_z1", "soap", 100.0, make_policy("classical"), 2, {"mu_contaminated": 0.07}
    )
    assert run["stopping_distance_m"] == results["classical"]["stopping_distance_m"]


def test_a_first_run_says_it_is_compiling(tmp_path, monkeypatch, capsys):
    """While numba compiles (tens of seconds on a first run) the command says so on a terminal's
    stderr; a warm run says nothing of it."""
    import wsp_env.cli as cli

    monkeypatch.setattr(cli, "stderr_is_terminal", lambda: True)  # a terminal (capsys is none)
    monkeypatch.setattr(cli, "compiled", lambda: False)
    assert cli.main(["simulate", "--speed-kmh", "30"]) == 0
    assert capsys.readouterr().err.splitlines() == [cli.COMPILE_NOTICE]
    monkeypatch.setattr(cli, "compiled", lambda: True)
    assert cli.main(["simulate", "--speed-kmh", "30"]) == 0
    assert "compiling" not in capsys.readouterr().err

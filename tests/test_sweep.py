"""``wsp-env sweep`` on local Ray with tiny budgets: a grid over seeds writes its table, its
summary over seeds and the best config; a search samples and prunes; a killed sweep resumes
without training its finished trials again; a bad sweep file is one line naming the field."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest
import yaml

pytest.importorskip("ray")
pytest.importorskip("optuna")

from wsp_env.cli import main
from wsp_env.sweep.config import load_sweep_config

# one module at a time uses Ray on this machine (conftest.ray_exclusive)
pytestmark = pytest.mark.usefixtures("ray_exclusive")

SUITE = {
    "name": "tiny", "description": "two short stops", "seeds": [7],
    "cases": [
        {"name": "s", "rail": "soap", "mu_contaminated": 0.08, "pattern": "uniform",
         "speeds_kmh": [30]},
        {"name": "d", "rail": "dry", "pattern": "uniform", "speeds_kmh": [30]},
    ],
}  # fmt: skip


def _files(tmp_path, sweep, n_timesteps=512, relative=False):
    """The sweep file, its base training config and suite in ``tmp_path``; ``relative``: the
    files name each other by paths relative to ``tmp_path`` (where the sweep then starts)."""
    where = (lambda name: name) if relative else (lambda name: str(tmp_path / name))
    (tmp_path / "suite.yaml").write_text(yaml.safe_dump(SUITE))
    train = {
        "algo": "ppo", "n_envs": 8, "n_timesteps": n_timesteps, "seed": 3, "normalize": True,
        "policy_kwargs": {"net_arch": [16, 16]}, "learning_rate": 3.0e-4, "n_steps": 32,
        "batch_size": 64, "n_epochs": 2, "gamma": 0.999,
        "env_kwargs": {"vehicle": "uic_z1", "scenario": {"speed_kmh": [30, 40]}},
        "eval": {"suite": where("suite.yaml"), "every_timesteps": 256,
                 "curve_every_timesteps": 256, "curve_runs": 2},
        "checkpoint_every_timesteps": 256,
    }  # fmt: skip
    (tmp_path / "train.yaml").write_text(yaml.safe_dump(train))
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"train": where("train.yaml"), **sweep}))
    return path


def test_grid_writes_its_table_summary_and_best_config(tmp_path, monkeypatch, local_ray):
    """Started with relative paths everywhere (the sweep file, its training config, that
    config's suite, --out), as a user types them: the trials find them all."""
    monkeypatch.setenv("WSP_CORES", "2")
    monkeypatch.chdir(tmp_path)
    _files(tmp_path, {"seeds": [0, 1], "report_every_timesteps": 256,
                      "grid": {"gae_lambda": [0.95]}}, relative=True)  # fmt: skip
    out = tmp_path / "out"
    assert main(["sweep", "--config", "sweep.yaml", "--out", "out", "--json", "r.json"]) == 0
    r = json.loads((out / "results.json").read_text())
    assert [t["seed"] for t in r["trials"]] == [0, 1]
    assert all(t["status"] == "finished" and t["timesteps"] == 512 for t in r["trials"])
    # each trial is a wsp-env train run folder with its curve; the metric is its last score
    for t in r["trials"]:
        curve = json.loads((out / "trials" / t["trial"] / "curve.json").read_text())
        assert t["metric"] == pytest.approx(curve["history"][-1]["score"])
    (s,) = r["summary"]
    assert s["overrides"] == {"gae_lambda": 0.95} and s["seeds"] == [0, 1]
    lo, hi = s["metric_ci95"]
    assert lo <= s["metric_mean"] <= hi
    best = yaml.safe_load((out / "best.yaml").read_text())
    assert best["gae_lambda"] == 0.95 and best["seed"] == r["best"]["seed"]
    assert "| trial | overrides | seed |" in (out / "results.md").read_text()


def test_search_samples_the_space_with_optuna(tmp_path, monkeypatch, local_ray):
    monkeypatch.setenv("WSP_CORES", "2")
    cfg = _files(tmp_path, {"report_every_timesteps": 256, "search": {
        "space": {"learning_rate": {"type": "loguniform", "low": 1e-5, "high": 1e-3},
                  "n_epochs": {"type": "int", "low": 1, "high": 3}},
        "trials": 2, "sampler": "random", "pruner": "asha"}})  # fmt: skip
    out = tmp_path / "out"
    assert main(["sweep", "--config", str(cfg), "--out", str(out)]) == 0
    r = json.loads((out / "results.json").read_text())
    assert len(r["trials"]) == 2
    for t in r["trials"]:
        assert 1e-5 <= t["overrides"]["learning_rate"] <= 1e-3
        assert t["overrides"]["n_epochs"] in (1, 2, 3)
    assert (out / "best.yaml").exists()


def test_a_killed_sweep_resumes_without_redoing_finished_trials(tmp_path, local_ray):
    cfg = _files(tmp_path, {"seeds": [0, 1], "report_every_timesteps": 256,
                            "resources": {"cpus": 2}}, n_timesteps=768)  # fmt: skip
    out = tmp_path / "out"
    env = {**os.environ, "WSP_CORES": "2"}  # one trial at a time
    cmd = [sys.executable, "-m", "wsp_env.cli", "sweep", "--config", str(cfg), "--out", str(out)]
    proc = subprocess.Popen(cmd, env=env, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    finished = None
    deadline = time.monotonic() + 240
    try:
        while finished is None and time.monotonic() < deadline:
            assert proc.poll() is None, "the sweep ended before it could be killed"
            for done in (out / "trials").glob("*/train.json"):
                if json.loads(done.read_text()).get("finished"):
                    finished = done
            time.sleep(0.2)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert finished is not None
    mtime = finished.stat().st_mtime_ns
    assert not (out / "results.json").exists()  # nothing of the end written
    assert main(["sweep", "--out", str(out), "--resume"]) == 0
    r = json.loads((out / "results.json").read_text())
    assert len(r["trials"]) == 2 and all(t["status"] == "finished" for t in r["trials"])
    assert finished.stat().st_mtime_ns == mtime  # the finished trial was not trained again


@pytest.mark.parametrize(
    ("sweep", "message"),
    [
        ({"seeds": [0, 0]}, "seeds: a seed is listed twice"),
        ({"grid": {"learning_rate": "fast"}}, "grid.learning_rate: expected a non-empty list"),
        ({"grid": {"n_epochs": [0]}}, "grid (n_epochs=0): n_epochs"),
        ({"grid": {"env_kwargs.vehicle": ["tgv"]}}, "grid (env_kwargs.vehicle='tgv')"),
        ({"metric": "reward"}, "metric: 'reward' is not one of"),
        ({"resources": {"tpus": 1}}, "resources.tpus: unknown"),
        ({"search": {"space": {"learning_rate": {"type": "loguniform", "low": 0, "high": 1}},
                     "trials": 2}}, "search.space.learning_rate.low: must be > 0"),
        ({"search": {"space": {"gamma": {"type": "normal"}}, "trials": 2}},
         "search.space.gamma.type: 'normal' is not one of"),
        ({"colour": "red"}, "colour: unknown field"),
        ({"resources": {"cpus": 64}}, "resources.cpus: 64 per trial, but this machine has 2"),
        ({"report_every_timesteps": 100}, "report_every_timesteps: 100 is shorter than"),
        ({"grid": {"eval.curve_every_timesteps": [0]}},
         "metric: curve_score needs the learning curve"),
    ],
)  # fmt: skip
def test_bad_sweep_file_is_one_line_naming_the_field(tmp_path, capsys, monkeypatch, sweep, message):
    monkeypatch.setenv("WSP_CORES", "2")
    cfg = _files(tmp_path, sweep)
    out = tmp_path / "out"
    assert main(["sweep", "--config", str(cfg), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and str(cfg) in err, err
    assert not out.exists()


def test_shipped_sweep_files_load():
    from wsp_env.core.config import configs_root

    files = sorted((configs_root() / "sweeps").glob("*.yaml"))
    assert files
    for f in files:
        load_sweep_config(f)


def test_attaches_to_a_running_cluster_with_the_same_file(tmp_path, monkeypatch):
    """``--address``: a Ray head started apart (``ray start --head``, as on a cluster) runs a
    sweep and a split evaluation; the evaluation equals the one-process one."""
    import socket
    from pathlib import Path

    with socket.socket() as s:  # a free port
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    import ray as ray_module

    ray_module.shutdown()  # attach from a process with no Ray of its own (the shared one)
    ray = str(Path(sys.executable).with_name("ray"))
    env = {**os.environ, "RAY_AUTH_MODE": "disabled"}
    start = [ray, "start", "--head", f"--port={port}", "--num-cpus=2",
             "--include-dashboard=false"]  # fmt: skip
    subprocess.run(start, env=env, check=True, capture_output=True, timeout=120)
    try:
        monkeypatch.setenv("RAY_AUTH_MODE", "disabled")
        cfg = _files(tmp_path, {"seeds": [0], "report_every_timesteps": 256})
        address = f"127.0.0.1:{port}"
        assert main(["sweep", "--config", str(cfg), "--out", str(tmp_path / "out"),
                     "--address", address]) == 0  # fmt: skip
        r = json.loads((tmp_path / "out" / "results.json").read_text())
        assert r["address"] == address and r["trials"][0]["status"] == "finished"
        argv = ["benchmark", "--policy", "classical", "--tier", "wheels", "--runs", "2",
                "--no-progress"]  # fmt: skip
        assert main([*argv, "--address", address, "--json", str(tmp_path / "a.json")]) == 0
        assert main([*argv, "--json", str(tmp_path / "b.json")]) == 0
        assert json.loads((tmp_path / "a.json").read_text()) == json.loads(
            (tmp_path / "b.json").read_text()
        )
    finally:
        subprocess.run([ray, "stop", "--force"], env=env, capture_output=True, timeout=120)

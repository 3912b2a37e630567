"""Evaluation split across workers through Ray (``--workers``): the payload is the
one-process payload, run for run, for the built-in controllers, a learned policy rebuilt from
its file in the workers, and recorded traces; bad worker arguments are one line."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

pytest.importorskip("ray")

from wsp_env.cli import main
from wsp_env.evaluation.distributed import chunks

# one module at a time uses Ray on this machine (conftest.ray_exclusive)
pytestmark = pytest.mark.usefixtures("ray_exclusive")


def test_chunks_cover_in_order():
    for n in (1, 5, 12, 13):
        for w in (1, 2, 3, 8):
            parts = chunks(n, w)
            assert [i for p in parts for i in p] == list(range(n)) and len(parts) <= w


def _run(tmp_path, name, argv):
    out = tmp_path / f"{name}.json"
    assert main([*argv, "--json", str(out), "--no-progress"]) == 0
    return json.loads(out.read_text())


def test_benchmark_over_two_workers_equals_one_process(tmp_path, local_ray):
    argv = ["benchmark", "--policy", "classical", "--policy", "ppo_bc_uic_z1",
            "--tier", "wheels+accel", "--runs", "6"]  # fmt: skip
    one = _run(tmp_path, "one", argv)
    two = _run(tmp_path, "two", [*argv, "--workers", "2"])
    assert one == two
    assert len(one["run_results"]["ppo_bc_uic_z1"]) == 6


def test_evaluate_over_two_workers_equals_one_process_with_its_report(tmp_path, local_ray):
    argv = ["evaluate", "--policy", "classical", "--policy", "none", "--suite", "quick"]
    one = _run(tmp_path, "one", [*argv, "--report", str(tmp_path / "r1")])
    two = _run(tmp_path, "two", [*argv, "--workers", "2", "--report", str(tmp_path / "r2")])
    one.pop("report"), two.pop("report")
    assert one == two
    # the same traces recorded (each scenario's first seed): the same plots
    assert sorted(p.name for p in (tmp_path / "r1").iterdir()) == sorted(
        p.name for p in (tmp_path / "r2").iterdir()
    )
    assert (tmp_path / "r1" / "report.md").read_text() == (
        tmp_path / "r2" / "report.md"
    ).read_text()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--workers", "0"], "--workers: must be 1-4096, got 0"),
        (["--address", "127.0.0.1:1"], "--address 127.0.0.1:1: could not start or reach Ray"),
    ],
)
def test_bad_worker_arguments_are_one_line(tmp_path, capsys, argv, message):
    out = tmp_path / "x.json"
    code = main(["evaluate", "--policy", "none", "--suite", "quick", *argv, "--json", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and message in err and len(err.splitlines()) == 1
    assert not out.exists()


def test_a_local_session_starts_its_own_ray_beside_another(local_ray):
    """``ray_session`` without an address starts a new local Ray with its own CPU count, even
    where another runs on the machine and ``RAY_ADDRESS`` names it. Ray would otherwise attach
    to it and refuse the count ("When connecting to an existing cluster, num_cpus and num_gpus
    must not be provided"), as it does to a head started apart with ``ray start`` (checked by
    hand: the same message): the suite's sweep bad-input case failed so on 2026-12-08 while
    ``test_sweep``'s attach test, on another worker, had its head up."""
    address = local_ray.get_runtime_context().gcs_address
    code = (
        "from wsp_env.evaluation.distributed import ray_session\n"
        "with ray_session(None, 1) as ray:\n"
        "    print(ray.cluster_resources().get('CPU'))\n"
    )
    env = {**os.environ, "RAY_ADDRESS": address}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=300, check=False)  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "1.0"

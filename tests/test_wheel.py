"""A non-editable install works: a wheel built from the project carries every config (the
classical WSP's thresholds, suites, vehicles, training configs, the anti-skid device's), the
shipped policies and the trace format, and every `wsp-env` command runs from it, outside the
source tree.

Two levels: the wheel's contents (seconds), and the wheel installed by pip into a fresh virtual
environment without extras, every subcommand run once, then ``[rl,export]`` added to that
environment as a user adds them later, the learning commands run and every shipped policy
evaluated (marked ``wheel``: minutes; ``make test`` runs it, ``pytest -m "not wheel"`` leaves it
out). One environment, not two: the second install's kernels would only compile again.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest
from test_train import train_config

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("wsp_env", "baselines", "agents", "configs", "docs", "pyproject.toml", "README.md")
SHIPPED = sorted(p.stem for p in (ROOT / "agents" / "pretrained").glob("*.zip"))


def _shipped_by_vehicle() -> dict[str, list[str]]:
    """The shipped policies by the vehicle each was trained for (its model file's metadata)."""
    from wsp_env.policy import model_metadata

    out: dict[str, list[str]] = {}
    for name in SHIPPED:
        meta = model_metadata(ROOT / "agents" / "pretrained" / f"{name}.zip")
        out.setdefault(meta.get("vehicle") or "uic_z1", []).append(name)
    return out


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    skip = shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc", "*.egg-info")
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, src / name, ignore=skip)
        else:
            shutil.copy(ROOT / name, src / name)
    dist = tmp / "dist"
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(dist), str(src)],
        check=True, capture_output=True,
    )  # fmt: skip
    (wheel,) = dist.glob("wsp_env-*.whl")
    return wheel


def test_wheel_carries_configs_and_shipped_policies(built):
    wheel = built
    names = set(zipfile.ZipFile(wheel).namelist())
    for required in ("wsp_env/configs/wsp/classical.yaml", "wsp_env/configs/scenarios/heldout.yaml",
                     "wsp_env/configs/vehicles/uic_z1.yaml", "wsp_env/configs/rails.yaml",
                     "wsp_env/baselines/classical.py"):  # fmt: skip
        assert required in names, required
    for folder in ("train", "antiskid", "vehicles", "scenarios", "wsp"):
        for cfg in (ROOT / "configs" / folder).glob("*.yaml"):
            assert f"wsp_env/configs/{folder}/{cfg.name}" in names, cfg
    assert {n for n in names if n.startswith("wsp_env/configs/train/")}
    for shipped in (ROOT / "agents" / "pretrained").glob("*"):
        assert f"wsp_env/agents/pretrained/{shipped.name}" in names, shipped.name
    # `wsp-env calibrate --help` names docs/trace_format.md: it is installed there, inside the
    # package (wsp_env/docs/, copied from docs/ at build time), and nothing else of docs/ is
    docs = {n for n in names if n.startswith("wsp_env/docs/")}
    assert docs == {"wsp_env/docs/trace_format.md"}
    text = zipfile.ZipFile(wheel).read("wsp_env/docs/trace_format.md")
    assert text == (ROOT / "docs" / "trace_format.md").read_bytes()


# ---- fresh installs ---------------------------------------------------------------------------

# the installed commands see nothing of this checkout or of the test's own environment
CLEAN = {k: v for k, v in os.environ.items()
         if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PYTHONSTARTUP")}  # fmt: skip
TIMINGS: dict[str, float] = {}


def _sh(cmd: list[str], cwd: Path, what: str) -> subprocess.CompletedProcess:
    t0 = time.perf_counter()
    done = subprocess.run(cmd, cwd=cwd, env=CLEAN, capture_output=True, text=True, check=False)
    TIMINGS[f"{what} #{len(TIMINGS) + 1}"] = time.perf_counter() - t0
    return done


def _fresh_venv(tmp: Path, wheel: Path, name: str) -> Path:
    """A new virtual environment with the wheel installed by pip, no extras (dependencies
    resolved as a user's install resolves them)."""
    venv = tmp / name
    done = _sh([sys.executable, "-m", "venv", str(venv)], tmp, f"{name}: venv")
    assert done.returncode == 0, done.stderr[-2000:]
    _pip(venv, tmp, str(wheel))
    return venv


def _pip(venv: Path, tmp: Path, *args: str) -> None:
    done = _sh([str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet", *args], tmp,
               f"{venv.name}: pip install {Path(args[0]).name}")  # fmt: skip
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]


def _add_extras(venv: Path, tmp: Path, wheel: Path, extras: str) -> None:
    """The extras added to an install, as a user adds them later: the CPU build of torch first,
    as the Makefile installs it (a plain `torch` requirement would fetch a CUDA build)."""
    _pip(venv, tmp, "torch==2.13.0")
    _pip(venv, tmp, f"{wheel}{extras}")


# one short stop on soap: the evaluation path from the installed copy, with a suite file of the
# user's (the shipped suites are installed too: `validate` reads them)
SMALL_SUITE = """name: small
description: one short stop on soap
seeds: [0]
cases:
  - {name: soap, rail: soap, mu_contaminated: 0.08, pattern: uniform, speeds_kmh: [60]}
"""


class Installed:
    def __init__(self, venv: Path, work: Path) -> None:
        self.venv, self.work = venv, work
        work.mkdir()
        (work / "small.yaml").write_text(SMALL_SUITE)

    def run(self, *args: str) -> subprocess.CompletedProcess:
        exe = str(self.venv / "bin" / "wsp-env")
        return _sh([exe, *args], self.work, f"{self.venv.name}: {args[0]}")

    def ok(self, *args: str) -> subprocess.CompletedProcess:
        done = self.run(*args)
        assert done.returncode == 0, f"{args}: {done.stderr[-3000:]}"
        return done

    def refused(self, *args: str) -> str:
        """The one-line error of a command that needs an extra this install lacks."""
        done = self.run(*args)
        err = done.stderr.strip()
        assert done.returncode == 2 and len(err.splitlines()) == 1, f"{args}: {done.stderr}"
        assert "Traceback" not in err and "ModuleNotFoundError" not in err, err
        return err

    def read(self, name: str) -> dict:
        return json.loads((self.work / name).read_text())


@pytest.fixture(scope="module")
def venvs(built, tmp_path_factory):
    """Where the fresh install goes (removed afterwards: with the extras about 1.5 GB)."""
    wheel = built
    tmp = tmp_path_factory.mktemp("venvs")
    yield tmp, wheel
    t0 = time.perf_counter()
    shutil.rmtree(tmp, ignore_errors=True)
    TIMINGS["rmtree"] = time.perf_counter() - t0
    if TIMINGS:
        sys.stderr.write("\nfresh-venv wheel test timings [s]: " + ", ".join(
            f"{k} {v:.1f}" for k, v in TIMINGS.items()) + "\n")  # fmt: skip


@pytest.mark.wheel
def test_every_command_runs_from_a_fresh_install_then_learning_with_rl_and_export_added(venvs):
    tmp, wheel = venvs
    site = Installed(_fresh_venv(tmp, wheel, "plain"), tmp / "plain_work")
    py = str(site.venv / "bin" / "python")
    where = subprocess.run([py, "-c", "import wsp_env; print(wsp_env.__file__)"], env=CLEAN,
                           cwd=site.work, capture_output=True, text=True, check=True)  # fmt: skip
    pkg = Path(where.stdout.strip()).parent
    assert pkg.is_relative_to(site.venv), pkg  # the installed copy, not this checkout

    site.ok("simulate", "--speed-kmh", "80", "--json", "sim.json", "--trace", "trace")
    assert site.read("sim.json")["stopping_distance_m"] > 0
    assert (site.work / "trace.csv").exists() and (site.work / "trace.meta.json").exists()
    site.ok("evaluate", "--suite", "small.yaml", "--policy", "classical", "--no-progress",
            "--json", "eval.json")  # fmt: skip
    assert {r["policy"] for r in site.read("eval.json")["runs"]} == {"classical"}
    site.ok("calibrate", "trace.csv", "--json", "cal.json")
    assert "errors_before" in site.read("cal.json")
    # the trace format calibrate's help names is installed with the package
    assert "docs/trace_format.md" in site.ok("calibrate", "--help").stdout
    assert (pkg / "docs" / "trace_format.md").read_bytes() == (
        ROOT / "docs" / "trace_format.md"
    ).read_bytes()
    site.ok("bench", "--quick", "--json", "bench.json")
    assert site.read("bench.json")
    site.ok("rig", "--speed-kmh", "60", "--json", "rig.json")
    assert site.read("rig.json")["policy"] == "classical"
    site.ok("traction", "--json", "traction.json")
    assert site.read("traction.json")["distance_m"] > 0
    site.ok("validate", "--json", "validate.json")  # exit 1 would be a failed fidelity check
    assert site.read("validate.json")["passed"] is True

    # without the rl and export extras: one line saying which extra to install
    for cmd in (["simulate", "--policy", SHIPPED[0]],
                ["evaluate", "--suite", "quick", "--policy", SHIPPED[0]]):  # fmt: skip
        err = site.refused(*cmd)
        assert f"{SHIPPED[0]}: learned policies need the rl extra" in err, err
        assert "pip install 'wsp-env[rl]'" in err, err
    cfg = train_config(tmp, n_timesteps=256)
    err = site.refused("train", "--config", str(cfg), "--out", "run", "--no-progress")
    assert "training needs the rl extra: pip install 'wsp-env[rl]'" in err, err
    assert not (site.work / "run").exists()
    err = site.refused("export-policy", SHIPPED[0], "--onnx", "p.onnx")
    assert "pip install 'wsp-env[rl,export]'" in err, err
    err = site.refused("bench", "--train", "--quick")
    assert "bench --train needs the rl extra: pip install 'wsp-env[rl]'" in err, err
    # without the sweep extra (Ray, Optuna): the same one line, the sweep files installed
    err = site.refused("sweep", "--config", "x.yaml", "--out", "sw")
    assert "sweep needs the rl and sweep extras: pip install 'wsp-env[rl,sweep]'" in err, err
    err = site.refused("evaluate", "--suite", "quick", "--policy", "none", "--workers", "2")
    assert "--workers/--address need the sweep extra" in err, err
    assert sorted(p.name for p in (pkg / "configs" / "sweeps").glob("*.yaml")) == sorted(
        p.name for p in (ROOT / "configs" / "sweeps").glob("*.yaml")
    )

    # [rl,export] added to the same install: the learning commands run, and every shipped
    # policy loads from the installed package and stops on the evaluation path
    _add_extras(site.venv, tmp, wheel, "[rl,export]")
    by_vehicle = _shipped_by_vehicle()
    uic = by_vehicle["uic_z1"][0]  # simulate's default vehicle
    site.ok("simulate", "--policy", uic, "--speed-kmh", "80", "--json", "sim.json")
    assert site.read("sim.json")["policy"] == uic
    for vehicle, names in by_vehicle.items():  # each on the vehicle it was trained for
        policies = [a for p in ["classical", *names] for a in ("--policy", p)]
        site.ok("evaluate", "--vehicle", vehicle, "--suite", "small.yaml", *policies,
                "--no-progress", "--json", f"eval_{vehicle}.json")  # fmt: skip
        runs = site.read(f"eval_{vehicle}.json")["runs"]
        assert {r["policy"] for r in runs} == {"classical", *names}
        assert all(r["stopped"] for r in runs)
    cfg = train_config(tmp, n_timesteps=256, checkpoint_every_timesteps=256)
    site.ok("train", "--config", str(cfg), "--out", "run", "--no-progress", "--json", "train.json")
    result = site.read("train.json")
    assert result["total_timesteps"] == 256 and result["finished"]
    assert (site.work / "run" / "model.zip").exists()
    site.ok("export-policy", SHIPPED[0], "--onnx", "p.onnx", "--json", "export.json")
    assert (site.work / "p.onnx").stat().st_size > 0
    assert site.read("export.json")["latency_median_us"] > 0

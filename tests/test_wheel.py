"""A non-editable install works: a wheel built from the project carries every config (the
classical WSP's thresholds, suites, vehicles, training configs) and the shipped policies, and
`wsp-env evaluate` runs from it, outside the source tree."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("wsp_env", "baselines", "agents", "configs", "pyproject.toml", "README.md")


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
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
    site = tmp / "site"
    with zipfile.ZipFile(wheel) as z:  # a pure-Python wheel unpacked is its installed layout
        z.extractall(site)
    return tmp, site, wheel


def _run(tmp: Path, site: Path, code: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(site)}
    return subprocess.run(
        [sys.executable, "-c", code], cwd=tmp, env=env, capture_output=True, text=True
    )


def test_wheel_carries_configs_and_shipped_policies(installed):
    _, _, wheel = installed
    names = set(zipfile.ZipFile(wheel).namelist())
    for required in ("wsp_env/configs/wsp/classical.yaml", "wsp_env/configs/scenarios/heldout.yaml",
                     "wsp_env/configs/vehicles/uic_z1.yaml", "wsp_env/configs/rails.yaml",
                     "wsp_env/baselines/classical.py"):  # fmt: skip
        assert required in names, required
    assert {n for n in names if n.startswith("wsp_env/configs/train/")}
    for shipped in (ROOT / "agents" / "pretrained").glob("*"):
        assert f"wsp_env/agents/pretrained/{shipped.name}" in names, shipped.name


def test_evaluate_runs_from_the_wheel(installed):
    tmp, site, _ = installed
    policies = ["classical"] + [p.stem for p in (ROOT / "agents" / "pretrained").glob("*.zip")]
    args = ["evaluate", "--suite", "quick", "--json", str(tmp / "e.json"), "--no-progress"]
    for p in policies:
        args += ["--policy", p]
    code = (
        "import sys, wsp_env; from wsp_env.cli import main; "
        f"assert wsp_env.__file__.startswith({str(site)!r}), wsp_env.__file__; "
        f"sys.exit(main({args!r}))"
    )
    done = _run(tmp, site, code)
    assert done.returncode == 0, done.stderr[-2000:]
    runs = json.loads((tmp / "e.json").read_text())["runs"]
    assert {r["policy"] for r in runs} >= {"classical"} and all(r["stopped"] for r in runs)

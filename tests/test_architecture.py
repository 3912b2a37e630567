"""The import contracts (``scripts/check_imports.py``, ``pyproject.toml``) hold on the tree and
catch a deliberate breach: an upward import, a cycle, a private name across modules."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))

import check_imports  # noqa: E402


def _copy(tmp_path: Path) -> Path:
    root = tmp_path / "repo"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "pretrained", "data")
    for sub in ("wsp_env", "baselines", "agents", "scripts", "tests"):
        shutil.copytree(ROOT / sub, root / sub, ignore=ignore)
    shutil.copy(ROOT / "pyproject.toml", root / "pyproject.toml")
    return root


def _append(path: Path, line: str) -> None:
    path.write_text(path.read_text(encoding="utf-8") + f"\n{line}\n", encoding="utf-8")


def test_the_tree_keeps_every_contract() -> None:
    assert check_imports.lint_imports(ROOT) == 0
    assert check_imports.private_imports(ROOT) == []


@pytest.mark.parametrize(
    ("module", "line"),
    [
        ("wsp_env/physics/brake.py", "import wsp_env.core.config  # upward"),
        ("wsp_env/core/braking.py", "import wsp_env.evaluation.runner  # the core imports a job"),
        ("wsp_env/training/train.py", "import wsp_env.cli  # a job imports the CLI"),
        ("wsp_env/core/config.py", "import wsp_env.core.braking  # a cycle inside core"),
        ("wsp_env/rig/traction.py", "import wsp_env.calibration.traces  # sibling jobs"),
    ],
)
def test_a_deliberate_breach_fails(tmp_path: Path, module: str, line: str) -> None:
    root = _copy(tmp_path)
    _append(root / module, line)
    assert check_imports.lint_imports(root) != 0


def test_a_private_name_across_modules_fails(tmp_path: Path) -> None:
    root = _copy(tmp_path)
    _append(root / "wsp_env/evaluation/runner.py", "from wsp_env.core.braking import _config")
    _append(root / "scripts/benchmark_tables.py", "import wsp_env.files as f\nf._UMASK")
    _append(root / "wsp_env/rig/traction.py", "from ..core import braking as b\nb._config")
    _append(root / "scripts/learned_tables.py", "import wsp_env.files\nwsp_env.files._UMASK")
    _append(root / "tests/test_env.py", "import wsp_env.files as g\ngetattr(g, '_UMASK')")
    found = check_imports.private_imports(root)
    assert any("runner.py" in f and "_config" in f for f in found)
    assert any("benchmark_tables.py" in f and "f._UMASK" in f for f in found)
    assert any("traction.py" in f and "b._config" in f for f in found)
    assert any("learned_tables.py" in f and "wsp_env.files._UMASK" in f for f in found)
    assert any("test_env.py" in f and "getattr(g, '_UMASK')" in f for f in found)

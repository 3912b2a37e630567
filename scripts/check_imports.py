"""Check the package's import contracts (``pyproject.toml``, ``[tool.importlinter]``) and that
no private name crosses a module boundary. Run by ``make test``; exits non-zero on a breach.

    .venv/bin/python scripts/check_imports.py [--root DIR]

import-linter builds its graph from the package's folder, but ``baselines/`` and ``agents/``
install inside the package (``wsp_env.baselines``, ``wsp_env.agents``) from the top level, so
the package is first laid out as a wheel installs it, in a temp folder, and ``lint-imports``
runs there. The private-name rule: no ``from M import _name`` and no ``M._name`` where ``M`` is
a module of the package, a script or a test module (``tests/`` helpers included).
"""

from __future__ import annotations

import argparse
import ast
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("wsp_env", "baselines", "agents", "scripts", "tests")


def stage(root: Path, into: Path) -> Path:
    """The package as it installs: ``wsp_env/`` with ``baselines/`` and ``agents/`` inside."""
    pkg = into / "wsp_env"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copytree(root / "wsp_env", pkg, ignore=ignore)
    for sub in ("baselines", "agents"):
        shutil.copytree(root / sub, pkg / sub, ignore=ignore)
    return pkg


def lint_imports(root: Path) -> int:
    """``lint-imports`` on the staged package with the contracts of ``root/pyproject.toml``."""
    with tempfile.TemporaryDirectory(prefix="wsp-imports-") as tmp:
        stage(root, Path(tmp))
        shutil.copy(root / "pyproject.toml", Path(tmp) / "pyproject.toml")
        env = {**os.environ, "PYTHONPATH": tmp}
        exe = Path(sys.executable).with_name("lint-imports")
        cmd = [str(exe), "pyproject.toml", "--no-cache"]
        return subprocess.run(cmd, cwd=tmp, env=env, check=False).returncode


def _local_modules(root: Path) -> set[str]:
    """Names a private import may come from: the package's modules, scripts and test modules."""
    names = {"wsp_env"}
    for sub in ("scripts", "tests"):
        names |= {p.stem for p in (root / sub).glob("*.py")}
    return names


def private_imports(root: Path) -> list[str]:
    """``file:line: what`` for every private name imported or read across modules."""
    local = _local_modules(root)

    def ours(module: str) -> bool:
        return module.split(".")[0] in local

    found = []
    for sub in SOURCES:
        for path in sorted((root / sub).rglob("*.py")):
            rel = path.relative_to(root)
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(rel))
            aliases: dict[str, str] = {}
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and node.module and ours(node.module):
                    for a in node.names:
                        if a.name.startswith("_") and not a.name.startswith("__"):
                            found.append(f"{rel}:{node.lineno}: from {node.module} import {a.name}")
                        aliases[a.asname or a.name] = f"{node.module}.{a.name}"
                elif isinstance(node, ast.Import):
                    for a in node.names:
                        if ours(a.name):
                            aliases[a.asname or a.name.split(".")[0]] = a.name
            for node in ast.walk(tree):
                if (
                    isinstance(node, ast.Attribute)
                    and node.attr.startswith("_")
                    and not node.attr.startswith("__")
                    and isinstance(node.value, ast.Name)
                    and node.value.id in aliases
                ):
                    found.append(f"{rel}:{node.lineno}: {node.value.id}.{node.attr}")
    return found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=ROOT, help="repository root")
    args = parser.parse_args(argv)
    status = lint_imports(args.root)
    private = private_imports(args.root)
    for line in private:
        print(f"private name across modules: {line}")
    if private:
        status = status or 1
    return status


if __name__ == "__main__":
    sys.exit(main())

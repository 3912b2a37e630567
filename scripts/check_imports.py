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


def _module_of(root: Path, path: Path) -> str:
    """The dotted module a file is, as installed (``baselines/x.py`` is ``wsp_env.baselines.x``)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[0] in ("baselines", "agents"):
        parts.insert(0, "wsp_env")
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _absolute(root: Path, path: Path, node: ast.ImportFrom) -> str:
    """``node``'s module, a relative import resolved against the importing file."""
    if not node.level:
        return node.module or ""
    package = _module_of(root, path).split(".")
    if path.name != "__init__.py":
        package.pop()
    base = package[: len(package) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def _root_name(node: ast.expr) -> str | None:
    """The name an attribute chain starts from (``a`` of ``a.b.c``)."""
    while isinstance(node, ast.Attribute):
        node = node.value
    return node.id if isinstance(node, ast.Name) else None


NAMEDTUPLE_API = ("_fields", "_replace", "_asdict", "_make", "_field_defaults")


def _private(name: str) -> bool:
    """A leading underscore, except dunders and namedtuple's public API (``_fields``, ...)."""
    return name.startswith("_") and not name.startswith("__") and name not in NAMEDTUPLE_API


def private_imports(root: Path) -> list[str]:
    """``file:line: what`` for every private name imported or read across modules: ``from M
    import _x`` (relative imports too), and ``M._x`` / ``M.sub._x`` / ``getattr(M, "_x")`` where
    ``M`` is a module of the package, a script or a test module."""
    local = _local_modules(root)

    def ours(module: str) -> bool:
        return module.split(".")[0] in local

    found = []
    for sub in SOURCES:
        for path in sorted((root / sub).rglob("*.py")):
            rel = path.relative_to(root)
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(rel))
            modules: set[str] = set()  # local names bound to modules (or names) of ours
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom):
                    module = _absolute(root, path, node)
                    if not ours(module):
                        continue
                    for a in node.names:
                        if _private(a.name):
                            found.append(f"{rel}:{node.lineno}: from {module} import {a.name}")
                        modules.add(a.asname or a.name)
                elif isinstance(node, ast.Import):
                    for a in node.names:
                        if ours(a.name):
                            modules.add(a.asname or a.name.split(".")[0])
            for node in ast.walk(tree):
                if isinstance(node, ast.Attribute) and _private(node.attr):
                    if _root_name(node.value) in modules:
                        found.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
                elif (
                    isinstance(node, ast.Call)
                    and isinstance(node.func, ast.Name)
                    and node.func.id == "getattr"
                    and len(node.args) >= 2
                    and isinstance(node.args[1], ast.Constant)
                    and isinstance(node.args[1].value, str)
                    and _private(node.args[1].value)
                    and _root_name(node.args[0]) in modules
                ):
                    found.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
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

"""The compiled-kernel cache guard (``physics/jit_cache.py``) hashes every file that holds a
kernel: a kernel file it missed could run stale compiled physics after an edit."""

from __future__ import annotations

from pathlib import Path

from wsp_env.physics import jit_cache

ROOT = Path(__file__).resolve().parents[1]


def test_every_kernel_file_is_hashed() -> None:
    hashed = {p.resolve() for p in jit_cache.kernel_files()}
    with_kernels = {
        p.resolve()
        for folder in ("wsp_env", "baselines", "agents")
        for p in (ROOT / folder).rglob("*.py")
        if "@njit" in p.read_text(encoding="utf-8") and p.name != "jit_cache.py"
    }
    assert with_kernels <= hashed, sorted(str(p) for p in with_kernels - hashed)


def test_an_edit_to_a_kernel_file_changes_the_digest(tmp_path, monkeypatch) -> None:
    pkg = tmp_path / "wsp_env"
    for rel in jit_cache.KERNEL_SOURCES:
        target = (pkg / rel) if not rel.startswith("baselines/") else (tmp_path / rel)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(f"# {rel}\n")
    monkeypatch.setattr(jit_cache, "PACKAGE", pkg)
    before = jit_cache.digest()
    (pkg / "core" / "kernel.py").write_text("# edited\n")
    assert jit_cache.digest() != before

"""Keep numba's on-disk cache consistent across the package's kernel modules.

numba's ``cache=True`` keys each cached function on its *own* source file only. Our kernels
call each other across files (the environment step inlines the physics step, which inlines the
creep laws), so editing ``adhesion.py`` would leave a stale compiled ``integrator`` or
``core/kernel`` in the cache — silently running old physics. Before any kernel module is
imported, this hashes every kernel source file and, when the hash differs from the one recorded
next to the cache, deletes the package's cached kernels so that they recompile.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1]  # wsp_env/
KERNEL_SOURCES = (  # every file with compiled kernels, relative to the package
    "physics/layout.py",
    "physics/adhesion.py",
    "physics/brake.py",
    "physics/rail.py",
    "physics/integrator.py",
    "core/kernel.py",
    "evaluation/reference.py",
    "rig/roller_rig.py",
    "calibration/recurrence.py",
    "calibration/independent.py",
    "baselines/classical.py",  # installed as wsp_env.baselines; ../baselines in a checkout
    "baselines/oracle.py",
)
STAMP_NAME = "wsp_env_kernels.sha256"


def kernel_files() -> list[Path]:
    """The kernel source files as this install lays them out (a checkout keeps ``baselines/``
    beside the package); a missing one is an error: it would escape the hash."""
    found = []
    for rel in KERNEL_SOURCES:
        path = next((p for p in (PACKAGE / rel, PACKAGE.parent / rel) if p.exists()), None)
        if path is None:
            raise FileNotFoundError(f"jit_cache: kernel source {rel} not found under {PACKAGE}")
        found.append(path)
    return found


def digest() -> str:
    """One hash over every kernel source file (its path and bytes)."""
    h = hashlib.sha256()
    for rel, path in zip(KERNEL_SOURCES, kernel_files(), strict=True):
        h.update(rel.encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def refresh() -> None:
    """Drop cached kernels compiled from other versions of the kernel sources."""
    current = digest()
    stamp = PACKAGE / "__pycache__" / STAMP_NAME
    with contextlib.suppress(OSError):
        if stamp.exists() and stamp.read_text() == current:
            return
    roots = [PACKAGE, PACKAGE.parent / "baselines"]
    for root in roots:
        for cached in (*root.rglob("*.nbi"), *root.rglob("*.nbc")):
            with contextlib.suppress(OSError):
                cached.unlink()
    with contextlib.suppress(OSError):
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(current)


def compiled() -> bool:
    """Whether the environment step is in the on-disk cache (False on a first run, and after a
    kernel source changed): the first stepping command then compiles for a while."""
    where = [PACKAGE / "core" / "__pycache__"]
    if os.environ.get("NUMBA_CACHE_DIR"):  # numba caches there instead (a read-only install)
        where = [Path(os.environ["NUMBA_CACHE_DIR"])]
    return any(any(w.rglob("kernel.env_step_serial-*.nbi")) for w in where if w.is_dir())

"""Writing outputs safely: atomic files and folders, and JSON that a strict reader accepts.

Every output of ``wsp-env`` goes through here, so that an interrupted or failed run never leaves
a half-written file: content is written to a temp file beside the target, flushed and
``fsync``-ed, then moved into place with ``os.replace`` (atomic on one file system). The bottom
layer of the package: it imports nothing from ``wsp_env``.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

Writer = Callable[[IO[Any]], None]


def json_default(obj: Any) -> Any:
    """``json.dump``'s ``default``: numpy scalars and arrays, and paths, as plain JSON."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def finite(obj: Any) -> Any:
    """NaN and infinities become null (JSON has no NaN; a reader must not meet a bare NaN)."""
    if isinstance(obj, float | np.floating):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite(v) for v in obj]
    return obj


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _current_umask()


def write_temp(target: Path, write: Writer, binary: bool = False) -> Path:
    """Write through ``write`` into a temp file next to ``target``; return the temp path.

    The temp file is removed if ``write`` fails.
    """
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    tmp_path = Path(tmp)
    os.chmod(tmp_path, 0o666 & ~_UMASK)  # mkstemp makes 0600; outputs get the usual mode
    try:
        fh_ctx = os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8", newline="")
        with fh_ctx as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise
    return tmp_path


def write_atomically(target: Path, write: Writer, binary: bool = False) -> Path:
    """Write ``target`` via a temp file in the same directory and ``os.replace``."""
    tmp = write_temp(target, write, binary)
    try:
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return target


def write_all_atomically(targets: Sequence[tuple[Path, Writer]]) -> list[Path]:
    """Write several files all or none: every temp file first, then the moves into place; a
    failure removes the temp files and whatever of ``targets`` this call already moved."""
    temps: list[Path] = []
    moved: list[Path] = []
    try:
        for target, write in targets:
            temps.append(write_temp(target, write))
        for tmp, (target, _) in zip(temps, targets, strict=True):
            os.replace(tmp, target)
            moved.append(target)
    except BaseException:
        for path in [*temps[len(moved) :], *moved]:
            with contextlib.suppress(OSError):
                path.unlink()
        raise
    return moved


def replace_dir_atomically(target: str | Path, build: Callable[[Path], None]) -> Path:
    """Build a report folder through ``build(tmp)`` in a temp folder beside ``target``, then
    swap it in: an interrupted run never leaves a half-written folder. An existing ``target``
    is replaced only if it is empty or holds a ``report.md`` (an earlier report)."""
    target = Path(target)
    if target.exists() and any(target.iterdir()) and not (target / "report.md").exists():
        raise ValueError(f"{target}: exists and is not a wsp-env report folder; not overwriting")
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    try:
        build(tmp)
        if target.exists():
            shutil.rmtree(target)
        os.replace(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return target


def write_json(path: str | Path, payload: dict[str, Any]) -> Path:
    """Write ``payload`` as JSON through a temp file (never half-written); NaN becomes null."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(finite(payload), indent=2, allow_nan=False, default=json_default) + "\n"
    return write_atomically(target, lambda fh: fh.write(text))

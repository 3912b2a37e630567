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
    """The process's umask now (read when a file is made: a caller may change it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_temp(target: Path, write: Writer, binary: bool = False) -> Path:
    """Write through ``write`` into a temp file next to ``target``; return the temp path.

    The temp file is removed if ``write`` fails.
    """
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    tmp_path = Path(tmp)
    os.chmod(tmp_path, 0o666 & ~_current_umask())  # mkstemp makes 0600; outputs get the usual mode
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
        os.chmod(tmp, 0o777 & ~_current_umask())  # mkdtemp makes 0700; a report gets the usual mode
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


# ---- a command's outputs: checked before the work, written together at the end -------------

_TEMP_PREFIX = ".wsp-"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove(path: Path) -> None:
    with contextlib.suppress(OSError):
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()


def _starting(folder: Path, prefix: str) -> list[Path]:
    """The entries of ``folder`` whose names start with ``prefix`` (no glob: names may hold
    ``[`` or ``*``)."""
    try:
        return sorted(folder / n for n in os.listdir(folder) if n.startswith(prefix))
    except OSError:
        return []


def remove_stale_temps(folder: Path, name: str) -> None:
    """Remove what an earlier, killed command left of its outputs for ``name`` in ``folder``
    (its temp names carry its process id; a living process's are left alone; a report's build
    folder is the temp name with one more leading dot)."""
    if not folder.is_dir():
        return
    for n in os.listdir(folder):
        bare = n.lstrip(".")
        if not n.startswith((_TEMP_PREFIX, "." + _TEMP_PREFIX)) or f".{name}" not in bare:
            continue
        pid = bare[len(_TEMP_PREFIX) - 1 :].split("-", 1)[0]
        if pid.isdigit() and int(pid) != os.getpid() and not _alive(int(pid)):
            _remove(folder / n)


class OutputError(ValueError):
    """An output path that cannot be written (one line naming the option and the path)."""


SUFFIXES = {"file": ("",), "dir": ("",), "stem": (".csv", ".meta.json")}


class Outputs:
    """A command's output files and folders: each path is checked when reserved, before any
    work; producers write to the temp sibling :meth:`reserve` returns (same folder, so the
    final move is an atomic rename); :meth:`commit` moves them all into place at the end, and
    on failure :meth:`abort` removes them, with any folder created for them: all of a
    command's outputs or none. An output may be several files named by suffixing one path
    (``kind="stem"``: ``STEM.csv`` and ``STEM.meta.json``; ``suffixes`` for others): each is
    checked, and each moves with it. Paths the command reads (:meth:`inputs`) are never
    outputs. Use as a context manager: leaving it by an exception aborts.
    """

    def __init__(self) -> None:
        # (final, temp, kind, suffixes): temp + suffix becomes final + suffix at the commit
        self._items: list[tuple[Path, Path, str, tuple[str, ...]]] = []
        self._created: list[Path] = []
        self._inputs: set[Path] = set()
        self._token = f"{os.getpid()}-{os.urandom(3).hex()}"

    def __enter__(self) -> Outputs:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is not None:
            self.abort()

    def inputs(self, *paths: str | Path | None) -> None:
        """Files the command reads: an output on one of them is refused."""
        self._inputs.update(Path(p).resolve() for p in paths if p is not None)

    def _finals(self) -> list[tuple[Path, str]]:
        return [(f.with_name(f.name + x), k) for f, _, k, xs in self._items for x in xs]

    def reserve(
        self, path: str | Path, option: str, kind: str = "file", suffixes: tuple[str, ...] = ()
    ) -> Path:
        """Check that ``path`` (given by ``option``) can be written as a ``kind`` (``file``;
        ``stem``: files named by suffixing it; ``dir``: a report folder) with ``suffixes`` (the
        further files a producer names after it); return the temp path to write instead."""
        text = str(path)
        final = Path(path)
        if not text or final.name in ("", ".", "..") or text.endswith(os.sep):
            raise OutputError(f"{option}: {text!r} is not a file name")
        suffixes = SUFFIXES[kind] + tuple(suffixes)
        taken = self._finals()
        for x in suffixes:
            self._check_target(final.with_name(final.name + x), option, kind, taken)
        self._make_parent(final.parent, option)
        remove_stale_temps(final.parent, final.name)
        end = "~" if kind == "stem" else ""  # a trace writer must not read a suffix into it
        temp = final.with_name(f"{_TEMP_PREFIX}{self._token}.{final.name}{end}")
        self._items.append((final, temp, kind, suffixes))
        return temp

    def _check_target(self, target: Path, option: str, kind: str, taken: list) -> None:
        resolved = target.resolve()
        if resolved in self._inputs:
            raise OutputError(f"{option}: {target} is one of this command's inputs")
        for other, other_kind in taken:
            o = other.resolve()
            if o == resolved:
                raise OutputError(f"{option}: {target} is also another output of this command")
            if (other_kind == "dir" and o in resolved.parents) or (
                kind == "dir" and resolved in o.parents
            ):
                raise OutputError(f"{option}: {target} and {other} are inside one another")
        if kind == "dir":
            if target.is_symlink() or (target.exists() and not target.is_dir()):
                raise OutputError(f"{option}: {target} exists and is not a folder")
            if target.is_dir() and any(target.iterdir()) and not (target / "report.md").exists():
                raise OutputError(
                    f"{option}: {target} exists and is not a wsp-env report folder; not overwriting"
                )
        elif target.is_dir():
            raise OutputError(f"{option}: {target} is a folder")
        elif target.exists() and not target.is_file():
            raise OutputError(f"{option}: {target} exists and is not a regular file")

    def _make_parent(self, folder: Path, option: str) -> None:
        missing = []
        probe = folder
        while not probe.exists():
            missing.append(probe)
            if probe.parent == probe:
                break
            probe = probe.parent
        if not probe.is_dir():
            raise OutputError(f"{option}: {probe} is not a folder")
        if not os.access(probe, os.W_OK | os.X_OK):
            raise OutputError(f"{option}: cannot write in {probe} (permission denied)")
        for p in reversed(missing):
            try:
                p.mkdir()
            except OSError as err:
                raise OutputError(f"{option}: cannot create {p} ({err.strerror})") from None
            self._created.append(p)

    def explain(self, message: str) -> str:
        """``message`` with every temp path of this command's outputs named as the output."""
        for final, temp, _, _ in self._items:
            message = message.replace(str(temp), str(final)).replace(temp.name, final.name)
        return message

    def commit(self) -> list[Path]:
        """Move every written output into place (folders first, so that an output is never
        inside a folder being replaced); return the final paths. Every target is checked again
        first; an old report folder is set aside and removed only after its successor is in."""
        moves = []
        for final, temp, kind, suffixes in self._items:
            for x in suffixes:
                written = temp.with_name(temp.name + x)
                if written.exists():
                    moves.append((kind, written, final.with_name(final.name + x)))
        moves.sort(key=lambda m: m[0] != "dir")
        for kind, _, target in moves:
            if kind != "dir" and target.is_dir():
                raise OutputError(f"{target}: became a folder while the command ran")
        done: list[Path] = []
        for kind, written, target in moves:
            old = None
            if kind == "dir" and (target.exists() or target.is_symlink()):
                old = target.with_name(f"{_TEMP_PREFIX}{self._token}.old.{target.name}")
                os.replace(target, old)
            os.replace(written, target)
            if old is not None:
                _remove(old)
            done.append(target)
        self._items.clear()
        self._created.clear()
        return done

    def abort(self) -> None:
        """Remove every temp output and every folder created for them."""
        for _, temp, _, _ in self._items:
            for written in _starting(temp.parent, temp.name):
                _remove(written)
            for stray in _starting(temp.parent, "." + temp.name):  # a report's build folder
                _remove(stray)
        for folder in reversed(self._created):
            with contextlib.suppress(OSError):
                folder.rmdir()  # only if empty
        self._created.clear()  # the items stay: ``explain`` still names them

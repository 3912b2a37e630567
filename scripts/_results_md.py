"""Results pages under ``docs/results/``: a measuring script writes its table(s) there itself,
with the exact command and the machine above them, so the docs quote tables nobody pasted.

    from _results_md import write_results, tee_stdout
    write_results(path, "Title", body_markdown, wall_s)
    with tee_stdout() as printed:  # a script whose figures are printed lines
        ...
    write_results(path, "Title", fenced(printed.getvalue()), wall_s)

Imported by the scripts in this folder (run as ``.venv/bin/python scripts/NAME.py``, which puts
``scripts/`` on the path); not a script itself.
"""

from __future__ import annotations

import contextlib
import io
import os
import platform
import shlex
import shutil
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TextIO

from wsp_env.files import write_atomically


def command_line() -> str:
    """The command as typed from the repository root: interpreter, script, arguments."""
    exe = Path(sys.executable)
    try:
        interpreter = str(exe.relative_to(Path.cwd()))
    except ValueError:
        interpreter = "python"
    script = Path(sys.argv[0])
    if script.is_absolute():
        try:
            script = script.relative_to(Path.cwd())
        except ValueError:
            pass
    return shlex.join([interpreter, str(script), *sys.argv[1:]])


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine() -> str:
    """E.g. ``2-core x86_64 (AMD EPYC), no GPU, Python 3.11.9``."""
    gpu = "NVIDIA GPU present" if shutil.which("nvidia-smi") else "no GPU"
    return (
        f"{os.cpu_count()}-core {platform.machine()} ({_cpu_model()}), {gpu}, "
        f"Python {platform.python_version()}"
    )


def write_results(path: str | Path, title: str, body: str, wall_s: float | None = None) -> Path:
    """Write ``body`` (Markdown) under a header naming the command and the machine."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    took = f"; {wall_s:.0f} s wall" if wall_s is not None else ""
    text = (
        f"# {title}\n\n"
        f"Produced by `{command_line()}` on a {machine()}{took}. Written by the script: "
        "regenerate with the same command rather than editing by hand.\n\n"
        f"{body.rstrip()}\n"
    )
    write_atomically(target, lambda fh: fh.write(text))
    return target


class _Tee(io.StringIO):
    """Keeps what is written and passes it on to ``out``."""

    def __init__(self, out: TextIO) -> None:
        super().__init__()
        self._out = out

    def write(self, text: str) -> int:
        self._out.write(text)
        return super().write(text)

    def flush(self) -> None:
        self._out.flush()


@contextlib.contextmanager
def tee_stdout() -> Iterator[io.StringIO]:
    """Print as usual and keep a copy of everything printed."""
    tee = _Tee(sys.stdout)
    with contextlib.redirect_stdout(tee):
        yield tee


def printed_results(markdown: str | Path | None, title: str, run: Callable[[], None]) -> None:
    """Run ``run`` printing as usual; with ``markdown``, write what it printed there too."""
    t0 = time.perf_counter()
    with tee_stdout() as printed:
        run()
    if markdown is not None:
        write_results(markdown, title, fenced(printed.getvalue()), time.perf_counter() - t0)
        print(f"wrote {markdown}")


def fenced(text: str) -> str:
    """Printed output as a Markdown code block."""
    return f"```text\n{text.rstrip()}\n```\n"

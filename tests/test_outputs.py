"""A command's outputs all or none (``files.Outputs``, the CLI): checked before the work,
written together at the end, removed on failure, and what a killed run left is cleared."""

from __future__ import annotations

import os
import stat
import subprocess
import sys

import pytest

from wsp_env.cli import main
from wsp_env.files import OutputError, Outputs, replace_dir_atomically


def test_commit_moves_every_output_into_place(tmp_path):
    with Outputs() as out:
        json_tmp = out.reserve(tmp_path / "new" / "r.json", "--json")
        stem_tmp = out.reserve(tmp_path / "t", "--trace", "stem")
        json_tmp.write_text("{}")
        stem_tmp.with_name(stem_tmp.name + ".csv").write_text("a\n")
        stem_tmp.with_name(stem_tmp.name + ".meta.json").write_text("{}")
        assert not (tmp_path / "new" / "r.json").exists()  # nothing final before the commit
        out.commit()
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == [
        "r.json", "t.csv", "t.meta.json"
    ]  # fmt: skip


def test_a_failure_leaves_nothing_not_even_a_folder(tmp_path):
    with pytest.raises(RuntimeError), Outputs() as out:
        out.reserve(tmp_path / "a" / "b" / "r.json", "--json").write_text("{}")
        report = out.reserve(tmp_path / "rep", "--report", "dir")
        replace_dir_atomically(report, lambda d: (d / "report.md").write_text("x"))
        raise RuntimeError("the work failed")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("path", "kind", "message"),
    [
        ("folder", "file", "is a folder"),
        ("mine", "dir", "not a wsp-env report folder"),
        ("plain.txt", "dir", "is not a folder"),
        ("plain.txt/x.json", "file", "is not a folder"),
    ],
)
def test_a_path_that_cannot_be_written_is_refused_before_the_work(tmp_path, path, kind, message):
    (tmp_path / "folder").mkdir()
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine")
    (tmp_path / "plain.txt").write_text("x")
    with pytest.raises(OutputError, match=message), Outputs() as out:
        out.reserve(tmp_path / path, "--opt", kind)


def test_the_same_path_twice_is_refused(tmp_path):
    with pytest.raises(OutputError, match="also another output"), Outputs() as out:
        out.reserve(tmp_path / "x.png", "--json")
        out.reserve(tmp_path / "x.png", "--plot")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_a_folder_without_write_permission_is_refused(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(stat.S_IRUSR | stat.S_IXUSR)
    with pytest.raises(OutputError, match="permission denied"), Outputs() as out:
        out.reserve(locked / "x.json", "--json")


def test_a_killed_runs_temps_are_cleared_by_the_next_run(tmp_path):
    """kill -9 runs no cleanup: the next run of the same output removes a dead process's
    temps (their names carry its pid); a living process's are left alone."""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()  # fmt: skip
    stale = tmp_path / f".wsp-{dead}-abcdef.r.json"
    stale.write_text("half")
    stale_dir = tmp_path / f".wsp-{dead}-abcdef.rep"
    stale_dir.mkdir()
    alive = tmp_path / f".wsp-{os.getppid()}-abcdef.r.json"
    alive.write_text("someone else's")
    with Outputs() as out:
        out.reserve(tmp_path / "r.json", "--json").write_text("{}")
        out.reserve(tmp_path / "rep", "--report", "dir").mkdir()
        out.commit()
    assert not stale.exists() and not stale_dir.exists() and alive.exists()


def test_the_cli_writes_no_output_when_one_producer_fails(tmp_path, monkeypatch, capsys):
    import wsp_env.evaluation.plotting as plotting

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(plotting, "plot_run", broken)
    out = tmp_path / "o"
    argv = ["simulate", "--speed-kmh", "30", "--json", str(out / "s.json"),
            "--trace", str(out / "t"), "--plot", str(out / "p.png")]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[-1] == "wsp-env simulate: error: disk full"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("mask", [0o022, 0o077])
def test_report_folders_get_the_usual_mode(tmp_path, mask):
    """The umask at the time of writing, not at import (mkdtemp alone would make 0700)."""
    old = os.umask(mask)
    try:
        replace_dir_atomically(tmp_path / "rep", lambda d: (d / "report.md").write_text("x"))
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "rep").stat().st_mode) == 0o777 & ~mask


def test_a_producers_error_names_the_output_not_its_temp(tmp_path, monkeypatch, capsys):
    import wsp_env.evaluation.plotting as plotting

    def full(record, path, title=""):
        raise OSError(f"[Errno 28] No space left on device: '{path}'")

    monkeypatch.setattr(plotting, "plot_run", full)
    assert main(["simulate", "--speed-kmh", "30", "--plot", str(tmp_path / "p.png")]) == 2
    err = capsys.readouterr().err.splitlines()[-1]
    assert str(tmp_path / "p.png") in err and ".wsp-" not in err


def test_a_killed_reports_build_folder_is_cleared_too(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()  # fmt: skip
    build = tmp_path / f"..wsp-{dead}-abcdef.rep.k2j3h4"  # replace_dir_atomically's own temp
    build.mkdir()
    (build / "report.md").write_text("half")
    with Outputs() as out:
        out.reserve(tmp_path / "rep", "--report", "dir")
        out.commit()
    assert not build.exists()


def test_a_closed_stdout_ends_quietly(tmp_path):
    """``wsp-env simulate | head -1``: the reader went away; no traceback, SIGPIPE's status."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "wsp_env.cli", "simulate", "--speed-kmh", "20"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path,
    )  # fmt: skip
    proc.stdout.close()  # before the command prints anything
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 141 and b"Traceback" not in err


def _simulate(tmp_path, *args):
    return main(["simulate", "--speed-kmh", "20", *(str(a) for a in args)])


def test_odd_names_are_written_and_leave_no_temp(tmp_path):
    """Names with glob characters (``[``, ``*``) are names like any other."""
    assert _simulate(tmp_path, "--json", tmp_path / "o[1]*.json") == 0
    assert [p.name for p in tmp_path.iterdir()] == ["o[1]*.json"]


def test_a_trace_stem_with_a_csv_in_its_name(tmp_path):
    assert _simulate(tmp_path, "--trace", tmp_path / "a.csv.csv") == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv.csv", "a.csv.meta.json"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--trace", "run", "--json", "run.csv"), "also another output"),
        (("--trace", "x", "--plot", "x.meta.json"), "also another output"),
        (("--json", "sub/"), "is not a file name"),
        (("--json", "/dev/null"), "not a regular file"),
    ],
)
def test_outputs_that_would_overwrite_each_other_are_refused(tmp_path, capsys, args, message):
    os.chdir(tmp_path)
    assert _simulate(tmp_path, *args) == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_an_output_inside_a_report_folder_is_refused(tmp_path, capsys):
    rep = tmp_path / "rep"
    code = main(["evaluate", "--policy", "none", "--suite", "quick", "--no-progress",
                 "--report", str(rep), "--json", str(rep / "r.json")])  # fmt: skip
    assert code == 2 and "inside one another" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_an_output_on_an_input_is_refused(tmp_path, capsys):
    assert _simulate(tmp_path, "--trace", tmp_path / "t") == 0
    before = (tmp_path / "t.meta.json").read_bytes()
    code = main(["calibrate", str(tmp_path / "t.csv"), "--json", str(tmp_path / "t.meta.json")])
    assert code == 2 and "one of this command's inputs" in capsys.readouterr().err
    assert (tmp_path / "t.meta.json").read_bytes() == before


def test_the_exported_table_names_its_options_file(tmp_path):
    assert _simulate(tmp_path, "--trace", tmp_path / "t", "--policy", "classical") == 0
    assert main(["calibrate", str(tmp_path / "t.csv"), "--export", str(tmp_path / "cal.yaml")]) == 0
    header = (tmp_path / "cal.yaml").read_text().splitlines()[:3]
    assert any("Scenario options: cal.yaml.options.yaml" in line for line in header)
    assert (tmp_path / "cal.yaml.options.yaml").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_report_is_replaced_whole(tmp_path):
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "report.md").write_text("old")
    (rep / "old_plot.png").write_text("old")
    with Outputs() as out:
        replace_dir_atomically(
            out.reserve(rep, "--report", "dir"), lambda d: (d / "report.md").write_text("new")
        )
        out.commit()
    assert [p.name for p in rep.iterdir()] == ["report.md"]
    assert (rep / "report.md").read_text() == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["rep"]


def test_ctrl_c_writes_nothing_and_says_so(tmp_path, monkeypatch, capsys):
    import wsp_env.evaluation.plotting as plotting

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(plotting, "plot_run", interrupted)
    assert _simulate(tmp_path, "--json", tmp_path / "s.json", "--plot", tmp_path / "p.png") == 130
    assert "interrupted; nothing written" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []

"""Bad inputs across every ``wsp-env`` subcommand and the environment's API, each judged as a
user would: clean (one line naming the option, field or file; exit status 2 or the documented
exception; nothing left behind), traceback, hang, wrong result (accepted), not one line, or
leftover files.

    .venv/bin/python scripts/bad_inputs.py [--markdown docs/results/bad_inputs.md]

Cases run in-process (``wsp_env.cli.main``) in a fresh copy of the fixture folder each: a file
added, removed or rewritten there by a failed command counts as left behind. A 60 s alarm
catches a hang in Python code; it cannot interrupt a compiled loop, so the inputs that made one
(a 1e-12 s substep, a 1e9 s traction test) must be refused before any compiled code runs, and
are. The environment's cases call ``gymnasium.make`` / ``reset`` / ``step`` directly and must
raise ``ValueError`` or ``RuntimeError`` with one line that starts with or names the field.
``tests/test_bad_inputs.py`` runs every case and requires every one clean.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import signal
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

HANG_S = 60


@dataclass(frozen=True)
class Case:
    """``argv`` for the CLI (or ``call`` for the API); ``names``: what the one line must name."""

    group: str
    what: str
    argv: tuple[str, ...] = ()
    call: Callable[[], Any] | None = None
    names: str = ""


def _fixtures(d: Path) -> None:
    """Files the cases point at, in the case folder ``d``."""
    (d / "bad_vehicle.yaml").write_text("id: bad\nname: Bad\nmass_kg: -5\n")
    import yaml

    from wsp_env.core.config import configs_root

    rails = yaml.safe_load((configs_root() / "rails.yaml").read_text())
    rails["soap"]["mu_contaminated_range"] = [5.0, 6.0]  # the shipped table, one level out
    (d / "bad_rails.yaml").write_text(yaml.safe_dump(rails))
    (d / "broken.yaml").write_text("a: [1, 2\n")
    (d / "empty.yaml").write_text("")
    (d / "garbage.zip").write_bytes(os.urandom(512))
    (d / "not_a_report").mkdir()
    (d / "not_a_report" / "keep.txt").write_text("mine")
    (d / "a_folder").mkdir()
    suite = {"name": "s", "description": "", "seeds": [0], "cases": []}
    case = {"name": "c", "rail": "soap", "speeds_kmh": [60]}
    for name, cases in {
        "dup_suite": [case, case],
        "fast_suite": [{**case, "speeds_kmh": [1e9]}],
        "nan_suite": [{**case, "speeds_kmh": [".nan"]}],
        "mu_suite": [{**case, "mu_contaminated": 7.0}],
    }.items():
        body = json.dumps({**suite, "cases": cases}).replace('".nan"', ".nan")
        (d / f"{name}.yaml").write_text(body)  # JSON is YAML
    (d / "bad_rig.yaml").write_text("roller_radius_m: -1\n")
    (d / "bad_antiskid.yaml").write_text("nonsense_field: 3\n")
    (d / "bad_train.yaml").write_text("algo: nosuch\nn_timesteps: 100\n")
    (d / "neg_train.yaml").write_text("algo: ppo\nn_timesteps: -5\n")
    (d / "seeds_dup.yaml").write_text(json.dumps({**suite, "seeds": [0, 0], "cases": [case]}))
    (d / "seeds_neg.yaml").write_text(json.dumps({**suite, "seeds": [-1], "cases": [case]}))
    (d / "afile").write_text("not a folder")
    (d / "train_out").mkdir()
    (d / "train_out" / "x.txt").write_text("not a run")
    (d / "empty_run").mkdir()
    base = "train: ppo_uic_z1\nn_timesteps: 1000\n"
    (d / "sweep_nobase.yaml").write_text("train: nosuch\n")
    (d / "sweep_epochs.yaml").write_text(base + "grid: {n_epochs: [0]}\n")
    (d / "sweep_both.yaml").write_text(
        base + "grid: {n_epochs: [3]}\nsearch: {space: {gamma: {type: uniform, low: 0.9, "
        "high: 0.99}}, trials: 2}\n"
    )
    (d / "sweep_cpus.yaml").write_text(base + "resources: {cpus: 512}\n")
    (d / "sweep_ok.yaml").write_text(base)
    _traces(d)


def _traces(d: Path) -> None:
    """A good simulated trace and spoilt copies of it."""
    from wsp_env.cli import main

    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", "--speed-kmh", "40", "--trace", str(d / "good")]) == 0
    lines = (d / "good.csv").read_text().splitlines()
    meta = (d / "good.meta.json").read_text()

    def spoil(name: str, rows: list[str], meta_text: str | None = meta) -> None:
        (d / f"{name}.csv").write_text("\n".join(rows) + "\n")
        if meta_text is not None:
            (d / f"{name}.meta.json").write_text(meta_text)

    header = lines[0].split(",")
    spoil("no_meta", lines, None)
    spoil("bad_meta", lines, "{not json")
    spoil("no_format", lines, meta.replace('"wsp-trace/1"', '"other"'))
    spoil("one_row", lines[:2])
    spoil("empty", [])
    cut = header.index("v_axle_2_kmh")
    spoil("missing_column", [",".join(r.split(",")[:cut] + r.split(",")[cut + 1 :]) for r in lines])
    rows = [r.split(",") for r in lines]
    rows[5][1] = "fast"
    spoil("non_numeric", [",".join(r) for r in rows])
    rows = [r.split(",") for r in lines]
    rows[6][0] = rows[4][0]
    spoil("time_back", [",".join(r) for r in rows])
    rows = [r.split(",") for r in lines]
    rows[8][1] = str(float(rows[8][1]) + 60.0)
    spoil("jump", [",".join(r) for r in rows])
    spoil("fields", [lines[0], *(r + ",1" for r in lines[1:])])
    spoil("huge_field", [lines[0], "1," + "9" * 200_000, *lines[2:]])
    import json

    m = json.loads(meta)
    m["vehicle"]["bogie_pivot_height_m"] = 650  # optional geometry in mm
    spoil("pivot_mm", lines, json.dumps(m))
    m = json.loads(meta)
    m["vehicle"]["bogie_cog_height_m"] = 0.5  # a bogie height without its mass
    spoil("bogie_no_mass", lines, json.dumps(m))
    m = json.loads(meta)
    m["vehicle"]["axle_offsets_m"] = [1000.0 * x for x in m["vehicle"]["axle_offsets_m"]]
    spoil("offsets_mm", lines, json.dumps(m))  # the axles' places in millimetres


def _env(**kwargs: Any) -> Any:
    import gymnasium as gym

    import wsp_env  # noqa: F401

    return gym.make("WSPBraking-v0", **kwargs)


def _reset(options: dict[str, Any], **kwargs: Any) -> Callable[[], Any]:
    return lambda: _env(**kwargs).reset(seed=0, options=options)


def _step(action: Any) -> Callable[[], Any]:
    def call() -> Any:
        env = _env()
        env.reset(seed=0)
        return env.step(action)

    return call


def _step_before_reset() -> Any:
    from wsp_env.envs import WSPBrakingEnv

    return WSPBrakingEnv().step(np.ones(4, dtype=np.float32))


NAN = "nan"
TRAIN = "ppo_uic_z1"  # a built-in training config, by name


def cases() -> list[Case]:
    """Every case (CLI paths are relative to the case folder, where ``_fixtures`` put them)."""
    c: list[Case] = []

    def cli(group: str, what: str, names: str, *argv: str) -> None:
        c.append(Case(group, what, (group, *argv), names=names))

    s = "simulate"
    cli(s, "negative seed", "--seed", "--seed", "-1")
    cli(s, "seed not a number", "--seed", "--seed", "abc")
    cli(s, "negative speed", "--speed-kmh", "--speed-kmh", "-5")
    cli(s, "speed 1e9", "--speed-kmh", "--speed-kmh", "1e9")
    cli(s, "speed NaN", "--speed-kmh", "--speed-kmh", NAN)
    cli(s, "speed a word", "--speed-kmh", "--speed-kmh", "fast")
    cli(s, "substep 1e-12 s", "--dt-s", "--dt-s", "1e-12")
    cli(s, "substep 0", "--dt-s", "--dt-s", "0")
    cli(s, "substep not dividing the period", "--dt-s", "--dt-s", "0.003")
    cli(s, "level 1e9", "--mu-contaminated", "--mu-contaminated", "1e9")
    cli(s, "level 0", "--mu-contaminated", "--mu-contaminated", "0")
    cli(s, "level NaN", "--mu-contaminated", "--mu-contaminated", NAN)
    cli(s, "negative level", "--mu-contaminated", "--mu-contaminated", "-0.1")
    cli(s, "unknown pattern", "--pattern", "--pattern", "zigzag")
    cli(s, "unknown rail", "gravel", "--rail", "gravel")
    cli(s, "unknown vehicle", "nosuch", "--vehicle", "nosuch")
    cli(s, "vehicle YAML with a bad field", "bad_vehicle.yaml", "--vehicle", "bad_vehicle.yaml")
    cli(s, "missing rails table", "missing.yaml", "--rails-config", "missing.yaml")
    cli(s, "rails table level 5", "mu_contaminated_range", "--rails-config", "bad_rails.yaml")
    cli(s, "broken YAML rails table", "broken.yaml", "--rails-config", "broken.yaml")
    cli(s, "unknown policy", "nosuch", "--policy", "nosuch")
    cli(s, "policy file not a model", "garbage.zip", "--policy", "garbage.zip")
    cli(s, "WSP config for no WSP", "--wsp-config", "--wsp-config", "x.yaml")
    cli(s, "missing WSP config", "missing.yaml", "--policy", "classical", "--wsp-config",
        "missing.yaml")  # fmt: skip
    cli(s, "JSON onto a folder", "--json", "--json", "a_folder")
    cli(s, "JSON where no folder can be", "--json", "--json", "/proc/nope/x.json")
    cli(s, "JSON and plot the same file", "--plot", "--json", "o.png", "--plot", "o.png")
    cli(s, "plot where no folder can be", "--plot", "--plot", "/proc/nope/x.png")
    cli(s, "trace where no folder can be", "--trace", "--trace", "/proc/nope/t")
    cli(s, "logger period 0", "--sample-period-s", "--sample-period-s", "0")
    cli(s, "logger period 1e-9", "--sample-period-s", "--sample-period-s", "1e-9")
    cli(s, "negative noise", "--speed-noise-kmh", "--speed-noise-kmh", "-1")
    cli(s, "noise 1e9", "--pressure-noise-bar", "--pressure-noise-bar", "1e9")
    cli(s, "unknown demand", "--demand", "--demand", "brake")
    cli(s, "speed 0.5 km/h", "--speed-kmh", "--speed-kmh", "0.5")
    cli(s, "policy is a folder", "--policy", "--policy", "a_folder")
    cli(s, "JSON with a trailing slash", "--json", "--json", "sub/")
    cli(s, "JSON onto a device", "--json", "--json", "/dev/null")
    cli(s, "JSON onto the trace's CSV", "also another output", "--trace", "run", "--json",
        "run.csv")  # fmt: skip
    cli(s, "plot onto the trace's metadata", "also another output", "--trace", "x", "--plot",
        "x.meta.json")  # fmt: skip
    cli(s, "unknown option", "--bogus", "--bogus", "1")
    cli(s, "gradient 200 per mille", "--gradient-permille", "--gradient-permille", "200")
    cli(s, "gradient NaN", "--gradient-permille", "--gradient-permille", NAN)
    cli(s, "bias without an accelerometer", "no accelerometer", "--accelerometer-bias-mps2",
        "0.1")  # fmt: skip
    cli(s, "bias 5 m/s^2", "--accelerometer-bias-mps2", "--accelerometer",
        "--accelerometer-bias-mps2", "5")  # fmt: skip
    cli(s, "negative wheel-speed noise", "--wheel-speed-noise-kmh", "--wheel-speed-noise-kmh",
        "-1")  # fmt: skip
    cli(s, "policy module:callable missing", "cannot import", "--policy", "no_such_mod:make")

    b = "benchmark"
    cli(b, "no policy", "--policy", "--tier", "wheels")
    cli(b, "unknown tier", "--tier", "--policy", "classical", "--tier", "eyes")
    cli(b, "vehicle without an id", "--vehicle", "--policy", "classical", "--vehicle",
        "bad_vehicle.yaml")  # fmt: skip
    cli(b, "runs 0", "--runs", "--policy", "classical", "--runs", "0")
    cli(b, "runs 1000", "--runs", "--policy", "classical", "--runs", "1000")
    cli(b, "callable that is no policy", "without bind", "--policy", "json:JSONDecoder")
    cli(b, "JSON where no folder can be", "--json", "--policy", "none", "--runs", "1", "--json",
        "/proc/nope/x.json")  # fmt: skip

    e = "evaluate"
    cli(e, "no policy", "--policy", "--suite", "quick")
    cli(e, "unknown suite", "nosuch", "--policy", "none", "--suite", "nosuch")
    cli(e, "duplicate case names", "cases[1].name", "--policy", "none", "--suite",
        "dup_suite.yaml")  # fmt: skip
    cli(e, "suite speed 1e9", "speed", "--policy", "none", "--suite", "fast_suite.yaml")
    cli(e, "suite speed NaN", "speeds_kmh", "--policy", "none", "--suite", "nan_suite.yaml")
    cli(e, "suite level 7", "mu_contaminated", "--policy", "none", "--suite", "mu_suite.yaml")
    cli(e, "empty suite file", "empty.yaml", "--policy", "none", "--suite", "empty.yaml")
    cli(e, "broken YAML suite", "broken.yaml", "--policy", "none", "--suite", "broken.yaml")
    cli(e, "the same policy twice", "--policy", "--policy", "none", "--policy", "none")
    cli(e, "report over a folder of other files", "--report", "--policy", "none", "--report",
        "not_a_report")  # fmt: skip
    cli(e, "report onto a file", "--report", "--policy", "none", "--report", "dup_suite.yaml")
    cli(e, "unknown vehicle", "nosuch", "--policy", "none", "--vehicle", "nosuch")
    cli(e, "a seed twice", "seeds", "--policy", "none", "--suite", "seeds_dup.yaml")
    cli(e, "a negative seed", "seeds[0]", "--policy", "none", "--suite", "seeds_neg.yaml")
    cli(e, "JSON inside the report folder", "inside one another", "--policy", "none",
        "--report", "rep", "--json", "rep/r.json")  # fmt: skip
    cli(e, "WSP config without classical", "--wsp-config", "--policy", "none", "--wsp-config",
        "x.yaml")  # fmt: skip

    k = "calibrate"
    cli(k, "missing trace", "missing.csv", "missing.csv")
    cli(k, "no metadata", "no_meta.meta.json", "no_meta.csv")
    cli(k, "metadata not JSON", "bad_meta.meta.json", "bad_meta.csv")
    cli(k, "not wsp-trace/1", "format", "no_format.csv")
    cli(k, "one data row", "one_row.csv", "one_row.csv")
    cli(k, "empty file", "empty.csv", "empty.csv")
    cli(k, "a required column missing", "v_axle_2_kmh", "missing_column.csv")
    cli(k, "a word among numbers", "v_train_kmh", "non_numeric.csv")
    cli(k, "time going back", "time_s", "time_back.csv")
    cli(k, "a 60 km/h ground-speed jump", "v_train_kmh", "jump.csv")
    cli(k, "rows longer than the header", "fields.csv", "fields.csv")
    cli(k, "a 200 kB field", "huge_field.csv", "huge_field.csv")
    cli(k, "JSON onto its own input", "inputs", "good.csv", "--json", "good.meta.json")
    cli(k, "export where no folder can be", "--export", "good.csv", "--export",
        "/proc/nope/r.yaml")  # fmt: skip
    cli(k, "report over a folder of other files", "--report", "good.csv", "--report",
        "not_a_report")  # fmt: skip
    cli(k, "a pivot height in millimetres", "bogie_pivot_height_m", "pivot_mm.csv")
    cli(k, "a bogie height without its mass", "bogie_mass_kg", "bogie_no_mass.csv")
    cli(k, "the axles' places in millimetres", "axle_offsets_m", "offsets_mm.csv")

    b = "bench"
    cli(b, "zero repeats", "--repeats", "--repeats", "0")
    cli(b, "a thousand repeats", "--repeats", "--repeats", "1000")
    cli(b, "repeats a word", "--repeats", "--repeats", "x")

    w = "sweep"
    cli(w, "neither config nor resume", "--config", "--out", "sw")
    cli(w, "missing sweep file", "missing.yaml", "--config", "missing.yaml", "--out", "sw")
    cli(w, "unknown base config", "train", "--config", "sweep_nobase.yaml", "--out", "sw")
    cli(w, "grid value the trainer refuses", "grid (n_epochs=0)", "--config",
        "sweep_epochs.yaml", "--out", "sw")  # fmt: skip
    cli(w, "grid and search at once", "search", "--config", "sweep_both.yaml", "--out", "sw")
    cli(w, "more CPUs per trial than the machine", "resources.cpus", "--config",
        "sweep_cpus.yaml", "--out", "sw")  # fmt: skip
    cli(w, "occupied output folder", "train_out", "--config", "sweep_ok.yaml", "--out",
        "train_out")  # fmt: skip
    cli(w, "resume with nothing to resume", "empty_run", "--out", "empty_run", "--resume")
    cli(e, "workers 0", "--workers", "--policy", "none", "--workers", "0")
    cli(e, "a Ray address nobody answers", "--address", "--policy", "none", "--address",
        "127.0.0.1:1")  # fmt: skip
    cli("bench", "rollouts 0 with --train", "--rollouts", "--train", "--rollouts", "0")
    cli("bench", "--busy without --train", "--busy", "--busy", "1")

    t = "train"
    cli(t, "neither config nor resume", "--config")
    cli(t, "missing config", "missing.yaml", "--config", "missing.yaml", "--out", "run")
    cli(t, "unknown algorithm", "algo", "--config", "bad_train.yaml", "--out", "run")
    cli(t, "negative timesteps in the config", "n_timesteps", "--config", "neg_train.yaml",
        "--out", "run")  # fmt: skip
    cli(t, "resume from an empty folder", "empty_run", "--resume", "empty_run")
    cli(t, "config and resume", "--config", "--config", TRAIN, "--resume", "empty_run")
    cli(t, "negative seed", "--seed", "--config", TRAIN, "--out", "run", "--seed", "-1")
    cli(t, "zero total timesteps", "--total-timesteps", "--config", TRAIN, "--out", "run",
        "--total-timesteps", "0")  # fmt: skip
    cli(t, "out is a folder of other files", "train_out", "--config", TRAIN, "--out",
        "train_out")  # fmt: skip
    cli(t, "out is a file", "afile", "--config", TRAIN, "--out", "afile")
    cli(t, "JSON where no folder can be", "--json", "--config", TRAIN, "--out", "run",
        "--json", "/proc/nope/t.json")  # fmt: skip

    v = "validate"
    cli(v, "report over a folder of other files", "--report", "--report", "not_a_report")
    cli(v, "JSON where no folder can be", "--json", "--json", "/proc/nope/v.json")

    r = "rig"
    cli(r, "speed 1e9", "--speed-kmh", "--speed-kmh", "1e9")
    cli(r, "missing rig config", "missing.yaml", "--rig-config", "missing.yaml")
    cli(r, "rig config with a bad field", "bad_rig.yaml", "--rig-config", "bad_rig.yaml")
    cli(r, "negative roller noise", "--omega-noise-kmh", "--omega-noise-kmh", "-1")
    cli(r, "roller noise 1e300", "omega_noise_kmh", "--omega-noise-kmh", "1e300")
    cli(r, "negative seed", "--seed", "--seed", "-1")
    cli(r, "level 5", "--mu-contaminated", "--mu-contaminated", "5")
    cli(r, "unknown rail", "gravel", "--rail", "gravel")
    cli(r, "plot onto a folder", "--plot", "--plot", "a_folder")

    x = "traction"
    cli(x, "duration 1e9 s", "--duration-s", "--duration-s", "1e9")
    cli(x, "speed 1e9", "--speed-kmh", "--speed-kmh", "1e9")
    cli(x, "zero torque", "--torque-nm", "--torque-nm", "0")
    cli(x, "level 1e9", "--mu-contaminated", "--mu-contaminated", "1e9")
    cli(x, "missing anti-skid config", "missing.yaml", "--antiskid-config", "missing.yaml")
    cli(x, "anti-skid config with an unknown field", "bad_antiskid.yaml", "--antiskid-config",
        "bad_antiskid.yaml")  # fmt: skip
    cli(x, "unknown vehicle", "nosuch", "--vehicle", "nosuch")

    o = "export-policy"
    cli(o, "a rule, not a model", "classical", "classical", "--onnx", "p.onnx")
    cli(o, "missing model", "missing.zip", "missing.zip", "--onnx", "p.onnx")
    cli(o, "output not .onnx", "--onnx", "ppo_bc_uic_z1", "--onnx", "p.txt")
    cli(o, "output where no folder can be", "--onnx", "ppo_bc_uic_z1", "--onnx",
        "/proc/nope/p.onnx")  # fmt: skip

    n = "environment"
    api = [
        ("options.mu_contaminated NaN", "options.mu_contaminated:",
         _reset({"mu_contaminated": math.nan})),
        ("options.mu_contaminated -0.1", "options.mu_contaminated:",
         _reset({"mu_contaminated": -0.1})),
        ("options.mu_contaminated 5", "options.mu_contaminated:", _reset({"mu_contaminated": 5.0})),
        ("options.pattern misspelt", "options.pattern:", _reset({"pattern": "unifrom"})),
        ("options.axle_mu_factor negative", "options.axle_mu_factor[0]:",
         _reset({"axle_mu_factor": [-1, 1, 1, 1]})),
        ("options.axle_mu_factor 3 of 4 axles", "options.axle_mu_factor:",
         _reset({"axle_mu_factor": [1, 1, 1]})),
        ("options.gradient_permille 1e6", "options.gradient_permille:",
         _reset({"gradient_permille": 1e6})),
        ("options.speed_kmh above the maximum", "options.speed_kmh:", _reset({"speed_kmh": 900.0})),
        ("options.speed_kmh a word", "options.speed_kmh:", _reset({"speed_kmh": "fast"})),
        ("options.load_factor 0", "options.load_factor:", _reset({"load_factor": 0.0})),
        ("options.demand unknown", "options.demand:", _reset({"demand": "brake"})),
        ("options.rail unknown", "options.rail:", _reset({"rail": "gravel"})),
        ("an unknown option", "options.bogus:", _reset({"bogus": 1})),
        ("max_time_s -5", "max_time_s:", lambda: _env(max_time_s=-5.0)),
        ("substep_s 0", "substep_s:", lambda: _env(substep_s=0.0)),
        ("substep_s not dividing the period", "substep_s:", lambda: _env(substep_s=0.003)),
        ("action_mode unknown", "action_mode:", lambda: _env(action_mode="foo")),
        ("vehicle unknown", "nosuch", lambda: _env(vehicle="nosuch")),
        ("reward distance scale -1", "reward.distance_scale_m:",
         lambda: _env(reward={"distance_scale_m": -1.0})),
        ("scenario rail unknown", "scenario.rails.gravel:",
         lambda: _env(scenario={"rails": {"gravel": 1.0}})),
        ("step before reset", "step before reset", _step_before_reset),
        ("NaN action", "action:", _step(np.full(4, np.nan, dtype=np.float32))),
        ("action of the wrong shape", "action:", _step(np.ones(3, dtype=np.float32))),
        ("substep_s 1e-12", "substep_s:", lambda: _env(substep_s=1e-12)),
        ("max_time_s 1e9", "max_time_s:", lambda: _env(max_time_s=1e9)),
    ]  # fmt: skip
    c.extend(Case(n, what, call=call, names=names) for what, names, call in api)
    return c


@dataclass
class Outcome:
    case: Case
    verdict: str  # clean | traceback | hang | wrong result | not one line | leftover files
    detail: str
    seconds: float


class _HangError(Exception):
    pass


def _alarm(signum: int, frame: Any) -> None:
    raise _HangError


def _files(d: Path) -> dict[str, tuple[int, int]]:
    """Every path in ``d`` with its size and modification time (files) or (-1, -1)."""
    out = {}
    for p in d.rglob("*"):
        st = p.lstat()
        out[str(p.relative_to(d))] = (st.st_size, st.st_mtime_ns) if p.is_file() else (-1, -1)
    return out


def _changed(before: dict, after: dict) -> list[str]:
    """What a failed command left, removed or rewrote in its folder."""
    new = [f"+{p}" for p in after if p not in before]
    gone = [f"-{p}" for p in before if p not in after]
    rewritten = [f"~{p}" for p in after if p in before and after[p] != before[p]]
    return sorted(new + gone + rewritten)


def run_case(case: Case, fixtures: Path) -> Outcome:
    """One case in a copy of the fixture folder (as the working directory)."""
    import shutil

    from wsp_env.cli import main

    work = Path(tempfile.mkdtemp(prefix="wsp-bad-"))
    shutil.copytree(fixtures, work, dirs_exist_ok=True)
    before = _files(work)
    err, out = io.StringIO(), io.StringIO()
    cwd = os.getcwd()
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(HANG_S)
    t0 = time.perf_counter()
    try:
        os.chdir(work)
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            if case.call is not None:
                case.call()
                return _outcome(case, "wrong result", "accepted", t0)
            try:
                code = main(list(case.argv))
            except SystemExit as stop:
                code = stop.code if isinstance(stop.code, int) else 2
    except _HangError:
        return _outcome(case, "hang", f"still running after {HANG_S} s", t0)
    except (ValueError, RuntimeError) as exc:  # the API's documented errors
        if case.call is None:
            return _outcome(case, "traceback", traceback.format_exc(limit=1).strip(), t0)
        message = str(exc)
        if "\n" in message.strip() or case.names not in message:
            return _outcome(case, "not one line", message, t0)
        return _outcome(case, "clean", f"{type(exc).__name__}: {message}", t0)
    except BaseException:
        return _outcome(case, "traceback", traceback.format_exc(limit=2).strip(), t0)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
        os.chdir(cwd)
        left = _changed(before, _files(work))
        shutil.rmtree(work, ignore_errors=True)
    from wsp_env.cli import COMPILE_NOTICE  # a first run's notice is no error line

    lines = [ln for ln in err.getvalue().splitlines() if ln.strip() and ln != COMPILE_NOTICE]
    if code == 0:
        return _outcome(case, "wrong result", "exit 0", t0)
    if left:
        return _outcome(case, "leftover files", ", ".join(sorted(left)), t0)
    if len(lines) != 1 or "Traceback" in err.getvalue():
        return _outcome(case, "not one line", " / ".join(lines)[:300], t0)
    if code != 2 or case.names not in lines[0]:
        return _outcome(case, "not one line", f"exit {code}: {lines[0]}", t0)
    return _outcome(case, "clean", lines[0], t0)


def _outcome(case: Case, verdict: str, detail: str, t0: float) -> Outcome:
    return Outcome(case, verdict, detail, time.perf_counter() - t0)


def run_all(only: str | None = None) -> list[Outcome]:
    """Every case (or those of one group), with the fixtures made once."""
    fixtures = Path(tempfile.mkdtemp(prefix="wsp-fixtures-"))
    try:
        _fixtures(fixtures)
        return [run_case(c, fixtures) for c in cases() if only in (None, c.group)]
    finally:
        import shutil

        shutil.rmtree(fixtures, ignore_errors=True)


def table(outcomes: list[Outcome]) -> str:
    """Markdown: a count per group and verdict, then every case and what it gives now."""
    verdicts = ("clean", "traceback", "hang", "wrong result", "not one line", "leftover files")
    groups = list(dict.fromkeys(o.case.group for o in outcomes))
    rows = ["| input to | tried | " + " | ".join(verdicts) + " |", "|---|---" + "|---" * 6 + "|"]
    for g in [*groups, None]:
        mine = [o for o in outcomes if g is None or o.case.group == g]
        counts = [sum(o.verdict == v for o in mine) for v in verdicts]
        label = f"`{g}`" if g else "**all**"
        rows.append(f"| {label} | {len(mine)} | " + " | ".join(map(str, counts)) + " |")
    rows += ["", "| input to | case | verdict | what it gives |", "|---|---|---|---|"]
    for o in outcomes:
        detail = o.detail.replace("|", "\\|").replace("\n", " ")
        rows.append(f"| `{o.case.group}` | {o.case.what} | {o.verdict} | {detail} |")
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", type=Path, default=None, help="write the tables here (.md)")
    ap.add_argument("--group", default=None, help="only this group's cases (e.g. simulate)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    outcomes = run_all(args.group)
    text = table(outcomes)
    print(text)
    if args.markdown:
        from _results_md import write_results

        write_results(args.markdown, "Bad inputs", text, time.perf_counter() - t0)
    return 0 if all(o.verdict == "clean" for o in outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())

"""Every bad input of the harness (``scripts/bad_inputs.py``: every subcommand and the
environment's options) is clean: one line naming the option, field or file; exit status 2 or
the documented exception; no traceback, no hang, nothing accepted, nothing left behind."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))

import bad_inputs  # noqa: E402


def test_every_bad_input_is_clean() -> None:
    outcomes = bad_inputs.run_all()
    assert len(outcomes) >= 100
    groups = {o.case.group for o in outcomes}
    assert groups >= {"simulate", "evaluate", "calibrate", "bench", "train", "validate", "rig",
                      "traction", "export-policy", "environment", "sweep"}  # fmt: skip
    unclean = [f"{o.case.group}: {o.case.what}: {o.verdict}: {o.detail}" for o in outcomes
               if o.verdict != "clean"]  # fmt: skip
    assert unclean == []


def test_the_harness_tells_an_unclean_input_from_a_clean_one(monkeypatch) -> None:
    """The judge itself: an accepted input, a crash, a second line, a wrong field and a file
    left behind are each caught."""
    fixtures = ROOT / "configs"  # any folder: these cases need no fixture
    accepted = bad_inputs.Case("simulate", "a good run", ("simulate", "--speed-kmh", "20"))
    assert bad_inputs.run_case(accepted, fixtures).verdict == "wrong result"
    api_ok = bad_inputs.Case("environment", "accepted", call=lambda: None, names="x")
    assert bad_inputs.run_case(api_ok, fixtures).verdict == "wrong result"

    def boom() -> None:
        raise ZeroDivisionError("float division by zero")

    crash = bad_inputs.Case("environment", "crash", call=boom, names="x")
    assert bad_inputs.run_case(crash, fixtures).verdict == "traceback"

    import wsp_env.cli

    def two_lines(argv):
        print("wsp-env x: error: --json: bad", file=sys.stderr)
        print("and more", file=sys.stderr)
        return 2

    def leaves_a_file(argv):
        Path("half.json").write_text("{")
        print("wsp-env x: error: --json: bad", file=sys.stderr)
        return 2

    def rewrites_a_fixture(argv):
        Path("rails.yaml").write_text("spoilt")
        print("wsp-env x: error: --json: bad", file=sys.stderr)
        return 2

    case = bad_inputs.Case("simulate", "fake", ("simulate",), names="--json")
    for fake, verdict in ((two_lines, "not one line"), (leaves_a_file, "leftover files"),
                          (rewrites_a_fixture, "leftover files")):  # fmt: skip
        monkeypatch.setattr(wsp_env.cli, "main", fake)
        assert bad_inputs.run_case(case, fixtures).verdict == verdict, fake.__name__
    other = bad_inputs.Case("simulate", "fake", ("simulate",), names="--plot")

    def names_json(argv):
        print("wsp-env x: error: --json: bad", file=sys.stderr)
        return 2

    monkeypatch.setattr(wsp_env.cli, "main", names_json)
    assert bad_inputs.run_case(case, fixtures).verdict == "clean"
    assert bad_inputs.run_case(other, fixtures).verdict == "not one line"  # the wrong option

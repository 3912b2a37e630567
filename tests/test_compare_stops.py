"""scripts/compare_stops.py: two policies stop by stop (the per-stop comparison of
docs/training_log.md)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import compare_stops


def _write(path: Path, policy: str, returns: list[float], rails: list[str],
           tier: str = "wheels+accel") -> None:  # fmt: skip
    runs = [{"scenario": f"s{i}", "seed": i, "return": r, "conditions": {"rail": rail}}
            for i, (r, rail) in enumerate(zip(returns, rails, strict=True))]  # fmt: skip
    path.write_text(json.dumps({"vehicle": "uic_z1", "tier": tier, "run_results": {policy: runs}}))


def test_counts_the_stops_where_one_returns_less_and_the_median_by_rail(tmp_path, capsys):
    _write(tmp_path / "a.json", "a", [-1.0, -2.0, -3.0, -4.0], ["soap", "soap", "dry", "dry"])
    _write(tmp_path / "b.json", "b", [-1.5, -2.5, -2.0, -4.0], ["soap", "soap", "dry", "dry"])
    assert compare_stops.main([str(tmp_path / "a.json"), "a", str(tmp_path / "b.json"), "b"]) == 0
    out = capsys.readouterr().out
    assert "returns less on 50 %, more on 25 %" in out
    assert "soap           n   2  median   -50.0 m  mean    -50.0 m  less on 100 %" in out
    assert "dry            n   2  median   +50.0 m  mean    +50.0 m  less on   0 %" in out
    assert "largest" not in out  # the changes sum to nothing


def test_says_how_much_of_a_mean_change_a_few_stops_carry(tmp_path, capsys):
    """Seven stops 1 m worse, one 100 m better: the mean rises, its one gain carries more than
    all of it (the others lose); mirrored, the one loss carries the mean's fall."""
    rails = ["leaves"] + ["soap"] * 7
    _write(tmp_path / "a.json", "a", [-10.0] * 8, rails)
    _write(tmp_path / "b.json", "b", [-9.0] + [-10.01] * 7, rails)
    _write(tmp_path / "c.json", "c", [-11.0] + [-9.99] * 7, rails)
    assert compare_stops.main([str(tmp_path / "a.json"), "a", str(tmp_path / "b.json"), "b"]) == 0
    out = capsys.readouterr().out
    assert "returns less on 88 %, more on 12 %; median change -1.0 m, mean +11.6 m" in out
    assert "the largest gains (the 1 most: +100 m) carry 108 % of the summed change" in out
    assert compare_stops.main([str(tmp_path / "a.json"), "a", str(tmp_path / "c.json"), "c"]) == 0
    out = capsys.readouterr().out
    assert "the largest losses (the 5 most: -100, +1, " not in out
    assert "the largest losses (the 1 most: -100 m) carry 108 % of the summed change" in out


def test_refuses_different_stops_tiers_and_a_missing_policy(tmp_path):
    _write(tmp_path / "a.json", "a", [-1.0, -2.0], ["soap", "dry"])
    _write(tmp_path / "w.json", "w", [-1.0, -2.0], ["soap", "dry"], tier="wheels")
    assert compare_stops.main([str(tmp_path / "a.json"), "a", str(tmp_path / "w.json"), "w"]) == 2
    _write(tmp_path / "b.json", "b", [-1.0], ["soap"])
    assert compare_stops.main([str(tmp_path / "a.json"), "a", str(tmp_path / "b.json"), "b"]) == 2
    with pytest.raises(SystemExit, match="no runs of policy 'c'"):
        compare_stops.main([str(tmp_path / "a.json"), "c", str(tmp_path / "b.json"), "b"])

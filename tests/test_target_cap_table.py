"""scripts/target_cap_table.py: choose_rail_targets' rule over (target, creep cap) pairs."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import target_cap_table
from test_choose_rail_targets import bench, runs_of


def test_a_pair_per_rail_and_the_bound_over_pairs(tmp_path, capsys):
    """Two caps of the same target are two candidates: on leaves the 3 km/h target at cap 0.3
    returns more than at the default cap and is chosen; each stop's best pair after the fact
    scores at least the table's teacher."""
    a = bench(tmp_path / "a.json", {
        "slip_target_3kmh": runs_of([95.0, 95.0, 80.0, 80.0], [-4.6, -4.6, -3.0, -3.0]),
        "slip_target_4kmh": runs_of([96.0, 96.0, 90.0, 90.0], [-4.4, -4.4, -3.5, -3.5]),
    })  # fmt: skip
    b = bench(tmp_path / "b.json", {
        "slip_target_3kmh_creep0.3": runs_of([95.0, 95.0, 70.0, 70.0], [-4.6, -4.6, -2.0, -2.0]),
        "slip_target_3kmh_always": runs_of([50.0] * 4, [-1.0] * 4),  # another gate: skipped
    })  # fmt: skip
    assert target_cap_table.main([a, b]) == 0
    out = capsys.readouterr().out
    assert "leaves: 3 km/h at cap 0.3" in out and "wet: 4 km/h at cap 0.2" in out
    assert "-1.00" not in out  # the other gate's runs are no candidate
    teacher = float(re.search(r"teacher of this table: score (\S+)", out).group(1))
    bound = float(re.search(r"best pair by return: score (\S+)", out).group(1))
    assert bound >= teacher
    *_, label = target_cap_table.load_pairs([a, b])
    assert sorted(label.values()) == [(3.0, 0.2), (3.0, 0.3), (4.0, 0.2)]


def test_the_same_pair_twice_or_no_file_is_one_line(tmp_path, capsys):
    a = bench(tmp_path / "a.json", {"slip_target_3kmh": runs_of([95.0] * 4, [-4.6] * 4)})
    assert target_cap_table.main([a, a]) == 2
    err = capsys.readouterr().err.strip()
    assert "is in an earlier file too" in err and "\n" not in err
    sealed = bench(tmp_path / "s.json", {"slip_target_3kmh": runs_of([95.0] * 4, [-4.6] * 4)},
                    stops="sealed")  # fmt: skip
    assert target_cap_table.main([sealed]) == 2
    assert "not development" in capsys.readouterr().err
    assert json.loads(Path(a).read_text())["stops"] == "development"

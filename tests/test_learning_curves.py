"""scripts/learning_curves.py: the pure-RL learning-curve figure of docs/training_log.md, read from
the runs' ``curve.json``."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import learning_curves


def _run(folder: Path, points: list[tuple[int, float]]) -> Path:
    folder.mkdir(parents=True)
    rows = [{"timesteps": t, "score": s, "mean_return": -1.0} for t, s in points]
    (folder / "curve.json").write_text(json.dumps({"history": rows, "classical": {}}))
    return folder


def test_groups_seeds_on_the_steps_they_share_and_draws_the_figure(tmp_path, capsys):
    a = _run(tmp_path / "a", [(0, 1.02), (1000, 1.00), (2000, 0.99), (3000, 0.98)])
    b = _run(tmp_path / "b", [(0, 1.02), (1500, 1.04), (2000, 1.01)])  # shorter: to 2000
    out = tmp_path / "fig" / "curves.png"
    assert learning_curves.main(["--group", f"PPO={a},{b}", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    # steps 0, 1000, 1500, 2000; best points 1.02 and 1.04; last 0.99 and 1.01
    assert "PPO: 2 seeds, to 2,000 steps; score at step 0 1.020, best point 1.030 " in text
    assert "(1.020-1.040), last 1.000 (0.990-1.010)" in text
    assert out.stat().st_size > 10_000
    s = learning_curves.summarise([learning_curves.read_curve(a), learning_curves.read_curve(b)])
    assert list(s["steps"]) == [0, 1000, 1500, 2000]
    assert s["values"][0].tolist() == [1.02, 1.00, 1.00, 0.99]  # a's point at or before each


def test_bad_groups_and_runs_are_one_line(tmp_path):
    with pytest.raises(SystemExit, match="expected 'LABEL=RUN_DIR"):
        learning_curves.main(["--group", "no runs", "--out", str(tmp_path / "x.png")])
    png = str(tmp_path / "x.png")
    with pytest.raises(SystemExit, match=r"curve\.json: no such file"):
        learning_curves.main(["--group", f"x={tmp_path / 'none'}", "--out", png])
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "curve.json").write_text('{"history": [{"timesteps": 0}]}')
    with pytest.raises(SystemExit, match="not a learning curve"):
        learning_curves.main(["--group", f"x={tmp_path / 'bad'}", "--out", png])
    late = _run(tmp_path / "late", [(1000, 1.0), (2000, 1.0)])
    early = _run(tmp_path / "early", [(0, 1.0), (2000, 1.0)])
    with pytest.raises(SystemExit, match=r"start at different steps: \[0, 1000\]"):
        learning_curves.main(["--group", f"x={early},{late}", "--out", png])
    back = _run(tmp_path / "back", [(0, 1.0), (2000, 1.0), (1000, 1.0)])
    with pytest.raises(SystemExit, match="steps do not increase"):
        learning_curves.main(["--group", f"x={back}", "--out", png])
    assert not (tmp_path / "x.png").exists()

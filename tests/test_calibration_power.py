"""The detection-power study (``scripts/calibration_power.py``, README "Calibration on
independent traces") runs end to end on a tiny grid and reports what the README quotes from it:
detection, the adhesion candidates' readings against the generator's truth, false positives."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"


def test_the_power_study_reports_the_adhesion_readings(tmp_path):
    sys.path.insert(0, str(SCRIPTS))
    try:
        import calibration_power as cp
    finally:
        sys.path.remove(str(SCRIPTS))
    out = tmp_path / "power.json"
    args = ["--scenarios", "1", "--clean", "2", "--pairs", "0", "--jobs", "1",
            "--categories", "load_transfer", "--json", str(out)]  # fmt: skip
    assert cp.main(args) == 0
    data = json.loads(out.read_text())
    summary, results = data["summary"], data["results"]
    assert summary["traces"] == 2 + 3 and not summary["errors"]
    rows = summary["categories"]["load_transfer"]["rows"]
    assert [r["magnitude"] for r in rows] == [1.5, 2.0, 3.0]
    assert all(0.0 <= r["tried_rate"] <= 1.0 for r in rows)
    for r in results:
        # the generator's bogie pitch (36-68 t cars, pivot 0.5-0.8 m over a 2.2-3 m wheelbase),
        # times the injected load-transfer factor
        factor = math.prod(p.get("factor", 1.0) for p in r["effect_params"])
        assert 1.5 <= r["true_bogie_pitch_kN_per_mps2"] / factor <= 13.0
        for fitted in r["adhesion_fits"].values():
            assert all(np.isfinite(v) for v in fitted.values())
    assert 0.0 <= summary["clean"]["false_positive_rate"] <= 1.0

"""scripts/set_loop_settings.py: a copy of a slip-target model file with its loop's later
settings set (the release gate, the creep cap); a file written before them loads with the old
loop (``always``, no cap); bad input is one line, nothing written."""

from __future__ import annotations

import shutil
import sys
import zipfile
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import set_loop_settings

from wsp_env.policy import META_NAME, model_metadata, pretrained_dir, write_model_metadata


def _slip_target_model(tmp_path: Path) -> Path:
    """The shipped model's file with metadata of a slip-target model written before the gate
    and the cap (no ``slip_target_release``, no ``slip_target_max_creep``): only the metadata
    matters here."""
    src = pretrained_dir() / "ppo_bc_uic_z1.zip"
    path = tmp_path / "old" / "student.zip"
    path.parent.mkdir()
    shutil.copy(src, path)
    shutil.copy(src.with_suffix(".vecnormalize.pkl"), path.with_suffix(".vecnormalize.pkl"))
    meta = model_metadata(src)
    meta["env_kwargs"] = {**meta["env_kwargs"], "action_mode": "slip_target"}
    meta["env_kwargs"].pop("slip_target_release", None)
    meta["env_kwargs"].pop("slip_target_max_creep", None)
    write_model_metadata(path, meta)
    return path


def test_the_copy_names_the_settings_and_keeps_the_rest(tmp_path, capsys):
    old = _slip_target_model(tmp_path)
    assert model_metadata(old)["env_kwargs"]["slip_target_release"] == "always"
    assert model_metadata(old)["env_kwargs"]["slip_target_max_creep"] == 0.0
    new = tmp_path / "new" / "student.zip"
    argv = [str(old), str(new), "--release", "working", "--max-creep", "0.2"]
    assert set_loop_settings.main(argv) == 0
    meta, before = model_metadata(new), model_metadata(old)
    assert meta["env_kwargs"]["slip_target_release"] == "working"
    assert meta["env_kwargs"]["slip_target_max_creep"] == 0.2
    assert meta["name"] == "new/student"
    keys = ("slip_target_release", "slip_target_max_creep")
    rest = {k: v for k, v in meta["env_kwargs"].items() if k not in keys}
    assert rest == {k: v for k, v in before["env_kwargs"].items() if k not in keys}
    assert (
        new.with_suffix(".vecnormalize.pkl").read_bytes()
        == old.with_suffix(".vecnormalize.pkl").read_bytes()
    )
    assert sorted(p.name for p in new.parent.iterdir()) == [
        "student.vecnormalize.pkl", "student.zip",
    ]  # fmt: skip
    assert "slip_target_release working, slip_target_max_creep 0.2" in capsys.readouterr().out
    # one setting alone: the other stays as the model had it
    gate_only = tmp_path / "gate" / "student.zip"
    assert set_loop_settings.main([str(old), str(gate_only), "--release", "working"]) == 0
    kw = model_metadata(gate_only)["env_kwargs"]
    assert (kw["slip_target_release"], kw["slip_target_max_creep"]) == ("working", 0.0)
    assert kw["slip_target_drift_correction"] is False  # a file from before it: the loop without
    drift = tmp_path / "drift" / "student.zip"
    assert set_loop_settings.main([str(old), str(drift), "--drift-correction", "on"]) == 0
    kw = model_metadata(drift)["env_kwargs"]
    assert kw["slip_target_drift_correction"] is True and kw["slip_target_release"] == "always"
    assert kw["slip_target_gain_scale_floor"] == 1.0  # a file from before it: a fixed gain
    scaled = tmp_path / "scaled" / "student.zip"
    assert set_loop_settings.main([str(old), str(scaled), "--pressure-gain", "0.8x0.25"]) == 0
    kw = model_metadata(scaled)["env_kwargs"]
    assert (kw["slip_target_gain_per_kmh"], kw["slip_target_gain_scale_floor"]) == (0.8, 0.25)
    assert kw["slip_target_drift_correction"] is False
    bad = tmp_path / "bad" / "student.zip"
    assert set_loop_settings.main([str(old), str(bad), "--pressure-gain", "0.8x0"]) == 2
    err = capsys.readouterr().err
    assert "--pressure-gain 0.8x0: slip_target_gain_scale_floor: must be in (0, 1]" in err
    assert not bad.parent.exists()
    # the onset reading: only on a drift-corrected copy
    onset = tmp_path / "onset" / "student.zip"
    assert set_loop_settings.main([str(old), str(onset), "--onset-drift", "on"]) == 2
    assert "the onset reading needs the drift correction" in capsys.readouterr().err
    argv = [str(old), str(onset), "--drift-correction", "on", "--onset-drift", "on"]
    assert set_loop_settings.main(argv) == 0
    kw = model_metadata(onset)["env_kwargs"]
    assert kw["slip_target_onset_drift"] is True and kw["slip_target_drift_correction"] is True
    assert kw["slip_target_scale_calibration"] is False  # a file from before it: no calibration
    cal = tmp_path / "cal" / "student.zip"
    assert set_loop_settings.main([str(old), str(cal), "--scale-calibration", "on"]) == 0
    assert model_metadata(cal)["env_kwargs"]["slip_target_scale_calibration"] is True
    # the onset reading's other sense: only on a copy with the onset reading
    two = tmp_path / "two" / "student.zip"
    assert set_loop_settings.main([str(old), str(two), "--onset-two-sided", "on"]) == 2
    assert "the two-sided onset reading needs the onset reading" in capsys.readouterr().err
    assert not two.parent.exists()
    assert set_loop_settings.main([str(onset), str(two), "--onset-two-sided", "on"]) == 0
    kw = model_metadata(two)["env_kwargs"]
    assert kw["slip_target_onset_two_sided"] is True and kw["slip_target_onset_drift"] is True
    assert model_metadata(onset)["env_kwargs"]["slip_target_onset_two_sided"] is False
    # the lock guard: a file from before it loads without; the copy names it
    assert model_metadata(old)["env_kwargs"]["slip_target_lock_guard"] is False
    guard = tmp_path / "guard" / "student.zip"
    assert set_loop_settings.main([str(old), str(guard), "--lock-guard", "on"]) == 0
    kw = model_metadata(guard)["env_kwargs"]
    assert kw["slip_target_lock_guard"] is True and kw["slip_target_release"] == "always"


def test_an_existing_copy_or_a_failed_write_leaves_nothing_new(tmp_path, capsys, monkeypatch):
    old = _slip_target_model(tmp_path)
    new = tmp_path / "new" / "student.zip"
    assert set_loop_settings.main([str(old), str(new), "--release", "working"]) == 0
    before = new.read_bytes()
    assert set_loop_settings.main([str(old), str(new), "--release", "always"]) == 2
    assert "exists; not overwriting" in capsys.readouterr().err
    assert new.read_bytes() == before

    def fail(path, meta):
        raise OSError(f"{path}: disk full")

    monkeypatch.setattr(set_loop_settings, "write_model_metadata", fail)
    other = tmp_path / "other" / "student.zip"
    assert set_loop_settings.main([str(old), str(other), "--max-creep", "0.2"]) == 2
    assert "disk full" in capsys.readouterr().err
    assert not other.parent.exists()


@pytest.mark.parametrize(
    "case",
    ["continuous", "same", "suffix", "missing", "nothing", "creep_range", "creep_text", "no_accel"],
)
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, case):
    model = _slip_target_model(tmp_path)
    out = tmp_path / "new" / "student.zip"
    settings = ["--release", "working"]
    if case == "nothing":
        settings, want = [], "nothing to set"
    elif case == "creep_range":
        settings, want = ["--max-creep", "1.5"], "slip_target_max_creep"
    elif case == "creep_text":
        settings, want = ["--max-creep", "much"], "--max-creep: a number"
    elif case == "no_accel":
        meta = model_metadata(model)
        meta["env_kwargs"]["accelerometer"] = False
        write_model_metadata(model, meta)
        settings, want = ["--drift-correction", "on"], "trained without the accelerometer"
    elif case == "continuous":
        model = pretrained_dir() / "ppo_bc_uic_z1.zip"
        want = "not a slip-target model"
    elif case == "same":
        out = model
        want = "the model itself"
    elif case == "suffix":
        out = out.with_suffix(".onnx")
        want = "must be a .zip model file"
    else:
        model = tmp_path / "nowhere.zip"
        want = "nowhere.zip"
    assert set_loop_settings.main([str(model), str(out), *settings]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and want in err
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize(
    ("named", "want"),
    [
        ({}, ("always", 0.0)),  # before the gate
        ({"slip_target_release": "working"}, ("working", 0.0)),  # the gate, before the cap
        ({"slip_target_release": "working", "slip_target_max_creep": 0.2}, ("working", 0.2)),
        ({"slip_target_release": "always", "slip_target_max_creep": 0.3}, ("always", 0.3)),
    ],
)
def test_a_model_without_its_own_entry_takes_the_loop_its_run_folder_names(tmp_path, named, want):
    """A model file without its metadata entry (written before entries existed) is read from
    its run folder's ``config.yaml``: the loop's later settings it names are kept, each one it
    does not name gets the loop before that setting."""
    import yaml

    src = pretrained_dir() / "ppo_bc_uic_z1.zip"
    run = tmp_path / "run"
    run.mkdir()
    path = run / "model.zip"
    with zipfile.ZipFile(src) as z, zipfile.ZipFile(path, "w") as out:
        for n in z.namelist():
            if n != META_NAME:
                out.writestr(n, z.read(n))
    env_kwargs = {"vehicle": "uic_z1", "action_mode": "slip_target", **named}
    (run / "config.yaml").write_text(yaml.safe_dump({"algo": "ppo", "env_kwargs": env_kwargs}))
    kw = model_metadata(path)["env_kwargs"]
    assert (kw["slip_target_release"], kw["slip_target_max_creep"]) == want

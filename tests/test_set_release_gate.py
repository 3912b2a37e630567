"""scripts/set_release_gate.py: a copy of a slip-target model file with its loop's release gate
set; a file written before the gate loads with ``always``; bad input is one line, nothing
written."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import set_release_gate

from wsp_env.policy import model_metadata, pretrained_dir, write_model_metadata


def _slip_target_model(tmp_path: Path) -> Path:
    """The shipped model's file with metadata of a slip-target model written before the gate
    (no ``slip_target_release``): only the metadata matters here."""
    src = pretrained_dir() / "ppo_bc_uic_z1.zip"
    path = tmp_path / "old" / "student.zip"
    path.parent.mkdir()
    shutil.copy(src, path)
    shutil.copy(src.with_suffix(".vecnormalize.pkl"), path.with_suffix(".vecnormalize.pkl"))
    meta = model_metadata(src)
    meta["env_kwargs"] = {**meta["env_kwargs"], "action_mode": "slip_target"}
    meta["env_kwargs"].pop("slip_target_release", None)
    write_model_metadata(path, meta)
    return path


def test_the_copy_names_the_gate_and_keeps_the_rest(tmp_path, capsys):
    old = _slip_target_model(tmp_path)
    assert model_metadata(old)["env_kwargs"]["slip_target_release"] == "always"
    new = tmp_path / "new" / "student.zip"
    assert set_release_gate.main([str(old), str(new), "working"]) == 0
    meta, before = model_metadata(new), model_metadata(old)
    assert meta["env_kwargs"]["slip_target_release"] == "working"
    assert meta["name"] == "new/student"
    rest = {k: v for k, v in meta["env_kwargs"].items() if k != "slip_target_release"}
    assert rest == {k: v for k, v in before["env_kwargs"].items() if k != "slip_target_release"}
    assert (
        new.with_suffix(".vecnormalize.pkl").read_bytes()
        == old.with_suffix(".vecnormalize.pkl").read_bytes()
    )
    assert sorted(p.name for p in new.parent.iterdir()) == [
        "student.vecnormalize.pkl", "student.zip",
    ]  # fmt: skip
    assert "slip_target_release working" in capsys.readouterr().out


def test_an_existing_copy_or_a_failed_write_leaves_nothing_new(tmp_path, capsys, monkeypatch):
    old = _slip_target_model(tmp_path)
    new = tmp_path / "new" / "student.zip"
    assert set_release_gate.main([str(old), str(new), "working"]) == 0
    before = new.read_bytes()
    assert set_release_gate.main([str(old), str(new), "always"]) == 2
    assert "exists; not overwriting" in capsys.readouterr().err
    assert new.read_bytes() == before

    def fail(path, meta):
        raise OSError(f"{path}: disk full")

    monkeypatch.setattr(set_release_gate, "write_model_metadata", fail)
    other = tmp_path / "other" / "student.zip"
    assert set_release_gate.main([str(old), str(other), "working"]) == 2
    assert "disk full" in capsys.readouterr().err
    assert not other.parent.exists()


@pytest.mark.parametrize("case", ["continuous", "same", "suffix", "missing"])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, case):
    model = _slip_target_model(tmp_path)
    out = tmp_path / "new" / "student.zip"
    if case == "continuous":
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
    assert set_release_gate.main([str(model), str(out), "working"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and want in err
    assert not (tmp_path / "new").exists()

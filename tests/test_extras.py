"""An install without the optional extras (`rl`: torch and stable-baselines3; `export`: onnx and
onnxruntime; `sweep`: ray and optuna): the learned policies, `train`, `export-policy`, `sweep`
and `--workers` say in one line which extra to install, never a ModuleNotFoundError traceback.
The modules are hidden here by a ``None`` in ``sys.modules`` (what makes ``import`` fail);
tests/test_wheel.py checks the same in a fresh install without extras."""

from __future__ import annotations

import sys

import pytest
import yaml

from wsp_env.cli import main
from wsp_env.policy import MissingExtraError, make_policy, require_extras, shipped_policies

SHIPPED = shipped_policies()[0]


@pytest.fixture
def without(monkeypatch):
    """``without("onnx", ...)``: those modules fail to import for the rest of the test."""

    def hide(*modules: str) -> None:
        for m in modules:
            for loaded in [k for k in sys.modules if k == m or k.startswith(m + ".")]:
                monkeypatch.delitem(sys.modules, loaded)
            monkeypatch.setitem(sys.modules, m, None)

    return hide


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def test_require_extras_names_the_extra_and_the_module(without):
    require_extras("x needs", "rl", "export")  # all installed here: nothing happens
    without("onnxruntime")
    with pytest.raises(MissingExtraError) as err:
        require_extras("x needs", "rl", "export")
    assert str(err.value) == (
        "x needs the rl and export extras: pip install 'wsp-env[rl,export]' "
        "(no module named 'onnxruntime')"
    )
    assert isinstance(err.value, ValueError)  # the CLI prints it as one line, exit 2


def test_shipped_policy_without_rl_is_one_line(without, capsys):
    without("stable_baselines3")
    with pytest.raises(MissingExtraError, match=rf"^{SHIPPED}: learned policies need the rl "):
        make_policy(SHIPPED)
    for cmd in (["simulate", "--speed-kmh", "30"], ["evaluate", "--suite", "quick"], ["rig"]):
        assert main([*cmd, "--policy", SHIPPED]) == 2, cmd
        err = _one_line(capsys)
        assert "pip install 'wsp-env[rl]'" in err and SHIPPED in err, err
    assert make_policy("classical").name == "classical"  # the rules need no extra


def test_model_file_without_rl_is_one_line(without, tmp_path):
    from wsp_env.policy import pretrained_dir

    without("torch")
    with pytest.raises(MissingExtraError, match=r"learned policies need the rl extra.*'torch'"):
        make_policy(str(pretrained_dir() / f"{SHIPPED}.zip"))


def test_train_without_rl_is_one_line(without, tmp_path, capsys):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump({"algo": "ppo", "n_timesteps": 256, "normalize": True}))
    without("stable_baselines3", "sb3_contrib")
    out = tmp_path / "run"
    assert main(["train", "--config", str(cfg), "--out", str(out), "--no-progress"]) == 2
    err = _one_line(capsys)
    assert err == (
        "wsp-env train: error: training needs the rl extra: pip install 'wsp-env[rl]' "
        "(no module named 'stable_baselines3')"
    )
    assert not out.exists()


def test_finetune_without_rl_is_one_line(without, tmp_path, capsys):
    from wsp_env.policy import pretrained_dir

    without("torch")
    out = tmp_path / "ft"
    start = str(pretrained_dir() / f"{SHIPPED}.zip")
    assert main(["finetune", start, "--out", str(out), "--generations", "1"]) == 2
    err = _one_line(capsys)
    assert err == (
        "wsp-env finetune: error: fine-tuning needs the rl extra: pip install 'wsp-env[rl]' "
        "(no module named 'torch')"
    )
    assert not out.exists()


@pytest.mark.parametrize("hidden", ["onnx", "onnxruntime", "stable_baselines3"])
def test_export_without_its_extras_is_one_line(without, tmp_path, capsys, hidden):
    without(hidden)
    onnx = tmp_path / "p.onnx"
    assert main(["export-policy", SHIPPED, "--onnx", str(onnx)]) == 2
    err = _one_line(capsys)
    assert f"{SHIPPED}: ONNX export needs the rl and export extras" in err
    assert f"pip install 'wsp-env[rl,export]' (no module named '{hidden}')" in err
    assert not onnx.exists()


@pytest.mark.parametrize("hidden", ["ray", "optuna"])
def test_sweep_and_workers_without_their_extra_are_one_line(without, tmp_path, capsys, hidden):
    without(hidden)
    out = tmp_path / "s"
    assert main(["sweep", "--config", "x.yaml", "--out", str(out)]) == 2
    err = _one_line(capsys)
    assert "sweep needs the rl and sweep extras: pip install 'wsp-env[rl,sweep]'" in err
    assert not out.exists()
    if hidden == "ray":
        j = tmp_path / "e.json"
        assert main(["evaluate", "--policy", "none", "--workers", "2", "--json", str(j)]) == 2
        err = _one_line(capsys)
        assert "--workers/--address need the sweep extra: pip install 'wsp-env[sweep]'" in err
        assert not j.exists()

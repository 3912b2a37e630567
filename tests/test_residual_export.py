"""Residual action mode (a learned correction on the frozen classical WSP), model metadata
(algorithm and environment settings inside the model file, vehicle mismatch) and the ONNX
export's parity with the SB3 policy."""

from __future__ import annotations

import json
import shutil
import zipfile

import numpy as np
import pytest
import yaml
from test_train import train_config

from wsp_env.cli import main
from wsp_env.envs import WSPBrakingEnv, WSPBrakingVectorEnv, make_core
from wsp_env.evaluation import load_suite, run_suite
from wsp_env.policy import META_NAME, SB3Policy, make_policy


class ZeroResidual:
    name = "zero_residual"
    privileged = False
    env_kwargs = {"action_mode": "residual"}  # noqa: RUF012

    def bind(self, core):
        self.shape = (core.n_envs, core.n_valves)

    def reset(self, env_ids):
        pass

    def act(self, obs):
        return np.zeros(self.shape, dtype=np.float32)


def test_zero_residual_is_the_classical_wsp_bit_for_bit():
    """Same scenarios, same code path: the zero residual stops exactly where the classical WSP
    does, with the same sliding energy and air (a float32 rounding in the composition would
    diverge through the WSP's thresholds)."""
    suite = load_suite("quick")
    classical, _ = run_suite("uic_z1", suite, make_policy("classical"), record="none")
    zero, _ = run_suite("uic_z1", suite, ZeroResidual(), record="none")
    for a, b in zip(classical, zero, strict=True):
        for key in ("stopping_distance_m", "sliding_energy_kJ", "air_litres"):
            assert a[key] == b[key], (a["scenario"], key)


def test_residual_moves_the_command_and_is_observed():
    env = WSPBrakingEnv(action_mode="residual")
    plain = WSPBrakingEnv()
    assert env.observation_space.shape[0] == plain.observation_space.shape[0] + 4
    obs, _ = env.reset(seed=1, options={"rail": "soap", "speed_kmh": 80})
    np.testing.assert_array_equal(obs[-4:], 1.0)  # the classical WSP applies at the start
    obs, _, _, _, info = env.step(np.array([-0.5, 0.0, 0.0, 2.0], dtype=np.float32))
    # axle 1 asked for 1 - 0.5 of the demand; the others for the classical request (apply)
    assert env.core.sim.cmd[0, 0] == pytest.approx(0.5)
    np.testing.assert_array_equal(env.core.sim.cmd[0, 1:], 1.0)
    assert info["action_clipped"] == 1  # the 2.0
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.array([np.nan, 0, 0, 0], dtype=np.float32))
    with pytest.raises(ValueError, match="residual_scale"):
        WSPBrakingEnv(action_mode="residual", residual_scale=0.0)
    with pytest.raises(ValueError, match="action_mode"):
        WSPBrakingEnv(action_mode="target_slip")


def test_residual_vector_env_state_round_trip_is_bit_for_bit():
    """A checkpoint holds the classical WSP's memory too: restored, the run continues the same."""
    venv = WSPBrakingVectorEnv(num_envs=3, action_mode="residual")
    venv.reset(seed=5, options={"rail": "soap", "speed_kmh": 50})
    rng = np.random.default_rng(0)
    actions = rng.uniform(-0.3, 0.3, (400, 3, 4)).astype(np.float32)
    for a in actions[:150]:
        venv.step(a)
    state = venv.core.state_dict()
    first = [venv.step(a)[0] for a in actions[150:]]
    other = WSPBrakingVectorEnv(num_envs=3, action_mode="residual")
    other.core.load_state_dict(state)
    second = [other.step(a)[0] for a in actions[150:]]
    for x, y in zip(first, second, strict=True):
        np.testing.assert_array_equal(x, y)


@pytest.fixture(scope="module")
def residual_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("residual")
    env_kwargs = {"vehicle": "uic_z1", "action_mode": "residual", "accelerometer": True,
                  "scenario": {"speed_kmh": [30, 40]}}  # fmt: skip
    cfg = train_config(tmp, n_timesteps=256, frame_stack=2, env_kwargs=env_kwargs)
    out = tmp / "run"
    assert main(["train", "--config", str(cfg), "--out", str(out), "--no-progress"]) == 0
    return tmp, out


def test_model_file_carries_its_settings_and_loads_alone(residual_run, tmp_path):
    """The algorithm and environment settings are read from the model file's own metadata:
    copied away from its run folder (no config.yaml) it still evaluates in residual mode."""
    tmp, out = residual_run
    with zipfile.ZipFile(out / "best_model.zip") as z:
        meta = json.loads(z.read(META_NAME))
    assert meta["algo"] == "ppo" and meta["vehicle"] == "uic_z1" and meta["frame_stack"] == 2
    assert meta["env_kwargs"]["action_mode"] == "residual"
    alone = tmp_path / "alone"
    alone.mkdir()
    shutil.copy(out / "best_model.zip", alone / "p.zip")
    shutil.copy(out / "best_model.vecnormalize.pkl", alone / "p.vecnormalize.pkl")
    policy = SB3Policy(alone / "p.zip")
    assert policy.env_kwargs["action_mode"] == "residual" and policy.n_stack == 2
    results, _ = run_suite("uic_z1", load_suite(str(tmp / "suite.yaml")), policy)
    assert all(r["stopped"] for r in results)


def test_vehicle_mismatch_and_unknown_files_are_one_line(residual_run, tmp_path, capsys):
    _, out = residual_run
    suite = tmp_path / "s.yaml"
    suite.write_text(yaml.safe_dump({
        "name": "x", "description": "x", "seeds": [1],
        "cases": [{"name": "d", "rail": "dry", "pattern": "uniform", "speeds_kmh": [30]}],
    }))  # fmt: skip
    code = main(["evaluate", "--policy", str(out / "best_model.zip"), "--suite", str(suite),
                 "--vehicle", "e402b"])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "'uic_z1'" in err and "'e402b'" in err
    junk = tmp_path / "junk.zip"
    junk.write_bytes(b"not a zip")
    assert main(["evaluate", "--policy", str(junk), "--suite", "quick"]) == 2
    assert "not a model file" in capsys.readouterr().err
    bare = tmp_path / "bare.zip"
    with zipfile.ZipFile(out / "best_model.zip") as z, zipfile.ZipFile(bare, "w") as w:
        for name in z.namelist():
            if name != META_NAME:
                w.writestr(name, z.read(name))
    assert main(["evaluate", "--policy", str(bare), "--suite", "quick"]) == 2
    assert "cannot tell the algorithm" in capsys.readouterr().err


def test_onnx_export_matches_the_sb3_policy(residual_run, tmp_path):
    """ONNX Runtime on the exported graph (normalisation folded in) gives the SB3 policy's
    deterministic actions to 1e-5 on observations of a real stop, frame stack included."""
    ort = pytest.importorskip("onnxruntime")
    _, out = residual_run
    onnx_path = tmp_path / "p.onnx"
    assert main(["export-policy", str(out / "best_model.zip"), "--onnx", str(onnx_path)]) == 0
    session = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    meta = session.get_modelmeta().custom_metadata_map
    fill = np.asarray(json.loads(meta["frame_fill"]), dtype=np.float32)
    policy = SB3Policy(out / "best_model.zip")
    core = make_core(4, **policy.env_kwargs)
    for e in range(4):
        core.rngs[e] = np.random.default_rng(e)
        core.reset_env(e, {"rail": "soap", "speed_kmh": 60})
    policy.bind(core)
    policy.reset(np.arange(4))
    frames = [np.tile(fill, (4, 1))] * 2
    worst = 0.0
    for _ in range(200):
        obs = core.obs.copy()
        frames = [*frames[1:], obs]
        ours = policy.act(obs)
        theirs = session.run(None, {"obs": np.concatenate(frames, axis=1)})[0]
        worst = max(worst, float(np.abs(ours - theirs).max()))
        core.step(core.check_actions(ours))
    assert worst < 1e-5

"""`wsp-env train`: configs, the run folder's contract, bit-for-bit resume, evaluation of what
the trainer makes (normalisation, discrete actions), one-line errors. Tiny budgets: these test
the machinery, not learning."""

from __future__ import annotations

import csv
import json
import pickle
import shutil
import zipfile

import numpy as np
import pytest
import torch
import yaml

from wsp_env.cli import main
from wsp_env.core.braking import BrakingCore
from wsp_env.envs import WSPBrakingVectorEnv
from wsp_env.evaluation import load_suite, run_suite
from wsp_env.policy import META_NAME, SB3Policy, make_policy, model_metadata, write_model_metadata
from wsp_env.training.config import LinearSchedule, load_train_config
from wsp_env.training.train import latest_checkpoint, merge_progress

SUITE = {
    "name": "tiny",
    "description": "two short stops",
    "seeds": [7],
    "cases": [
        {"name": "s", "rail": "soap", "mu_contaminated": 0.08, "pattern": "uniform",
         "speeds_kmh": [30]},
        {"name": "d", "rail": "dry", "pattern": "uniform", "speeds_kmh": [30]},
    ],
}  # fmt: skip


def train_config(tmp_path, **changes):
    suite = tmp_path / "suite.yaml"
    suite.write_text(yaml.safe_dump(SUITE))
    cfg = {
        "algo": "ppo", "n_envs": 8, "n_timesteps": 512, "seed": 3, "normalize": True,
        "policy_kwargs": {"net_arch": [16, 16]}, "learning_rate": "lin_3e-4", "n_steps": 32,
        "batch_size": 64, "n_epochs": 2, "gamma": 0.999,
        "env_kwargs": {"vehicle": "uic_z1", "scenario": {"speed_kmh": [30, 40]}},
        "eval": {"suite": str(suite), "every_timesteps": 256, "curve_every_timesteps": 256,
                 "curve_runs": 2},
        "checkpoint_every_timesteps": 256,
    }  # fmt: skip
    cfg.update(changes)
    path = tmp_path / f"{cfg['algo']}_{len(list(tmp_path.glob('*.yaml')))}.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


SAC = {
    "algo": "sac", "n_envs": 4, "n_timesteps": 400, "normalize": {"norm_reward": False},
    "learning_rate": 3e-4, "buffer_size": 10000, "learning_starts": 100, "batch_size": 32,
    "train_freq": 1, "gradient_steps": 1, "checkpoint_every_timesteps": 200,
}  # fmt: skip


def _sac(tmp_path):
    cfg = yaml.safe_load(train_config(tmp_path).read_text())
    for key in ("n_steps", "n_epochs"):  # PPO's
        cfg.pop(key)
    cfg.update(SAC)
    cfg["eval"]["every_timesteps"] = 200
    path = tmp_path / "sac.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def model_params(model_path):
    from sb3_contrib import RecurrentPPO
    from stable_baselines3 import PPO, SAC

    for cls in (PPO, SAC, RecurrentPPO):
        try:
            return cls.load(model_path, device="cpu").policy.state_dict()
        except Exception:
            continue
    raise AssertionError(model_path)


def same_params(a, b):
    return all(torch.equal(a[k], b[k]) for k in a)


@pytest.fixture(scope="module")
def ppo_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("train")
    out = tmp / "run"
    code = main(["train", "--config", str(train_config(tmp)), "--out", str(out), "--no-progress",
                 "--json", str(tmp / "train.json")])  # fmt: skip
    return code, tmp, out


def test_train_writes_the_contract(ppo_run):
    code, tmp, out = ppo_run
    assert code == 0
    result = json.loads((tmp / "train.json").read_text())
    for key in ("model_path", "algo", "total_timesteps", "wall_time_s", "env_steps_per_s",
                "best_validation"):  # fmt: skip
        assert key in result
    assert result["algo"] == "ppo" and result["total_timesteps"] == 512 and result["finished"]
    assert result["env_steps_per_s"] > 0
    for name in ("config.yaml", "model.zip", "model.vecnormalize.pkl", "best_model.zip",
                 "best_model.vecnormalize.pkl", "validation.json", "progress.csv"):  # fmt: skip
        assert (out / name).exists(), name
    assert latest_checkpoint(out).name == "step_512"
    assert list((out / "logs" / "from_step_0").glob("events.out.tfevents.*"))  # TensorBoard
    validation = json.loads((out / "validation.json").read_text())
    # the classical WSP on the same suite, and the policy at every evaluation (256, 512)
    assert validation["classical"]["runs"] == 2
    assert [row["timesteps"] for row in validation["history"]] == [256, 512]
    best = result["best_validation"]
    assert best in validation["history"] and best["stop_vs_classical"] > 0
    # the exact config (seed included) is kept, and it loads again
    kept = load_train_config(out / "config.yaml")
    assert kept.seed == 3 and isinstance(
        kept.hyperparams["learning_rate"], str
    )  # the schedule as written


def test_learning_curve_is_the_same_stops_beside_the_classical_line(ppo_run):
    """curve.json: the first ``curve_runs`` runs of the validation suite at step 0, every
    ``curve_every_timesteps`` and at the end, with the classical WSP's constant line and the
    benchmark's score (1 = the classical WSP); the same rows in the logger's CSV."""
    _, _, out = ppo_run
    curve = json.loads((out / "curve.json").read_text())
    assert [h["timesteps"] for h in curve["history"]] == [0, 256, 512]
    assert curve["cases"] == ["s_30", "d_30"] and curve["runs"] == [7, 7]
    assert curve["classical"]["score"] == pytest.approx(1.0)
    for row in curve["history"]:
        assert row["passed"] <= 2 and row["mean_stopping_distance_m"] > 0
        assert row["score"] is None or np.isfinite(row["score"])
    with (out / "progress.csv").open(newline="") as fh:
        logged = [r for r in csv.DictReader(fh) if r.get("curve/mean_return")]
    assert len(logged) >= 1
    result = json.loads((out / "train.json").read_text())
    assert result["threads"]["role"] == "train" and result["threads"]["update"]["updates"] >= 1


def test_a_trained_model_evaluates_and_simulates(ppo_run, tmp_path):
    _, tmp, out = ppo_run
    suite = str(tmp / "suite.yaml")
    js = tmp_path / "eval.json"
    assert main(["evaluate", "--policy", str(out / "best_model.zip"), "--policy", "classical",
                 "--suite", suite, "--json", str(js)]) == 0  # fmt: skip
    runs = json.loads(js.read_text())["runs"]
    assert {r["policy"] for r in runs} == {"run/best_model", "classical"} and len(runs) == 4
    sim = tmp_path / "sim.json"
    assert main(["simulate", "--policy", str(out / "model.zip"), "--speed-kmh", "30",
                 "--json", str(sim)]) == 0  # fmt: skip
    assert json.loads(sim.read_text())["stopping_distance_m"] > 0


def test_normalisation_is_found_under_any_checkpoint_name(ppo_run, tmp_path):
    _, _, out = ppo_run
    ckpt = latest_checkpoint(out) / "model.zip"
    policy = SB3Policy(ckpt)
    with (ckpt.parent / "model.vecnormalize.pkl").open("rb") as fh:
        saved = pickle.load(fh)
    np.testing.assert_array_equal(policy._obs_rms.mean, saved.obs_rms.mean)
    # SB3's CheckpointCallback naming
    shutil.copy(ckpt, tmp_path / "rl_model_512_steps.zip")
    shutil.copy(
        ckpt.parent / "model.vecnormalize.pkl", tmp_path / "rl_model_vecnormalize_512_steps.pkl"
    )
    other = SB3Policy(tmp_path / "rl_model_512_steps.zip")
    np.testing.assert_array_equal(other._obs_rms.mean, saved.obs_rms.mean)
    obs = np.full((1, saved.obs_rms.mean.size), 0.3, dtype=np.float32)
    np.testing.assert_allclose(other.normalise(obs), saved.normalize_obs(obs), rtol=1e-6)


RECURRENT = {"algo": "recurrent_ppo", "policy_kwargs": {"net_arch": [16], "lstm_hidden_size": 8}}


@pytest.mark.parametrize(
    "kind", ["ppo", "sac", "frame_stack", "recurrent_ppo", "time_limit", "stop_weight"]
)
def test_resume_in_chunks_is_bit_for_bit(tmp_path, kind):
    """A run stopped half way (--chunk-timesteps) and resumed ends with exactly the weights
    and normalisation of the run trained in one go: the schedules follow the run's total, the
    environments' physics and random generators, torch's and numpy's random state (and SAC's
    replay buffer, the frame stack, the LSTM state, each stop's steps towards its time limit)
    come back from the checkpoint. ``time_limit``: 1 s stops (50 periods) that straddle the
    chunk's end (32 steps of each environment) truncate at the same step after the resume."""
    cfg = {  # ppo: a curve cadence (300) that is no multiple of a rollout (256)
        "ppo": lambda: train_config(
            tmp_path,
            n_timesteps=768,
            eval={
                "suite": str(tmp_path / "suite.yaml"),
                "every_timesteps": 256,
                "curve_every_timesteps": 300,
                "curve_runs": 2,
            },
        ),
        "sac": lambda: _sac(tmp_path),
        "frame_stack": lambda: train_config(tmp_path, frame_stack=3),
        "recurrent_ppo": lambda: train_config(tmp_path, **RECURRENT),
        "time_limit": lambda: train_config(tmp_path, env_kwargs={
            "vehicle": "uic_z1", "scenario": {"speed_kmh": [30, 40]}, "max_time_s": 1.0}),
        # the per-stop weights of the stops under way come back from the restored scenarios
        "stop_weight": lambda: train_config(tmp_path, stop_weight={"reference_m": 50.0},
            env_kwargs={"vehicle": "uic_z1", "scenario": {"speed_kmh": [30, 40],
                        "gradient_permille": [-20, 20]}, "max_time_s": 1.0}),
    }[kind]()  # fmt: skip
    # ppo: the chunk ends past a curve point (300) that the one-go run takes at its next
    # rollout's start, at the same step
    half = {"sac": "200", "ppo": "512"}.get(kind, "256")
    one, part, rest = tmp_path / "one", tmp_path / "part", tmp_path / "rest"
    assert main(["train", "--config", str(cfg), "--out", str(one), "--no-progress"]) == 0
    assert main(["train", "--config", str(cfg), "--out", str(part), "--no-progress",
                 "--chunk-timesteps", half]) == 0  # fmt: skip
    assert json.loads((part / "train.json").read_text())["finished"] is False
    assert main(["train", "--resume", str(part), "--out", str(rest), "--no-progress"]) == 0
    assert same_params(model_params(one / "model.zip"), model_params(rest / "model.zip"))
    with (
        (one / "model.vecnormalize.pkl").open("rb") as a,
        (rest / "model.vecnormalize.pkl").open("rb") as b,
    ):
        np.testing.assert_array_equal(pickle.load(a).obs_rms.var, pickle.load(b).obs_rms.var)
    # the chunked run's history holds both evaluations, as the one-go run's does
    hist = json.loads((rest / "validation.json").read_text())["history"]
    whole = json.loads((one / "validation.json").read_text())["history"]
    assert [h["timesteps"] for h in hist] == [h["timesteps"] for h in whole]
    assert int(half) in [h["timesteps"] for h in hist]
    if kind == "sac":  # the first validation early: a tenth of the budget
        assert hist[0]["timesteps"] == 40
    # the fixed-seed learning curve is deterministic: the chunked run's rows are the one-go's
    curve = json.loads((rest / "curve.json").read_text())
    assert curve["history"] == json.loads((one / "curve.json").read_text())["history"]
    if kind == "ppo":
        assert [h["timesteps"] for h in curve["history"]] == [0, 512, 768]
    # both calls' CSV logs in one progress.csv: each timestep once, in order
    with (rest / "progress.csv").open(newline="") as fh:
        steps = [int(float(r["time/total_timesteps"])) for r in csv.DictReader(fh)]
    assert steps == sorted(set(steps)) and (kind == "sac" or steps[-1] > int(half))
    if kind == "stop_weight":  # the run was weighted, and says so
        saved = yaml.safe_load((rest / "config.yaml").read_text())
        assert saved["stop_weight"]["reference_m"] == 50.0
    if kind == "time_limit":  # the stops that straddle the resume count their whole length
        with (
            (one / "progress.csv").open(newline="") as a,
            (rest / "progress.csv").open(newline="") as b,
        ):
            lengths = [[r["rollout/ep_len_mean"] for r in csv.DictReader(f)
                        if r.get("rollout/ep_len_mean")] for f in (a, b)]  # fmt: skip
        assert lengths[0] and lengths[0][-1] == lengths[1][-1] == "50.0"


def _first_returns(env, act, n_envs):
    """Each environment's first episode return, acting with ``act(obs, ended)``."""
    obs, _ = env.reset(seed=123)
    ret, acc, done = np.full(n_envs, np.nan), np.zeros(n_envs), np.zeros(n_envs, dtype=bool)
    ended = np.zeros(n_envs, dtype=bool)
    while not done.all():
        obs, r, term, trunc, _ = env.step(act(obs, ended))
        acc += np.where(done, 0.0, r)
        ended = term | trunc
        ret[ended & ~done] = acc[ended & ~done]
        done |= ended
    return ret


def test_a_run_with_action_repeat_trains_and_evaluates_with_its_repeat(tmp_path, capsys):
    """The environment holds each action 3 periods in training; the model file remembers it
    and its evaluation on the 20 ms core holds its actions as long: on the same seeded stops
    the model returns exactly what it returns in its training environment (the repeat inside
    the environment, the model on normalised, stacked observations)."""
    cfg = train_config(
        tmp_path, n_timesteps=256, gamma=0.997, frame_stack=2,
        env_kwargs={"vehicle": "uic_z1", "scenario": {"speed_kmh": [30, 40]}, "action_repeat": 3},
    )  # fmt: skip
    out = tmp_path / "run"
    assert main(["train", "--config", str(cfg), "--out", str(out), "--no-progress"]) == 0
    assert model_metadata(out / "model.zip")["env_kwargs"]["action_repeat"] == 3
    policy = make_policy(str(out / "model.zip"))
    assert policy.action_repeat == 3
    res = json.loads((out / "curve.json").read_text())["history"]
    assert res and res[-1]["timesteps"] == 256
    n, kwargs = 2, {"scenario": {"speed_kmh": [30, 40]}}
    evaluated = WSPBrakingVectorEnv(num_envs=n, **kwargs)
    policy.bind(evaluated.core)
    by_adapter = _first_returns(evaluated, lambda obs, ended: policy.act(obs), n)
    stack = np.zeros((n, 2 * evaluated.core.obs_dim), dtype=np.float32)

    def in_training(obs, ended):
        stack[ended] = 0.0  # a new stop: its stack empty, as the adapter's
        w = obs.shape[1]
        stack[:, :-w], stack[:, -w:] = stack[:, w:], policy.normalise(obs)
        return policy.model.predict(stack, deterministic=True)[0]

    trained = WSPBrakingVectorEnv(num_envs=n, action_repeat=3, **kwargs)
    np.testing.assert_allclose(_first_returns(trained, in_training, n), by_adapter, atol=1e-9)


def test_another_seed_is_another_run(ppo_run, tmp_path):
    _, tmp, out = ppo_run
    cfg = tmp / "ppo_1.yaml" if (tmp / "ppo_1.yaml").exists() else next(tmp.glob("ppo_*.yaml"))
    other = tmp_path / "other"
    assert main(["train", "--config", str(cfg), "--out", str(other), "--seed", "4",
                 "--no-progress", "--total-timesteps", "512"]) == 0  # fmt: skip
    assert not same_params(model_params(out / "model.zip"), model_params(other / "model.zip"))


def test_discrete_models_are_evaluated_in_discrete_mode(tmp_path):
    """A model trained on valve modes (0 vent, 1 hold, 2 fill) brings its action mode to the
    evaluation: its outputs are never read as continuous valve commands."""
    env_kwargs = {"vehicle": "uic_z1", "action_mode": "discrete",
                  "scenario": {"speed_kmh": [30, 40]}}  # fmt: skip
    cfg = train_config(tmp_path, env_kwargs=env_kwargs, n_timesteps=256)
    out = tmp_path / "run"
    assert main(["train", "--config", str(cfg), "--out", str(out), "--no-progress"]) == 0
    policy = make_policy(str(out / "model.zip"))
    assert policy.env_kwargs["action_mode"] == "discrete"
    with pytest.raises(ValueError, match="trained in action_mode 'discrete', this environment's"):
        policy.bind(BrakingCore(2))  # a continuous environment refuses it
    core = BrakingCore(2, action_mode="discrete")
    policy.bind(core)
    actions = policy.act(core.obs)
    assert actions.shape == (2, 4) and np.isin(actions, (0, 1, 2)).all()
    results, _ = run_suite("uic_z1", load_suite(str(tmp_path / "suite.yaml")), policy)
    assert len(results) == 2 and all(r["stopped"] for r in results)


@pytest.mark.parametrize(
    "changes,field",
    [
        ({"learning_rat": 1e-3}, "learning_rat: unknown"),
        ({"learning_rate": "lin_x"}, "learning_rate"),
        ({"algo": "dqn"}, "algo"),
        ({"n_envs": 0}, "n_envs"),
        ({"policy_kwargs": {"activation_fn": "sigmoidal"}}, "policy_kwargs.activation_fn"),
        ({"env_kwargs": {"reward": {"air_m_per_litre": 1.0}}}, "env_kwargs.reward.air_m_per_litre"),
        ({"env_kwargs": {"vehicle": "tgv"}}, "env_kwargs"),
        ({"env_kwargs": {"scenario": {"rails": {"ice": 1.0}}}}, "env_kwargs.scenario.rails.ice"),
        ({"eval": {"suite": "heldout"}}, "eval.suite"),
        ({"eval": {"suite": "en15595"}}, "eval.suite"),
        ({"eval": {"suite": "no_such_suite"}}, "eval.suite"),
        ({"gamma": "0.99"}, "gamma"),
        ({"batch_size": True}, "batch_size"),
        ({"n_epochs": "lin_3"}, "n_epochs"),
        ({"n_epochs": 0}, "n_epochs: expected a whole number >= 1"),
        ({"env_kwargs": {"action_repeat": 0}}, "env_kwargs.action_repeat: must be an integer"),
        (
            {"env_kwargs": {"action_repeat": 3, "reward": {"shaping_decel_mps2": 1.0}}},
            "env_kwargs.reward.shaping_decel_mps2: the shaping is written per control period",
        ),
        (
            {"env_kwargs": {"reward": {"shaping_decel_mps2": 1.0, "shaping_gamma": 0.99}}},
            "env_kwargs.reward.shaping_gamma",
        ),
        ({"algo": "sac", "frame_stack": 3}, "frame_stack: 3 with normalize is not supported"),
        ({"stop_weight": {"reference_m": -1.0}}, "stop_weight.reference_m"),
        ({"stop_weight": {"min_weight": 5.0, "max_weight": 1.0}}, "stop_weight.min_weight"),
        ({"stop_weight": {"scale": 1.0}}, "stop_weight.scale: unknown field"),
        ({"stop_weight": "yes"}, "stop_weight: expected a mapping"),
    ],
)
def test_bad_config_is_one_line_naming_file_and_field(tmp_path, capsys, changes, field):
    cfg = train_config(tmp_path, **changes)
    out = tmp_path / "run"
    assert main(["train", "--config", str(cfg), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(cfg) in err and field in err, err
    assert not out.exists()  # nothing half-written


def test_resume_without_checkpoint_and_occupied_out_are_refused(tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["train", "--resume", str(empty), "--no-progress"]) == 2
    assert "no checkpoint" in capsys.readouterr().err
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "x").write_text("keep me")
    assert main(["train", "--config", str(train_config(tmp_path)), "--out", str(busy)]) == 2
    assert (busy / "x").read_text() == "keep me"


def test_schedules_and_episode_scenarios():
    assert LinearSchedule(3e-4)(1.0) == 3e-4 and LinearSchedule(3e-4)(0.5) == 1.5e-4
    # an episode's end carries its scenario, so learning curves split by condition
    venv = WSPBrakingVectorEnv(num_envs=2, scenario={"speed_kmh": [20, 25]})
    venv.reset(seed=0)
    for _ in range(3000):
        _, _, term, trunc, info = venv.step(np.ones((2, 4), dtype=np.float32))
        if (term | trunc).any():
            e = int(np.flatnonzero(term | trunc)[0])
            assert {"rail", "speed_kmh", "mu_contaminated"} <= set(
                info["final_info"][e]["scenario"]
            )
            return
    raise AssertionError("no episode ended")


@pytest.mark.parametrize("changes", [{"frame_stack": 3}, RECURRENT])
def test_stacked_and_recurrent_policies_evaluate_with_their_memory(tmp_path, changes):
    """The evaluation rebuilds a frame-stacked policy's stack and carries a recurrent policy's
    state, reset per episode: acting twice on the same observation after a reset gives the
    same first action, and the state/stack then differs from a fresh episode's."""
    out = tmp_path / "run"
    cfg = train_config(tmp_path, n_timesteps=256, **changes)
    assert main(["train", "--config", str(cfg), "--out", str(out), "--no-progress"]) == 0
    policy = make_policy(str(out / "model.zip"))
    core = BrakingCore(2)
    policy.bind(core)

    def memory():
        if policy.n_stack > 1:
            return policy._stack.copy()
        return np.concatenate([np.asarray(t).ravel() for t in policy._state])  # LSTM (h, c)

    policy.reset(np.arange(2))
    first = policy.act(core.obs)
    after_one = memory()
    policy.act(core.obs)
    after_two = memory()
    assert not np.array_equal(after_one, after_two)  # the memory moves with each step
    policy.reset(np.arange(2))
    np.testing.assert_array_equal(policy.act(core.obs), first)  # and restarts per episode
    np.testing.assert_array_equal(memory(), after_one)
    assert policy.recurrent or policy._stack.shape == (2, 3 * core.obs_dim)
    results, _ = run_suite("uic_z1", load_suite(str(tmp_path / "suite.yaml")), policy)
    assert len(results) == 2 and all(r["stopped"] for r in results)


def test_shipped_training_configs_load():
    from wsp_env.core.config import configs_root

    paths = sorted((configs_root() / "train").glob("*.yaml"))
    assert paths
    for p in paths:
        cfg = load_train_config(p)
        assert cfg.eval.suite == "validation" and cfg.n_timesteps >= 1_000_000


def test_a_run_failing_before_its_first_checkpoint_leaves_no_folder(tmp_path, monkeypatch):
    """Otherwise it could neither be started again in place nor resumed."""
    from wsp_env.training import train as training

    def broken(*args, **kwargs):
        raise RuntimeError("broken on purpose")

    monkeypatch.setattr(training, "merge_progress", broken)  # fails at the very end
    out = tmp_path / "run"
    monkeypatch.setattr(training, "_save_checkpoint", broken)
    with pytest.raises(RuntimeError):
        training.train(train_config(tmp_path, n_timesteps=64), out, progress=False)
    assert not out.exists()


def test_resume_refuses_a_second_config(ppo_run, capsys):
    _, tmp, out = ppo_run
    assert main(["train", "--resume", str(out), "--config", str(train_config(tmp))]) == 2
    assert "--config" in capsys.readouterr().err


def _progress(path, rows, extra="train/loss"):
    path.parent.mkdir(parents=True)
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=["time/total_timesteps", extra])
        w.writeheader()
        w.writerows({"time/total_timesteps": n, extra: v} for n, v in rows)


def test_progress_after_kill_and_resume_is_one_row_per_timestep_in_order(tmp_path):
    """A run killed at 768 after its checkpoint at 512 and resumed from it logged 640 and 768
    twice: the merged CSV has each timestep once, in order, the resumed call's row winning, and
    nothing of the killed call's steps past 512 (576: a branch the resume discarded)."""
    logs = tmp_path / "logs"
    old = [(128, "a"), (256, "a"), (384, "a"), (512, "a"), (576, "a"), (640, "a"), (768, "a")]
    _progress(logs / "from_step_0" / "progress.csv", old)
    new = [(640, "b"), (768, "b"), (896, "b"), (1024, "b")]
    _progress(logs / "from_step_512" / "progress.csv", new, extra="validation/passed")
    _progress(logs / "from_step_1024" / "progress.csv", [(1152, "c"), (1152, "d")])
    merge_progress(tmp_path)
    with (tmp_path / "progress.csv").open(newline="") as fh:
        reader = csv.DictReader(fh)
        rows = list(reader)
    assert reader.fieldnames == ["time/total_timesteps", "train/loss", "validation/passed"]
    steps = [int(r["time/total_timesteps"]) for r in rows]
    assert steps == [128, 256, 384, 512, 640, 768, 896, 1024, 1152]
    assert [r["train/loss"] for r in rows[:4]] == ["a"] * 4
    assert [r["validation/passed"] for r in rows[4:8]] == ["b"] * 4
    assert [r["train/loss"] for r in rows[4:8]] == [""] * 4  # the resumed call's rows, whole
    assert rows[-1]["train/loss"] == "d"  # a timestep logged twice: the later row


def test_the_model_file_says_it_needs_its_normalisation(ppo_run, tmp_path, capsys):
    """A model trained on normalised observations, copied without its normalisation file, is
    refused in one line naming the missing file (by make_policy and by evaluate), never used
    un-normalised."""
    _, tmp, out = ppo_run
    meta = model_metadata(out / "best_model.zip")
    assert meta["obs_normalization"] is True and meta["frame_stack"] == 1
    assert (
        meta["env_kwargs"]["privileged"] is False and meta["env_kwargs"]["accelerometer"] is False
    )
    alone = tmp_path / "alone"
    alone.mkdir()
    shutil.copy(out / "best_model.zip", alone / "p.zip")
    with pytest.raises(ValueError, match=r"p\.vecnormalize\.pkl is missing"):
        make_policy(str(alone / "p.zip"))
    code = main(["evaluate", "--policy", str(alone / "p.zip"), "--suite", str(tmp / "suite.yaml")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert str(alone / "p.vecnormalize.pkl") in err and "Traceback" not in err
    code = main(["export-policy", str(alone / "p.zip"), "--onnx", str(tmp_path / "p.onnx")])
    assert code == 2 and "p.vecnormalize.pkl is missing" in capsys.readouterr().err
    shutil.copy(out / "best_model.vecnormalize.pkl", alone / "p.vecnormalize.pkl")
    assert make_policy(str(alone / "p.zip")).normalisation() is not None


def _with_metadata(src, dst, change):
    shutil.copy(src, dst)
    with zipfile.ZipFile(dst) as z:
        meta = json.loads(z.read(META_NAME))
    change(meta)
    write_model_metadata(dst, meta)


def test_normalisation_follows_the_metadata_and_older_models_keep_loading(ppo_run, tmp_path):
    _, _, out = ppo_run
    stats = out / "best_model.vecnormalize.pkl"
    # trained without normalisation: a statistics file lying beside it is not applied
    _with_metadata(out / "best_model.zip", tmp_path / "raw.zip",
                   lambda m: m.update(obs_normalization=False))  # fmt: skip
    shutil.copy(stats, tmp_path / "raw.vecnormalize.pkl")
    assert make_policy(str(tmp_path / "raw.zip")).normalisation() is None
    # written before the field existed, nothing beside it tells: as before, the statistics are
    # used when found and the model loads without them
    old = tmp_path / "old"
    old.mkdir()
    _with_metadata(out / "best_model.zip", old / "m.zip", lambda m: m.pop("obs_normalization"))
    assert model_metadata(old / "m.zip")["obs_normalization"] is None
    assert make_policy(str(old / "m.zip")).normalisation() is None
    shutil.copy(stats, old / "m.vecnormalize.pkl")
    assert make_policy(str(old / "m.zip")).normalisation() is not None
    # ... but the config it was trained with, beside it (a shipped policy's STEM.yaml), tells
    (old / "m.vecnormalize.pkl").unlink()
    shutil.copy(out / "config.yaml", old / "m.yaml")
    assert model_metadata(old / "m.zip")["obs_normalization"] is True
    with pytest.raises(ValueError, match=r"m\.vecnormalize\.pkl is missing"):
        make_policy(str(old / "m.zip"))

"""Warm start by imitation (DAgger on a privileged teacher) before PPO: it fits, it is recorded,
and a wrong pretrain block is one line."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from conftest import script
from test_train import train_config

from wsp_env.cli import main
from wsp_env.envs import make_core
from wsp_env.policy import SB3Policy
from wsp_env.training.imitation import make_teacher

PRETRAIN = {
    "teacher": "oracle_peak", "rounds": 2, "steps_per_round": 8192, "warmup_steps": 2048,
    "epochs": 30, "batch_size": 512, "learning_rate": 3e-3,
}  # fmt: skip
TABLE = {"teacher": "oracle_target_rail"}
RAILS = {"soap": 3.0, "leaves": 2.0, "oil": 3.0, "wet": 8.0}  # the default scenario's rails


def _teacher_gap(policy: SB3Policy, seed: int) -> float:
    """Mean |student - teacher| action over a soap stop the student drives (its own states)."""
    core = make_core(4, **policy.env_kwargs)
    for e in range(4):
        core.rngs[e] = np.random.default_rng(seed + e)
        core.reset_env(e, {"rail": "soap", "speed_kmh": 40, "mu_contaminated": 0.07})
    teacher = make_teacher("oracle_peak")
    teacher.bind(core)
    policy.bind(core)
    policy.reset(np.arange(4))
    gaps = []
    for _ in range(300):
        action = policy.act(core.obs)
        gaps.append(np.abs(np.clip(action, -1, 1) - teacher.act(core.obs)).mean())
        core.step(core.check_actions(action))
    return float(np.mean(gaps))


def test_pretraining_moves_the_student_toward_the_teacher(tmp_path):
    env_kwargs = {"vehicle": "uic_z1", "accelerometer": True,
                  "scenario": {"speed_kmh": [30, 50], "rails": {"soap": 1.0}}}  # fmt: skip
    runs = {}
    for name, extra in (("plain", {}), ("bc", {"pretrain": PRETRAIN})):
        cfg = train_config(
            tmp_path,
            n_timesteps=256,
            env_kwargs=env_kwargs,
            policy_kwargs={"net_arch": [64, 64]},
            **extra,
        )
        out = tmp_path / name
        assert main(["train", "--config", str(cfg), "--out", str(out), "--no-progress"]) == 0
        runs[name] = out
    record = json.loads((runs["bc"] / "pretrain.json").read_text())
    assert record["teacher"] == "oracle_peak" and len(record["rounds"]) == 2
    assert record["validation"]["timesteps"] == 0  # the warm start is validated on its own
    history = json.loads((runs["bc"] / "validation.json").read_text())["history"]
    assert history[0]["timesteps"] == 0
    first, second = record["rounds"]
    # the fit halves the actor's distance to the teacher on the teacher-driven states ...
    assert first["data_mae_after_fit"] < 0.5 * first["data_mae_before_fit"]
    # ... and again on the aggregate with the states the student reached driving itself in
    # round 1 (DAgger: where plain behaviour cloning drifts, there are labels)
    assert second["student_vs_teacher_mae"] is not None
    assert second["data_mae_after_fit"] < 0.5 * second["data_mae_before_fit"]
    # after PPO's first update both runs end with a model; the imitation one is nearer the
    # teacher on the states it reaches itself
    plain = _teacher_gap(SB3Policy(runs["plain"] / "model.zip"), 11)
    bc = _teacher_gap(SB3Policy(runs["bc"] / "model.zip"), 11)
    assert bc < plain

    # scripts/ship_policy.py --model student ships the warm start with its own figures (the
    # shipped students: agents/pretrained/bc_*), acting as the run's student.zip
    shipped = tmp_path / "shipped"
    script("ship_policy").main([str(runs["bc"]), "--name", "tiny_bc", "--model", "student",
                                "--out-dir", str(shipped)])  # fmt: skip
    info = json.loads((shipped / "tiny_bc.json").read_text())
    with pytest.raises(SystemExit, match=r"no pretrain\.json: no imitation warm start"):
        script("ship_policy").main([str(runs["plain"]), "--name", "x", "--model", "student",
                                    "--out-dir", str(tmp_path / "refused")])  # fmt: skip
    assert not (tmp_path / "refused").exists()
    assert info["timesteps_trained"] == 0 and info["shipped_at_timesteps"] == 0
    assert info["wall_time_s"] == record["wall_time_s"] > 0
    assert info["env_steps_per_s"] == pytest.approx(record["env_steps"] / record["wall_time_s"])
    assert info["best_validation"] == record["validation"]
    assert (shipped / "tiny_bc_learning_curve.png").stat().st_size > 0
    assert "wsp-env train --config" in (shipped / "tiny_bc.yaml").read_text()
    ours, theirs = SB3Policy(shipped / "tiny_bc.zip"), SB3Policy(runs["bc"] / "student.zip")
    assert ours.name == "tiny_bc"
    a, b = ours.model.policy.state_dict(), theirs.model.policy.state_dict()
    assert a.keys() == b.keys() and all((a[k] == b[k]).all() for k in a)
    for x, y in zip(ours.normalisation(), theirs.normalisation(), strict=True):
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize(
    "changes, field",
    [
        ({"algo": "sac", "pretrain": PRETRAIN}, "pretrain"),
        ({"pretrain": {**PRETRAIN, "teacher": "nobody"}}, "pretrain.teacher"),
        ({"pretrain": {**PRETRAIN, "rounds": 0}}, "pretrain.rounds"),
        ({"pretrain": {**PRETRAIN, "steps_per_round": 4}}, "pretrain.steps_per_round"),
        ({"pretrain": PRETRAIN, "env_kwargs": {"action_mode": "residual"}}, "pretrain"),
        # a valve-fraction teacher on slip targets, a slip-target teacher on valve fractions
        (
            {
                "pretrain": PRETRAIN,
                "env_kwargs": {"action_mode": "slip_target", "action_repeat": 4},
            },
            "valve fractions), not slip_target",
        ),
        ({"pretrain": {**PRETRAIN, "teacher": "oracle_target_rail"}}, "gives slip targets"),
        # the slip-target teacher's own table: its teacher, every rail drawn, none other, range
        (
            {"pretrain": {**PRETRAIN, "teacher_targets_kmh": {"soap": 3.0}}},
            "pretrain.teacher_targets_kmh: a table for a slip-target teacher",
        ),
        (
            {"pretrain": {**PRETRAIN, **TABLE, "teacher_targets_kmh": {"soap": 3.0}}},
            "pretrain.teacher_targets_kmh: no target for rail leaves",
        ),
        (
            {"pretrain": {**PRETRAIN, **TABLE, "teacher_targets_kmh": {**RAILS, "ice": 1.0}}},
            "pretrain.teacher_targets_kmh.ice: not a rail the scenario names",
        ),
        (
            {"pretrain": {**PRETRAIN, **TABLE, "teacher_targets_kmh": {**RAILS, "oil": 9.0}}},
            "pretrain.teacher_targets_kmh.oil: 9.0 km/h is outside the slip-target range",
        ),
        (
            {"pretrain": {**PRETRAIN, **TABLE, "teacher_targets_kmh": {**RAILS, "oil": -1}}},
            "pretrain.teacher_targets_kmh.oil",
        ),
    ],
)
def test_bad_pretrain_block_is_one_line(tmp_path, capsys, changes, field):
    cfg = yaml.safe_load(train_config(tmp_path).read_text())
    cfg.update(changes)
    if cfg["algo"] == "sac":
        for key in ("n_steps", "n_epochs", "gae_lambda"):
            cfg.pop(key, None)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["train", "--config", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{field}" in err, err
    assert not (tmp_path / "o").exists()


def test_rail_aware_teacher_slides_where_the_rail_recovers():
    """oracle_rail: a ~4 km/h slide on soap (recovering) above 25 km/h, the curve's peak on
    leaves (no recovery: there a slide buys nothing): the soap axles slide several times
    deeper than the leaves axles."""
    from wsp_env.baselines.oracle import RailAwareTracker
    from wsp_env.evaluation import CaseConfig, SuiteConfig, run_suite

    cases = tuple(
        CaseConfig(name=r, rail=r, mu_contaminated=m, pattern="uniform", speeds_kmh=("80",))
        for r, m in (("soap", 0.08), ("leaves", 0.05))
    )
    suite = SuiteConfig(name="t", description="", seeds=(3,), cases=cases)
    (soap, leaves), _ = run_suite("uic_z1", suite, RailAwareTracker(), record="none")
    soap_slide = np.mean([a["mean_sliding_kmh"] for a in soap["axles"]])
    leaves_slide = np.mean([a["mean_sliding_kmh"] for a in leaves["axles"]])
    assert 1.5 < soap_slide < 5.0 and leaves_slide < 0.5 * soap_slide
    assert soap["max_lock_s"] == 0.0 and leaves["max_lock_s"] == 0.0


HANDOVER = {**PRETRAIN, "rounds": 1, "steps_per_round": 1024, "warmup_steps": 512,
            "epochs": 2, "warmup_episodes": 1}  # fmt: skip


def _state(out):
    import pickle

    from wsp_env.training.train import latest_checkpoint

    with (latest_checkpoint(out) / "state.pkl").open("rb") as fh:
        return pickle.load(fh)


def test_handover_keeps_the_students_actions_while_the_critic_warms_up(tmp_path):
    """A tiny imitation -> PPO hand-over: with the critic warming up over the whole run, the
    RL updates move the critic only; the actor (and its log-std) end exactly where the imitation
    left them, the normalisation stays as fitted, and the warm-up covered whole stops."""
    import pickle

    import torch

    env_kwargs = {"vehicle": "uic_z1", "accelerometer": True,
                  "scenario": {"speed_kmh": [20, 30], "rails": {"soap": 1.0}}}  # fmt: skip
    # a constant learning rate (lin_ would end at 0 and hide a last update that moved);
    # warm-up 512 steps = both rollouts' updates
    pre = {**HANDOVER, "critic_warmup_timesteps": 512, "anchor_coef": 1.0,
           "anchor_timesteps": 512}  # fmt: skip
    cfg = train_config(tmp_path, n_timesteps=512, env_kwargs=env_kwargs, pretrain=pre,
                       learning_rate=3e-4)  # fmt: skip
    out = tmp_path / "run"
    assert main(["train", "--config", str(cfg), "--out", str(out), "--no-progress"]) == 0
    record = json.loads((out / "pretrain.json").read_text())
    assert record["warmup_episodes_min"] >= 1  # every environment finished a whole stop
    start = _state(out)["handover"]["anchor"]  # the student at the hand-over
    final = SB3Policy(out / "model.zip").model.policy.state_dict()
    actor = [k for k in start if k.startswith(("mlp_extractor.policy_net", "action_net"))]
    actor.append("log_std")
    critic = [k for k in start if k.startswith(("mlp_extractor.value_net", "value_net"))]
    assert all(torch.equal(start[k], final[k]) for k in actor)
    assert not all(torch.equal(start[k], final[k]) for k in critic)  # the critic learned
    with (out / "model.vecnormalize.pkl").open("rb") as fh:
        norm = pickle.load(fh)
    assert norm.training is False  # frozen at the hand-over (freeze_normalization)


def test_critic_warmup_of_one_rollout_freezes_exactly_the_first_update():
    from types import SimpleNamespace

    import torch

    from wsp_env.training.imitation import HandOver, PretrainConfig

    h = HandOver.__new__(HandOver)
    h.cfg, h.start_step, h.anchor = PretrainConfig(critic_warmup_timesteps=256), 0, None
    param = torch.nn.Parameter(torch.zeros(1))
    h._actor_params = lambda model: [param]
    frozen = []
    for n in (256, 512, 768):  # num_timesteps at each rollout's end (rollouts of 8 x 32)
        h.before_update(SimpleNamespace(num_timesteps=n, n_steps=32, n_envs=8))
        frozen.append(not param.requires_grad)
    assert frozen == [True, False, False]


def test_anchor_pull_decays_and_a_chunked_handover_resumes_bit_for_bit(tmp_path):
    from test_train import model_params, same_params

    from wsp_env.training.imitation import HandOver, PretrainConfig

    h = HandOver.__new__(HandOver)
    h.cfg, h.start_step, h.anchor = PretrainConfig(anchor_coef=2.0, anchor_timesteps=100), 0, 1
    assert [h.anchor_weight(t) for t in (0, 50, 100, 200)] == [2.0, 1.0, 0.0, 0.0]
    env_kwargs = {"vehicle": "uic_z1", "scenario": {"speed_kmh": [20, 30]}}
    pre = {**HANDOVER, "warmup_episodes": 0, "critic_warmup_timesteps": 256,
           "anchor_coef": 0.5, "anchor_timesteps": 2048}  # fmt: skip
    cfg = train_config(tmp_path, n_timesteps=768, env_kwargs=env_kwargs, pretrain=pre)
    one, part, rest = tmp_path / "one", tmp_path / "part", tmp_path / "rest"
    assert main(["train", "--config", str(cfg), "--out", str(one), "--no-progress"]) == 0
    assert main(["train", "--config", str(cfg), "--out", str(part), "--no-progress",
                 "--chunk-timesteps", "512"]) == 0  # fmt: skip
    assert main(["train", "--resume", str(part), "--out", str(rest), "--no-progress"]) == 0
    assert same_params(model_params(one / "model.zip"), model_params(rest / "model.zip"))


def test_rail_target_teacher_is_the_constant_target_of_its_rail():
    """oracle_target_rail through the slip-target loop is, stop by stop and bit for bit, the
    constant target ``RAIL_TARGETS_KMH`` names for the stop's rail; its actions are those
    targets on the slip-target mode's scale (a = 0: 4.25 km/h of 0.5-8)."""
    from wsp_env.baselines.oracle import (
        DEFAULT_TARGET_KMH,
        RAIL_TARGETS_KMH,
        SlipTargetOracle,
        SlipTargetTeacher,
    )
    from wsp_env.baselines.slip_target import SlipTargetPolicy
    from wsp_env.evaluation import CaseConfig, SuiteConfig, run_suite

    for rail, mu in (("oil", 0.06), ("leaves", 0.05)):
        assert RAIL_TARGETS_KMH[rail] != DEFAULT_TARGET_KMH  # else this proves little
        case = CaseConfig(name=rail, rail=rail, mu_contaminated=mu, pattern="uniform",
                          speeds_kmh=("80",))  # fmt: skip
        suite = SuiteConfig(name="t", description="", seeds=(3,), cases=(case,))
        (own,), _ = run_suite("uic_z1", suite, SlipTargetOracle(), record="none")
        const = SlipTargetPolicy(RAIL_TARGETS_KMH[rail])
        (ref,), _ = run_suite("uic_z1", suite, const, record="none")
        assert own["stopping_distance_m"] == ref["stopping_distance_m"]
        assert own["sliding_energy_kJ"] == ref["sliding_energy_kJ"]
    core = make_core(3, vehicle="uic_z1", action_mode="slip_target")
    teacher = SlipTargetTeacher({"soap": 4.25, "leaves": 2.0, "oil": 9.0})
    teacher.bind(core)
    for e, rail in enumerate(("soap", "leaves", "oil")):
        core.reset_env(e, {"rail": rail})
    teacher.reset(np.arange(3))
    # 9 km/h is beyond the mode's 8: clipped to its range, in the targets and the actions
    assert np.allclose(teacher.targets_kmh(), [[4.25] * 4, [2.0] * 4, [8.0] * 4])
    assert np.allclose(teacher.act(core.obs), [[0.0] * 4, [-0.6] * 4, [1.0] * 4])


def test_rail_teachers_creep_schedule_follows_the_loops_reference():
    """``pretrain.teacher_creep``: a scheduled rail's target is ``min(T, max(c 3.6 v_ref,
    floor))`` on the reference the environment's loop tracks (its drift-corrected one here),
    read when the teacher acts; a rail without a schedule keeps its constant target. Through
    ``SlipTargetOracle`` (its own loop) the schedule is the same loop's creep cap at that
    creep and floor, bit for bit: the two say the same thing."""
    from wsp_env.baselines.oracle import SlipTargetOracle, SlipTargetTeacher
    from wsp_env.baselines.slip_target import SlipTargetLoop, SlipTargetPolicy
    from wsp_env.evaluation import CaseConfig, SuiteConfig, run_suite

    core = make_core(2, vehicle="uic_z1", action_mode="slip_target", accelerometer=True,
                     slip_target_drift_correction=True)  # fmt: skip
    teacher = SlipTargetTeacher({"soap": 3.5, "leaves": 2.0}, {"leaves": 0.015}, 0.5)
    teacher.bind(core)
    for e, rail in enumerate(("soap", "leaves")):
        core.reset_env(e, {"rail": rail, "speed_kmh": 60.0})
    teacher.reset(np.arange(2))
    for v_kmh, want in ((150.0, 2.0), (60.0, 0.9), (20.0, 0.5)):
        t = teacher.targets_kmh(np.full(2, v_kmh / 3.6))
        assert np.allclose(t, [[3.5] * 4, [want] * 4])
    # the loop advances on the period's observation (its first read); the teacher reads its
    # reference
    v_loop = core.loop.reference_mps(core.obs[:, : core.kernel_obs_dim])
    assert np.array_equal(v_loop, core.loop.v_ref) and v_loop[1] > 0.0
    assert np.allclose(teacher.targets_kmh()[1], min(2.0, 0.015 * 3.6 * v_loop[1]))
    # without the drift correction the reference is the estimator's observed one, on the
    # calibrated scale (the factors are 1 until the onset window closes)
    plain = make_core(1, vehicle="uic_z1", action_mode="slip_target", accelerometer=True,
                      slip_target_scale_calibration=True)  # fmt: skip
    plain.reset_env(0, {"rail": "leaves", "speed_kmh": 60.0})
    kobs = plain.obs[:, : plain.kernel_obs_dim]
    want = kobs[:, 4 * plain.n_axles + 1].astype(np.float64) * plain.loop.v_scale
    assert np.array_equal(plain.loop.reference_mps(kobs), want) and want[0] > 15.0
    case = CaseConfig(name="leaves", rail="leaves", mu_contaminated=0.05, pattern="uniform",
                      speeds_kmh=("60",))  # fmt: skip
    suite = SuiteConfig(name="t", description="", seeds=(3,), cases=(case,))
    sched = SlipTargetOracle(SlipTargetTeacher({"leaves": 2.0}, {"leaves": 0.015}, 0.5))
    (own,), _ = run_suite("uic_z1", suite, sched, record="none")
    capped = SlipTargetPolicy(2.0, SlipTargetLoop(max_creep=0.015, creep_floor_kmh=0.5))
    (ref,), _ = run_suite("uic_z1", suite, capped, record="none")
    const = SlipTargetPolicy(2.0)
    (plain,), _ = run_suite("uic_z1", suite, const, record="none")
    assert own["stopping_distance_m"] == ref["stopping_distance_m"]
    assert own["stopping_distance_m"] != plain["stopping_distance_m"]  # the schedule acted
    assert sched.name == "oracle_target_rail_creepleaves0.015at0.5"


@pytest.mark.parametrize(
    ("creep", "words"),
    [
        ({"leaves": 0.0}, "pretrain.teacher_creep.leaves: must be > 0"),
        ({"leaves": 1.5}, "pretrain.teacher_creep.leaves: must be <= 1"),
        ({"sand": 0.01}, "pretrain.teacher_creep.sand: not a rail of pretrain.teacher_targets_kmh"),
        ({"leaves": "x"}, "pretrain.teacher_creep.leaves: expected a number"),
        (None, "pretrain.teacher_creep: needs pretrain.teacher_targets_kmh"),
    ],
)
def test_a_bad_teacher_creep_is_one_line(creep, words):
    """``pretrain.teacher_creep``: each value in (0, 1], only rails of the table, only beside a
    table; every refusal one line naming the field."""
    import copy
    from pathlib import Path

    import yaml

    from wsp_env.core.config import ConfigError
    from wsp_env.training.config import parse_train_config

    root = Path(__file__).resolve().parents[1] / "configs" / "train"
    data = yaml.safe_load((root / "ppo_bc_slip_target_guard_accel_regiolis.yaml").read_text())
    data = copy.deepcopy(data)
    if creep is None:
        del data["pretrain"]["teacher_targets_kmh"]
    else:
        data["pretrain"]["teacher_creep"] = creep
    with pytest.raises(ConfigError) as err:
        parse_train_config(data, "c.yaml")
    assert words in str(err.value) and len(str(err.value).splitlines()) == 1


def test_slip_target_student_is_the_imitation_start_handed_over(tmp_path):
    """A slip-target learner (action repeat 4, staggered starts) warm-started by
    oracle_target_rail with the config's own table (``pretrain.teacher_targets_kmh``): the fit
    halves its distance to the teacher's targets; every stop the DAgger rounds drive is labelled
    with its own rail's target from that table (the teacher is reset on each autoreset: a leaves
    stop after a soap stop is not taught soap's 3 km/h); and ``student.zip`` is
    exactly the start the hand-over pulls towards (the anchor), not what RL made of it."""
    import torch

    from wsp_env.training import imitation

    env_kwargs = {
        "vehicle": "uic_z1",
        "accelerometer": True,
        "action_mode": "slip_target",
        "action_repeat": 4,
        "memory_features": True,
        "memory_target_mean": True,  # the student's own mean target observed
        "stagger_reset_steps": 20,
        "scenario": {"speed_kmh": [30, 50], "rails": {"soap": 0.5, "leaves": 0.5}},
    }
    labels = []  # (rail of the stop, label) at every teacher call
    real = imitation.make_teacher

    def spy(name, *args):
        teacher = real(name, *args)
        act = teacher.act

        def recorded(obs):
            out = act(obs)
            rails = [s.rail_name for s in teacher.core.sim.setups]
            labels.extend(zip(rails, out[:, 0].tolist(), strict=True))
            return out

        teacher.act = recorded
        return teacher

    pre = {**PRETRAIN, "teacher": "oracle_target_rail", "steps_per_round": 2048,
           "warmup_steps": 512, "anchor_coef": 1.0, "anchor_timesteps": 256,
           "teacher_targets_kmh": {"soap": 3.0, "leaves": 2.0}}  # fmt: skip
    cfg = train_config(
        tmp_path,
        n_timesteps=256,
        env_kwargs=env_kwargs,
        policy_kwargs={"net_arch": [32, 32]},
        pretrain=pre,
        learning_rate=3e-4,
    )  # a constant learning rate: lin_ would end at 0 after the one update
    out = tmp_path / "run"
    imitation.make_teacher = spy
    try:
        assert main(["train", "--config", str(cfg), "--out", str(out), "--no-progress"]) == 0
    finally:
        imitation.make_teacher = real
    want = {"soap": -1.0 / 3.0, "leaves": -0.6}  # the config's 3 and 2 km/h on the 0.5-8 scale
    assert {r for r, _ in labels} == {"soap", "leaves"}
    assert all(abs(a - want[r]) < 1e-6 for r, a in labels)
    record = json.loads((out / "pretrain.json").read_text())
    assert record["teacher"] == "oracle_target_rail"
    assert record["teacher_targets_kmh"] == {"soap": 3.0, "leaves": 2.0}
    first = record["rounds"][0]
    assert first["data_mae_after_fit"] < 0.5 * first["data_mae_before_fit"]
    student = SB3Policy(out / "student.zip")
    assert student.env_kwargs["action_mode"] == "slip_target"
    start = _state(out)["handover"]["anchor"]
    own = student.model.policy.state_dict()
    assert all(torch.equal(start[k], own[k]) for k in start)
    final = SB3Policy(out / "model.zip").model.policy.state_dict()
    assert not all(torch.equal(own[k], final[k]) for k in own)  # RL moved; the file kept the start

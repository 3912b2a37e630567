"""Evolution-strategies fine-tuning (``wsp_env.training.es``, ``wsp-env finetune``): a member
holding some weights acts exactly as a model file holding them; no generation moves nothing
(the start's own actions come back); a run resumed between generations ends where the run in
one go ends; the pool's stops are no benchmark or suite stop; bad settings are one line."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from test_train import train_config

from wsp_env.cli import main
from wsp_env.core.config import configs_root
from wsp_env.evaluation.benchmark import POLICY_KEYS, sealed_seeds
from wsp_env.evaluation.runner import run_runs
from wsp_env.evaluation.suites import load_suite
from wsp_env.policy import SB3Policy

es = pytest.importorskip("wsp_env.training.es")
pytest.importorskip("stable_baselines3")

SEEDS = [es.TRAINING_SEED_BASE + i for i in (0, 3, 6)]


@pytest.fixture(autouse=True)
def short_stops(monkeypatch):
    """The pool's stops cut at 8 s (the benchmark's limit is 600 s): what is compared here is
    the same either way, and an untrained model's stops are long."""
    setup = es.env_setup

    def capped(policy):
        veh, kwargs, _, tier = setup(policy)
        return veh, kwargs, 8.0, tier

    monkeypatch.setattr(es, "env_setup", capped)


@pytest.fixture(scope="module")
def start(tmp_path_factory):
    """A tiny trained slip-target model (frame stack, normalisation, an action repeat)."""
    tmp = tmp_path_factory.mktemp("es")
    env_kwargs = {"vehicle": "uic_z1", "action_mode": "slip_target", "memory_features": True,
                  "action_repeat": 2, "scenario": {"speed_kmh": [30, 40]}}  # fmt: skip
    path = train_config(tmp, n_timesteps=256, env_kwargs=env_kwargs, frame_stack=2)
    assert main(["train", "--config", str(path), "--out", str(tmp / "run"), "--no-progress"]) == 0
    return tmp / "run" / "model.zip"


def _returns(policy, start, seeds):
    veh, kwargs, max_time_s, _ = es.env_setup(SB3Policy(start))
    res, _ = run_runs(veh, es.training_runs(veh, seeds), policy, max_time_s=max_time_s,
                      env_kwargs=kwargs, policy_keys=POLICY_KEYS)  # fmt: skip
    return np.array([r["return"] for r in res])


def test_a_member_acts_as_the_model_file_holding_its_weights_bit_for_bit(start, tmp_path):
    layers, _ = es.actor_layers(SB3Policy(start).model)
    theta0 = es.get_parameters(layers[-1:])
    theta1 = theta0 + 0.05 * np.random.default_rng(0).standard_normal(theta0.size)
    both, watchdog, dist = es.evaluate_population(start, np.stack([theta0, theta1]), SEEDS, 1)
    assert watchdog.shape == both.shape == dist.shape and watchdog.dtype == bool
    assert (dist > 0).all()
    assert np.array_equal(both[0], _returns(SB3Policy(start), start, SEEDS))
    moved = es.write_model(start, tmp_path / "model.zip", theta1, 1, _meta(start))
    assert np.array_equal(both[1], _returns(SB3Policy(moved), start, SEEDS))
    assert not np.array_equal(both[0], both[1])  # the perturbation reaches the returns
    # two moving layers: the same weights in a member and in a file
    theta2 = es.get_parameters(layers[-2:])
    theta2 = theta2 + 0.05 * np.random.default_rng(1).standard_normal(theta2.size)
    pair, _, _ = es.evaluate_population(start, np.stack([theta2, theta2]), SEEDS[:2], 2)
    (tmp_path / "two").mkdir()
    moved = es.write_model(start, tmp_path / "two" / "model.zip", theta2, 2, _meta(start))
    assert np.array_equal(pair[0], pair[1])
    assert np.array_equal(pair[0], _returns(SB3Policy(moved), start, SEEDS[:2]))


def _meta(start):
    from wsp_env.policy import model_metadata

    return model_metadata(start)


def _finetune(start, out, generations, resume=False, **more):
    settings = es.ESSettings(start=str(start), pairs=1, stops=2, pool=4, sigma=0.05,
                             learning_rate=0.01, seed=5, **more)  # fmt: skip
    return es.finetune(start, out, generations, None if resume else settings, resume=resume)


def test_resumed_fine_tune_ends_where_one_go_ends_and_zero_generations_keep_the_start(
    start, tmp_path
):
    one = _finetune(start, tmp_path / "one", 2)
    _finetune(start, tmp_path / "two", 1)
    two = _finetune(None, tmp_path / "two", 1, resume=True)
    a, b = np.load(tmp_path / "one" / es.STATE), np.load(tmp_path / "two" / es.STATE)
    assert np.array_equal(a["theta"], b["theta"]) and int(b["generation"]) == 2
    assert one["generations"] == two["generations"] == 2 and one["distance_from_start"] > 0
    hist = json.loads((tmp_path / "one" / es.HISTORY).read_text())
    other = json.loads((tmp_path / "two" / es.HISTORY).read_text())
    assert [_untimed(r) for r in hist] == [_untimed(r) for r in other]
    # generation 0 runs the start and the current weights, which are the same
    assert hist[0]["score_gain"] == 0.0 and hist[0]["stops_better"] == 0.0
    # the written model is the current weights: it acts as the state's
    moved = SB3Policy(tmp_path / "one" / "model.zip")
    layers, _ = es.actor_layers(moved.model)
    assert np.allclose(es.get_parameters(layers[-1:]), a["theta"], atol=1e-7)
    assert (tmp_path / "one" / "model.vecnormalize.pkl").exists()
    # a pool copied into a new run's folder is used as it is, not computed again
    (tmp_path / "copy").mkdir()
    (tmp_path / "copy" / es.POOL).write_text((tmp_path / "one" / es.POOL).read_text())

    def no_pool(*args, **kwargs):
        raise AssertionError("the pool was computed again")

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(es, "training_pool", no_pool)
        _finetune(start, tmp_path / "copy", 2)
    assert np.array_equal(np.load(tmp_path / "copy" / es.STATE)["theta"], a["theta"])
    # no generation at all: the start itself
    _finetune(start, tmp_path / "none", 0)
    same = SB3Policy(tmp_path / "none" / "model.zip")
    assert np.array_equal(_returns(same, start, SEEDS[:1]), _returns(SB3Policy(start), start,
                                                                       SEEDS[:1]))  # fmt: skip


def test_population_forward_is_the_models_for_members_over_several_blocks(start):
    """Members of 64 rows (no padding) and of 100 (two blocks, the last padded), three
    members: each member holding the model's own weights gives the model's actions."""
    base = SB3Policy(start)
    layers, _ = es.actor_layers(base.model)
    theta = es.get_parameters(layers[-2:])
    other = theta + 0.1
    width = base.model.observation_space.shape[0]
    rng = np.random.default_rng(3)
    for rows in (64, 100):
        pop = es.PopulationPolicy(start, np.stack([theta, other, theta]), rows, 2)
        n = 3 * rows
        x = rng.normal(size=(n + (-n) % 64, width)).astype(np.float32)
        got = pop._forward(x)
        want = base._forward(x)
        assert got.shape == want.shape
        assert np.array_equal(got[:rows], want[:rows])
        assert np.array_equal(got[2 * rows : n], want[2 * rows : n])
        assert not np.array_equal(got[rows : 2 * rows], want[rows : 2 * rows])
        # rows whose stops ended (as the runner's frozen environments): a block of them all is
        # skipped (zeros), every other row's action is unchanged, bit for bit
        stopped = np.zeros(n, dtype=bool)
        stopped[:rows] = True  # member 0 ended: its blocks and the batch's first block(s)
        stopped[rows + 1] = True  # one row of member 1: its block still runs
        pop._sim = SimpleNamespace(n_envs=n, stopped=stopped)
        part = pop._forward(x)
        live = np.flatnonzero(~stopped)
        assert np.array_equal(part[live], got[live])
        assert np.array_equal(part[rows + 1], got[rows + 1])  # in a block that ran
        assert not part[:64].any()  # the first block's rows all ended: skipped
        if rows == 100:  # a member's block beside zeros of a skipped shared block
            stopped = np.zeros(n, dtype=bool)
            stopped[192:] = True  # shared blocks 3, 4 skipped; 192-199 ended in a block that runs
            pop._sim = SimpleNamespace(n_envs=n, stopped=stopped)
            part = pop._forward(x)
            assert np.array_equal(part[:192], got[:192])  # live rows beside skipped ones
            assert not part[200:n].any()  # member 2: every row ended, its blocks skipped
        pop._sim = None


def test_a_discrete_start_is_refused():
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", "CartPole-v1", device="cpu")
    with pytest.raises(ValueError, match=r"^PPO: Discrete actions \(continuous only\)$"):
        es.actor_layers(model)


def test_a_fine_tune_stopped_in_its_first_generation_resumes_and_damage_is_one_line(
    start, tmp_path
):
    _finetune(start, tmp_path / "whole", 1)
    _finetune(start, tmp_path / "cut", 0)  # the pool, the settings and the start's weights
    assert not (tmp_path / "cut" / es.STATE).exists()
    _finetune(None, tmp_path / "cut", 1, resume=True)
    whole = np.load(tmp_path / "whole" / es.STATE)["theta"]
    assert np.array_equal(np.load(tmp_path / "cut" / es.STATE)["theta"], whole)
    # a history one row ahead of the state (a stop between the two writes) is cut back
    hist = json.loads((tmp_path / "cut" / es.HISTORY).read_text())
    (tmp_path / "cut" / es.HISTORY).write_text(json.dumps(hist + hist))
    two = _finetune(None, tmp_path / "cut", 1, resume=True)
    assert two["generations"] == 2
    # damaged files: one line naming the file
    (tmp_path / "cut" / es.STATE).write_bytes(b"not a state")
    with pytest.raises(ValueError, match=r"es_state\.npz: not the fine-tune's state"):
        _finetune(None, tmp_path / "cut", 1, resume=True)
    # a pool of an earlier benchmark version (the classical WSP's returns are not today's)
    pool = json.loads((tmp_path / "cut" / es.POOL).read_text())
    assert pool["version"] == es.VERSION
    (tmp_path / "cut" / es.POOL).write_text(json.dumps({**pool, "version": "v2"}))
    with pytest.raises(ValueError, match=r"pool\.json: not this fine-tune's pool.*version"):
        _finetune(None, tmp_path / "cut", 1, resume=True)
    (tmp_path / "cut" / es.POOL).write_text("[1, 2]")
    with pytest.raises(ValueError, match=r"pool\.json: not this fine-tune's pool"):
        _finetune(None, tmp_path / "cut", 1, resume=True)
    (tmp_path / "whole" / es.SETTINGS).write_text("{")
    with pytest.raises(ValueError, match=r"es\.json: not the fine-tune's settings"):
        _finetune(None, tmp_path / "whole", 1, resume=True)
    # a start that changed since the fine-tune began
    import shutil

    moved = tmp_path / "start" / "model.zip"
    moved.parent.mkdir()
    shutil.copyfile(start, moved)
    shutil.copyfile(start.with_suffix(".vecnormalize.pkl"), moved.with_suffix(".vecnormalize.pkl"))
    _finetune(moved, tmp_path / "pinned", 0)
    moved.write_bytes(moved.read_bytes() + b"\0")
    with pytest.raises(ValueError, match=r"model\.zip: changed since the fine-tune began"):
        _finetune(None, tmp_path / "pinned", 1, resume=True)
    # the start's own folder would be overwritten
    with pytest.raises(ValueError, match=r"the start's own folder and name"):
        _finetune(start, start.parent, 0)


def test_averaged_and_guarded_fine_tune_resumes_and_writes_the_average(start, tmp_path):
    """With ``average`` and ``guard`` on, a resumed run still ends where one go ends, the
    written model holds the average (not the last step), and the history counts the guard."""
    more = {"average": 0.5, "guard": 0.01}
    one = _finetune(start, tmp_path / "one", 3, **more)
    _finetune(start, tmp_path / "two", 2, **more)
    _finetune(None, tmp_path / "two", 1, resume=True)
    a, b = np.load(tmp_path / "one" / es.STATE), np.load(tmp_path / "two" / es.STATE)
    assert np.array_equal(a["theta"], b["theta"])
    assert np.array_equal(a["theta_average"], b["theta_average"])
    want = es.averaged(a["theta"], a["theta_average"], 0.5, 3)
    assert not np.allclose(want, a["theta"])  # the average is not the last step
    layers, _ = es.actor_layers(SB3Policy(tmp_path / "one" / "model.zip").model)
    assert np.allclose(es.get_parameters(layers[-1:]), want, atol=1e-7)
    hist = json.loads((tmp_path / "one" / es.HISTORY).read_text())
    assert all(0 <= r["members_guarded"] <= 2 for r in hist) and one["generations"] == 3
    assert hist[0]["current_guarded"] is False  # generation 0's current is the start


def _scripted(monkeypatch, out, member_s, calls, member_ratio=None, member_watchdog=None):
    """``evaluate_population`` replaced by scripted normalised returns: the start and the
    current weights 1.0 on every stop, the members ``member_s`` (one row a member, + then -);
    their stopping distances the classical WSP's (the pool's ``d_classical``, else 100 m)
    times 1 for the start and the current weights and ``member_ratio`` for the members (1
    where not given); the watchdog on the members' stops ``member_watchdog`` (none where not
    given); the ``thetas`` it was given kept in ``calls``."""

    def fake(start, thetas, seeds, n_layers):
        pool = json.loads((out / es.POOL).read_text())
        i = [s - es.TRAINING_SEED_BASE for s in seeds]
        r0, r1 = np.array(pool["r_none"])[i], np.array(pool["r_classical"])[i]
        s = np.vstack([np.ones((2, len(seeds))), np.asarray(member_s, dtype=float)])
        ratio = np.ones(s.shape)
        if member_ratio is not None:
            ratio[2:] = member_ratio
        d = np.array(pool.get("d_classical", [100.0] * len(pool["seeds"])))[i]
        wd = np.zeros(s.shape, dtype=bool)
        if member_watchdog is not None:
            wd[2:] = member_watchdog
        calls.append(thetas.copy())
        return r0 + s * (r1 - r0), wd, ratio * d

    monkeypatch.setattr(es, "evaluate_population", fake)


def test_the_guard_turns_the_step_away_from_a_member_that_loses_a_stop(start, tmp_path):
    """One pair: the + member scores higher (the mean of 1.5 and 0.5 against 0.95) but loses
    0.5 on a stop. Without the guard the step goes its way; with a guard of 0.2, the other."""
    pool = tmp_path / "pool.json"
    _finetune(start, tmp_path / "p", 0)
    pool.write_text((tmp_path / "p" / es.POOL).read_text())
    moved = {}
    for guard in (0.0, 0.2):
        out = tmp_path / f"g{guard}"
        out.mkdir()
        (out / es.POOL).write_text(pool.read_text())
        calls = []
        with pytest.MonkeyPatch.context() as mp:
            _scripted(mp, out, [[1.5, 0.5], [0.95, 0.95]], calls)
            _finetune(start, out, 1, guard=guard)
        theta = calls[0][1]
        eps = calls[0][2] - theta
        moved[guard] = float((np.load(out / es.STATE)["theta"] - theta) @ eps)
        hist = json.loads((out / es.HISTORY).read_text())
        assert hist[0]["members_guarded"] == (1 if guard else 0)
    assert moved[0.0] > 0 > moved[0.2]


def test_the_distance_cap_turns_the_step_away_from_a_member_running_long(start, tmp_path):
    """One pair, scored alike on the score (the same normalised returns, mirrored), but the
    + member runs its second stop 1.3 times the classical WSP's distance and the - member
    1.0 times: without the cap the step goes the + member's way (its higher score), with a cap
    of 1.05 and a weight of 1 the other way, and the history carries the hinge's terms."""
    _finetune(start, tmp_path / "p", 0)
    pool = json.loads((tmp_path / "p" / es.POOL).read_text())
    assert len(pool["d_classical"]) == 4 and min(pool["d_classical"]) > 0  # a new pool has them
    moved = {}
    for cap in (0.0, 1.05):
        out = tmp_path / f"c{cap}"
        out.mkdir()
        (out / es.POOL).write_text(json.dumps(pool))
        calls = []
        with pytest.MonkeyPatch.context() as mp:
            # score (IQM of two stops: their mean) 1.02 against 1.0
            _scripted(mp, out, [[1.02, 1.02], [1.0, 1.0]], calls, [[1.0, 1.3], [1.0, 1.0]])
            _finetune(start, out, 1, ratio_cap=cap)
        theta = calls[0][1]
        eps = calls[0][2] - theta
        moved[cap] = float((np.load(out / es.STATE)["theta"] - theta) @ eps)
        row = json.loads((out / es.HISTORY).read_text())[0]
        assert ("hinge_current" in row) == bool(cap)
        if cap:
            assert row["hinge_current"] == 0.0 and row["stops_over_cap_current"] == 0
            assert row["fitness_current"] == row["score_current"]
    assert moved[0.0] > 0 > moved[1.05]


def test_the_watchdog_weight_turns_the_step_away_from_a_caught_member(start, tmp_path):
    """One pair: the + member scores higher (1.02 against 1.0) but the watchdog intervened
    on one of its two stops. Without the weight the step goes its way; with a weight of 0.1
    (a fitness of 1.02 - 0.05) the other way."""
    _finetune(start, tmp_path / "p", 0)
    pool = (tmp_path / "p" / es.POOL).read_text()
    moved = {}
    for weight in (0.0, 0.1):
        out = tmp_path / f"w{weight}"
        out.mkdir()
        (out / es.POOL).write_text(pool)
        calls = []
        with pytest.MonkeyPatch.context() as mp:
            _scripted(mp, out, [[1.02, 1.02], [1.0, 1.0]], calls,
                      member_watchdog=[[True, False], [False, False]])  # fmt: skip
            _finetune(start, out, 1, watchdog_weight=weight)
        theta = calls[0][1]
        moved[weight] = float((np.load(out / es.STATE)["theta"] - theta) @ (calls[0][2] - theta))
        row = json.loads((out / es.HISTORY).read_text())[0]
        assert ("fitness_current" in row) == bool(weight)
    assert moved[0.0] > 0 > moved[0.1]


def test_the_distance_hinge_is_the_mean_excess_over_the_cap():
    d_cls = np.array([100.0, 200.0, 400.0])
    d = np.array([[100.0, 200.0, 400.0], [130.0, 190.0, 440.0], [100.0, 300.0, 400.0]])
    h = es.distance_hinge(d / d_cls, 1.05)
    assert np.allclose(h, [0.0, (0.25 + 0.0 + 0.05) / 3, 0.45 / 3])
    assert np.allclose(es.distance_hinge(d / d_cls, 1.0), [0.0, 0.4 / 3, 0.5 / 3])


def test_a_pool_without_distances_gets_them_and_unscored_stops_enter_the_hinge_not_the_score(
    start, tmp_path
):
    """A pool written before it carried the classical WSP's distances (an older run's) gets
    them from the classical WSP when the cap asks for them, equal to a new pool's; with
    unscored stops drawn, the score is the same as without them; scripted, every member runs
    them after the scored ones, and the hinge and the watchdog share count them."""
    _finetune(start, tmp_path / "p", 0)
    pool = json.loads((tmp_path / "p" / es.POOL).read_text())
    old = {k: v for k, v in pool.items() if k != "d_classical"}
    out = tmp_path / "old"
    out.mkdir()
    (out / es.POOL).write_text(json.dumps(old))
    _finetune(start, out, 0, ratio_cap=1.05)
    assert json.loads((out / es.POOL).read_text())["d_classical"] == pool["d_classical"]
    # the pool's unscored stops, made so by the none's returns (an 8 s stop gains little)
    r_cls = np.array(pool["r_classical"])
    pool["r_none"][2:] = (r_cls[2:] - 0.01).tolist()  # under benchmark.MIN_GAIN
    pool["r_none"][:2] = (r_cls[:2] - 1.0).tolist()
    runs = {}
    for unscored in (0, 2):
        out = tmp_path / f"u{unscored}"
        out.mkdir()
        (out / es.POOL).write_text(json.dumps(pool))
        runs[unscored] = _finetune(start, out, 1, ratio_cap=1.05, unscored=unscored)["last"]
    assert runs[0]["score_current"] == runs[2]["score_current"]
    assert runs[0]["generation"] == runs[2]["generation"] == 0
    (tmp_path / "u3").mkdir()
    (tmp_path / "u3" / es.POOL).write_text(json.dumps(pool))
    with pytest.raises(ValueError, match="unscored: the pool holds 2 unscored stops, fewer"):
        _finetune(start, tmp_path / "u3", 1, ratio_cap=1.05, unscored=3)
    # scripted: every member runs the two scored stops, then the two unscored ones; each runs
    # its last stop (an unscored one) 1.3 times the classical WSP's distance, which the hinge
    # counts ((1.3 - 1.05) / 4 stops) and the score does not; the watchdog acts there too
    seen = []

    def fake(start_, thetas, seeds, n_layers):
        seen.append(list(seeds))
        i = [x - es.TRAINING_SEED_BASE for x in seeds]
        r1 = np.array(pool["r_classical"])[i]
        ratio = np.ones((len(thetas), len(seeds)))
        ratio[:, -1] = 1.3
        wd = np.zeros(ratio.shape, dtype=bool)
        wd[:, -1] = True
        d = np.array(pool["d_classical"])[i]
        return np.tile(r1, (len(thetas), 1)), wd, ratio * d

    out = tmp_path / "scripted"
    out.mkdir()
    (out / es.POOL).write_text(json.dumps(pool))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(es, "evaluate_population", fake)
        row = _finetune(start, out, 1, ratio_cap=1.05, unscored=2, watchdog_weight=0.1)["last"]
    assert len(seen[0]) == 4 and sorted(i - es.TRAINING_SEED_BASE for i in seen[0][2:]) == [2, 3]
    assert row["score_current"] == pytest.approx(1.0)  # the scored stops: the classical's
    assert row["hinge_current"] == pytest.approx(0.25 / 4)
    assert row["stops_over_cap_current"] == 1 and row["watchdog_stops_current"] == 1
    assert row["fitness_current"] == pytest.approx(1.0 - 0.25 / 4 - 0.1 / 4)


def test_the_current_member_is_the_average_of_the_steps_taken(start, tmp_path, monkeypatch):
    """Each generation's row 1 (scored as "current") is the bias-corrected exponential
    average of the steps taken so far, computed here from the members' centres."""
    _finetune(start, tmp_path / "p", 0)  # the pool, copied below
    calls = []
    out = tmp_path / "avg"
    out.mkdir()
    (out / es.POOL).write_text((tmp_path / "p" / es.POOL).read_text())
    _scripted(monkeypatch, out, [[1.2, 1.1], [0.9, 1.0]], calls)
    _finetune(start, out, 3, average=0.5)
    steps = [c[2:].mean(axis=0) for c in calls]  # generation g's centre: the g-th step
    assert np.allclose(calls[0][1], calls[0][0])  # no step yet: the start
    assert np.allclose(calls[1][1], steps[1], atol=1e-12)
    want = (0.25 * steps[1] + 0.5 * steps[2]) / 0.75
    assert np.allclose(calls[2][1], want, atol=1e-12)
    assert not np.allclose(calls[2][1], steps[2])


def test_the_average_is_bias_corrected_and_the_guard_names_tail_losses_and_new_watchdogs():
    theta = np.array([1.0, -2.0])
    total = np.zeros(2)
    for _ in range(3):  # the same iterate three times: its average is itself
        total = 0.9 * total + 0.1 * theta
    assert np.allclose(es.averaged(theta + 5, total, 0.9, 3), theta)
    assert np.array_equal(es.averaged(theta, total, 0.0, 3), theta)  # off: the last step
    assert np.array_equal(es.averaged(theta, total, 0.9, 0), theta)  # no step yet
    # rows: the start, then three members; columns: stops
    s = np.array([[1.0, 1.0, 1.0], [1.2, 1.1, 0.95], [1.3, 1.3, 0.7], [1.0, 1.0, 1.0]])
    wd = np.zeros_like(s, dtype=bool)
    wd[3, 0] = True  # a new intervention
    assert es.guarded(s, wd, 0.1).tolist() == [False, True, True]
    assert es.guarded(s, wd, 0.0).tolist() == [False, False, False]  # off
    wd[0, 0] = True  # where the start had one too, it does not count
    assert es.guarded(s, wd, 0.1).tolist() == [False, True, False]


def _untimed(row):
    return {k: v for k, v in row.items() if k != "wall_s"}


def test_the_pool_shares_no_seed_with_the_benchmark_or_any_suite():
    pool = set(range(es.TRAINING_SEED_BASE, es.TRAINING_SEED_BASE + es.MAX_POOL))
    for stop_set in ("sealed", "development"):
        assert not pool & set(sealed_seeds(stop_set=stop_set))
    suites = sorted((configs_root() / "scenarios").glob("*.yaml"))
    assert len(suites) >= 4
    for path in suites:
        assert not pool & set(load_suite(path.stem).seeds), path.stem


def test_centred_ranks_are_scale_free_and_share_ties():
    assert es.centred_ranks(np.array([3.0, 1.0, 2.0])).tolist() == [0.5, -0.5, 0.0]
    assert es.centred_ranks(np.array([1e-9, 1e9, 7.0])).tolist() == [-0.5, 0.5, 0.0]
    assert es.centred_ranks(np.array([1.0, 1.0, 0.0])).tolist() == [0.25, 0.25, -0.5]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--generations", "1"], "start: the model file to fine-tune is required"),
        (["{start}", "--generations", "1"], "--out: required"),
        (["{start}", "--out", "{out}", "--generations", "1", "--stops", "5", "--pool", "4"],
         "stops: 5 a generation, more than the pool's 4"),
        (["{start}", "--out", "{out}", "--generations", "1", "--pairs", "0"],
         "pairs: must be a whole number >= 1"),
        (["{start}", "--out", "{out}", "--generations", "1", "--layers", "9"],
         "layers: 1-3 for this actor, got 9"),
        (["--resume", "{out}", "--generations", "1"], "no fine-tune to resume"),
        (["{out}/missing.zip", "--out", "{out}", "--generations", "1"], "no such model file"),
        (["{start}", "--out", "{start}", "--generations", "1"], "a file, not a run folder"),
        (["{start}", "--out", "{out}", "--generations", "-1"], "--generations: must be >= 0"),
        (["{start}", "--out", "{out}", "--generations", "1", "--average", "1"],
         "average: must be a number in [0, 1)"),
        (["{start}", "--out", "{out}", "--generations", "1", "--guard", "-0.5"],
         "guard: must be a number >= 0"),
        (["{start}", "--out", "{out}", "--generations", "1", "--guard", "nan"],
         "guard: must be a number >= 0"),
        (["{start}", "--out", "{out}", "--generations", "1", "--ratio-cap", "0.9"],
         "ratio_cap: must be 0 (off) or a number in [1, 10)"),
        (["{start}", "--out", "{out}", "--generations", "1", "--ratio-weight", "-1"],
         "ratio_weight: must be a number >= 0"),
        (["{start}", "--out", "{out}", "--generations", "1", "--watchdog-weight", "inf"],
         "watchdog_weight: must be a number >= 0"),
        (["{start}", "--out", "{out}", "--generations", "1", "--unscored", "2"],
         "unscored: counts in the distance hinge and the watchdog share only; set ratio_cap"),
        (["{start}", "--out", "{out}", "--generations", "1", "--ratio-cap", "nan"],
         "ratio_cap: must be 0 (off) or a number in [1, 10)"),
        (["{start}", "--out", "{out}", "--generations", "1", "--ratio-cap", "1.05",
          "--unscored", "-1"], "unscored: must be a whole number >= 0"),
    ],
)  # fmt: skip
def test_bad_fine_tune_input_is_one_line_and_writes_nothing(start, tmp_path, capsys, argv,
                                                             message):  # fmt: skip
    out = tmp_path / "ft"
    argv = [a.format(start=start, out=out) for a in argv]
    assert main(["finetune", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err
    assert not out.exists() or not any(out.iterdir())


def test_es_curve_script_draws_a_history_and_refuses_a_missing_one(tmp_path, capsys):
    from conftest import script

    curve = script("es_curve")
    assert curve.moving_mean(np.array([1.0, 3.0, 5.0, 7.0]), 2).tolist() == [1.0, 2.0, 4.0, 6.0]
    run = tmp_path / "ft"
    run.mkdir()
    rows = [{"generation": g, "score_gain": 0.001 * g, "stops_better": 0.5} for g in range(4)]
    (run / "history.json").write_text(json.dumps(rows))
    assert curve.main([str(run), "--png", str(tmp_path / "c.png")]) == 0
    assert (tmp_path / "c.png").stat().st_size > 0
    assert curve.main([str(tmp_path / "nothing"), "--png", str(tmp_path / "d.png")]) == 2
    assert "nothing/history.json" in capsys.readouterr().err
    assert not (tmp_path / "d.png").exists()

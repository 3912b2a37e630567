"""``stagger_reset_steps`` of the vector env (a training option, off by default): ``reset``
leaves each environment a random, seeded number of steps into a stop, so stops do not all end
together; reproducible with a seed; in every action mode and with ``action_repeat`` the
warm-up is the stop the tier's classical WSP (or the mode's zero action) gives from the start,
driven every control period, with the residual's WSP or the slip-target loop advanced once per
period; ``SB3VecEnv``'s first episode statistics leave the warm-up out; a DAgger teacher is
reset after it; a bad value, or the option on a single environment, is one line."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from wsp_env.agents.sb3_vec import SB3VecEnv
from wsp_env.baselines.classical import ClassicalWSP, load_wsp_config
from wsp_env.baselines.slip_target import SlipTargetLoop, SlipTargetPolicy
from wsp_env.envs import WSPBrakingVectorEnv

OPTS = {"rail": "soap", "mu_contaminated": 0.08, "speed_kmh": 60.0, "pattern": "uniform"}


def _first_ends(venv: WSPBrakingVectorEnv) -> np.ndarray:
    """Steps until each environment's current stop ends, under the full demand."""
    n = venv.num_envs
    ends = np.full(n, -1)
    ones = np.ones(venv.action_space.shape, dtype=np.float32)
    for t in range(20000):
        _, _, term, trunc, _ = venv.step(ones)
        ended = (term | trunc) & (ends < 0)
        ends[ended] = t + 1
        if (ends >= 0).all():
            return ends
    raise AssertionError("the stops did not end")


def test_off_by_default_every_stop_starts_at_its_beginning():
    venv = WSPBrakingVectorEnv(num_envs=4)
    assert venv.stagger_reset_steps == 0
    venv.reset(seed=1, options=OPTS)
    np.testing.assert_array_equal(venv.episode_steps, 0)
    np.testing.assert_array_equal(venv.core.sim.time_s, 0.0)


def test_staggered_reset_is_reproducible_with_a_seed_and_spreads_the_ends():
    """Same seed: the same offsets, observations, scenarios and steps after; another seed:
    other offsets. Stops of one scenario then end at spread steps (unstaggered, within a few
    steps of each other)."""
    first = WSPBrakingVectorEnv(num_envs=6, stagger_reset_steps=400)
    second = WSPBrakingVectorEnv(num_envs=6, stagger_reset_steps=400)
    obs1, info1 = first.reset(seed=7, options=OPTS)
    obs2, info2 = second.reset(seed=7, options=OPTS)
    np.testing.assert_array_equal(obs1, obs2)
    np.testing.assert_array_equal(first.episode_steps, second.episode_steps)
    assert list(info1["scenario"]) == list(info2["scenario"])
    offsets = first.episode_steps.copy()
    assert offsets.max() < 400 and len(set(offsets.tolist())) == 6
    np.testing.assert_allclose(first.core.sim.time_s, 0.02 * offsets, atol=1e-9)
    ends = _first_ends(first)
    np.testing.assert_array_equal(ends, _first_ends(second))
    other = WSPBrakingVectorEnv(num_envs=6, stagger_reset_steps=400)
    other.reset(seed=8, options=OPTS)
    assert not np.array_equal(other.episode_steps, offsets)
    plain = WSPBrakingVectorEnv(num_envs=6)
    plain.reset(seed=7, options=OPTS)
    together = _first_ends(plain)
    assert np.ptp(ends) > np.ptp(together) + 100


def _driven_alone(mode: str, k: int, seed: int, fresh: bool, periods: int) -> WSPBrakingVectorEnv:
    """One environment's stop as the warm-up should leave it: reset with ``seed`` (``fresh``:
    then started anew, its next scenario, as the warm-up does), then ``periods`` control
    periods driven from outside by the classical WSP of the tier (discrete mode: its vent /
    hold / fill; residual: the classical WSP on a continuous environment, which the zero
    residual is) or, for the slip-target mode, the same loop at the middle target."""
    own = mode if mode == "discrete" else "continuous"
    env = WSPBrakingVectorEnv(num_envs=1, action_mode=own)
    obs, _ = env.reset(seed=[seed], options=OPTS)
    if fresh:
        env.core.reset_env(0, OPTS)
        obs = env.core.obs.copy()
    if mode == "slip_target":
        driver = SlipTargetPolicy(4.25, SlipTargetLoop(load_wsp_config()))
    else:
        driver = ClassicalWSP(load_wsp_config())
    driver.bind(env.core)
    driver.reset(np.arange(1))
    for _ in range(periods):
        a = driver.act(obs)
        if mode == "discrete":
            a = np.where(a <= -1.0, 0.0, np.where(a >= 1.0, 2.0, 1.0))
        obs, *_ = env.step(a)
    return env


@pytest.mark.parametrize("k", [1, 5])
@pytest.mark.parametrize("mode", ["continuous", "discrete", "residual", "slip_target"])
def test_every_action_mode_staggers_as_its_driver_drives(mode, k):
    """Three environments, ``action_repeat`` 1 and 5: each is left ``episode_steps`` steps
    (``k`` periods each) into a stop, and that stop — the first one, or the next one where it
    started anew within the warm-up — is bit for bit the one its driver gives from outside
    period by period: the physical state and the kernel's observation. Driven once per step
    instead of once per period (what the warm-up did with ``action_repeat > 1``), the
    classical WSP's timers run 5 times slow and the stops differ."""
    seed, n = 11, 3
    venv = WSPBrakingVectorEnv(
        num_envs=n, action_mode=mode, action_repeat=k, stagger_reset_steps=60
    )
    obs, _ = venv.reset(seed=seed, options=OPTS)
    steps = venv.episode_steps.copy()
    assert len(set(steps.tolist())) == n and steps.max() > 20
    np.testing.assert_allclose(venv.core.sim.time_s, 0.02 * k * steps, atol=1e-9)
    width = venv.core.kernel_obs_dim
    for i in range(n):
        alone = _driven_alone(mode, k, seed + i, steps[i] < steps.max(), int(steps[i]) * k)
        sim, ref = venv.core.sim, alone.core.sim
        np.testing.assert_array_equal(sim.env_state[i], ref.env_state[0])
        np.testing.assert_array_equal(sim.axle_state[i], ref.axle_state[0])
        np.testing.assert_array_equal(obs[i, :width], alone.core.obs[0, :width])


@pytest.mark.parametrize("k", [1, 5])
@pytest.mark.parametrize("mode", ["residual", "slip_target"])
def test_warm_up_advances_the_inner_controller_once_per_period(mode, k):
    """The residual's classical WSP and the slip-target loop advance exactly once per control
    period through the warm-up (environments started anew in it included) and the read that
    ``reset`` returns: ``periods + 1`` calls; one more per period after. Before the fix (an
    environment started anew after the last step's read, so read again): 49 calls for 45
    periods here (46 expected), 229 for 225 with ``action_repeat`` 5."""
    venv = WSPBrakingVectorEnv(
        num_envs=4, action_mode=mode, action_repeat=k, stagger_reset_steps=50
    )
    core = venv.core
    controller, method = (core.base, "act") if mode == "residual" else (core.loop, "advance")
    calls = []
    inner = getattr(controller, method)

    def counted(*args, **kwargs):
        calls.append(core.sim.time_s.copy())
        return inner(*args, **kwargs)

    setattr(controller, method, counted)
    venv.reset(seed=0, options=OPTS)
    periods = int(venv.episode_steps.max()) * k
    assert periods > 0 and len(set(venv.episode_steps.tolist())) > 1
    assert len(calls) == periods + 1
    venv.step(np.zeros((4, 4), dtype=np.float32))
    assert len(calls) == periods + 1 + k


def test_sb3_episode_statistics_leave_the_warm_up_out():
    """``SB3VecEnv`` over a staggered env: each first episode's ``r`` is the sum of the rewards
    the adapter returned since ``reset`` and ``l`` their count (the warm-up's return, in the
    stop's metrics, is left out of both)."""
    env = SB3VecEnv(num_envs=3, stagger_reset_steps=300, scenario={"speed_kmh": [30.0, 40.0]})
    env.seed(0)  # unseeded, a low-adhesion draw now and then outlasted the 5,000 steps
    env.reset()
    warm = env.venv.core.episode_return.copy()
    assert (env.venv.episode_steps > 0).sum() >= 2 and (warm != 0.0).sum() >= 2
    returns = np.zeros(3)
    lengths = np.zeros(3, dtype=np.int64)
    seen: dict[int, dict] = {}
    ones = np.ones((3, 4), dtype=np.float32)
    for _ in range(5000):
        env.step_async(ones)
        _, rewards, dones, infos = env.step_wait()
        returns += rewards
        lengths += 1
        for i in np.flatnonzero(dones):
            if i not in seen:
                seen[i] = infos[i]["episode"]
                assert seen[i]["l"] == lengths[i]
                assert seen[i]["r"] == pytest.approx(returns[i], rel=1e-5)
                whole = infos[i]["metrics"]["episode_return"]
                assert whole == pytest.approx(warm[i] + returns[i], rel=1e-5)
        if len(seen) == 3:
            break
    assert len(seen) == 3


@pytest.mark.parametrize("bad", [-1, 100_001, 2.5, True, "10"])
def test_bad_stagger_is_one_line(bad):
    with pytest.raises(
        ValueError, match=r"^stagger_reset_steps: must be an integer 0-100000, got "
    ):
        WSPBrakingVectorEnv(num_envs=2, stagger_reset_steps=bad)


@pytest.mark.parametrize(
    "make",
    [
        lambda: gym.make("WSPBraking-v0", stagger_reset_steps=50),
        lambda: gym.make_vec(
            "WSPBraking-v0", num_envs=2, vectorization_mode="sync", stagger_reset_steps=50
        ),
    ],
    ids=["make", "make_vec_sync"],
)
def test_single_environment_refuses_the_stagger_in_one_line(make):
    with pytest.raises(
        ValueError, match=r"^stagger_reset_steps: a vector-environment option"
    ) as err:
        make()
    assert len(str(err.value).splitlines()) == 1
    venv = gym.make_vec(
        "WSPBraking-v0", num_envs=2, vectorization_mode="vector_entry_point", stagger_reset_steps=5
    )
    assert venv.unwrapped.stagger_reset_steps == 5


def test_dagger_teacher_is_reset_after_the_warm_up(monkeypatch):
    """``pretrain`` resets its teacher once the staggered ``reset`` has driven the stops in: a
    teacher with memory then starts with the stops it takes over, not before them."""
    from wsp_env.training import imitation

    class SeenError(Exception):
        pass

    class Teacher:
        def bind(self, core):
            self.core = core

        def reset(self, env_ids):
            self.times = self.core.sim.time_s[env_ids].copy()

        def act(self, obs):
            raise SeenError

    teacher = Teacher()
    monkeypatch.setattr(imitation, "make_teacher", lambda name, *args: teacher)
    env = SB3VecEnv(num_envs=3, stagger_reset_steps=100)
    with pytest.raises(SeenError):
        imitation.pretrain(None, env, env.venv.core, imitation.PretrainConfig(), gamma=0.99)
    np.testing.assert_array_equal(teacher.times, env.venv.core.sim.time_s)
    assert (teacher.times > 0.0).sum() >= 2


def test_the_adapters_counters_round_trip_for_a_resume():
    """``SB3VecEnv.state_dict``: each stop's steps and periods towards its limit and the
    adapter's episode length and warm-up return come back in a new adapter (a resumed run's
    episode statistics and time limits go on where they were); another size is refused."""
    kwargs = {"num_envs": 3, "scenario": {"speed_kmh": [30, 40]}, "stagger_reset_steps": 20}
    a = SB3VecEnv(**kwargs)
    a.seed(5)
    a.reset()
    for _ in range(7):
        a.step(np.zeros((3, a.action_space.shape[0]), dtype=np.float32))
    state = a.state_dict()
    assert (state["_lengths"] == 7).all() and (state["episode_periods"] >= 7).all()
    b = SB3VecEnv(**kwargs)
    b.load_state_dict(state)
    for k, v in state.items():
        np.testing.assert_array_equal(b.state_dict()[k], v)
    with pytest.raises(ValueError, match="episode_steps for"):
        SB3VecEnv(**{**kwargs, "num_envs": 2}).load_state_dict(state)

"""The thread policy (``wsp_env.threads``): the rule per role and core count, the overrides'
one-line errors, the adaptive update-thread choice, and that thread counts do not change what
training computes (reproducibility does not depend on which count the timing picked)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from wsp_env import threads
from wsp_env.threads import NEVER, AdaptiveThreads, ThreadPolicyError, thread_policy


@pytest.fixture(autouse=True)
def _no_overrides(monkeypatch):
    for name in (threads.ENV_TORCH, threads.ENV_NUMBA, threads.ENV_PARALLEL):
        monkeypatch.delenv(name, raising=False)


def test_rule_per_role_and_core_count():
    # a learner in the process on few cores: the kernel serial, torch 1 thread in rollouts
    p = thread_policy("train", cores=2)
    assert p.parallel_min_envs == NEVER and p.numba_threads == 1
    assert p.rollout_torch_threads == 1 and p.update_torch_threads == (1, 2)
    # no learner: the kernel's parallel path from 64 environments on every core
    e = thread_policy("evaluate", cores=2)
    assert e.parallel_min_envs == 64 and e.numba_threads == 2
    big = thread_policy("train", cores=16)
    assert big.parallel_min_envs == 256 and big.numba_threads == 8
    assert big.update_torch_threads == (1, 2, 4, 8)
    assert thread_policy("train", cores=1).update_torch_threads == (1,)


def test_overrides_and_their_errors(monkeypatch):
    monkeypatch.setenv(threads.ENV_TORCH, "3")
    monkeypatch.setenv(threads.ENV_PARALLEL, "0")
    p = thread_policy("evaluate", cores=2)
    assert p.update_torch_threads == (3,) and p.parallel_min_envs == NEVER
    assert "WSP_TORCH_THREADS=3" in p.source
    monkeypatch.setenv(threads.ENV_TORCH, "two")
    with pytest.raises(ThreadPolicyError, match=r"^WSP_TORCH_THREADS='two': not an integer$"):
        thread_policy("train")
    monkeypatch.setenv(threads.ENV_TORCH, "0")
    with pytest.raises(ThreadPolicyError, match=r"^WSP_TORCH_THREADS=0: must be >= 1$"):
        thread_policy("train")
    with pytest.raises(ThreadPolicyError, match="role"):
        thread_policy("serve")  # type: ignore[arg-type]


def test_the_kernel_follows_the_applied_policy(monkeypatch):
    from wsp_env.core.braking import BrakingCore
    from wsp_env.core.kernel import env_step_parallel, env_step_serial

    before = threads.active_policy()
    try:
        threads.apply(thread_policy("train", cores=2))
        assert BrakingCore(n_envs=64)._step_fn is env_step_serial
        threads.apply(thread_policy("evaluate", cores=2))
        assert BrakingCore(n_envs=64)._step_fn is env_step_parallel
        assert BrakingCore(n_envs=63)._step_fn is env_step_serial
    finally:
        threads.apply(before)


def test_adaptive_threads_pick_the_fastest_and_probe_again(monkeypatch):
    """A fake clock: 2 threads twice as fast until the machine gets busy, then 1 is faster."""
    clock = [0.0]
    cost = {1: 1.0, 2: 0.5}
    monkeypatch.setattr(threads.time, "perf_counter", lambda: clock[0])
    monkeypatch.setattr(threads, "set_torch_threads", lambda n: None)
    a = AdaptiveThreads((1, 2), reprobe_every=4)
    used = []

    def update() -> None:
        used.append(a.begin_update())
        clock[0] += cost[used[-1]]
        a.end_update()

    for _ in range(8):
        update()
    # warm-up, each candidate once, the fastest; every 4 updates each candidate again
    assert used == [1, 1, 2, 2, 2, 1, 2, 2]
    cost.update({1: 1.0, 2: 3.0})  # a busy neighbour: 2 threads now lose
    for _ in range(8):
        update()
    assert used[-1] == 1 and a.choice() == 1


def _train_hash(threads_n: int) -> str:
    code = f"""
import hashlib, torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from wsp_env import threads
from wsp_env.agents.sb3_vec import SB3VecEnv
threads.apply(threads.thread_policy("train", cores=2))
class Set(BaseCallback):
    def _on_step(self): return True
    def _on_rollout_end(self): torch.set_num_threads({threads_n})
    def _on_rollout_start(self): torch.set_num_threads(1)
venv = SB3VecEnv(num_envs=8, scenario={{"speed_kmh": [20.0, 40.0]}})
m = PPO("MlpPolicy", venv, n_steps=64, batch_size=256, n_epochs=2, seed=0, device="cpu",
        policy_kwargs={{"net_arch": [64, 64]}})
m.learn(1024, callback=Set())
print(hashlib.sha1(b"".join(p.detach().numpy().tobytes()
                            for p in m.policy.parameters())).hexdigest())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.strip().splitlines()[-1]


def test_update_thread_count_does_not_change_the_weights():
    """What AdaptiveThreads picks depends on timing; the trained weights must not."""
    assert _train_hash(1) == _train_hash(2)


def test_bench_train_quick_measures_both_learners(tmp_path, capsys):
    """``wsp-env bench --train``: WSP and CartPole through the same learner settings."""
    import json

    from wsp_env.cli import main

    out = tmp_path / "train_bench.json"
    assert main(["bench", "--train", "--quick", "--repeats", "1", "--rollouts", "1",
                 "--json", str(out)]) == 0  # fmt: skip
    r = json.loads(out.read_text())
    assert r["wsp_env_steps_per_s"] > 0 and r["cartpole_env_steps_per_s"] > 0
    assert r["ratio_to_cartpole"] == pytest.approx(
        r["wsp_env_steps_per_s"] / r["cartpole_env_steps_per_s"]
    )
    assert r["threads"]["role"] == "train" and r["threads"]["parallel_min_envs"] is None
    assert r["steps_per_run"] == 4 * 32  # quick: 4 envs x 32 steps, one rollout
    assert "ratio WSP / CartPole" in capsys.readouterr().out
    assert main(["bench", "--busy", "1"]) == 2
    assert "--busy: only with --train" in capsys.readouterr().err


def test_applied_restores_the_process_state():
    """A training run in a longer-lived process leaves its threads as it found them."""
    import torch

    before_torch, before = torch.get_num_threads(), threads.active_policy()
    with threads.applied(thread_policy("train", cores=2)) as p:
        assert threads.active_policy() is p and torch.get_num_threads() == 1
        assert threads.parallel_min_envs() == NEVER
    assert torch.get_num_threads() == before_torch
    assert threads.active_policy() == before

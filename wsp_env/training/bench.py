"""``wsp-env bench --train``: training throughput, env-steps per second **including updates**,
for a shipped training config, beside SB3's PPO on gymnasium's CartPole-v1 with the same
learner settings, in the same run.

Both runs use the same algorithm class and hyperparameters (``n_envs``, ``n_steps``,
``batch_size``, ``n_epochs``, ...), network (``policy_kwargs``), device (CPU) and thread
policy (``wsp_env.threads``, role ``train``: torch's update threads chosen by timing,
``AdaptiveThreads``); CartPole runs on SB3's
own ``DummyVecEnv`` (``make_vec_env``), without normalisation or frame stack, WSP on exactly
what ``wsp-env train`` builds from the config (``train.make_training_env``). The ratio
``wsp / cartpole`` says whether the learner (near 1) or the physics (well below 1) bounds
training.

Each figure is the median of ``repeats`` timed ``learn`` calls of ``rollouts`` rollouts each
(the steps collected and the updates on them), after one warm-up rollout and update (torch's
first backward pass and numba's compilation are not timed). ``busy``: this many busy-looping
processes run beside the measurement (a shared machine), started before and stopped after.
"""

from __future__ import annotations

import multiprocessing
import os
import platform
import statistics
import time
from collections.abc import Callable
from typing import Any

from wsp_env.threads import AdaptiveThreads, ThreadPolicy, applied, thread_policy
from wsp_env.training.config import (
    algo_class,
    algo_hyperparams,
    algo_policy_kwargs,
    load_train_config,
)
from wsp_env.training.train import make_training_env, thread_switch

DEFAULT_CONFIG = "ppo_uic_z1"


def _spin() -> None:  # a competing process: one core's worth of busy work
    while True:
        pass


def _learn_rate(make_model: Callable[[], Any], steps: int, repeats: int) -> dict[str, Any]:
    """Median env-steps/s of ``repeats`` timed ``learn(steps)`` calls of one model."""
    model, adaptive = make_model()
    per_rollout = model.n_envs * model.n_steps
    model.learn(per_rollout, callback=thread_switch(adaptive))  # warm-up
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        model.learn(steps, callback=thread_switch(adaptive), reset_num_timesteps=False)
        rates.append(steps / (time.perf_counter() - t0))
    return {
        "env_steps_per_s": statistics.median(rates),
        "runs": rates,
        "update_threads": adaptive.as_dict(),
    }


def run_train_bench(
    config: str = DEFAULT_CONFIG,
    rollouts: int = 4,
    repeats: int = 3,
    busy: int = 0,
    quick: bool = False,
) -> dict[str, Any]:
    """The figures of ``wsp-env bench --train`` (module docstring). ``quick``: 4 environments'
    tiny rollouts, for tests."""
    with applied(thread_policy("train")) as policy:
        return _measure(config, rollouts, repeats, busy, quick, policy)


def _measure(
    config: str, rollouts: int, repeats: int, busy: int, quick: bool, policy: ThreadPolicy
) -> dict[str, Any]:
    import torch
    from stable_baselines3.common.env_util import make_vec_env

    cfg = load_train_config(config)
    if cfg.algo not in ("ppo", "recurrent_ppo"):
        raise ValueError(f"{config}: bench --train measures PPO configs, not {cfg.algo}")
    hyper = algo_hyperparams(cfg)
    if quick:
        import dataclasses

        cfg = dataclasses.replace(cfg, n_envs=4)
        hyper.update(n_steps=32, batch_size=64, n_epochs=1)
    cls = algo_class(cfg.algo)
    kwargs = algo_policy_kwargs(cfg) or None
    steps = rollouts * cfg.n_envs * int(hyper.get("n_steps", 2048))

    def wsp_model() -> tuple[Any, AdaptiveThreads]:
        torch.manual_seed(0)
        env = make_training_env(cfg)
        model = cls(cfg.policy, env, seed=0, policy_kwargs=kwargs, device="cpu", **hyper)
        return model, AdaptiveThreads(policy.update_torch_threads, policy.rollout_torch_threads)

    def cartpole_model() -> tuple[Any, AdaptiveThreads]:
        env = make_vec_env("CartPole-v1", n_envs=cfg.n_envs, seed=0)
        model = cls(cfg.policy, env, seed=0, policy_kwargs=kwargs, device="cpu", **hyper)
        return model, AdaptiveThreads(policy.update_torch_threads, policy.rollout_torch_threads)

    spinners = [multiprocessing.get_context("spawn").Process(target=_spin, daemon=True)
                for _ in range(busy)]  # fmt: skip
    for sp in spinners:
        sp.start()
    try:
        wsp = _learn_rate(wsp_model, steps, repeats)
        cartpole = _learn_rate(cartpole_model, steps, repeats)
    finally:
        for sp in spinners:
            sp.terminate()
            sp.join()
    return {
        "config": cfg.source or config,
        "algo": cfg.algo,
        "n_envs": cfg.n_envs,
        "n_steps": int(hyper.get("n_steps", 2048)),
        "batch_size": int(hyper.get("batch_size", 64)),
        "n_epochs": int(hyper.get("n_epochs", 10)),
        "net_arch": (cfg.policy_kwargs or {}).get("net_arch"),
        "frame_stack": cfg.frame_stack,
        "normalize": cfg.normalize is not None,
        "steps_per_run": steps,
        "wsp_env_steps_per_s": wsp["env_steps_per_s"],
        "cartpole_env_steps_per_s": cartpole["env_steps_per_s"],
        "ratio_to_cartpole": wsp["env_steps_per_s"] / cartpole["env_steps_per_s"],
        "wsp_runs": wsp["runs"],
        "cartpole_runs": cartpole["runs"],
        "wsp_update_threads": wsp["update_threads"],
        "cartpole_update_threads": cartpole["update_threads"],
        "busy_processes": busy,
        "threads": policy.as_dict(),
        "repeats": repeats,
        "statistic": "median",
        "quick": quick,
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "torch": torch.__version__,
        },
    }


def format_train_bench(r: dict[str, Any]) -> str:
    net = r["net_arch"]
    return "\n".join(
        [
            f"PPO training, env-steps/s including updates ({r['config']}: {r['n_envs']} envs, "
            f"n_steps {r['n_steps']}, batch {r['batch_size']}, {r['n_epochs']} epochs, "
            f"net {net}, frame stack {r['frame_stack']})",
            f"  WSP (uic_z1):  {r['wsp_env_steps_per_s']:>10,.0f}"
            f"   update threads {r['wsp_update_threads']['choice']}",
            f"  CartPole-v1:   {r['cartpole_env_steps_per_s']:>10,.0f}"
            f"   update threads {r['cartpole_update_threads']['choice']}",
            f"  ratio WSP / CartPole: {r['ratio_to_cartpole']:.2f}"
            f"   (medians over {r['repeats']} runs; {r['busy_processes']} busy process(es) "
            f"beside; {r['machine']['cpus']} cpus{'; quick' if r['quick'] else ''})",
        ]
    )

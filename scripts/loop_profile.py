"""Where a batch of stops spends its wall time: every control period timed against the number of
stops still running (the evaluation's code path, ``runner.run_runs``, on the benchmark's stops).

    .venv/bin/python scripts/loop_profile.py runs/train/bc_st_s1/student.zip [--stops 100]
        [--set development] [--tier wheels+accel]

A batch runs as long as its longest stop; this shows how much of its time is the tail where only
a few stops still run (the fine-tune's generations: docs/training.md). Run it twice: the first
run of a session may include numba's compilation.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from wsp_env.core.config import load_vehicle
from wsp_env.envs.tiers import benchmark_env_kwargs
from wsp_env.evaluation.benchmark import POLICY_KEYS, sealed_runs
from wsp_env.evaluation.runner import run_runs
from wsp_env.policy import make_policy


class _Timed:
    """The policy, with the wall clock and the live stops read at every decision."""

    def __init__(self, inner: Any) -> None:
        self.inner, self.name, self.privileged = inner, inner.name, inner.privileged
        self.times: list[float] = []
        self.live: list[int] = []

    def __getattr__(self, attr: str) -> Any:
        return getattr(self.inner, attr)

    def bind(self, core: Any) -> None:
        self.core = core
        self.inner.bind(core)

    def reset(self, env_ids: np.ndarray) -> None:
        self.inner.reset(env_ids)

    def act(self, obs: np.ndarray) -> np.ndarray:
        self.times.append(time.perf_counter())
        self.live.append(int((~self.core.sim.stopped).sum()))
        return self.inner.act(obs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("policy", help="a policy make_policy takes (a model file, classical, ...)")
    ap.add_argument("--stops", type=int, default=100)
    ap.add_argument("--set", default="development", choices=("development", "sealed"))
    ap.add_argument("--tier", default="wheels+accel", choices=("wheels", "wheels+accel"))
    args = ap.parse_args()
    vehicle = load_vehicle("uic_z1")
    runs = sealed_runs(vehicle, args.stops, args.set)
    kwargs = benchmark_env_kwargs("uic_z1", args.tier)
    kwargs.pop("vehicle")
    max_time_s = kwargs.pop("max_time_s")
    policy = _Timed(make_policy(args.policy, tier=args.tier))  # the tier: classical's only
    start = time.perf_counter()
    run_runs(vehicle, runs, policy, env_kwargs=kwargs, max_time_s=max_time_s,
             policy_keys=POLICY_KEYS)  # fmt: skip
    total = time.perf_counter() - start
    period = np.diff(np.array([*policy.times, time.perf_counter()]))
    live = np.array(policy.live)
    print(f"{args.stops} stops: {total:.1f} s, {period.size} control periods, "
          f"median {1e3 * np.median(period):.2f} ms a period")  # fmt: skip
    n = args.stops
    for lo, hi in ((n // 2 + 1, n), (n // 10 + 1, n // 2), (1, n // 10)):
        m = (live >= lo) & (live <= hi)
        share = 100 * period[m].sum() / period.sum()
        med = 1e3 * np.median(period[m]) if m.any() else 0.0
        print(f"  {lo}-{hi} stops running: {int(m.sum())} periods, {period[m].sum():.1f} s "
              f"({share:.0f} %), median {med:.2f} ms")  # fmt: skip


if __name__ == "__main__":
    main()

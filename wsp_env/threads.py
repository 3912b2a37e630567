"""The thread policy: how many threads numba's compiled step and torch's learner may use.

Both libraries keep a pool of worker threads that spin while they wait for the next parallel
region. On a machine with few cores, two such pools in one process (or one pool and a process
that shares the machine) take turns badly: a parallel region waits for its slowest thread, and
a thread that lost its core to someone else holds everyone up. Measured on the project's
2-core machine (``docs/training.md``, *Threads*; PPO, 64 environments, 128x128 networks,
frame stack 4), env-steps/s including updates:

=====================================================  ======  =================================
threads                                                 idle    one busy process beside it
=====================================================  ======  =================================
torch 2, kernel parallel at >= 64 envs (the old rule)   37.5k   12.5k
torch 1, kernel parallel                                31.4k   10.5k
torch 2, kernel serial                                  37.1k   11.7k
torch 1, kernel serial                                  26.4k   27.2k
=====================================================  ======  =================================

So, when a learner shares the process (``role="train"``):

* the kernel steps **serially** below 8 cores: its parallel path adds ~4 % to a rollout's
  speed on 2 cores (the learner's forward pass dominates), and it is what fights torch (numba's
  OpenMP layer also resets the OpenMP thread count that torch reads, which is why
  ``torch.set_num_threads(1)`` read back 2). From 8 cores it runs in parallel from 256
  environments with half the cores (not measured here: no such machine in the project yet);
* torch uses **1 thread while collecting rollouts** (forward passes of one observation per
  environment: too small to split);
* torch's **update** thread count is chosen by measurement (``AdaptiveThreads``): each candidate
  (1, 2, 4, 8 up to the core count) times one update, the fastest is used, and the others are
  timed again every ``reprobe_every`` updates, so a run that starts sharing the machine moves
  to 1 thread within that many updates and back when the machine frees up.

Without a learner (``role="evaluate"``: suites, the benchmark, calibration) the kernel's
parallel path runs from 64 environments on all cores, as before.

Overrides (documented in ``docs/training.md``), read when a policy is made: ``WSP_CORES=N``
the cores to plan for (a sweep sets it to a trial's declared CPUs), ``WSP_TORCH_THREADS=N``
pins the update threads (no probing), ``WSP_NUMBA_THREADS=N`` the kernel's threads and
``WSP_PARALLEL_MIN_ENVS=N`` where its parallel path starts (``0``: never).
Thread counts do not change results: torch's CPU kernels split work over outputs, not over
sums (``tests/test_threads.py`` trains with 1 and with 2 update threads and compares
parameters bit for bit), and the kernel gives the same numbers serial or parallel.

The bottom layer: imports nothing from ``wsp_env``; numba and torch only inside functions.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Literal

Role = Literal["train", "evaluate"]
ROLES: tuple[str, ...] = ("train", "evaluate")
NEVER = 2**62  # a parallel threshold no environment count reaches
ENV_TORCH = "WSP_TORCH_THREADS"
ENV_NUMBA = "WSP_NUMBA_THREADS"
ENV_PARALLEL = "WSP_PARALLEL_MIN_ENVS"
ENV_CORES = "WSP_CORES"
CANDIDATES = (1, 2, 4, 8)


class ThreadPolicyError(ValueError):
    """A thread override that is not a usable number (one line naming the variable)."""


def available_cores() -> int:
    """Cores this process may run on: ``WSP_CORES`` where set (a sweep's trial: the CPUs it
    declared to Ray), else its CPU affinity (which containers and ``taskset`` set;
    ``os.cpu_count()`` counts the machine's)."""
    declared = _env_int(ENV_CORES, 1)
    if declared is not None:
        return declared
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


@dataclass(frozen=True)
class ThreadPolicy:
    """Thread counts for one process (module docstring)."""

    role: str
    cores: int
    numba_threads: int
    parallel_min_envs: int  # the kernel steps in parallel from this many environments
    rollout_torch_threads: int
    update_torch_threads: tuple[int, ...]  # one entry: fixed; several: probed (AdaptiveThreads)
    source: str = "auto"

    def as_dict(self) -> dict[str, object]:
        return {
            "role": self.role,
            "cores": self.cores,
            "numba_threads": self.numba_threads,
            "parallel_min_envs": None
            if self.parallel_min_envs >= NEVER
            else self.parallel_min_envs,
            "rollout_torch_threads": self.rollout_torch_threads,
            "update_torch_threads": list(self.update_torch_threads),
            "source": self.source,
        }


def _env_int(name: str, low: int) -> int | None:
    text = os.environ.get(name)
    if text is None or text.strip() == "":
        return None
    try:
        value = int(text)
    except ValueError:
        raise ThreadPolicyError(f"{name}={text!r}: not an integer") from None
    if value < low:
        raise ThreadPolicyError(f"{name}={value}: must be >= {low}")
    return value


def thread_policy(role: Role = "evaluate", cores: int | None = None) -> ThreadPolicy:
    """The policy for a process of this ``role`` on ``cores`` cores (default: its affinity),
    with the environment's overrides applied."""
    if role not in ROLES:
        raise ThreadPolicyError(f"role: {role!r} (one of {', '.join(ROLES)})")
    n = available_cores() if cores is None else int(cores)
    if n < 1:
        raise ThreadPolicyError(f"cores: {n} (must be >= 1)")
    if role == "evaluate":
        numba, par_min = n, (64 if n > 1 else NEVER)
    elif n >= 8:
        numba, par_min = n // 2, 256
    else:
        numba, par_min = 1, NEVER
    updates = tuple(c for c in CANDIDATES if c <= n) or (1,)
    source = "auto"
    pinned = _env_int(ENV_TORCH, 1)
    if pinned is not None:
        updates, source = (pinned,), f"{ENV_TORCH}={pinned}"
    numba_env = _env_int(ENV_NUMBA, 1)
    if numba_env is not None:
        numba, source = numba_env, f"{source}, {ENV_NUMBA}={numba_env}"
    par_env = _env_int(ENV_PARALLEL, 0)
    if par_env is not None:
        par_min = NEVER if par_env == 0 else par_env
        source = f"{source}, {ENV_PARALLEL}={par_env}"
    return ThreadPolicy(role, n, numba, par_min, 1, updates, source)


_ACTIVE: list[ThreadPolicy] = []


def active_policy() -> ThreadPolicy:
    """The policy last applied in this process (``apply``), else the evaluate policy."""
    return _ACTIVE[-1] if _ACTIVE else thread_policy("evaluate")


def parallel_min_envs() -> int:
    """From how many environments the kernel steps in parallel under the active policy."""
    return active_policy().parallel_min_envs


def apply(policy: ThreadPolicy) -> ThreadPolicy:
    """Make ``policy`` the process's (this thread's, for numba): numba's thread count (capped
    at the pool numba starts with), torch's (if torch is installed) at the rollout count, and
    the kernel's parallel threshold for environments built from now on."""
    if policy.parallel_min_envs < NEVER:  # only where the parallel path may run: setting it
        import numba  # starts numba's pool, whose OpenMP layer resets torch's thread count

        if policy.numba_threads < numba.config.NUMBA_NUM_THREADS:
            numba.set_num_threads(max(1, policy.numba_threads))
    set_torch_threads(policy.rollout_torch_threads)
    _ACTIVE[:] = [policy]
    return policy


@contextlib.contextmanager
def applied(policy: ThreadPolicy) -> Iterator[ThreadPolicy]:
    """``apply(policy)`` for a ``with`` block; then the process's previous policy and torch's
    and numba's thread counts come back (a training run inside a longer-lived process, a
    test)."""
    saved = list(_ACTIVE)
    torch_before = _torch_threads()
    numba_before = None
    if policy.parallel_min_envs < NEVER:  # apply may change numba's count then only
        import numba

        numba_before = numba.get_num_threads()
    try:
        yield apply(policy)
    finally:
        _ACTIVE[:] = saved
        if torch_before is not None:
            set_torch_threads(torch_before)
        if numba_before is not None:
            import numba

            numba.set_num_threads(numba_before)


def _torch_threads() -> int | None:
    try:
        import torch
    except ImportError:
        return None
    return int(torch.get_num_threads())


def set_torch_threads(n: int) -> None:
    """``torch.set_num_threads(n)`` if torch is importable (training, policies); else nothing."""
    try:
        import torch
    except ImportError:
        return
    if torch.get_num_threads() != n:
        torch.set_num_threads(n)


@dataclass
class AdaptiveThreads:
    """Chooses torch's update thread count by timing updates (module docstring).

    ``begin_update()`` before an update sets the count to use and starts the clock;
    ``end_update()`` after it records the time. The first update is a warm-up (not counted);
    then each candidate is timed once, the fastest is used, and every ``reprobe_every``
    updates the others are timed again (one update each)."""

    candidates: tuple[int, ...]
    rollout_threads: int = 1
    reprobe_every: int = 16
    seconds: dict[int, float] = field(default_factory=dict)
    updates: int = 0
    _current: int = 0
    _t0: float = 0.0
    _queue: list[int] = field(default_factory=list)

    def choice(self) -> int:
        """The fastest candidate measured so far (the first candidate before any)."""
        if not self.seconds:
            return self.candidates[0]
        return min(self.seconds, key=lambda c: (self.seconds[c], c))

    def begin_update(self) -> int:
        if len(self.candidates) > 1 and self.updates >= 1:
            if self.updates == 1 or (self.updates - 1) % self.reprobe_every == 0:
                self._queue = list(self.candidates)  # time every candidate again
        self._current = self._queue.pop(0) if self._queue else self.choice()
        set_torch_threads(self._current)
        self._t0 = time.perf_counter()
        return self._current

    def end_update(self) -> None:
        dt = time.perf_counter() - self._t0
        if self.updates >= 1:  # the first update is a warm-up
            self.seconds[self._current] = dt
        self.updates += 1
        set_torch_threads(self.rollout_threads)

    def as_dict(self) -> dict[str, object]:
        return {
            "candidates": list(self.candidates),
            "choice": self.choice(),
            "update_seconds": {str(k): v for k, v in sorted(self.seconds.items())},
            "updates": self.updates,
        }


__all__ = [
    "ENV_CORES",
    "ENV_NUMBA",
    "ENV_PARALLEL",
    "ENV_TORCH",
    "AdaptiveThreads",
    "ThreadPolicy",
    "ThreadPolicyError",
    "active_policy",
    "applied",
    "apply",
    "available_cores",
    "parallel_min_envs",
    "set_torch_threads",
    "thread_policy",
]

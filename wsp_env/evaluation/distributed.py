"""Evaluation split across workers through Ray (``wsp-env evaluate/benchmark --workers N``
or ``--address ADDR``), with results identical, run for run, to one process.

Every stop of a suite or of the sealed set is independent: its own environment in the batched
core, its own seeded generator, a controller whose state is per environment. So the runs of one
``run_runs`` call (one policy, one vehicle) are cut into contiguous chunks, one per worker; each
worker rebuilds the policy from how it was named (``PolicySpec``: model files are not shipped
as objects), runs its chunk through the same ``runner.run_runs`` and the results are put back
in order. Recorded traces of "each scenario's first seed" are kept only for the runs that are
first in the whole list, as one process keeps them.

Ray is an optional extra (``pip install 'wsp-env[sweep]'``; the Makefile's environment has it).
Locally (no ``address``) Ray starts in this process with ``workers`` CPUs and stops at the end;
with ``address`` (``auto`` or ``HOST:PORT``) it attaches to a running cluster and uses as many
workers as asked. Each worker follows the thread policy (``wsp_env.threads``) for one core.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from wsp_env.core.config import VehicleConfig
from wsp_env.evaluation.runner import run_runs
from wsp_env.evaluation.suites import Run


def require_ray() -> Any:
    """``ray``, or one line saying how to install it (``policy.MissingExtraError``)."""
    from wsp_env.policy import require_extras

    require_extras("--workers/--address need", "sweep")
    import ray

    return ray


@contextlib.contextmanager
def ray_session(address: str | None = None, num_cpus: int | None = None) -> Iterator[Any]:
    """Ray for the duration of a ``with``: attached to ``address`` or started here with
    ``num_cpus`` CPUs, a new local instance even where another runs on the machine (quietly:
    warnings only on failure); shut down after if started here.
    Already initialised (a caller's session): used as it is."""
    ray = require_ray()
    if ray.is_initialized():  # a caller's session (a test's, a notebook's): used as it is
        if address:
            _check_reachable(address)
        yield ray
        return
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")  # a local, single-user session
    kwargs: dict[str, Any] = {
        "include_dashboard": False,
        "log_to_driver": False,
        "logging_level": logging.ERROR,
    }
    if address:
        _check_reachable(address)
    try:
        if address:
            ray.init(address=address, **kwargs)
        else:  # a new local instance: never a cluster someone else runs on this machine
            # (Ray would attach to one it finds, and refuse the CPU count)
            ray.init(address="local", num_cpus=num_cpus, **kwargs)
    except (ConnectionError, RuntimeError, ValueError) as err:
        where = f"--address {address}" if address else "a local Ray"
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise ValueError(f"{where}: could not start or reach Ray ({first})") from None
    try:
        yield ray
    finally:
        ray.shutdown()


def _check_reachable(address: str, timeout_s: float = 5.0) -> None:
    """A ``HOST:PORT`` address that accepts no connection is one line within ``timeout_s``
    (Ray itself retries for minutes). ``auto`` and ``ray://`` addresses are left to Ray."""
    import socket

    host, sep, port = address.rpartition(":")
    if not sep or "://" in address or not port.isdigit():
        return
    try:
        with socket.create_connection((host or "127.0.0.1", int(port)), timeout=timeout_s):
            pass
    except OSError as err:
        raise ValueError(
            f"--address {address}: could not start or reach Ray (nothing answers there: "
            f"{err.strerror or err})"
        ) from None


@dataclass(frozen=True)
class PolicySpec:
    """How a worker rebuilds a policy: ``policy.make_policy``'s arguments, the name it runs
    under (``label``) and the folder a relative path or ``module:callable`` is read from."""

    name: str
    wsp_config: str | None
    tier: str
    label: str
    cwd: str

    def build(self) -> Any:
        from wsp_env.policy import make_policy

        if self.cwd not in sys.path:
            sys.path.insert(0, self.cwd)  # module:callable policies import from there
        here = os.getcwd()
        try:
            os.chdir(self.cwd)
        except OSError:
            raise ValueError(
                f"policy {self.label}: the folder it was named from ({self.cwd}) is not on this "
                "worker's machine (model files and modules must be at the same path on every "
                "node)"
            ) from None
        try:
            policy = make_policy(self.name, self.wsp_config, tier=self.tier)
        finally:
            os.chdir(here)
        policy.name = self.label
        return policy


def policy_spec(policy: Any) -> PolicySpec:
    """The spec of a policy made by ``policy.make_policy`` (which records its arguments as
    ``policy.spec``); a policy built otherwise cannot be rebuilt in a worker."""
    spec = getattr(policy, "spec", None)
    if spec is None:
        raise ValueError(
            f"policy {getattr(policy, 'name', policy)!r}: not made by make_policy, so a worker "
            "cannot rebuild it (run without --workers/--address)"
        )
    name, wsp_config, tier = spec
    return PolicySpec(name, wsp_config, tier, policy.name, os.getcwd())


def _run_chunk(
    vehicle: VehicleConfig,
    runs: list[Run],
    spec: PolicySpec,
    record: str,
    max_time_s: float,
    env_kwargs: dict[str, Any] | None,
    policy_keys: tuple[str, ...] | None,
) -> tuple[list[dict[str, Any]], dict[tuple[str, int], Any]]:
    """One worker's share (in the worker's process)."""
    from wsp_env import threads

    threads.apply(threads.thread_policy("evaluate", cores=1))
    return run_runs(vehicle, runs, spec.build(), record, max_time_s, env_kwargs, None, policy_keys)


def chunks(n: int, workers: int) -> list[range]:
    """``range(n)`` cut into at most ``workers`` contiguous, near-equal pieces."""
    size = max(1, math.ceil(n / max(1, workers)))
    return [range(i, min(i + size, n)) for i in range(0, n, size)]


class RayExecutor:
    """``run_runs`` with the runs split across ``workers`` Ray tasks (module docstring). Use
    inside ``ray_session``; pass as ``executor`` to ``run_suite`` / ``run_benchmark``."""

    def __init__(self, ray: Any, workers: int, bar: Any = None) -> None:
        if workers < 1:
            raise ValueError(f"--workers: must be >= 1, got {workers}")
        self.ray, self.workers = ray, workers
        self.remote = ray.remote(num_cpus=1)(_run_chunk)

    def run_runs(
        self,
        vehicle: VehicleConfig,
        runs: list[Run],
        policy: Any,
        record: str = "none",
        max_time_s: float = 600.0,
        env_kwargs: dict[str, Any] | None = None,
        bar: Any = None,
        policy_keys: tuple[str, ...] | None = None,
    ) -> tuple[list[dict[str, Any]], dict[tuple[str, int], Any]]:
        spec = policy_spec(policy)
        parts = chunks(len(runs), self.workers)
        futures = [
            self.remote.remote(
                vehicle, [runs[i] for i in part], spec, record, max_time_s, env_kwargs, policy_keys
            )
            for part in parts
        ]
        results: list[dict[str, Any]] = []
        records: dict[tuple[str, int], Any] = {}
        try:
            parts_done = self.ray.get(futures)
        except self.ray.exceptions.RayTaskError as err:  # the worker's error, in one line
            cause = err.cause if getattr(err, "cause", None) is not None else err
            text = str(cause).strip().splitlines()
            raise ValueError(
                f"a worker failed: {text[0] if text else type(cause).__name__}"
            ) from None
        for res, rec in parts_done:
            results.extend(res)
            records.update(rec)
            if bar is not None:
                bar.update(len(res))
        if record == "first_seed":  # as one process: the first run of each scenario only
            first: dict[str, tuple[str, int]] = {}
            for run in runs:
                first.setdefault(run.scenario, (run.scenario, run.seed))
            keep = set(first.values())
            records = {k: v for k, v in records.items() if k in keep}
        return results, records


__all__ = [
    "PolicySpec",
    "RayExecutor",
    "chunks",
    "policy_spec",
    "ray_session",
    "require_ray",
]

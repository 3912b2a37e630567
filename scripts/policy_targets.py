"""A slip-target policy's targets by rail and train speed on fresh stops: does a learned policy
ask for its rail's target at every speed, or only while the train is fast?

The stops are the fresh seeds ``FRESH_SEED_BASE + i``, ``i < --draw`` (``fresh_stops.py``: no
sealed, development, fine-tune pool or suite stop), run with the benchmark's scenario, sensors
and watchdog of ``--vehicle`` and ``--tier`` through the benchmark's runner. Every decision's
targets (km/h, every valve's, as the environment maps the actions) are binned by the true train
speed (``--bands``, km/h) while the stop runs; per rail and band the table gives the mean over
stops of each stop's mean target, and the 10th and 90th percentiles of those stop means. With
``--teacher CONFIG`` the config's ``pretrain.teacher_targets_kmh`` (the rail table the student
imitated) is printed beside each rail. ``--policy`` is anything ``fresh_stops.py`` takes in the
slip-target mode (a model file, ``target:X...``).

    PYTHONPATH=scripts .venv/bin/python scripts/policy_targets.py \\
        --policy runs/train/bc_st_mean_s1/student.zip --draw 400 \\
        --teacher configs/train/ppo_bc_slip_target_mean_accel_uic_z1.yaml
"""

from __future__ import annotations

import argparse
import itertools
import sys
from typing import Any

import numpy as np
from fresh_stops import FRESH_SEED_BASE, MAX_DRAW, benchmark_setup, build_policy

from wsp_env.envs.tiers import TIERS, VERSION
from wsp_env.evaluation.benchmark import DAMAGE_CRITERIA, POLICY_KEYS
from wsp_env.evaluation.runner import run_runs
from wsp_env.evaluation.suites import Run
from wsp_env.physics import layout as L
from wsp_env.training.config import config_teacher_creep, config_teacher_table


class TargetRecorder:
    """``policy`` as the runner uses it, every decision's targets summed per environment and
    speed band (the train's true speed) until the stop ends."""

    def __init__(self, policy: Any, edges_kmh: np.ndarray) -> None:
        self.policy = policy
        self.edges_kmh = edges_kmh
        self.name = policy.name
        self.env_kwargs = getattr(policy, "env_kwargs", None)
        self.core: Any = None
        self.sums: np.ndarray = np.zeros(0)
        self.counts: np.ndarray = np.zeros(0)

    def bind(self, core: Any) -> None:
        if core.action_mode != "slip_target":
            raise ValueError(
                f"--policy {self.name}: not a model of the slip-target action mode (a constant "
                "target:X runs the loop from outside; its target is X)"
            )
        self.core = core
        self.policy.bind(core)
        bands = len(self.edges_kmh) + 1
        self.sums = np.zeros((core.n_envs, bands))
        self.counts = np.zeros((core.n_envs, bands))

    def reset(self, env_ids: np.ndarray) -> None:
        self.policy.reset(env_ids)

    def act(self, obs: np.ndarray) -> np.ndarray:
        actions = self.policy.act(obs)
        core = self.core
        running = core.sim.env_state[:, L.ES_STOPPED] == 0.0
        band = np.searchsorted(self.edges_kmh, 3.6 * core.sim.speed_mps)
        target = core.slip_targets_kmh(actions).mean(axis=1)
        rows = np.flatnonzero(running)
        np.add.at(self.sums, (rows, band[rows]), target[rows])
        np.add.at(self.counts, (rows, band[rows]), 1.0)
        return actions


def band_names(edges_kmh: np.ndarray) -> list[str]:
    e = [f"{x:g}" for x in edges_kmh]
    return [f"<{e[0]}"] + [f"{a}-{b}" for a, b in itertools.pairwise(e)] + [f">={e[-1]}"]


def table(rails: list[str], sums: np.ndarray, counts: np.ndarray) -> dict[str, list[Any]]:
    """Per rail and band: (stops, mean of the stops' mean targets, 10th and 90th percentile)."""
    out: dict[str, list[Any]] = {}
    for rail in sorted(set(rails)):
        rows = np.array([r == rail for r in rails])
        cells = []
        for b in range(sums.shape[1]):
            seen = rows & (counts[:, b] > 0)
            means = sums[seen, b] / counts[seen, b]
            if means.size == 0:
                cells.append(None)
            else:
                cells.append((int(means.size), float(means.mean()),
                              *(float(q) for q in np.percentile(means, [10, 90]))))  # fmt: skip
        out[rail] = cells
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", required=True)
    ap.add_argument("--draw", type=int, default=400, help="fresh seeds run (default 400)")
    ap.add_argument("--bands", default="20,40", help="band edges, km/h (default 20,40)")
    ap.add_argument("--teacher", help="a training config whose rail table to print beside")
    ap.add_argument("--vehicle", default="uic_z1")
    ap.add_argument("--tier", default="wheels+accel", choices=list(TIERS))
    args = ap.parse_args(argv)
    try:
        if not 1 <= args.draw <= MAX_DRAW:
            raise ValueError(f"--draw: must be 1-{MAX_DRAW}, got {args.draw}")
        try:
            edges = np.array(sorted(float(x) for x in args.bands.split(",")))
        except ValueError:
            raise ValueError(
                f"--bands: expected km/h edges like 20,40, got {args.bands!r}"
            ) from None
        teacher: dict[str, float] = {}
        if args.teacher:
            try:
                teacher = config_teacher_table(args.teacher)
                scheduled = config_teacher_creep(args.teacher)[0]
            except ValueError as err:
                raise ValueError(f"--teacher {err}") from None
            if scheduled:  # a target that moves with the speed is no table row
                raise ValueError(
                    f"--teacher {args.teacher}: rail {sorted(scheduled)[0]}'s target is a "
                    "creep schedule (pretrain.teacher_creep); this compares constant tables"
                )
        veh, max_time_s, kw = benchmark_setup(args.vehicle, args.tier)
        policy = TargetRecorder(build_policy(args.policy, args.tier), edges)
        seeds = [FRESH_SEED_BASE + i for i in range(args.draw)]
        runs = [Run(f"fresh_{s}", s, {}, dict(DAMAGE_CRITERIA), veh) for s in seeds]
        run_runs(veh, runs, policy, max_time_s=max_time_s, env_kwargs=kw,
                              policy_keys=POLICY_KEYS)  # fmt: skip
    except (OSError, ValueError, KeyError) as err:
        msg = str(err) if isinstance(err, ValueError) else f"{type(err).__name__}: {err}"
        print(f"policy_targets: {msg}", file=sys.stderr)
        return 2
    rails = [s.rail_name for s in policy.core.sim.setups]  # the runs' order
    names = band_names(edges)
    print(f"{args.policy}: targets (km/h) by rail and train speed, {len(seeds)} fresh stops "
          f"(seeds {seeds[0]}-{seeds[-1]}, {args.vehicle}, {args.tier}, {VERSION}); per band "
          "the mean of the stops' mean targets [10th-90th percentile of them] (stops)")  # fmt: skip
    print(f"{'rail':14s}{'teacher':>9s}" + "".join(f"{n + ' km/h':>26s}" for n in names))
    for rail, cells in table(rails, policy.sums, policy.counts).items():
        row = f"{rail:14s}{teacher.get(rail, float('nan')):9.2f}"
        for c in cells:
            cell = "-" if c is None else f"{c[1]:.2f} [{c[2]:.2f}-{c[3]:.2f}] ({c[0]:3d})"
            row += f"{cell:>26s}"
        print(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())

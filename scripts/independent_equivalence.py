"""Compare the independent trace generator (``calibration/independent.py``) with another version
of itself, bit for bit: every array of the 20 ms record on random scenarios with random effects,
and the time each takes. For a change that must not move a trace (a port, a refactor):

    git show c9d12bf:wsp_env/calibration/independent.py > /tmp/independent_before.py
    .venv/bin/python scripts/independent_equivalence.py /tmp/independent_before.py --scenarios 80

(c9d12bf: the last numpy-only version, before its cycle loop was compiled). The last row of
``mu_level`` is left out: the numpy version never wrote it (``np.empty``), so it held whatever
was in memory; nothing reads it. Exit status 1 if any scenario differs."""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time

import numpy as np

from wsp_env.calibration import independent as current

MAGNITUDE = {
    "gradient": 5.0, "running_resistance": 1.5, "pad_friction": 1.2, "wheel_radius": 0.005,
    "unmeasured_brake_force": 3000.0, "pressure_lag": 0.15, "sensor_lag": 0.1,
    "pressure_time_constant": 0.3, "sensor_scale": 0.03, "load_transfer": 1.5,
    "adhesion_per_axle": 0.6, "adhesion_position": 0.6,
}  # fmt: skip


def _load(path: str):
    spec = importlib.util.spec_from_file_location("independent_other", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["independent_other"] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def _differs(a: dict, b: dict) -> list[str]:
    out = []
    for key, x in a.items():
        y = b[key]
        if key == "mu_level":
            x, y = x[:-1], y[:-1]
        if isinstance(x, np.ndarray):
            if x.dtype != y.dtype or not np.array_equal(x, y, equal_nan=True):
                out.append(key)
        elif isinstance(x, (float, int, tuple)) and x != y and not (x != x and y != y):
            out.append(key)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("other", help="path of the other version of independent.py")
    ap.add_argument("--scenarios", type=int, default=40)
    ap.add_argument("--first-seed", type=int, default=0)
    args = ap.parse_args()
    other = _load(args.other)
    categories = list(MAGNITUDE)
    # the record's function: public from the compiled version on, private before it
    other_record = vars(other).get("simulate_record") or vars(other)["_simulate"]
    current.simulate_record(current.random_scenario(np.random.default_rng(0)), [], seed=0)
    bad, t_other, t_current = 0, [], []
    for s in range(args.first_seed, args.first_seed + args.scenarios):
        rng = np.random.default_rng(1000 + s)
        sc = current.random_scenario(rng)
        chosen = rng.choice(categories, size=int(rng.integers(0, 4)), replace=False)
        effects = [current.random_effect(str(c), MAGNITUDE[str(c)], rng, sc) for c in chosen]
        t0 = time.perf_counter()
        a = other_record(sc, effects, seed=s)
        t1 = time.perf_counter()
        b = current.simulate_record(sc, effects, seed=s)
        t2 = time.perf_counter()
        t_other.append(t1 - t0)
        t_current.append(t2 - t1)
        if diff := _differs(a, b):
            bad += 1
            print(f"seed {s}: {sc.n_axles} axles, {sc.contaminant}, {list(chosen)}: {diff}")
    print(
        f"{args.scenarios} scenarios, {bad} differ; median s per stop: other "
        f"{np.median(t_other):.3f}, current {np.median(t_current):.4f} "
        f"(ratio {np.median(t_other) / np.median(t_current):.0f})"
    )
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Where the physics kernel's time goes: time it with one part at a time switched off.

    .venv/bin/python scripts/kernel_profile.py [--markdown docs/results/kernel_profile.md]
        # ~1 minute, pins itself to one core

Each variant recompiles ``wsp_env/physics/integrator.py`` with one piece replaced by a trivial
stand-in, runs 256 environments (mixed rails, random valve commands) from the same state, and
reports the best of 12 timings in ns per axle and substep. The differences to ``base`` are the
parts' costs. Variants are physically wrong on purpose: this is a profile, not a simulation.
``--markdown P`` also writes the printed figures there, with the command and the machine above.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
from _results_md import printed_results

SOURCE = Path(__file__).resolve().parent.parent / "wsp_env/physics/integrator.py"
VARIANTS = {
    "base": [],
    "creep law -> linear stand-in": [
        (
            "m, m_xi, m_w = adhesion(\n                law, axi, w, level, mu_rec, kw_eff, k_n, "
            "inv_k_n, lp0, lp1, lp2, lp3\n            )",
            "m, m_xi, m_w = min(axi * 30.0, level), 30.0, 0.0",
        )
    ],
    "recovery off": [("recovery_on = recovers(env_par, e)", "recovery_on = False")],
    "no zero-creep re-linearisation": [
        ("if (v_c - (omega + d_omega) * r) * dv < 0.0:", "if False:")
    ],
    "no work/cleaning pass": [
        (
            "        for k in range(n_axles):\n            r = axle_par[e, k, AP_RADIUS]\n"
            "            inertia = axle_par[e, k, AP_INERTIA]\n            d_omega",
            "        for k in range(0):\n            r = axle_par[e, k, AP_RADIUS]\n"
            "            inertia = axle_par[e, k, AP_INERTIA]\n            d_omega",
        )
    ],
}


def time_variant(name: str) -> float:
    from wsp_env.core.config import load_rail, load_vehicle
    from wsp_env.core.simulator import TrainSim, draw_run_setup
    from wsp_env.physics import layout as L

    src = SOURCE.read_text().replace('"cache": True', '"cache": False')
    for old, new in VARIANTS[name]:
        if old not in src:
            raise SystemExit(f"variant {name!r}: source pattern not found (kernel changed?)")
        src = src.replace(old, new)
    mod = types.ModuleType("integrator_variant")
    exec(compile(src, "integrator_variant", "exec"), mod.__dict__)
    rails = [load_rail(r) for r in ("soap", "soap", "leaves", "oil", "wet")]
    n = 256
    rng = np.random.default_rng(0)
    sim = TrainSim(load_vehicle("uic_z1"), n_envs=n)
    for e in range(n):
        sim.configure(e, draw_run_setup(rails[e % 5], rng, float(rng.uniform(40, 200))))
    sim.reset()
    cmds = rng.uniform(0, 1, size=(8, n, 4))
    args = [sim.n_sub, sim.dt_s, sim.cmd, sim.env_par, sim.axle_par, sim.sections,
            sim.env_state, sim.axle_state, sim.field, sim.env_acc, sim.axle_acc]  # fmt: skip
    for i in range(200):
        sim.axle_state[:, :, L.AS_CMD] = sim.cmd
        sim.cmd[...] = cmds[i % 8]
        mod._step_serial(*args)
    snap = [a.copy() if isinstance(a, np.ndarray) else a for a in args]
    best = float("inf")
    for _ in range(12):
        run = [a.copy() if isinstance(a, np.ndarray) else a for a in snap]
        t0 = time.perf_counter()
        for i in range(10):
            run[2][...] = cmds[i % 8]
            mod._step_serial(*run)
        best = min(best, time.perf_counter() - t0)
    return best / (10 * n * sim.n_sub * 4) * 1e9


def main() -> None:
    if len(sys.argv) > 1 and not sys.argv[1].startswith("-"):  # child process: one variant
        print(f"{time_variant(sys.argv[1]):.1f}")
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", default=None, help="also write the figures here")
    args = ap.parse_args()
    printed_results(args.markdown, "Where the physics kernel's time goes", profile)


def profile() -> None:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    base = None
    for name in VARIANTS:
        cmd = ["taskset", "-c", "1", sys.executable, __file__, name]
        out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True)
        ns = float(out.stdout.strip().splitlines()[-1])
        base = ns if base is None else base
        extra = "" if name == "base" else f"   (part costs ~{base - ns:4.1f} ns)"
        print(f"{name:34s} {ns:6.1f} ns per axle-substep{extra}")


if __name__ == "__main__":
    main()

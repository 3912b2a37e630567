"""Time one fine-tune generation's evaluation: 14 members (the start twice and six antithetic
pairs, sigma 0.01) on 100 fixed stops of a pool, through whichever ``wsp_env`` is first on
``sys.path``, so two versions of the code can be timed on the same work (docs/training_log.md,
"The second run"). Prints the wall time and the returns' sum (equal sums: the same results).

    .venv/bin/python scripts/es_generation_timing.py runs/train/bc_st_s1/student.zip \\
        runs/train/es_avg_s1/pool.json --draw 7
    PYTHONPATH=/tmp/old .venv/bin/python scripts/es_generation_timing.py ...   # another checkout
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("start", help="the model file")
    ap.add_argument("pool", help="a fine-tune's pool.json")
    ap.add_argument("--draw", type=int, default=7, help="the stops' draw, default_rng([0, DRAW])")
    args = ap.parse_args(argv)
    from wsp_env.policy import SB3Policy
    from wsp_env.threads import applied, thread_policy
    from wsp_env.training import es

    try:
        pool = json.loads(open(args.pool).read())
        seeds_all = pool["seeds"]
    except (OSError, ValueError, KeyError, TypeError) as err:
        print(f"{args.pool}: not a fine-tune's pool ({type(err).__name__})", file=sys.stderr)
        return 2
    rng = np.random.default_rng([0, args.draw])
    seeds = [int(s) for s in np.sort(rng.choice(seeds_all, size=100, replace=False))]
    layers, _ = es.actor_layers(SB3Policy(args.start).model)
    theta = es.get_parameters(layers[-1:])
    eps = np.random.default_rng(1).standard_normal((6, theta.size))
    if hasattr(es, "population"):
        thetas = es.population(theta, theta, theta, 0.01 * eps)
    else:  # the code before 2026-11-26 had no helper; the same members
        thetas = np.concatenate([theta[None], theta[None], theta + 0.01 * eps, theta - 0.01 * eps])
    with applied(thread_policy("evaluate")):
        es.evaluate_population(args.start, thetas[:2], seeds[:2], 1)  # compile, warm up
        t = time.perf_counter()
        out = es.evaluate_population(args.start, thetas, seeds, 1)
        dt = time.perf_counter() - t
    returns = out[0] if isinstance(out, tuple) else out  # before 2026-11-26: returns only
    print(json.dumps({"module": es.__file__, "wall_s": round(dt, 1),
                      "return_sum": float(returns.sum())}))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())

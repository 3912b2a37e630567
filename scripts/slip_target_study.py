"""The slip-target action mode with constant targets: the figures its documentation quotes.

.venv/bin/python scripts/slip_target_study.py [--part P ...] [--sensors S] [--markdown PATH]

``table``: stopping distance and sliding energy of constant 4 and 2 km/h targets against the
classical WSP of the tier, six seeds each, on soap 0.07 at 120 km/h, oil and leaves at 100 km/h
(uniform patterns; the rest of each stop drawn from the default scenario), with the stops where
the watchdog intervened and the longest lock. ``lead``: the inner loop's lead and gain swept on
soap 0.07 at 120 km/h, 0.05 at 160 and 0.08 at 60, two seeds each, the 4 km/h target's distance
against the classical WSP's. ``slip``: the median measured slip ``v_ref - v_i`` mid-stop
(reference between 85 % and 25 % of the initial speed, axles not in a periodic release) for
targets of 2, 4 and 6 km/h on those three soap stops, six seeds. ``zero``: the lowest target
(action -1) held from a stop's start (dry rail at 120 km/h, soap at 120 and 160, six seeds),
with ``slip_target_min_kmh`` 0 and the default 0.5, with ideal and with wheel-tier sensors
whatever ``--sensors`` says: the brake at 5 s and what the watchdog does (minimum-deceleration
overrides, axles restored after the safety time). ``release``: a
constant 4 km/h target on soap 0.07 at 120 km/h, six seeds, with and without the loop's
periodic release (run from outside, ``SlipTargetPolicy``): the longest lock. ``--sensors``:
``wheels`` (default: the benchmark's wheel-sensor tier, ``envs.tiers.TIER_SENSORS``) or
``ideal`` (the environment's default sensors). ``--markdown P`` also writes the printed figures
there, with the command and the machine above (``docs/results/slip_target_study.md``).
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import Any

import numpy as np
from _results_md import printed_results

from wsp_env.baselines.classical import load_wsp_config
from wsp_env.baselines.slip_target import SlipTargetLoop, SlipTargetPolicy
from wsp_env.core import kernel as K
from wsp_env.envs import WSPBrakingVectorEnv
from wsp_env.envs.tiers import TIER_SENSORS
from wsp_env.policy import make_policy

SEEDS = list(range(6))
WHEELS = {"sensors": dataclasses.asdict(TIER_SENSORS["wheels"])}
MIN_KMH = 0.5  # the environment's default slip_target_min_kmh
MAX_KMH = 8.0


def soap(mu: float, speed_kmh: float) -> dict[str, Any]:
    return {"rail": "soap", "mu_contaminated": mu, "speed_kmh": speed_kmh, "pattern": "uniform"}


TABLE = {
    "soap 0.07, 120 km/h": soap(0.07, 120.0),
    "oil, 100 km/h": {"rail": "oil", "speed_kmh": 100.0, "pattern": "uniform"},
    "leaves, 100 km/h": {"rail": "leaves", "speed_kmh": 100.0, "pattern": "uniform"},
}
SOAP_STOPS = [soap(0.07, 120.0), soap(0.05, 160.0), soap(0.08, 60.0)]


def action_for(target_kmh: float) -> float:
    """The action whose target is ``target_kmh`` (the default 0.5-8 km/h range)."""
    return 2.0 * (target_kmh - MIN_KMH) / (MAX_KMH - MIN_KMH) - 1.0


def stops(opts, seeds, env_kwargs, policy=None, target_kmh=None, on_period=None):
    """Each seed's stop's metrics: ``policy`` on a continuous environment, or a constant
    ``target_kmh`` in slip-target mode; ``on_period(venv, live)`` before every step."""
    n = len(seeds)
    mode = {} if policy is not None else {"action_mode": "slip_target"}
    venv = WSPBrakingVectorEnv(num_envs=n, **mode, **env_kwargs)
    obs, _ = venv.reset(seed=list(seeds), options=opts)
    if policy is not None:
        policy.bind(venv.core)
        policy.reset(np.arange(n))
    else:
        action = np.full((n, venv.core.n_valves), action_for(target_kmh), dtype=np.float32)
    out: list = [None] * n
    while any(m is None for m in out):
        if on_period is not None:
            on_period(venv, np.array([m is None for m in out]))
        obs, _, term, trunc, info = venv.step(policy.act(obs) if policy is not None else action)
        for e in np.flatnonzero(term | trunc):
            if out[e] is None:
                out[e] = info["final_info"][e]["metrics"]
    return out


def span(values) -> str:
    return f"{min(values):.2f}-{max(values):.2f}"


def part_table(env_kwargs) -> None:
    print("| stop | target | distance / classical | sliding energy / classical | "
          "watchdog | longest lock (s) |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for name, opts in TABLE.items():
        wsp = stops(opts, SEEDS, env_kwargs, policy=make_policy("classical"))
        for target in (4.0, 2.0):
            got = stops(opts, SEEDS, env_kwargs, target_kmh=target)
            dist = [
                m["stopping_distance_m"] / w["stopping_distance_m"]
                for m, w in zip(got, wsp, strict=True)
            ]
            energy = [
                m["sliding_energy_kJ"] / w["sliding_energy_kJ"]
                for m, w in zip(got, wsp, strict=True)
            ]
            trips = sum(m["watchdog"]["total"] > 0 for m in got)
            lock = max(m["max_lock_s"] for m in got)
            print(f"| {name} | {target:g} km/h | {span(dist)} | {span(energy)} | "
                  f"{trips} of {len(SEEDS)} | {lock:.1f} |")  # fmt: skip


def part_lead(env_kwargs) -> None:
    wsp = [stops(o, SEEDS[:2], env_kwargs, policy=make_policy("classical")) for o in SOAP_STOPS]
    for lead in (0.0, 0.05, 0.1, 0.2):
        for gain in (0.1, 0.2, 0.4):
            kw = {**env_kwargs, "slip_target_lead_s": lead, "slip_target_gain_per_kmh": gain}
            ratios = [
                m["stopping_distance_m"] / w["stopping_distance_m"]
                for opts, ref in zip(SOAP_STOPS, wsp, strict=True)
                for m, w in zip(stops(opts, SEEDS[:2], kw, target_kmh=4.0), ref, strict=True)
            ]
            print(f"lead {lead:g} s, gain {gain:g} per km/h: distance / classical {span(ratios)}")


def part_slip(env_kwargs) -> None:
    for opts in SOAP_STOPS:
        v0 = opts["speed_kmh"] / 3.6
        for target in (2.0, 4.0, 6.0):
            slips: list[list[float]] = [[] for _ in SEEDS]

            def record(venv, live, slips=slips, v0=v0):
                core = venv.core
                v_ref = core.reference_speed_mps
                slip = (v_ref[:, None] - core.measured_wheel_speed_mps) * 3.6
                for e in np.flatnonzero(live & (v_ref > 0.25 * v0) & (v_ref < 0.85 * v0)):
                    slips[e].extend(slip[e][~core.loop.vent[e]].tolist())

            # the slip a period's command acts on: read after the observation's read (the loop
            # has advanced; ``vent`` is this period's)
            stops(opts, SEEDS, env_kwargs, target_kmh=target, on_period=record)
            medians = [float(np.median(s)) for s in slips]
            print(f"soap {opts['mu_contaminated']:g}, {opts['speed_kmh']:g} km/h, target "
                  f"{target:g} km/h: median measured slip {span(medians)} km/h")  # fmt: skip


def part_zero(env_kwargs) -> None:
    for sensors in ("ideal", "wheels"):  # both, whatever --sensors says
        print(f"{sensors} sensors:")
        part_zero_on({} if sensors == "ideal" else WHEELS)


def part_zero_on(env_kwargs) -> None:
    for low in (0.0, MIN_KMH):
        for rail, speed in (("dry", 120.0), ("soap", 120.0), ("soap", 160.0)):
            kw = {**env_kwargs, "action_mode": "slip_target", "slip_target_min_kmh": low}
            venv = WSPBrakingVectorEnv(num_envs=len(SEEDS), **kw)
            venv.reset(seed=SEEDS, options={"rail": rail, "speed_kmh": speed})
            core, steps = venv.core, 0
            override = np.full(len(SEEDS), np.nan)
            pressure_5s = np.zeros(len(SEEDS))
            out: list = [None] * len(SEEDS)
            low_action = np.full((len(SEEDS), core.n_valves), -1.0, dtype=np.float32)
            while any(m is None for m in out):
                _, _, term, trunc, info = venv.step(low_action)
                steps += 1
                tripped = np.isnan(override) & (core.wsp[:, K.W_OVERRIDE] > 0.0)
                override[tripped] = steps * 0.02
                if steps == 250:
                    pressure_5s = core.sim.pressure_bar.max(axis=1)
                for e in np.flatnonzero(term | trunc):
                    if out[e] is None:
                        out[e] = info["final_info"][e]["metrics"]
            restored = sum(m["watchdog"]["safety_time_axles"] for m in out)
            overrides = override[~np.isnan(override)]
            when = f" at {span(overrides)} s" if overrides.size else ""
            lock = max(m["max_lock_s"] for m in out)
            print(f"slip_target_min_kmh {low:g}, action -1 throughout, {rail} {speed:g} km/h: "
                  f"fullest cylinder at 5 s {span(pressure_5s)} bar; minimum-deceleration "
                  f"overrides {overrides.size} of {len(SEEDS)}{when}; axles restored after the "
                  f"safety time {restored}; longest lock {lock:.1f} s")  # fmt: skip


def part_release(env_kwargs) -> None:
    opts = TABLE["soap 0.07, 120 km/h"]
    for interval in (None, 1e9):
        cfg = load_wsp_config()
        if interval is not None:  # the periodic release never starts
            cfg = dataclasses.replace(cfg, periodic_release_interval_s=interval)
        policy = SlipTargetPolicy(4.0, SlipTargetLoop(cfg))
        locks = [m["max_lock_s"] for m in stops(opts, SEEDS, env_kwargs, policy=policy)]
        what = "with" if interval is None else "without"
        print(f"4 km/h on soap 0.07 at 120 km/h {what} the periodic release: longest lock "
              f"{span(locks)} s")  # fmt: skip


PARTS = {"table": part_table, "lead": part_lead, "slip": part_slip, "zero": part_zero,
         "release": part_release}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=tuple(PARTS), action="append", help="default: all")
    ap.add_argument("--sensors", choices=("wheels", "ideal"), default="wheels")
    ap.add_argument("--markdown", default=None, help="also write the figures here")
    args = ap.parse_args()
    env_kwargs: dict[str, Any] = WHEELS if args.sensors == "wheels" else {}

    def study() -> None:
        for name in args.part or list(PARTS):
            print(
                f"## {name} ({'both sensor sets' if name == 'zero' else args.sensors + ' sensors'})"
            )
            PARTS[name](env_kwargs)

    printed_results(args.markdown, "The slip-target action mode with constant targets", study)


if __name__ == "__main__":
    main()

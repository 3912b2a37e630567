"""What the calibration loop may believe: physical bounds on every effect's parameters, and
which residual channels are fit to choose an effect on.

A least-squares fit always returns *a* number. A ground-speed scale error of -16 % or a wheel
12 % off its nominal radius fits some residual, but no train runs with such a sensor or wheel;
accepting it makes the next effect compensate for it. Each bound below is the edge of what a
vehicle in service can have, with its reason; a candidate whose fit lands outside is rejected
(and listed among the candidates with the reason), never added.

A channel whose RMSE is NaN (no samples to score) or whose values lie far outside any physical
range (a unit or channel-mapping fault, not an effect) is reported with its reason and never
used to choose an effect.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wsp_env.calibration.residuals import resistance_N
from wsp_env.calibration.traces import Trace, braked

G = 9.80665

# bound, reason — the reason is printed with the rejected value
GRADIENT_MAX_PERMILLE = 40.0  # steepest main lines: 35-40 permille (Cologne-Frankfurt 40)
SPEED_SCALE_MAX = 0.05  # radar / GPS / tachometer-based ground speed: calibrated to ~1-2 %
SPEED_LAG_MAX_S = 2.0  # a GPS fix held for a second, filtered: beyond 2 s no speed display works
RADIUS_ERROR_MAX = 0.06  # wear from 920 to ~860 mm diameter; beyond, the wheel is scrapped
PAD_SCALE_RANGE = (0.5, 1.6)  # organic / sintered pads: mu 0.25-0.45 against a nominal ~0.35
PRESSURE_LAG_MAX_S = 1.0  # pipe and cylinder filling behind the sensor: tenths of a second
UNMEASURED_FORCE_MAX_G = 0.15  # a magnetic-track brake: ~0.1 g of the vehicle's weight
# the whole running resistance (nominal + change): a long train at 200 km/h has ~1-2 % of its
# weight, a single car (nose and tail drag on one body) ~2 %, and a storm headwind doubles the
# aerodynamic part: 6 % is beyond any of them
RESISTANCE_MAX_G = 0.06
PITCH_HEIGHT_RATIO_MAX = 1.0  # bogie pitch k = (bogie's share of the mass) h / b: h < b

# below these an effect is inside what a logger and its nominal data resolve: not reported
SPEED_SCALE_MIN = 0.003  # a speed sensor's calibration tolerance (~0.3 %)
# a force effect smaller than a gradient of this (RMS over the stop) is not reported: "level"
# track varies by a permille along a stop, and so does the nominal resistance's accuracy
GRADIENT_MIN_PERMILLE = 1.0
# a pad's friction varies by a few percent from stop to stop (temperature, moisture, bedding):
# a pad effect that stays inside that over the whole stop is nothing to recalibrate
PAD_SCALE_MIN = 0.03
# a running-resistance formula is good to about a third (measured coast-downs scatter by that
# with wind and rail condition): a change inside it is the formula's own uncertainty
RESISTANCE_REL_MIN = 1.0 / 3.0
# the logging's timing resolution: a 10 Hz fix averaged over a 0.1 s log period trails by half a
# period, a receiver's latency adds up to ~0.05 s, an update placed between two log samples is
# off by up to half a period (a 5 Hz fix averaged at 10 Hz trails by half an update more, which
# the reader finds and ``negligible`` takes off first)
LAG_MIN_S = 0.15

COASTING_CREEP_MAX_PCT = 8.0  # a rolling wheel reads at most radius + sensor errors off


def implausible(category: str, params: dict[str, float], trace: Trace) -> str | None:
    """The reason a fitted effect cannot be physical on this vehicle, or ``None``."""
    mass = float(trace.vehicle["mass_kg"])
    weight = mass * G
    for key, value in params.items():
        if not math.isfinite(float(value)):
            return f"{key} is not finite"
    if "gradient_permille" in params and abs(params["gradient_permille"]) > GRADIENT_MAX_PERMILLE:
        return (
            f"gradient {params['gradient_permille']:.1f} permille: beyond the "
            f"{GRADIENT_MAX_PERMILLE:g} permille of the steepest main lines"
        )
    if "speed_scale_error" in params and abs(params["speed_scale_error"]) > SPEED_SCALE_MAX:
        return (
            f"ground-speed scale {100 * params['speed_scale_error']:+.1f} %: no speed sensor in "
            f"service is more than {100 * SPEED_SCALE_MAX:g} % off"
        )
    if "speed_lag_s" in params and not 0.0 < params["speed_lag_s"] <= SPEED_LAG_MAX_S:
        return f"ground-speed lag {params['speed_lag_s']:.2f} s outside (0, {SPEED_LAG_MAX_S:g}] s"
    if category == "wheel_radius":
        worst = max(abs(v) for k, v in params.items() if k.endswith("_radius_error"))
        if worst > RADIUS_ERROR_MAX:
            return (
                f"wheel radius {100 * worst:.1f} % off nominal: beyond the "
                f"{100 * RADIUS_ERROR_MAX:g} % a wheel may wear before it is scrapped"
            )
    if category == "pad_friction":
        lo, hi = PAD_SCALE_RANGE
        scale = np.asarray(params.get("scale", 1.0), dtype=float)
        if "slope_per_mps" in params:
            v = trace.v_train_kmh[trace.v_train_kmh > 10.0] / 3.6 - 100.0 / 3.6
            scale = scale + params["slope_per_mps"] * (v if v.size else np.zeros(1))
        if np.any(scale < lo) or np.any(scale > hi):
            return (
                f"pad friction x{float(np.min(scale)):.2f}..{float(np.max(scale)):.2f} of nominal: "
                f"outside the {lo:g}-{hi:g} that pad materials span"
            )
    if "force_at_full_demand_N" in params:
        force = params["force_at_full_demand_N"]
        if force > UNMEASURED_FORCE_MAX_G * weight:
            return (
                f"unmeasured force {force / 1e3:.1f} kN: beyond "
                f"{UNMEASURED_FORCE_MAX_G:g} g of the vehicle's weight (a track brake's)"
            )
        if force < 0.0:
            return (
                f"unmeasured force {force / 1e3:.1f} kN propelling the train in step with the "
                "brake demand: no brake does that (traction left on would not follow the "
                "demand; brake force weaker than declared is pad_friction)"
            )
    if "lag_s" in params and not 0.0 < params["lag_s"] <= PRESSURE_LAG_MAX_S:
        return f"pressure lag {params['lag_s']:.2f} s outside (0, {PRESSURE_LAG_MAX_S:g}] s"
    tc = params.get("time_constant_s")
    if tc is not None and not 0.0 < tc <= PRESSURE_LAG_MAX_S:
        return f"pressure time constant {tc:.2f} s outside (0, {PRESSURE_LAG_MAX_S:g}] s"
    if category == "running_resistance":
        v = np.linspace(0.0, float(np.nanmax(trace.v_train_kmh)) / 3.6, 20)
        delta = resistance_change_N(params, trace, v)
        nominal = resistance_N(trace, v)
        if np.any(nominal + delta > RESISTANCE_MAX_G * weight):
            return (
                f"running resistance up to {np.max(nominal + delta) / 1e3:.1f} kN: beyond "
                f"{100 * RESISTANCE_MAX_G:g} % of the vehicle's weight"
            )
        if np.any(nominal + delta < -0.002 * weight):
            return "running resistance would turn into a propelling force"
    if "bogie_pitch_kN_per_mps2" in params:
        bogie_mass = 2.0 * mass / max(trace.n_axles, 1)  # two axles per bogie
        if abs(params["bogie_pitch_kN_per_mps2"]) * 1e3 > PITCH_HEIGHT_RATIO_MAX * bogie_mass:
            return (
                f"bogie pitch {params['bogie_pitch_kN_per_mps2']:.1f} kN per m/s^2: the pivot "
                "would stand higher than the wheelbase is long"
            )
    return None


def negligible(category: str, params: dict[str, float], trace: Trace) -> str | None:
    """The reason a fitted effect is too small to act on, or ``None``: a ground-speed scale
    inside a sensor's calibration tolerance, a lag inside the logging's timing resolution, pads
    inside their stop-to-stop variation (``PAD_SCALE_MIN``), a running resistance inside its
    formula's accuracy (``RESISTANCE_REL_MIN``). A ground-speed lag is judged beyond the part
    the reader puts down to the logger (``Trace.v_train_logger_lag_s``).
    Such effects are statistically real on long clean records (the logger's own sampling,
    averaging and fix timing produce them) and physically nothing. Every force effect is
    judged by the force it adds (``implied_force_N``, RMS over the stop, ``stop_samples``) against
    a permille of the vehicle's weight, the force of the smallest gradient reported — so a
    two-parameter effect whose parameters cancel is as negligible as its force."""
    force = implied_force_N(category, params, trace)
    if force is not None and (why := negligible_force(force, trace, category)):
        return why
    moving = trace.v_train_kmh > 10.0
    v = trace.v_train_kmh[moving] / 3.6 if moving.any() else np.zeros(1)
    if category == "pad_friction":
        scale = params.get("scale", 1.0) + params.get("slope_per_mps", 0.0) * (v - 100.0 / 3.6)
        worst = float(np.max(np.abs(scale - 1.0)))
        if worst < PAD_SCALE_MIN:
            return (
                f"pad friction within {100 * worst:.1f} % of nominal over the stop: inside the "
                f"{100 * PAD_SCALE_MIN:g} % a pad's friction varies from stop to stop"
            )
    if category == "running_resistance":
        nominal = resistance_N(trace, v)
        if np.all(nominal > 0.0):
            worst = float(np.max(np.abs(resistance_change_N(params, trace, v)) / nominal))
            if worst < RESISTANCE_REL_MIN:
                return (
                    f"running resistance within {100 * worst:.0f} % of the metadata's over the "
                    f"stop: inside the {100 * RESISTANCE_REL_MIN:.0f} % a Davis formula is good to"
                )
    if "speed_scale_error" in params and abs(params["speed_scale_error"]) < SPEED_SCALE_MIN:
        return (
            f"ground-speed scale {100 * params['speed_scale_error']:+.2f} %: inside a sensor's "
            f"{100 * SPEED_SCALE_MIN:g} % calibration tolerance"
        )
    # a pressure lag's size is its mean delay: the dead time plus the time constant
    pressure = params.get("lag_s", 0.0) + params.get("time_constant_s", 0.0)
    lags = (("speed_lag_s", "ground-speed lag", trace.v_train_logger_lag_s,
             params.get("speed_lag_s")),
            ("lag_s", "pressure lag", 0.0,
             pressure if {"lag_s", "time_constant_s"} & set(params) else None))  # fmt: skip
    for _key, what, logger, value in lags:
        if value is not None and abs(value) - logger < LAG_MIN_S:
            of_it = (f", {logger:.2f} s of it the logger's averaging of "
                     f"{trace.v_train_update_s:g} s updates" if logger else "")  # fmt: skip
            return f"{what} {value:.3f} s{of_it}: inside the logging's {LAG_MIN_S:g} s resolution"
    return None


def stop_samples(trace: Trace) -> np.ndarray:
    """The stop: from the brake application (the first sample with an axle ``braked``) while
    the train runs above 10 km/h. A coasting lead-in is no part of it: a force that acts with
    the brake would otherwise be judged smaller the longer the logger ran before the driver
    braked."""
    applied = np.maximum.accumulate(braked(trace).any(axis=1))
    stop = applied & (trace.v_train_kmh > 10.0)
    return stop if stop.any() else trace.v_train_kmh > 10.0


def negligible_force(force_N: np.ndarray, trace: Trace, what: str) -> str | None:
    """The reason an extra retarding force (N, per sample) is too small to report: its RMS
    over the stop (``stop_samples``) under the force of a ``GRADIENT_MIN_PERMILLE`` gradient."""
    force_min = GRADIENT_MIN_PERMILLE * 1e-3 * float(trace.vehicle["mass_kg"]) * G
    moving = stop_samples(trace)
    rms = float(np.sqrt(np.mean(force_N[moving] ** 2))) if moving.any() else 0.0
    if rms < force_min:
        return (
            f"{what} changes the retarding force by {rms / 1e3:.2f} kN (RMS over the "
            f"stop): below {force_min / 1e3:.2f} kN, the force of a "
            f"{GRADIENT_MIN_PERMILLE:g} permille gradient"
        )
    return None


CANCEL_RATIO = 0.5


def cancelling_forces(
    force_a_N: np.ndarray, force_b_N: np.ndarray, trace: Trace, what: str
) -> str | None:
    """The reason two force effects fitted together are a compensation, not a finding: their
    sum's RMS over the stop under ``CANCEL_RATIO`` of the larger one's (each one, large, is
    there only to cancel the other: the data show the difference of their shapes, not their
    sizes — e.g. a downhill gradient against an extra brake force on a trace whose coasting
    lead-in and braking disagree)."""
    moving = stop_samples(trace)
    if not moving.any():
        return None

    def rms(f: np.ndarray) -> float:
        return float(np.sqrt(np.mean(f[moving] ** 2)))

    both, larger = rms(force_a_N + force_b_N), max(rms(force_a_N), rms(force_b_N))
    if both < CANCEL_RATIO * larger:
        return (
            f"{what} cancel: {larger / 1e3:.2f} kN each, {both / 1e3:.2f} kN together (RMS over "
            "the stop): one compensates the other"
        )
    return None


def implied_force_N(category: str, params: dict[str, float], trace: Trace) -> np.ndarray | None:
    """The extra retarding force (N, per sample) a force effect adds to the nominal model, or
    ``None`` for an effect that is not a force (a lag, a sensor, a wheel, the adhesion)."""
    weight = float(trace.vehicle["mass_kg"]) * G
    v = trace.v_train_kmh / 3.6
    if category == "gradient" and "gradient_permille" in params:
        return np.full(v.shape, weight * params["gradient_permille"] * 1e-3)
    if category == "running_resistance":
        return resistance_change_N(params, trace, v)
    if category == "pad_friction":
        from wsp_env.calibration.residuals import brake_force_N

        scale = params.get("scale", 1.0) + params.get("slope_per_mps", 0.0) * (v - 100.0 / 3.6)
        return (scale - 1.0) * brake_force_N(trace).sum(axis=1)
    if category == "unmeasured_brake_force" and "force_at_full_demand_N" in params:
        brake = trace.vehicle.get("brake", {})
        p_max = float(brake.get("p_max_bar", 0.0)) or float(trace.p_cyl_bar.max())
        demand = trace.optional.get("p_demand_bar", trace.p_cyl_bar.max(axis=1)) / p_max
        return params["force_at_full_demand_N"] * np.asarray(demand, dtype=float)
    return None


def resistance_change_N(params: dict[str, float], trace: Trace, v_mps: np.ndarray) -> np.ndarray:
    """The change of the running resistance (N) a ``running_resistance`` effect makes at
    ``v_mps``: the metadata's ``R(V)`` times ``factor - 1``, or ``dA + dC V^2``."""
    if "factor" in params:
        return (params["factor"] - 1.0) * resistance_N(trace, v_mps)
    return params.get("delta_a_N", 0.0) + params.get("delta_c_N_per_mps2", 0.0) * v_mps * v_mps


def channel_health(trace: Trace, chans: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Per channel: its RMSE, whether it may choose an effect, and why not."""
    out: dict[str, dict[str, Any]] = {}
    for name, ch in chans.items():
        n = int(np.sum(ch.mask))
        reason = ""
        if not math.isfinite(ch.rmse):
            reason = {
                "train_speed_balance_kmh": "no sample above 10 km/h with every wheel turning",
                "adhesion_fit_kN": (
                    "no adhesion evidence: fewer than 10 critical points above 10 km/h "
                    "(the wheels hardly slid) or the law fit failed"
                ),
                "coasting_creep_pct": (
                    "no unbraked sample above 10 km/h (no coasting lead-in in the record)"
                ),
            }.get(name, "no samples")
        elif name == "coasting_creep_pct":
            worst = float(np.max(np.abs(np.mean(np.where(ch.mask, ch.residual, 0.0), axis=0)
                                        / np.maximum(ch.mask.mean(axis=0), 1e-9))))  # fmt: skip
            if worst > COASTING_CREEP_MAX_PCT:
                reason = (
                    f"rolling wheels read {worst:.1f} % off the ground speed: beyond any radius "
                    "or sensor error a train runs with (units? channel mapping?)"
                )
        out[name] = {
            "rmse": ch.rmse,
            "samples": n,
            "usable": reason == "",
            "reason": reason,
        }
    return out


__all__ = [
    "cancelling_forces",
    "channel_health",
    "implausible",
    "implied_force_N",
    "negligible",
    "negligible_force",
    "resistance_change_N",
    "stop_samples",
]

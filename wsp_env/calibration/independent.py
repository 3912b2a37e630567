"""Independent simulator of railway braking tests that writes ``wsp-trace/1`` traces.

What it is
----------
A small, self-contained generator of *measured-style* braking traces (a BCU / test-logger
record of one emergency stop) with a known list of injected "effects" (a gradient nobody
wrote down, a worn wheel, weak pads, ...). It exists to judge the project's calibration
tool: the tool reads the trace, and its findings are compared with the truth injected here.

Why it is independent
---------------------
It was written from the public trace-format specification (``docs/trace_format.md``), the
physical facts in ``shared/REFERENCES.md`` and the source papers only, without reading or
importing anything of the code under test. It imports only the standard library, numpy and
numba (its 20 ms cycle loop is compiled: a compiler, not code of the project).
Its models deliberately differ from a textbook/Polach setup: a Burckhardt-type creep curve,
a rail-energy cleaning law of its own, its own WSP algorithm and its own logger model.
Agreement between the tool and this generator is therefore evidence, not an echo.

Model
-----
*Vehicle.* One rigid rake of ``n_cars`` cars (4 axles each, two two-axle bogies per car,
cars coupled rigidly; coupler moments are ignored), total mass ``M`` (the metadata mass), one
longitudinal speed ``V`` and position ``X``, and per axle a wheelset rotation ``omega_i``
(inertia ``J``, true radius ``r_i``)::

    M dV/dt   = -sum_i F_i - R(V) - M g theta - F_ub(t)
    J domega_i/dt = r_i F_i - T_i                 (T_i only while omega_i > 0; omega_i >= 0)

``F_i = mu_i N_i`` is the adhesion force (positive when braking, i.e. the wheel slower than
the train), ``R(V) = A + B V + C V^2`` (V in m/s, zero at standstill), ``theta`` the gradient
(rad ~ permille/1000, positive uphill), ``F_ub`` an unmeasured brake force (effect). The
wheelsets' rotational inertia is in the wheel equations, so the apparent mass is
``M + sum J / r_i^2``.

*Normal loads.* ``N_i = N_static,i + k_i a`` with ``a`` the vehicle deceleration (positive
when slowing, low-pass filtered with 0.1 s, i.e. quasi-static). ``k_i`` (kg) adds, per car c
of mass ``m_c``: body pitch ``+m_c h / L`` shared by the two axles of the car's leading bogie
(``-`` on the trailing bogie), ``h`` = ``cog_height_m``, ``L`` = ``bogie_centre_distance_m``;
and bogie pitch ``+m_c h_p / (2 w)`` on the leading axle of each bogie (``-`` on its trailing
axle), ``h_p`` the bogie pivot height (in the metadata only with ``pivot_in_metadata``),
``w`` = ``bogie_wheelbase_m``.
Static loads: each car's weight is split between its bogies with a small drawn asymmetry
(``static_front_share``), equally within a bogie; these true static loads are in the metadata.

*Friction law* (Burckhardt-type with sliding-speed decay; not Polach)::

    mu(s, w, V, xi) = L(V, xi) * g(|s|) / g_peak * (A + (1 - A) exp(-B |w|)) * sign(s)
    g(s) = 1 - exp(-c2 s) - c3 s,  g_peak = g(ln(c2/c3)/c2)
    s = (V - omega r) / max(V, 0.3 m/s)   (creep),   w = V - omega r   (sliding speed)

``c2`` 80-200 on contaminated rail (curve peak at 3-7 % creep), 300-600 on wet/dry rail;
``c3`` 0.2-0.4; ``A`` the sliding-speed asymptote ratio, ``B`` the decay per km/h of sliding
(0.03-0.06 /(km/h) on soap, seed 000 Table 4 gives ~0.03 per km/h). The level
``L = level(xi) * (1 - d_V (1 - exp(-V_kmh / V_s)))`` falls mildly with train speed
(``d_V`` 0.15-0.25 contaminated, 0.3-0.4 dry/wet). Levels are "peak mu at standstill and zero
sliding speed": soap 0.05-0.10, leaves 0.04-0.12, oil 0.04-0.09, wet 0.20-0.30, dry 0.35-0.55.

*Rail recovery* (own law). The rail coordinate ``xi`` is 0 where axle 1 was at the brake
application and grows in the running direction. Every axle's sliding power ``F_i w_i`` is
deposited on a 1 m grid along ``xi`` (energy per metre of rail, split linearly over the cells
covered in each 20 ms cycle; an axle reads the cell 1-2 m ahead of its contact, so it never
reads its own deposit). An axle reaching position ``xi`` sees the contaminant fraction
``rho = (1 - q)^(j-1) exp(-E(xi) / E_c)`` (j = axle number: j - 1 rolling passes before it,
``q`` 1-6 % per pass; ``E`` the sliding energy left there by the axles ahead; ``E_c`` 1-3 kJ/m
for soap, after seed 002 Table 5 ``W_lim`` = 1.6 kJ/m) and its level is
``level = mu_clean + (mu_cont (1 + roughness(xi)) - mu_clean) rho`` with ``mu_clean``
0.15-0.25. Oil is hard to clean (``E_c`` 10-30 kJ/m, ``q`` ~ 0.5 %). Wet and dry rail have no
contaminant and no recovery: their level is flat along the rail. ``roughness`` is a smooth random
variation (three sinusoids, wavelengths 15-250 m, relative RMS 0-6 %) of the contaminated level.

*Brake.* Demand pressure ramps linearly from 0 to ``p_max`` over ``demand_ramp_s`` (0.5-1.5 s)
from the brake application (emergency brake); optionally (``demand_drop_s`` > 0, never drawn:
a scenario override, for the clean traces whose wheels stop sliding because the demand falls)
the demand falls to ``demand_drop_factor`` of itself ``demand_drop_s`` after the application
(a driver easing the brake). Each axle's cylinder pressure follows a valve
state: apply -> first order towards the demand with ``tau_fill_s`` (0.4-1.0 s); vent ->
first order towards 0 with ``tau_vent_s`` (0.2-0.5 s, a different value); hold -> frozen.
(Pressure above the demand while applying also falls with ``tau_vent_s``.) Torque
``T_i = gain_true * max(0, p_i - p_threshold)``; nominal gain
``g_ref * (axle load / 13 t) * (r / 0.46 m)``, ``g_ref`` 2200-2800 N m/bar, one value for the
vehicle. ``p_max`` 3-4 bar, ``p_threshold`` 0.10-0.30 bar.

*WSP* (own design, 20 ms BCU cycle). Per axle an alpha-beta filter (alpha 0.35, beta 0.04) of
the BCU's speed reading ``omega r_nominal`` + sensor noise gives a filtered speed ``v_i`` and
acceleration. Reference speed: ``v_ref <- clip(max_i v_i, v_ref - a_bound dt, v_ref +
0.5 m/s^2 dt)``, ``a_bound = clip(a_ref + margin, 0.8, 2.5) m/s^2`` with ``a_ref`` the
reference's own deceleration low-passed over 0.3 s and ``margin`` 0.3-0.5 m/s^2 (so when
every axle slides, the reference falls slightly faster than the train had been braking). Per
axle: ``dv = v_ref - v_i`` (km/h), ``arel`` = axle deceleration minus ``a_ref`` (m/s^2);
``S1 = min(max(s1_kmh, s1_frac v_ref), 0.3 v_ref)`` (2.5-4 km/h, 6-10 %),
``S2 = min(max(s2_kmh, s2_frac v_ref), 0.45 v_ref)`` (5-8 km/h, 12-18 %).
Valve states APPLY / HOLD / VENT:

- APPLY -> HOLD if ``dv > S1`` or (``arel > a_dec`` and ``dv > S1/2``); -> VENT if
  ``dv > S2`` or (``arel > 2 a_dec`` and ``dv > S1``); ``a_dec`` 2.0-3.5 m/s^2.
- HOLD -> VENT on the vent criterion, or after ``hold_max`` (0.6-1.2 s) still above ``S1``;
  HOLD -> APPLY after ``hold_min`` (0.08-0.2 s) once ``dv < 0.4 S1`` and ``arel > -1``.
- VENT -> HOLD after ``vent_min`` (0.04-0.1 s) once ``dv < S1`` or the axle re-accelerates
  faster than 2 m/s^2 relative to the train.
- After a slide the re-application is stepped: pulses of apply (40-80 ms) and hold
  (100-200 ms) until the pressure is within 0.15 bar of the demand or 4 s have passed.
- Below ``v_ref`` < 2-3.5 km/h the WSP is off (all APPLY). No safety watchdog is modelled.
- The valve command reaches the valve ``valve_delay_cycles`` (1-3) BCU cycles later
  (20-60 ms). The WSP knows only nominal radii; it has no wheel-diameter compensation.

*Integration.* Fixed 10 ms substeps (2 per 20 ms BCU cycle; 1, 2, 4 and 10 substeps gave
the same stops and slide statistics). Each wheelset is advanced by implicit Euler against the
predicted end-of-substep train speed, solved per axle by Newton's method on the creep (in
``exp(-c2 |s|)`` on the steep part of the curve, in ``s`` on the saturated part, residual
< 2 N m); this is unconditionally stable for the stiff low-speed wheel dynamics (creep time
constants far below 1 ms). ``omega`` is clamped at 0: a locked wheel is held by the brake and
never turns backwards. The force on the vehicle is the one consistent with the implicit wheel
step (momentum conserving). ``V`` and ``X`` are explicit/trapezoidal, ``V`` clamped at 0. The
cylinder pressure is exact for the first-order law inside a cycle. The record ends 1 s
(``record_tail_s``) after the true speed first falls below 0.5 km/h, or after
``max_duration_s`` of braking.

Logger quirks (what the CSV looks like)
--------------------------------------
- Internal signals every 20 ms; logged every ``log_period_s`` (0.05 or 0.1 s, sometimes
  0.08 s) either by sample-and-hold of the last internal value (``log_mode="hold"``) or by
  the mean over the logging period (``"mean"``; ``wsp_active_<i>`` is then the OR over the
  period). Each row's sampling instant jitters by up to ``time_jitter_s`` (<= 2 ms) and is
  stamped exactly (times strictly increasing, row 0 at 0.0 s).
- ``v_axle_<i>_kmh`` = ``omega_i * r_nominal`` + Gaussian noise (std ``v_noise_kmh``,
  0.05-0.5 km/h, the same reading the WSP uses), clipped at 0, quantised to ``v_quant_kmh``.
- ``p_cyl_<i>_bar`` = the cylinder-pressure sensor + noise (``p_noise_bar``, 3-15 mbar),
  quantised to ``p_quant_bar`` (0.01/0.02/0.05 bar).
- ``v_train_kmh`` is GPS-like: fixes at ``gps_rate_hz`` (1, 2, 5 or 10 Hz, random phase),
  each the true speed ``gps_lag_s`` (0-0.05 s, plus any ``sensor_lag`` effect) earlier, times
  ``1 + scale_error`` (``sensor_scale`` effect), plus noise (``gps_noise_kmh``), clipped at 0;
  held between fixes; dropouts (Poisson, ``gps_dropout_per_s``) during which the receiver
  misses fixes for 0.2-1.0 s and holds its last one. Quantised to 0.01 km/h.
- ``n_empty_cells`` isolated single empty cells (never in ``time_s``, never in the first or
  last row, never two adjacent in a column).
- Optional columns: ``p_demand_bar``, ``v_ref_kmh`` (the WSP reference), ``wsp_active_<i>``.
- A coasting lead-in (``lead_in_s``, 0.5-10 s, no traction, wheels rolling freely: speed
  falls only by resistance and gradient) precedes the brake application. ``speed_kmh`` is the
  true speed at the start of the record; ``initial_speed_kmh`` in the metadata is the speed
  at the brake application (rounded to 0.1 km/h).

Metadata
--------
Only nominal data: format, test_id, sample_period_s, initial_speed_kmh, contaminant,
brake_type and vehicle {name, mass_kg, n_axles, wheel_radius_m (nominal),
wheelset_inertia_kgm2, axle_static_load_kN, cog_height_m, bogie_centre_distance_m,
bogie_wheelbase_m (all three left out when ``geometry_in_metadata`` is False; with them
``bogie_pivot_height_m`` where ``pivot_in_metadata``: half of the random scenarios; and
``axle_offsets_m``, each axle's distance behind axle 1, where ``offsets_in_metadata``: half of
those with geometry), brake
{p_threshold_bar, torque_gain_Nm_per_bar, p_max_bar}, resistance {a_N, b_N_per_mps,
c_N_per_mps2}}. With ``transfer_list_in_metadata`` (default False) it also gives
``axle_load_transfer_kN_per_mps2``: the NOMINAL body + bogie pitch transfer per axle. The
geometry fields describe one car; for a multi-car rake this simulator applies the body pitch
per car (``m_c``, not the rake's mass). The truth of injected effects is never written.

Quirks a calibration tool will meet even with no injected effect (all part of the scenario,
none of them an effect): the true load transfer includes bogie pitch, which the format's
body-only default (geometry fields without ``axle_load_transfer_kN_per_mps2``) leaves out;
the ground speed is held between GPS fixes, so it lags the truth by ``gps_lag_s`` plus on
average half a fix period (up to 0.5 s at 1 Hz) plus dropouts; the WSP's reference is the
fastest noisy axle (it reads slightly high); the rail adhesion varies smoothly along the track
(``adhesion_roughness``) and recovers behind sliding axles.

Injected effects (``Effect(category, params)``), exact conventions
-----------------------------------------------------------------
- ``gradient``: ``gradient_permille`` (permille, positive = uphill = helps braking); force
  ``M g permille/1000`` retarding (negative: accelerating), the whole record long.
- ``running_resistance``: ``factor`` (-); true ``A, B, C`` = factor x the metadata's.
- ``wheel_radius``: ``axle`` (1-based), ``radius_error`` (fraction); true radius = nominal
  x (1 + e). The logged axle speed stays ``omega r_nominal`` (reads low for e > 0).
- ``pad_friction``: ``scale`` (-); true torque gain = nominal x scale (every axle).
- ``unmeasured_brake_force``: ``force_N`` (N, positive retarding) at full demand; the force is
  ``force_N * p_demand(t) / p_max`` while the train moves (not in any column).
- ``pressure_lag``: ``lag_s`` (s); the brake torque follows the logged pressure ``lag_s`` later
  (sensor upstream of the cylinder): ``T(t) = gain max(0, p_logged(t - lag_s) - p_th)``.
- ``pressure_time_constant`` (calibration category ``pressure_lag``): ``time_constant_s`` (s);
  the cylinder behind the sensor fills through a restriction: the pressure that makes the
  torque is the logged one (after any ``pressure_lag`` dead time) through a first-order lag,
  ``tc dp_eff/dt = p_logged(t - lag_s) - p_eff`` (exact per 10 ms substep for a pressure held
  over it). Both together are a dead time followed by a first-order lag.
- ``sensor_scale`` (calibration category ``sensor``): ``scale_error`` (fraction); logged
  ground speed = (1 + s) x true speed.
- ``sensor_lag`` (calibration category ``sensor``): ``lag_s`` (s); logged ground speed is the
  true one ``lag_s`` late (on top of the logger's own small ``gps_lag_s``).
- ``load_transfer``: ``factor`` (-); true ``k_i`` (body + bogie pitch) = factor x the value
  the nominal geometry gives; the metadata geometry stays nominal.
- ``adhesion_position``: ``position_m`` (m, rail coordinate ``xi`` from axle 1's position at the
  brake application) and ``factor`` (-): at ``xi >= position_m`` every mu (contaminated and
  clean levels) is factor x what it would be; axle j meets the change when the train has run
  ``position_m + d_j`` (``d_j`` its distance behind axle 1).
- ``adhesion_per_axle``: ``axle`` (1-based), ``factor`` (-): that axle's mu x factor.

Several effects may be combined; two of the same category multiply (factors, scales) or add
(gradients, forces, lags, radius errors).

Public API: ``Scenario``, ``Effect``, ``random_scenario``, ``generate``, ``write_trace``,
``random_effect``, ``sliding_around`` (the truth a power study needs; see their docstrings).
Everything random comes from the given ``numpy.random.Generator`` or seed: the same seed gives
identical output.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

G = 9.80665
BCU_DT = 0.02
N_SUB = 2
SUB_DT = BCU_DT / N_SUB
V_MIN_CREEP = 0.3  # m/s, creep regularisation
STOP_KMH = 0.5
APPLY, HOLD, VENT = 0, 1, 2
GRID_DX = 1.0  # m, rail cleaning grid
TOL_G = 2.0  # N m, residual of the implicit wheel equation

CONTAMINANTS = ("soap", "leaves", "oil", "wet", "dry")

EFFECT_PARAMS: dict[str, tuple[str, ...]] = {
    "gradient": ("gradient_permille",),
    "running_resistance": ("factor",),
    "wheel_radius": ("axle", "radius_error"),
    "pad_friction": ("scale",),
    "unmeasured_brake_force": ("force_N",),
    "pressure_lag": ("lag_s",),
    "pressure_time_constant": ("time_constant_s",),
    "sensor_scale": ("scale_error",),
    "sensor_lag": ("lag_s",),
    "load_transfer": ("factor",),
    "adhesion_position": ("position_m", "factor"),
    "adhesion_per_axle": ("axle", "factor"),
}

CALIBRATION_CATEGORY: dict[str, str] = {
    k: ("sensor" if k.startswith("sensor_") else "pressure_lag" if k.startswith("pressure_") else k)
    for k in EFFECT_PARAMS
}


@dataclass
class Effect:
    """One injected effect: ``category`` (a key of ``EFFECT_PARAMS``) and its ``params``."""

    category: str
    params: dict[str, float]

    @property
    def calibration_category(self) -> str:
        """The calibration loop's name for this category (``sensor_*`` -> ``sensor``)."""
        return CALIBRATION_CATEGORY[self.category]


@dataclass
class Scenario:
    """Every drawn quantity of one simulated braking test (true physics + logger settings)."""

    seed: int = 0
    name: str = "independent-sim coach"
    n_axles: int = 4
    speed_kmh: float = 120.0
    lead_in_s: float = 3.0
    contaminant: str = "soap"
    # vehicle
    car_axle_load_t: list[float] = field(default_factory=lambda: [13.0])
    static_front_share: list[float] = field(default_factory=lambda: [0.5])
    wheel_radius_m: float = 0.46
    wheelset_inertia_kgm2: float = 180.0
    cog_height_m: float = 1.7
    bogie_centre_distance_m: float = 17.5
    bogie_wheelbase_m: float = 2.56
    bogie_pivot_height_m: float = 0.65
    car_overhang_m: float = 3.5
    # adhesion
    mu_contaminated: float = 0.07
    mu_clean: float = 0.2
    clean_energy_J_per_m: float = 1600.0
    rolling_clean_fraction: float = 0.03
    creep_c2: float = 120.0
    creep_c3: float = 0.3
    slide_asymptote: float = 0.4
    slide_decay_per_kmh: float = 0.045
    mu_speed_drop: float = 0.2
    mu_speed_kmh: float = 80.0
    adhesion_roughness: float = 0.0
    roughness_wavelengths_m: list[float] = field(default_factory=lambda: [30.0, 80.0, 200.0])
    roughness_phases: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    # brake
    p_max_bar: float = 3.8
    p_threshold_bar: float = 0.174
    torque_gain_Nm_per_bar: float = 2600.0
    demand_ramp_s: float = 1.0
    demand_drop_s: float = 0.0  # > 0: the demand falls to demand_drop_factor this long after
    demand_drop_factor: float = 1.0  # the application (a scenario override only, never drawn)
    tau_fill_s: float = 0.6
    tau_vent_s: float = 0.4
    valve_delay_cycles: int = 2
    # running resistance (nominal)
    resistance_a_N: float = 800.0
    resistance_b_N_per_mps: float = 15.0
    resistance_c_N_per_mps2: float = 5.0
    # WSP
    wsp_s1_kmh: float = 4.0
    wsp_s1_frac: float = 0.08
    wsp_s2_kmh: float = 8.0
    wsp_s2_frac: float = 0.15
    wsp_decel_mps2: float = 2.5
    wsp_hold_min_s: float = 0.12
    wsp_hold_max_s: float = 0.9
    wsp_vent_min_s: float = 0.06
    wsp_step_on_s: float = 0.06
    wsp_step_off_s: float = 0.14
    wsp_ref_margin_mps2: float = 0.4
    wsp_off_kmh: float = 4.0
    # logger
    log_period_s: float = 0.1
    log_mode: str = "hold"
    time_jitter_s: float = 0.001
    p_quant_bar: float = 0.01
    p_noise_bar: float = 0.005
    v_noise_kmh: float = 0.1
    v_quant_kmh: float = 0.01
    gps_rate_hz: float = 5.0
    gps_noise_kmh: float = 0.1
    gps_lag_s: float = 0.02
    gps_dropout_per_s: float = 0.02
    n_empty_cells: int = 0
    include_p_demand: bool = True
    include_v_ref: bool = False
    include_wsp_active: bool = False
    geometry_in_metadata: bool = True
    pivot_in_metadata: bool = False
    transfer_list_in_metadata: bool = False
    offsets_in_metadata: bool = False
    record_tail_s: float = 1.0
    max_duration_s: float = 300.0

    @property
    def n_cars(self) -> int:
        return self.n_axles // 4


def random_scenario(rng: np.random.Generator, **overrides: Any) -> Scenario:
    """Draw a scenario; ``overrides`` fix any ``Scenario`` field (dependent draws follow them).

    Every field is drawn in a fixed order whether or not it is overridden, so overriding one
    field leaves the others' draws unchanged (apart from fields that depend on it, e.g. the
    adhesion parameters on ``contaminant`` or the per-car lists on ``n_axles``).
    """
    names = {f.name for f in dataclasses.fields(Scenario)}
    unknown = set(overrides) - names
    if unknown:
        raise TypeError(f"unknown Scenario field(s): {sorted(unknown)}")

    def pick(name: str, value: Any) -> Any:
        return overrides.get(name, value)

    u = rng.uniform
    d: dict[str, Any] = {}
    d["seed"] = pick("seed", int(rng.integers(0, 2**31 - 1)))
    d["n_axles"] = int(pick("n_axles", int(rng.choice([4, 8, 12, 16], p=[0.4, 0.25, 0.15, 0.2]))))
    if d["n_axles"] < 4 or d["n_axles"] % 4:
        raise ValueError("n_axles must be 4, 8, 12 or 16 (4 axles per car)")
    n_cars = d["n_axles"] // 4
    d["speed_kmh"] = float(pick("speed_kmh", u(40.0, 200.0)))
    d["lead_in_s"] = float(pick("lead_in_s", u(0.5, 10.0)))
    cont = pick("contaminant", str(rng.choice(CONTAMINANTS, p=[0.45, 0.15, 0.1, 0.15, 0.15])))
    if cont not in CONTAMINANTS:
        raise ValueError(f"contaminant must be one of {CONTAMINANTS}")
    d["contaminant"] = cont
    d["name"] = pick("name", f"independent-sim {n_cars}-car rake")
    mean_load = u(9.0, 17.0)
    loads = np.clip(mean_load * (1.0 + rng.uniform(-0.05, 0.05, n_cars)), 9.0, 17.0)
    d["car_axle_load_t"] = pick("car_axle_load_t", [float(x) for x in loads])
    d["static_front_share"] = pick(
        "static_front_share", [float(x) for x in rng.uniform(0.48, 0.52, n_cars)]
    )
    r = float(pick("wheel_radius_m", u(0.40, 0.50)))
    d["wheel_radius_m"] = r
    d["wheelset_inertia_kgm2"] = float(pick("wheelset_inertia_kgm2", u(0.55, 0.75) * 1400 * r**2))
    d["cog_height_m"] = float(pick("cog_height_m", u(1.4, 1.9)))
    d["bogie_centre_distance_m"] = float(pick("bogie_centre_distance_m", u(14.0, 19.5)))
    d["bogie_wheelbase_m"] = float(pick("bogie_wheelbase_m", u(2.2, 3.0)))
    d["bogie_pivot_height_m"] = float(pick("bogie_pivot_height_m", u(0.5, 0.8)))
    d["car_overhang_m"] = float(pick("car_overhang_m", u(3.0, 4.5)))
    # adhesion (drawn for every contaminant, then chosen: keeps the stream fixed)
    draws = {
        "soap": (u(0.05, 0.10), u(0.15, 0.25), u(1000, 3000), u(0.02, 0.06)),
        "leaves": (u(0.04, 0.12), u(0.15, 0.22), u(2000, 5000), u(0.01, 0.04)),
        "oil": (u(0.04, 0.09), u(0.15, 0.20), u(10000, 30000), u(0.003, 0.008)),
        "wet": (u(0.20, 0.30), 0.0, 0.0, 0.0),
        "dry": (u(0.35, 0.55), 0.0, 0.0, 0.0),
    }
    curve_cont = (u(80, 200), u(0.2, 0.4), u(0.3, 0.5), u(0.03, 0.06), u(0.15, 0.25), u(60, 100))
    curve_good = (u(300, 600), u(0.2, 0.4), u(0.5, 0.7), u(0.01, 0.02), u(0.3, 0.4), u(80, 120))
    mu_c, mu_cl, e_c, q = draws[cont]
    good = cont in ("wet", "dry")
    if good:
        mu_cl, e_c, q = mu_c, 1.0, 0.0
    curve = curve_good if good else curve_cont
    d["mu_contaminated"] = float(pick("mu_contaminated", mu_c))
    d["mu_clean"] = float(pick("mu_clean", mu_cl))
    d["clean_energy_J_per_m"] = float(pick("clean_energy_J_per_m", e_c))
    d["rolling_clean_fraction"] = float(pick("rolling_clean_fraction", q))
    for key, val in zip(
        (
            "creep_c2",
            "creep_c3",
            "slide_asymptote",
            "slide_decay_per_kmh",
            "mu_speed_drop",
            "mu_speed_kmh",
        ),
        curve,
        strict=True,
    ):
        d[key] = float(pick(key, val))
    rough = u(0.0, 0.06)
    d["adhesion_roughness"] = float(pick("adhesion_roughness", 0.0 if good else rough))
    d["roughness_wavelengths_m"] = pick(
        "roughness_wavelengths_m", [float(x) for x in rng.uniform(15.0, 250.0, 3)]
    )
    d["roughness_phases"] = pick(
        "roughness_phases", [float(x) for x in rng.uniform(0.0, 2 * np.pi, 3)]
    )
    # brake
    d["p_max_bar"] = float(pick("p_max_bar", u(3.0, 4.0)))
    d["p_threshold_bar"] = float(pick("p_threshold_bar", u(0.10, 0.30)))
    mean_load_t = float(np.mean(d["car_axle_load_t"]))
    d["torque_gain_Nm_per_bar"] = float(
        pick("torque_gain_Nm_per_bar", u(2200.0, 2800.0) * mean_load_t / 13.0 * r / 0.46)
    )
    d["demand_ramp_s"] = float(pick("demand_ramp_s", u(0.5, 1.5)))
    d["tau_fill_s"] = float(pick("tau_fill_s", u(0.4, 1.0)))
    d["tau_vent_s"] = float(pick("tau_vent_s", u(0.2, 0.5)))
    d["valve_delay_cycles"] = int(pick("valve_delay_cycles", int(rng.integers(1, 4))))
    mass = 4000.0 * float(np.sum(d["car_axle_load_t"]))
    d["resistance_a_N"] = float(pick("resistance_a_N", mass * G * u(0.0012, 0.002)))
    d["resistance_b_N_per_mps"] = float(pick("resistance_b_N_per_mps", mass * u(2e-4, 5e-4)))
    d["resistance_c_N_per_mps2"] = float(
        pick("resistance_c_N_per_mps2", u(2.0, 4.0) + (n_cars - 1) * u(1.0, 2.0))
    )
    # WSP
    for key, lo, hi in (
        ("wsp_s1_kmh", 2.5, 4.0),
        ("wsp_s1_frac", 0.06, 0.10),
        ("wsp_s2_kmh", 5.0, 8.0),
        ("wsp_s2_frac", 0.12, 0.18),
        ("wsp_decel_mps2", 2.0, 3.5),
        ("wsp_hold_min_s", 0.08, 0.2),
        ("wsp_hold_max_s", 0.6, 1.2),
        ("wsp_vent_min_s", 0.04, 0.1),
        ("wsp_step_on_s", 0.04, 0.08),
        ("wsp_step_off_s", 0.1, 0.2),
        ("wsp_ref_margin_mps2", 0.3, 0.5),
        ("wsp_off_kmh", 2.0, 3.5),
    ):
        d[key] = float(pick(key, u(lo, hi)))
    # logger
    d["log_period_s"] = float(
        pick("log_period_s", float(rng.choice([0.05, 0.1, 0.08], p=[0.45, 0.45, 0.1])))
    )
    d["log_mode"] = pick("log_mode", str(rng.choice(["hold", "mean"])))
    d["time_jitter_s"] = float(pick("time_jitter_s", u(0.0, 0.002)))
    d["p_quant_bar"] = float(pick("p_quant_bar", float(rng.choice([0.01, 0.02, 0.05]))))
    d["p_noise_bar"] = float(pick("p_noise_bar", u(0.003, 0.015)))
    d["v_noise_kmh"] = float(pick("v_noise_kmh", math.exp(u(math.log(0.05), math.log(0.5)))))
    d["v_quant_kmh"] = float(pick("v_quant_kmh", float(rng.choice([0.01, 0.01, 0.05]))))
    d["gps_rate_hz"] = float(pick("gps_rate_hz", float(rng.choice([1.0, 2.0, 5.0, 10.0]))))
    d["gps_noise_kmh"] = float(pick("gps_noise_kmh", u(0.05, 0.3)))
    d["gps_lag_s"] = float(pick("gps_lag_s", u(0.0, 0.05)))
    d["gps_dropout_per_s"] = float(pick("gps_dropout_per_s", u(0.0, 0.05)))
    d["n_empty_cells"] = int(pick("n_empty_cells", int(rng.choice([0, 0, 1, 2, 3, 5]))))
    d["include_p_demand"] = bool(pick("include_p_demand", bool(rng.random() < 0.5)))
    d["include_v_ref"] = bool(pick("include_v_ref", bool(rng.random() < 0.5)))
    d["include_wsp_active"] = bool(pick("include_wsp_active", bool(rng.random() < 0.3)))
    d["geometry_in_metadata"] = bool(pick("geometry_in_metadata", bool(rng.random() < 0.75)))
    d["transfer_list_in_metadata"] = bool(pick("transfer_list_in_metadata", False))
    d["record_tail_s"] = float(pick("record_tail_s", 1.0))
    d["max_duration_s"] = float(pick("max_duration_s", 300.0))
    # from a stream of its own (the scenario's seed), so that the caller's generator moves as
    # it did before this field existed: of the traces with geometry (75 %), two in three also
    # give the bogie pivot height (50 % of all)
    own = np.random.default_rng([int(d["seed"]), 25])
    d["pivot_in_metadata"] = bool(pick("pivot_in_metadata", bool(own.random() < 2.0 / 3.0)))
    # and, drawn after it on the same stream, each axle's position along the train in one in two
    d["offsets_in_metadata"] = bool(pick("offsets_in_metadata", bool(own.random() < 0.5)))
    d["demand_drop_s"] = float(pick("demand_drop_s", 0.0))  # overrides only: the stream stays
    d["demand_drop_factor"] = float(pick("demand_drop_factor", 1.0))
    if not d["demand_drop_s"] >= 0.0:
        raise ValueError(f"demand_drop_s must be >= 0 (s), got {d['demand_drop_s']}")
    if not 0.0 < d["demand_drop_factor"] <= 1.0:
        raise ValueError(f"demand_drop_factor must be in (0, 1], got {d['demand_drop_factor']}")
    sc = Scenario(**d)
    for lst in ("car_axle_load_t", "static_front_share"):
        if len(getattr(sc, lst)) != sc.n_cars:
            raise ValueError(f"{lst} needs one value per car ({sc.n_cars})")
    if sc.log_mode not in ("hold", "mean"):
        raise ValueError("log_mode must be 'hold' or 'mean'")
    return sc


# ----------------------------------------------------------------------------------------
# vehicle and effects
# ----------------------------------------------------------------------------------------


def _vehicle(sc: Scenario) -> dict[str, Any]:
    """Nominal per-axle arrays: static loads (N), transfer k (kg), offsets behind axle 1 (m)."""
    n = sc.n_axles
    n_static = np.empty(n)
    k_body = np.empty(n)
    k_bogie = np.empty(n)
    offset = np.empty(n)
    car_len = sc.bogie_centre_distance_m + 2 * sc.car_overhang_m
    wb, lbc = sc.bogie_wheelbase_m, sc.bogie_centre_distance_m
    for c in range(sc.n_cars):
        m_c = 4000.0 * sc.car_axle_load_t[c]
        share = sc.static_front_share[c]
        front = c * car_len + sc.car_overhang_m
        centres = (front, front + lbc)
        for b in range(2):
            bogie_w = m_c * G * (share if b == 0 else 1.0 - share)
            for a in range(2):
                i = 4 * c + 2 * b + a
                n_static[i] = bogie_w / 2.0
                k_body[i] = (1 if b == 0 else -1) * m_c * sc.cog_height_m / lbc / 2.0
                k_bogie[i] = (1 if a == 0 else -1) * m_c * sc.bogie_pivot_height_m / (2.0 * wb)
                offset[i] = centres[b] + (a - 0.5) * wb
    offset -= offset[0]
    mass = 4000.0 * float(np.sum(sc.car_axle_load_t))
    return {
        "mass": mass,
        "n_static": n_static,
        "k": k_body + k_bogie,
        "offset": offset,
    }


def _check_effect(e: Effect, n_axles: int) -> None:
    if e.category not in EFFECT_PARAMS:
        raise ValueError(f"unknown effect category {e.category!r}")
    need = set(EFFECT_PARAMS[e.category])
    if set(e.params) != need:
        raise ValueError(f"{e.category} needs exactly the params {sorted(need)}")
    if "axle" in need:
        ax = e.params["axle"]
        if ax != int(ax) or not 1 <= int(ax) <= n_axles:
            raise ValueError(f"{e.category}: axle must be 1..{n_axles}")


def _resolve_effects(sc: Scenario, effects: Sequence[Effect]) -> dict[str, Any]:
    n = sc.n_axles
    t: dict[str, Any] = {
        "gradient_permille": 0.0,
        "resistance_factor": 1.0,
        "radius_error": np.zeros(n),
        "pad_scale": 1.0,
        "ub_force": 0.0,
        "pressure_lag": 0.0,
        "pressure_tc": 0.0,
        "gps_scale_error": 0.0,
        "gps_extra_lag": 0.0,
        "transfer_factor": 1.0,
        "positions": [],
        "axle_factor": np.ones(n),
    }
    for e in effects:
        _check_effect(e, n)
        p = e.params
        c = e.category
        if c == "gradient":
            t["gradient_permille"] += float(p["gradient_permille"])
        elif c == "running_resistance":
            t["resistance_factor"] *= float(p["factor"])
        elif c == "wheel_radius":
            t["radius_error"][int(p["axle"]) - 1] += float(p["radius_error"])
        elif c == "pad_friction":
            t["pad_scale"] *= float(p["scale"])
        elif c == "unmeasured_brake_force":
            t["ub_force"] += float(p["force_N"])
        elif c == "pressure_lag":
            t["pressure_lag"] += float(p["lag_s"])
        elif c == "pressure_time_constant":
            t["pressure_tc"] += float(p["time_constant_s"])
        elif c == "sensor_scale":
            t["gps_scale_error"] = (1 + t["gps_scale_error"]) * (1 + float(p["scale_error"])) - 1
        elif c == "sensor_lag":
            t["gps_extra_lag"] += float(p["lag_s"])
        elif c == "load_transfer":
            t["transfer_factor"] *= float(p["factor"])
        elif c == "adhesion_position":
            t["positions"].append((float(p["position_m"]), float(p["factor"])))
        elif c == "adhesion_per_axle":
            t["axle_factor"][int(p["axle"]) - 1] *= float(p["factor"])
    if t["pressure_lag"] < 0 or t["gps_extra_lag"] < 0 or t["pressure_tc"] < 0:
        raise ValueError("lags must be >= 0")
    return t


def _estimated_stop(sc: Scenario) -> tuple[float, float]:
    """Rough (deceleration m/s^2, braking distance m) for placing effects and the grid."""
    veh = _vehicle(sc)
    a_brake = (
        sc.n_axles
        * sc.torque_gain_Nm_per_bar
        * (sc.p_max_bar - sc.p_threshold_bar)
        / sc.wheel_radius_m
        / veh["mass"]
    )
    if sc.contaminant in ("wet", "dry"):
        mu = sc.mu_contaminated * (1 - 0.5 * sc.mu_speed_drop)
    else:
        mu = 0.5 * (sc.mu_contaminated + sc.mu_clean) * 0.85
    a = max(0.2, min(a_brake, G * mu))
    v = sc.speed_kmh / 3.6
    return a, v * v / (2 * a) + v * sc.demand_ramp_s / 2


def random_effect(
    category: str, magnitude: float, rng: np.random.Generator, scenario: Scenario
) -> Effect:
    """An effect of ``category`` with size ``magnitude`` in the category's natural unit.

    gradient: +-magnitude permille (sign drawn); running_resistance, pad_friction (scale),
    load_transfer, adhesion_per_axle, adhesion_position: the factor itself = magnitude;
    wheel_radius: radius_error +-magnitude (fraction, sign drawn, random axle);
    unmeasured_brake_force: force_N = magnitude (N); pressure_lag, sensor_lag: lag_s =
    magnitude (s); pressure_time_constant: time_constant_s = magnitude (s); sensor_scale:
    scale_error +-magnitude (fraction, sign drawn);
    adhesion_per_axle: random axle; adhesion_position: position drawn in 15-60 % of the
    estimated braking distance.
    """
    if category not in EFFECT_PARAMS:
        raise ValueError(f"unknown effect category {category!r}")
    m = float(magnitude)

    def sign() -> float:
        return 1.0 if rng.random() < 0.5 else -1.0

    def axle() -> float:
        return float(rng.integers(1, scenario.n_axles + 1))

    if category == "gradient":
        params = {"gradient_permille": sign() * m}
    elif category in ("running_resistance", "load_transfer"):
        params = {"factor": m}
    elif category == "pad_friction":
        params = {"scale": m}
    elif category == "wheel_radius":
        params = {"axle": axle(), "radius_error": sign() * m}
    elif category == "unmeasured_brake_force":
        params = {"force_N": m}
    elif category in ("pressure_lag", "sensor_lag"):
        params = {"lag_s": m}
    elif category == "pressure_time_constant":
        params = {"time_constant_s": m}
    elif category == "sensor_scale":
        params = {"scale_error": sign() * m}
    elif category == "adhesion_per_axle":
        params = {"axle": axle(), "factor": m}
    else:  # adhesion_position
        _, dist = _estimated_stop(scenario)
        params = {"position_m": float(rng.uniform(0.15, 0.6) * dist), "factor": m}
    return Effect(category, params)


# ----------------------------------------------------------------------------------------
# the 20 ms cycles, compiled
# ----------------------------------------------------------------------------------------
# The cycle loop below was numpy array operations on a handful of axles (about 1 s a stop, most
# of it interpreter overhead); compiled with numba it is the same IEEE operations in the same
# order: ``np.maximum``/``np.minimum``/``np.clip`` keep numpy's NaN rule (``_fmax``, ``_fmin``),
# Python's ``max``/``min`` theirs (``_pmax``, ``_pmin``), a sum over axles numpy's pairwise order
# (``_np_sum``), and ``a[idx] += v`` numpy's buffered fancy assignment (the last write wins).
# numba is a compiler, not code of the project: the generator still shares nothing with it.
# Every exp, log, pow and sin of a trace is the C library's: in the kernels (numba calls it), and
# in the set-up through ``math`` and ``_roughness``, never numpy's array or scalar versions. On an
# AVX-512 machine numpy uses its own vector routines (numpy 2.4: its ``X86_V4`` dispatch), which
# differ from the C library's in the last bit on some arguments (on an AVX2 machine numpy calls
# the C library), so a trace made with them depended on the CPU. With the C library it depends on
# the C library alone (tests/test_cpu_independence.py; test_independent_traces.py's frozen
# digests, met on an AVX2 and an AVX-512 machine).


@njit(cache=True, error_model="numpy", inline="always")
def _fmax(a, b):  # np.maximum: NaN if either is
    return a if (a >= b or a != a) else b


@njit(cache=True, error_model="numpy", inline="always")
def _fmin(a, b):  # np.minimum: NaN if either is
    return a if (a <= b or a != a) else b


@njit(cache=True, error_model="numpy", inline="always")
def _pmax(a, b):  # Python's max(a, b): the first unless the second is larger
    return b if b > a else a


@njit(cache=True, error_model="numpy", inline="always")
def _pmin(a, b):  # Python's min(a, b): the first unless the second is smaller
    return b if b < a else a


@njit(cache=True, error_model="numpy")
def _roughness(xi_cells, wavelengths, phases):
    """``sum_k sin(2 pi xi / lambda_k + phase_k)`` over the cells, the terms added in order,
    each sine the C library's."""
    rough = np.zeros(xi_cells.shape[0])
    two_pi = 2 * np.pi
    for k in range(wavelengths.shape[0]):
        for c in range(xi_cells.shape[0]):
            rough[c] += math.sin(two_pi * xi_cells[c] / wavelengths[k] + phases[k])
    return rough


@njit(cache=True, error_model="numpy")
def _np_sum(a):
    """``a.sum()`` as numpy (2.4) adds a float64 vector of up to 128 entries: pairwise blocks
    of 8 (checked against ``np.sum`` for 1-40 entries; a sum of -0.0s is 0.0 in both)."""
    n = a.shape[0]
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[i]
        return res
    r = a[:8].copy()
    i = 8
    while i < n - (n % 8):
        for j in range(8):
            r[j] += a[i + j]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        res += a[i]
        i += 1
    return res


@njit(cache=True, error_model="numpy")
def _cycles(
    scalars, counts, r, inv_r, Jdt_r, gain, n_static, k_tr, offset, axle_fac, L_pre, qpow,
    v_noise, p_noise, mu_cont_g, mu_clean_g, e_grid, dec_fill, dec_vent, p_hist,
    rec_V, rec_X, rec_om, rec_p, rec_T, rec_F, rec_N, rec_L, rec_pd, rec_vref, rec_state, rec_ub,
):  # fmt: skip
    """The BCU and the physics, cycle by cycle, into the ``rec_`` arrays (``simulate_record``);
    returns (cycles recorded, the stop's cycle or -1, the position at the brake application)."""
    (v0, r_nom, M, pth, res_a, res_b, res_c, f_grade, ub_force, c2, c3, g_pk, A_s, B_s,
     one_minus_A, lead_in_s, demand_ramp_s, demand_drop_s, demand_drop_factor, p_max_bar,
     wsp_off_kmh, ref_margin, s1_kmh, s1_frac, s2_kmh, s2_frac, a_dec, mu_speed_drop,
     mu_speed_kmh, grid_lo, inv_ec, lag_sub, dec_tc) = scalars  # fmt: skip
    (n_max, k_b, n_cells, n_hold_min, n_hold_max, n_vent_min, n_on, n_per, n_step_max, n_delay,
     tail_k, good, lagged, filtered) = counts  # fmt: skip
    n = r.shape[0]
    ab_a, ab_b = 0.35, 0.04
    cmd_line = np.zeros((n_delay + 1, n), dtype=np.int8)  # the valve commands on their way

    V = v0
    X = 0.0
    om = np.empty(n)
    xf = np.empty(n)
    for i in range(n):
        om[i] = V / r[i]
        xf[i] = om[i] * r_nom * 3.6
    p = np.zeros(n)
    a_f = 0.0
    F = np.zeros(n)
    T = np.zeros(n)
    af = np.zeros(n)
    vref = xf[0]
    for i in range(1, n):
        vref = _fmax(vref, xf[i])
    aref = 0.0
    state = np.zeros(n, dtype=np.int8)
    cmd = np.zeros(n, dtype=np.int8)
    valve = np.zeros(n, dtype=np.int8)
    timer = np.zeros(n, dtype=np.int64)
    stepped = np.zeros(n, dtype=np.bool_)
    zp = np.empty(n)
    Ln = np.empty(n)
    p_sub = np.empty((N_SUB, n))
    p_use = np.empty((N_SUB, n))
    T_sub = np.empty((N_SUB, n))
    p_eff = np.zeros(n)  # the first-order lagged pressure (pressure_time_constant)
    e_slide = np.empty(n)
    rLn = np.empty(n)
    w = np.empty(n)
    a_m = np.empty(n)
    K = np.empty(n)
    C = np.empty(n)
    Ca = np.empty(n)
    x_max = np.empty(n)
    x = np.empty(n)
    kap = np.empty(n)
    f = np.empty(n)
    at_max = np.zeros(n, dtype=np.bool_)
    om_new = np.empty(n)
    F_used = np.empty(n)
    i0s = np.empty(n, dtype=np.int64)
    add = np.empty(n)
    dens = np.empty(n)
    frac0 = np.empty(n)
    X_b = 0.0
    k_end = n_max
    k_stop = -1
    acc = 0.0
    m_sub = 0
    for k in range(n_max):
        t = k * BCU_DT
        braking = k >= k_b
        if k == k_b:
            X_b = X
        # ---------------- BCU: sensing and WSP ----------------
        cand = 0.0
        for i in range(n):
            z = _fmax(om[i] * r_nom * 3.6 + v_noise[k, i], 0.0)
            zp[i] = p[i] + p_noise[k, i]
            xp = xf[i] + af[i] * BCU_DT
            res = z - xp
            xf[i] = xp + ab_a * res
            af[i] = af[i] + (ab_b / BCU_DT) * res
            cand = xf[i] if i == 0 else _fmax(cand, xf[i])
        a_bound = _pmin(_pmax(aref + ref_margin, 0.8), 2.5)
        v_new = _pmin(_pmax(cand, vref - a_bound * BCU_DT * 3.6), vref + 0.5 * BCU_DT * 3.6)
        aref += ((vref - v_new) / (BCU_DT * 3.6) - aref) * (BCU_DT / 0.3)
        vref = v_new
        pd = p_max_bar * _pmin(1.0, (t - lead_in_s) / demand_ramp_s) if braking else 0.0
        if demand_drop_s > 0.0 and t - lead_in_s >= demand_drop_s:
            pd *= demand_drop_factor
        pd = _pmax(pd, 0.0)
        if braking and vref > wsp_off_kmh:
            s1 = _pmin(_pmax(s1_kmh, s1_frac * vref), 0.3 * vref)
            s2 = _pmin(_pmax(s2_kmh, s2_frac * vref), 0.45 * vref)
            for i in range(n):
                dv = vref - xf[i]
                arel = -af[i] / 3.6 - aref
                crit_vent = (dv > s2) or ((arel > 2 * a_dec) and (dv > s1))
                crit_hold = (dv > s1) or ((arel > a_dec) and (dv > 0.5 * s1))
                recovered = (dv < 0.4 * s1) and (arel > -1.0)
                timer[i] += 1
                st = state[i]
                nw = st
                if st == APPLY and crit_hold:
                    nw = HOLD
                if st == APPLY and crit_vent:
                    nw = VENT
                to_apply = st == HOLD and not crit_vent and timer[i] >= n_hold_min and recovered
                if to_apply:
                    nw = APPLY
                if st == HOLD and (crit_vent or (timer[i] >= n_hold_max and dv > s1)):
                    nw = VENT
                if st == VENT and timer[i] >= n_vent_min and (dv < s1 or arel < -2.0):
                    nw = HOLD
                if nw != st:
                    timer[i] = 0
                stepped[i] = stepped[i] or to_apply
                state[i] = nw
                if state[i] == APPLY and (zp[i] > pd - 0.15 or timer[i] > n_step_max):
                    stepped[i] = False
                cmd[i] = state[i]
                if stepped[i] and state[i] == APPLY and (timer[i] % n_per) >= n_on:
                    cmd[i] = HOLD
        else:
            for i in range(n):
                state[i] = APPLY
                stepped[i] = False
                timer[i] = 0
                cmd[i] = state[i]
        slot = k % (n_delay + 1)  # the command of n_delay + 1 cycles ago reaches the valve
        for i in range(n):
            valve[i] = cmd_line[slot, i]
            cmd_line[slot, i] = cmd[i]

        # ---------------- record (values at t_k) ----------------
        rec_V[k] = V
        rec_X[k] = X
        for i in range(n):
            rec_om[k, i] = om[i]
            rec_p[k, i] = zp[i]
            rec_T[k, i] = T[i]
            rec_F[k, i] = F[i]
            rec_N[k, i] = n_static[i] + k_tr[i] * a_f
            rec_state[k, i] = state[i]
        rec_pd[k] = pd
        rec_vref[k] = vref
        rec_ub[k] = ub_force * pd / p_max_bar if V > 0 else 0.0
        if k_stop < 0 and braking and V * 3.6 < STOP_KMH:
            k_stop = k
            k_end = min(n_max, k + tail_k + 1)
        if k + 1 >= k_end:
            k_end = k + 1
            break

        # ---------------- adhesion level for this cycle ----------------
        v_kmh = V * 3.6
        f_v = 1.0 - mu_speed_drop * (1.0 - math.exp(-v_kmh / mu_speed_kmh))
        for i in range(n):
            if braking:
                # read one cell beyond where this cycle's own deposit will go (< the wheelbase)
                xi0 = X - X_b - offset[i] + (V * BCU_DT + GRID_DX)
                idx0 = min(max(np.int64((xi0 - grid_lo) / GRID_DX), 0), n_cells - 1)
                if good:
                    Lv = mu_clean_g[idx0]
                else:
                    rho = qpow[i] * np.exp(-e_grid[idx0] * inv_ec)
                    mc = mu_clean_g[idx0]
                    Lv = mc + (mu_cont_g[idx0] - mc) * rho
                Ln[i] = Lv * (f_v * axle_fac[i])
            else:
                Ln[i] = L_pre[i] * f_v
            rec_L[k, i] = Ln[i] * g_pk

        # ---------------- pressures over the cycle (exact first order) ----------------
        for i in range(n):
            vent = valve[i] == VENT
            target = 0.0 if vent else pd
            down = vent or (p[i] > target)
            for j in range(N_SUB):
                decay = dec_vent[j] if down else dec_fill[j]
                p_sub[j, i] = p[i] if valve[i] == HOLD else target + (p[i] - target) * decay
        if lagged:
            for j in range(N_SUB):
                m = m_sub + 1 + j
                for i in range(n):
                    p_hist[m, i] = p_sub[j, i]
            for j in range(N_SUB):
                q = _fmax(np.float64(m_sub + 1 + j) - lag_sub, 0.0)
                i0 = np.int64(np.floor(q))
                fr = q - i0
                i1 = min(i0 + 1, m_sub + N_SUB)
                for i in range(n):
                    p_use[j, i] = p_hist[i0, i] * (1 - fr) + p_hist[i1, i] * fr
        else:
            p_use[:, :] = p_sub
        if filtered:  # first order behind the dead time, exact for a pressure held per substep
            for j in range(N_SUB):
                for i in range(n):
                    p_eff[i] = p_use[j, i] + (p_eff[i] - p_use[j, i]) * dec_tc
                    p_use[j, i] = p_eff[i]
        for j in range(N_SUB):
            for i in range(n):
                T_sub[j, i] = gain[i] * _fmax(p_use[j, i] - pth, 0.0)
        for i in range(n):
            p[i] = p_sub[N_SUB - 1, i]
        m_sub += N_SUB
        f_ub = ub_force * pd / p_max_bar

        # ---------------- substeps ----------------
        X_start = X
        for i in range(n):
            e_slide[i] = 0.0
            rLn[i] = r[i] * Ln[i]
        for j in range(N_SUB):
            V1 = V + SUB_DT * acc if V > 0.0 else 0.0  # predicted speed at the substep end
            if V1 < 0.0:
                V1 = 0.0
            vd = V1 if V1 > V_MIN_CREEP else V_MIN_CREEP
            s_max = V1 / vd
            # Implicit Euler for omega (sliding-speed factor h frozen over the substep), in the
            # creep s: G(s) = a_m m(s) + K s - C = 0 with a_m = r L N h, K = J vd/(r dt),
            # C = T + J w/(r dt). G(0) = -C and G increases, so the root has the sign of C:
            # solve f(x) = a_m (1 - exp(-c2 x) - c3 x) + K x - |C| = 0 for x = |s|. Newton in
            # x where the curve is saturated (c2 x > 2: f nearly linear), Newton in
            # z = exp(-c2 x) elsewhere (f convex and decreasing in z: monotone convergence).
            for i in range(n):
                T[i] = T_sub[j, i]
                w[i] = V1 - om[i] * r[i]
                a_m[i] = (rLn[i] * (n_static[i] + k_tr[i] * a_f)) * (
                    A_s + one_minus_A * np.exp(-B_s * np.abs(w[i]))
                )
                K[i] = Jdt_r[i] * vd
                C[i] = T[i] + Jdt_r[i] * w[i]
                Ca[i] = np.abs(C[i])
                x_max[i] = s_max if C[i] >= 0.0 else 0.05
                x[i] = _fmin(np.abs(w[i]) / vd, x_max[i])
                kap[i] = (K[i] - c3 * a_m[i]) / c2
            any_max = False
            for _it in range(8):
                worst = 0.0
                any_max = False
                for i in range(n):
                    e2 = np.exp(-c2 * x[i])
                    f[i] = a_m[i] * (1.0 - e2 - c3 * x[i]) + K[i] * x[i] - Ca[i]
                    at_max[i] = x[i] >= x_max[i]
                    any_max = any_max or at_max[i]
                    fe = _fmax(f[i], 0.0) if at_max[i] else f[i]
                    worst = np.abs(fe) if i == 0 else _fmax(worst, np.abs(fe))
                if worst < TOL_G:
                    break
                for i in range(n):
                    e2 = np.exp(-c2 * x[i])
                    x_s = x[i] - f[i] / (a_m[i] * (c2 * e2 - c3) + K[i])
                    z_new = e2 + f[i] * e2 / (a_m[i] * e2 + kap[i])
                    x_z = np.log(_fmax(z_new, 1e-300)) / -c2
                    xn = x_s if ((c2 * x[i] > 2.0) or (z_new <= 0.0)) else x_z
                    x[i] = _fmin(_fmax(xn, 0.0), x_max[i])
            for i in range(n):
                om_new[i] = (V1 - np.copysign(x[i], C[i]) * vd) * inv_r[i]
                F_used[i] = Jdt_r[i] * (om_new[i] - om[i]) + T[i] * inv_r[i]
            if any_max:
                for i in range(n):
                    if at_max[i] and f[i] < 0.0:  # locked
                        F_used[i] = a_m[i] * inv_r[i] * (1.0 - math.exp(-c2 * s_max) - c3 * s_max)
                    om_new[i] = _fmax(om_new[i], 0.0)
            for i in range(n):
                om[i] = om_new[i]
                F[i] = F_used[i]
                e_slide[i] += F_used[i] * w[i]
            if V > 0.0:
                R = res_a + (res_b + res_c * V) * V
                acc = -(_np_sum(F_used) + R + f_grade + f_ub) / M
                V_new = V + SUB_DT * acc
                if V_new < 0.0:
                    V_new = 0.0
                a_f += (-(V_new - V) / SUB_DT - a_f) * (SUB_DT / 0.1)
                X += 0.5 * (V + V_new) * SUB_DT
                V = V_new
            else:
                a_f += (0.0 - a_f) * (SUB_DT / 0.1)
        # ---------------- rail cleaning: deposit the cycle's sliding energy ----------------
        if braking and not good:
            dx = X - X_start
            if dx > 1e-9:
                for i in range(n):
                    e_slide[i] = _fmax(e_slide[i], 0.0) * SUB_DT
                    x0 = (X_start - X_b - offset[i] - grid_lo) / GRID_DX
                    x1 = (X - X_b - offset[i] - grid_lo) / GRID_DX
                    i0s[i] = min(max(np.int64(np.floor(x0)), 0), n_cells - 2)
                    frac0[i] = _fmin(_fmax((np.float64(i0s[i] + 1) - x0) / (x1 - x0), 0.0), 1.0)
                    dens[i] = e_slide[i] / GRID_DX  # J per metre, split over the cells covered
                # e_grid[i0] += ...: every sum from the values before, the last write wins
                for i in range(n):
                    add[i] = e_grid[i0s[i]] + dens[i] * frac0[i]
                for i in range(n):
                    e_grid[i0s[i]] = add[i]
                for i in range(n):
                    add[i] = e_grid[i0s[i] + 1] + dens[i] * (1.0 - frac0[i])
                for i in range(n):
                    e_grid[i0s[i] + 1] = add[i]
    return k_end, k_stop, X_b


# ----------------------------------------------------------------------------------------
# physics + BCU
# ----------------------------------------------------------------------------------------
# scenario fields a stop divides by or scales with, and what each may be: random_scenario draws
# them within these, a hand-made scenario may not. inf: ``mu_speed_kmh`` no fall of the adhesion
# with speed, ``clean_energy_J_per_m`` a rail that never cleans; 0: ``demand_ramp_s`` a step,
# ``tau_fill_s``/``tau_vent_s`` a cylinder that follows at once
_FIELD_RULES = {
    **dict.fromkeys(("speed_kmh", "wheel_radius_m", "wheelset_inertia_kgm2", "creep_c2",
                     "creep_c3", "p_max_bar", "log_period_s", "gps_rate_hz", "max_duration_s"),
                    "> 0"),
    **dict.fromkeys(("mu_speed_kmh", "clean_energy_J_per_m"), "> 0, may be inf"),
    **dict.fromkeys(("demand_ramp_s", "tau_fill_s", "tau_vent_s"), ">= 0"),
}  # fmt: skip


def _decay(t_s: float, tau_s: float) -> float:
    """``exp(-t / tau)`` by the C library, 0.0 for ``tau`` 0."""
    return math.exp(-t_s / tau_s) if tau_s > 0.0 else 0.0


def simulate_record(
    sc: Scenario, effects: Sequence[Effect] = (), seed: int | None = None
) -> dict[str, Any]:
    """Run the physics and the WSP; returns the 20 ms internal record (truth included): what
    ``generate`` logs from, and ``scripts/independent_equivalence.py`` compares across versions."""
    if sc.valve_delay_cycles < 0:  # the compiled loop indexes its command queue by it
        raise ValueError(f"valve_delay_cycles must be >= 0, got {sc.valve_delay_cycles}")
    for name, rule in _FIELD_RULES.items():  # 0, NaN or inf would run on to NaN, or stop nowhere
        value = getattr(sc, name)
        ok = value > 0.0 if rule != ">= 0" else value >= 0.0
        if not (ok and (math.isfinite(value) or rule == "> 0, may be inf")):
            raise ValueError(f"{name} must be {rule}{'' if 'inf' in rule else ' and finite'}, "
                             f"got {value}")  # fmt: skip
    seed = sc.seed if seed is None else seed
    ss = np.random.SeedSequence(seed)
    rng_bcu = np.random.default_rng(ss.spawn(1)[0])
    tr = _resolve_effects(sc, effects)
    veh = _vehicle(sc)
    n = sc.n_axles
    M = veh["mass"]
    r_nom = sc.wheel_radius_m
    r = r_nom * (1.0 + tr["radius_error"])
    J = sc.wheelset_inertia_kgm2
    gain = sc.torque_gain_Nm_per_bar * tr["pad_scale"]
    pth = sc.p_threshold_bar
    n_static = veh["n_static"]
    k_tr = veh["k"] * tr["transfer_factor"]
    offset = veh["offset"]
    res_a = sc.resistance_a_N * tr["resistance_factor"]
    res_b = sc.resistance_b_N_per_mps * tr["resistance_factor"]
    res_c = sc.resistance_c_N_per_mps2 * tr["resistance_factor"]
    f_grade = M * G * tr["gradient_permille"] / 1000.0
    ub_force = tr["ub_force"]
    c2, c3 = sc.creep_c2, sc.creep_c3
    s_pk = math.log(c2 / c3) / c2
    g_pk = 1.0 - c3 / c2 - c3 * s_pk
    A_s = sc.slide_asymptote
    B_s = sc.slide_decay_per_kmh * 3.6  # per m/s of sliding
    one_minus_A = 1.0 - A_s
    good = sc.contaminant in ("wet", "dry")

    k_b = round(sc.lead_in_s / BCU_DT)
    n_max = k_b + math.ceil((sc.max_duration_s + sc.record_tail_s) / BCU_DT) + 1
    v_noise = rng_bcu.normal(0.0, sc.v_noise_kmh, (n_max, n))
    p_noise = rng_bcu.normal(0.0, sc.p_noise_bar, (n_max, n))

    # rail grid (rail coordinate xi from axle 1 at brake application)
    v0 = sc.speed_kmh / 3.6
    grid_lo = -(offset[-1] + 10.0)
    grid_hi = v0 * (sc.max_duration_s + 10.0) + 50.0
    n_cells = int((grid_hi - grid_lo) / GRID_DX) + 2
    xi_cells = grid_lo + GRID_DX * (np.arange(n_cells) + 0.5)
    rough = np.zeros(n_cells)
    if sc.adhesion_roughness > 0:
        lams = np.asarray(sc.roughness_wavelengths_m, dtype=float)
        phases = np.asarray(sc.roughness_phases, dtype=float)
        if lams.shape != phases.shape:
            raise ValueError("roughness_wavelengths_m and roughness_phases differ in length")
        rough = _roughness(xi_cells, lams, phases)
        rough *= sc.adhesion_roughness / math.sqrt(len(sc.roughness_wavelengths_m) / 2)
    pos_fac = np.ones(n_cells)
    for pos, fac in tr["positions"]:
        pos_fac[xi_cells >= pos] *= fac
    mu_cont_g = sc.mu_contaminated * (1.0 + rough) * pos_fac / g_pk
    mu_clean_g = (sc.mu_contaminated if good else sc.mu_clean) * pos_fac / g_pk
    e_grid = np.zeros(n_cells)
    qpow = np.array([(1.0 - sc.rolling_clean_fraction) ** i for i in range(n)])  # C pow
    inv_ec = 1.0 / sc.clean_energy_J_per_m
    axle_fac = tr["axle_factor"]

    # pressure dynamics coefficients per substep (j = 1..N_SUB)
    # exp(-t / tau), 0 for tau 0 (exp(-inf): the numpy version's value, an instant cylinder)
    dec_fill = np.array([[_decay(j * SUB_DT, sc.tau_fill_s)] for j in range(1, N_SUB + 1)])
    dec_vent = np.array([[_decay(j * SUB_DT, sc.tau_vent_s)] for j in range(1, N_SUB + 1)])
    lag = tr["pressure_lag"]
    lag_sub = lag / SUB_DT
    p_hist = np.zeros((n_max * N_SUB + 1, n)) if lag > 0 else None
    tc = tr["pressure_tc"]
    dec_tc = math.exp(-SUB_DT / tc) if tc > 0 else 0.0

    # WSP parameters
    n_hold_min = max(1, round(sc.wsp_hold_min_s / BCU_DT))
    n_hold_max = max(n_hold_min + 1, round(sc.wsp_hold_max_s / BCU_DT))
    n_vent_min = max(1, round(sc.wsp_vent_min_s / BCU_DT))
    n_on = max(1, round(sc.wsp_step_on_s / BCU_DT))
    n_per = n_on + max(1, round(sc.wsp_step_off_s / BCU_DT))
    n_step_max = round(4.0 / BCU_DT)

    # records
    rec_V = np.empty(n_max)
    rec_X = np.empty(n_max)
    rec_om = np.empty((n_max, n))
    rec_p = np.empty((n_max, n))
    rec_T = np.empty((n_max, n))
    rec_F = np.empty((n_max, n))
    rec_N = np.empty((n_max, n))
    rec_L = np.full((n_max, n), np.nan)  # the last cycle recorded computes none
    rec_pd = np.empty(n_max)
    rec_vref = np.empty(n_max)
    rec_state = np.empty((n_max, n), dtype=np.int8)
    rec_ub = np.empty(n_max)

    def axles(x: Any) -> np.ndarray:  # a per-axle float array (a scalar broadcast)
        return np.ascontiguousarray(np.broadcast_to(np.asarray(x, dtype=np.float64), (n,)))

    inv_r = 1.0 / r
    Jdt_r = J / (SUB_DT * r)
    scalars = (
        v0, r_nom, M, pth, res_a, res_b, res_c, f_grade, ub_force, c2, c3, g_pk, A_s, B_s,
        one_minus_A, sc.lead_in_s, sc.demand_ramp_s, sc.demand_drop_s, sc.demand_drop_factor,
        sc.p_max_bar, sc.wsp_off_kmh, sc.wsp_ref_margin_mps2, sc.wsp_s1_kmh, sc.wsp_s1_frac,
        sc.wsp_s2_kmh, sc.wsp_s2_frac, sc.wsp_decel_mps2, sc.mu_speed_drop, sc.mu_speed_kmh,
        grid_lo, inv_ec, lag_sub, dec_tc,
    )  # fmt: skip
    counts = (
        n_max, k_b, n_cells, n_hold_min, n_hold_max, n_vent_min, n_on, n_per, n_step_max,
        sc.valve_delay_cycles, round(sc.record_tail_s / BCU_DT), int(good), int(lag > 0),
        int(tc > 0),
    )  # fmt: skip
    k_end, k_stop, X_b = _cycles(
        tuple(float(x) for x in scalars), tuple(int(x) for x in counts),
        axles(r), axles(inv_r), axles(Jdt_r), axles(gain), axles(n_static), axles(k_tr),
        axles(offset), axles(axle_fac), axles(sc.mu_contaminated / g_pk * axle_fac), axles(qpow),
        v_noise, p_noise, mu_cont_g, mu_clean_g, e_grid, dec_fill[:, 0].copy(),
        dec_vent[:, 0].copy(), p_hist if p_hist is not None else np.zeros((1, n)),
        rec_V, rec_X, rec_om, rec_p, rec_T, rec_F, rec_N, rec_L, rec_pd, rec_vref, rec_state,
        rec_ub,
    )  # fmt: skip

    sl = slice(0, k_end)
    return {
        "t": np.arange(k_end) * BCU_DT,
        "V": rec_V[sl],
        "X": rec_X[sl],
        "omega": rec_om[sl],
        "r_true": r,
        "z_kmh": np.maximum(rec_om[sl] * r_nom * 3.6 + v_noise[sl], 0.0),
        "p": rec_p[sl],
        "p_true_noise_free": rec_p[sl] - p_noise[sl],
        "torque": rec_T[sl],
        "force": rec_F[sl],
        "normal": rec_N[sl],
        "mu_level": rec_L[sl],
        "p_demand": rec_pd[sl],
        "v_ref_kmh": rec_vref[sl],
        "state": rec_state[sl],
        "ub_force": rec_ub[sl],
        "k_brake": k_b,
        "k_stop": k_stop,
        "X_brake": X_b,
        "mass": M,
        "J": J,
        "gain_true": gain,
        "n_static": n_static,
        "k_transfer": k_tr,
        "offset": offset,
        "truth": tr,
        "e_grid": e_grid,
        "grid_lo": grid_lo,
        "resistance_true": (res_a, res_b, res_c),
        "f_grade": f_grade,
    }


# ----------------------------------------------------------------------------------------
# logger
# ----------------------------------------------------------------------------------------


def sliding_around(
    scenario: Scenario,
    effects: Sequence[Effect],
    position_m: float,
    seed: int | None = None,
) -> tuple[float, float]:
    """Seconds of adhesion-limited braking before and after rail coordinate ``position_m``.

    From the generator's own 20 ms record (the truth, not the log): the time, between the
    brake application and the stop, during which at least one axle's creep
    ``(V - omega_i r_i) / max(V, 0.3)`` is past the friction curve's peak (``ln(c2/c3)/c2``),
    split by whether that axle's rail coordinate (``X - X_b - d_i``, as for
    ``adhesion_position``) is before or past ``position_m``. A friction change along the
    rail can be seen by any method only where the wheels meet the adhesion limit on both sides
    of it; the detection-power study reports how often they do.
    """
    sim = simulate_record(scenario, effects, seed)
    k_b = sim["k_brake"]
    k_end = sim["k_stop"] if sim["k_stop"] > 0 else len(sim["t"])
    sl = slice(k_b, k_end)
    v = sim["V"][sl, None]
    creep = (v - sim["omega"][sl] * sim["r_true"]) / np.maximum(v, 0.3)
    c2, c3 = scenario.creep_c2, scenario.creep_c3
    sliding = creep >= math.log(c2 / c3) / c2
    xi = sim["X"][sl, None] - sim["X_brake"] - sim["offset"]
    before = np.any(sliding & (xi < position_m), axis=1)
    after = np.any(sliding & (xi >= position_m), axis=1)
    return float(before.sum() * BCU_DT), float(after.sum() * BCU_DT)


def _decimate(
    sig: np.ndarray, t_log: np.ndarray, period: float, mode: str, op: str = "mean"
) -> np.ndarray:
    """Sample a 20 ms signal (rows) at log instants: last value, or mean/max over the period."""
    k_hi = np.floor(t_log / BCU_DT + 1e-9).astype(np.int64)
    k_hi = np.clip(k_hi, 0, len(sig) - 1)
    if mode == "hold":
        return sig[k_hi].astype(float)
    k_lo = np.floor((t_log - period) / BCU_DT + 1e-9).astype(np.int64) + 1
    k_lo = np.clip(k_lo, 0, k_hi)
    if op == "max":
        out = np.empty((len(t_log), *sig.shape[1:]))
        for i, (a, b) in enumerate(zip(k_lo, k_hi, strict=True)):
            out[i] = sig[a : b + 1].max(axis=0)
        return out
    cs = np.concatenate([np.zeros((1, *sig.shape[1:])), np.cumsum(sig, axis=0)])
    cnt = (k_hi - k_lo + 1).astype(float)
    if sig.ndim > 1:
        cnt = cnt[:, None]
    return (cs[k_hi + 1] - cs[k_lo]) / cnt


def _quant(x: np.ndarray, q: float) -> np.ndarray:
    return np.round(x / q) * q


def generate(
    scenario: Scenario, effects: Sequence[Effect] = (), seed: int | None = None
) -> tuple[dict[str, np.ndarray], dict]:
    """Simulate one braking test; return the CSV columns (NaN = empty cell) and metadata.

    ``seed`` (default ``scenario.seed``) drives all noise; the same inputs give identical
    output. Column order: time_s, v_train_kmh, v_axle_<i>_kmh, p_cyl_<i>_bar, then the
    optional p_demand_bar, v_ref_kmh, wsp_active_<i>.
    """
    sc = scenario
    seed = sc.seed if seed is None else seed
    sim = simulate_record(sc, effects, seed)
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(2)[1])
    n = sc.n_axles
    tr = sim["truth"]
    t_bcu = sim["t"]
    t_end = float(t_bcu[-1])
    per = sc.log_period_s
    n_rows = math.floor(t_end / per + 1e-9) + 1
    t_log = np.arange(n_rows) * per
    jit = rng.uniform(-sc.time_jitter_s, sc.time_jitter_s, n_rows)
    jit[0] = 0.0
    t_log = np.clip(t_log + jit, 0.0, t_end)
    t_log[0] = 0.0
    # GPS fixes
    gps_per = 1.0 / sc.gps_rate_hz
    phase = rng.uniform(0.0, gps_per)
    t_fix = np.arange(phase - gps_per, t_end + gps_per, gps_per)
    lag_total = sc.gps_lag_s + tr["gps_extra_lag"]
    v_true_lag = np.interp(t_fix - lag_total, t_bcu, sim["V"]) * 3.6
    fix_val = np.maximum(
        (1.0 + tr["gps_scale_error"]) * v_true_lag + rng.normal(0.0, sc.gps_noise_kmh, t_fix.size),
        0.0,
    )
    valid = np.ones(t_fix.size, dtype=bool)
    n_drop = rng.poisson(sc.gps_dropout_per_s * t_end)
    for _ in range(int(n_drop)):
        t0 = rng.uniform(0.0, t_end)
        dur = rng.uniform(0.2, 1.0)
        valid[(t_fix > t0) & (t_fix <= t0 + dur)] = False
    valid[0] = True
    tf_v, fv_v = t_fix[valid], fix_val[valid]
    i_fix = np.clip(np.searchsorted(tf_v, t_bcu, side="right") - 1, 0, tf_v.size - 1)
    gps_sig = fv_v[i_fix]

    mode = sc.log_mode
    cols: dict[str, np.ndarray] = {"time_s": np.round(t_log, 4)}
    cols["v_train_kmh"] = _quant(_decimate(gps_sig, t_log, per, mode), 0.01)
    vax = _quant(np.maximum(_decimate(sim["z_kmh"], t_log, per, mode), 0.0), sc.v_quant_kmh)
    pcy = _quant(_decimate(sim["p"], t_log, per, mode), sc.p_quant_bar)
    for i in range(n):
        cols[f"v_axle_{i + 1}_kmh"] = vax[:, i]
    for i in range(n):
        cols[f"p_cyl_{i + 1}_bar"] = pcy[:, i]
    if sc.include_p_demand:
        cols["p_demand_bar"] = _quant(_decimate(sim["p_demand"], t_log, per, mode), 0.01)
    if sc.include_v_ref:
        cols["v_ref_kmh"] = _quant(_decimate(sim["v_ref_kmh"], t_log, per, mode), 0.01)
    if sc.include_wsp_active:
        act = (sim["state"] != APPLY).astype(float)
        wa = _decimate(act, t_log, per, mode, op="max")
        for i in range(n):
            cols[f"wsp_active_{i + 1}"] = wa[:, i]
    # isolated empty cells
    names = [c for c in cols if c != "time_s"]
    used: dict[str, list[int]] = {}
    if n_rows > 6:
        for _ in range(sc.n_empty_cells):
            name = names[int(rng.integers(0, len(names)))]
            row = int(rng.integers(1, n_rows - 1))
            if any(abs(row - r0) < 2 for r0 in used.get(name, [])):
                continue
            used.setdefault(name, []).append(row)
            cols[name] = cols[name].copy()
            cols[name][row] = np.nan
    meta = _metadata(sc, sim)
    return cols, meta


def _metadata(sc: Scenario, sim: dict[str, Any]) -> dict:
    veh: dict[str, Any] = {
        "name": sc.name,
        "mass_kg": round(sim["mass"], 1),
        "n_axles": sc.n_axles,
        "wheel_radius_m": round(sc.wheel_radius_m, 4),
        "wheelset_inertia_kgm2": round(sc.wheelset_inertia_kgm2, 1),
        "axle_static_load_kN": [round(float(x) / 1000.0, 2) for x in sim["n_static"]],
    }
    if sc.geometry_in_metadata:
        veh["cog_height_m"] = round(sc.cog_height_m, 3)
        veh["bogie_centre_distance_m"] = round(sc.bogie_centre_distance_m, 3)
        veh["bogie_wheelbase_m"] = round(sc.bogie_wheelbase_m, 3)
        if sc.pivot_in_metadata:
            veh["bogie_pivot_height_m"] = round(sc.bogie_pivot_height_m, 3)
        if sc.offsets_in_metadata:
            veh["axle_offsets_m"] = [round(float(x), 3) for x in sim["offset"]]
        if sc.transfer_list_in_metadata:
            k_nom = _vehicle(sc)["k"]
            veh["axle_load_transfer_kN_per_mps2"] = [round(float(x) / 1000, 3) for x in k_nom]
    veh["brake"] = {
        "p_threshold_bar": round(sc.p_threshold_bar, 3),
        "torque_gain_Nm_per_bar": round(sc.torque_gain_Nm_per_bar, 1),
        "p_max_bar": round(sc.p_max_bar, 3),
    }
    veh["resistance"] = {
        "a_N": round(sc.resistance_a_N, 1),
        "b_N_per_mps": round(sc.resistance_b_N_per_mps, 2),
        "c_N_per_mps2": round(sc.resistance_c_N_per_mps2, 3),
    }
    v_b = float(sim["V"][min(sim["k_brake"], len(sim["V"]) - 1)]) * 3.6
    return {
        "format": "wsp-trace/1",
        "test_id": f"independent-sim seed {sc.seed} ({sc.contaminant})",
        "sample_period_s": sc.log_period_s,
        "initial_speed_kmh": round(v_b, 1),
        "contaminant": sc.contaminant,
        "brake_type": "emergency",
        "vehicle": veh,
    }


def _decimals(name: str) -> int:
    if name == "time_s":
        return 4
    if name.startswith("p_"):
        return 3
    if name.startswith("wsp_active_"):
        return 0
    return 2


def write_trace(stem: str | Path, columns: dict[str, np.ndarray], meta: dict) -> tuple[Path, Path]:
    """Write ``STEM.csv`` (NaN -> empty cell) and ``STEM.meta.json``; return both paths."""
    stem = Path(stem)
    if stem.suffix == ".csv":
        stem = stem.with_suffix("")
    stem.parent.mkdir(parents=True, exist_ok=True)
    csv_path = stem.parent / (stem.name + ".csv")
    meta_path = stem.parent / (stem.name + ".meta.json")
    names = list(columns)
    str_cols = []
    for name in names:
        dec = _decimals(name)
        vals = np.round(np.asarray(columns[name], dtype=float), dec) + 0.0  # no "-0.00"
        str_cols.append([f"{v:.{dec}f}" if math.isfinite(v) else "" for v in vals.tolist()])
    lines = [",".join(names)]
    lines.extend(",".join(row) for row in zip(*str_cols, strict=True))
    csv_path.write_text("\n".join(lines) + "\n")
    meta_path.write_text(json.dumps(meta, indent=2) + "\n")
    return csv_path, meta_path

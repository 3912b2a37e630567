"""Batched braking simulator: vehicle + rail configs -> kernel arrays, reset, step, read-out.

``TrainSim`` owns the arrays of ``physics.layout`` for ``n_envs`` runs of one vehicle and
advances them one control period at a time through ``physics.integrator.step_batch``.
``RunSetup`` is everything that may differ between runs (speed, rail, pattern, load, pad
friction, gradient, demand); ``draw_run_setup`` draws one from a rail's distribution with a
seeded generator. Nothing here loops over environments in the hot path: ``step`` is one call.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from wsp_env.core.config import RailConfig, VehicleConfig, check_number, check_option
from wsp_env.physics import layout as L
from wsp_env.physics.adhesion import LAW_NAMES, REC_BASIS_NAMES, tustin_second_order
from wsp_env.physics.brake import decay_factor, demand_pressures
from wsp_env.physics.contact import STIFFNESS_LOAD_EXPONENT, kalker_longitudinal_stiffness_N
from wsp_env.physics.integrator import step_batch
from wsp_env.physics.libm import elementwise
from wsp_env.physics.rail import friction_level, reset_field
from wsp_env.physics.vehicle import Bogie, Car, TrainLayout

KMH = 1.0 / 3.6
G = 9.80665


def _load_power(ratio: float) -> float:
    """The creep stiffness's load scaling ``(Q / Q_ref)^(2/3)`` (``STIFFNESS_LOAD_EXPONENT``)."""
    return ratio**STIFFNESS_LOAD_EXPONENT


@dataclass(frozen=True)
class RunSetup:
    """The conditions of one braking run (one environment row)."""

    speed_kmh: float
    rail: RailConfig
    mu_contaminated: float | None = None  # None: the rail's nominal value
    background: float | None = None  # contamination outside sections; None: rail default
    sections: tuple[tuple[float, float, float], ...] = ()  # (start_m, end_m, level)
    injection_level: float = 0.0  # laid at the leading axle while t < injection_until_s
    injection_until_s: float = -1.0
    demand_fraction: float = 1.0  # 1 = emergency (p_max); full service ~0.85
    load_factor: float = 1.0  # body masses x this (payload)
    pad_factor: float = 1.0  # actual / nominal pad friction
    gradient_permille: float = 0.0  # > 0 uphill
    axle_mu_factor: tuple[float, ...] | None = None  # R_i (seed 002 Fig. 8); None = all 1
    recovery_basis: str | None = None  # override the rail's recovery basis
    rail_name: str = ""  # for reports: the rail condition's name in the rail table
    extra_brake_force_N: float = 0.0  # brake force not through the wheels, at full demand

    def __post_init__(self) -> None:
        # the bounds of the environment options (config.OPTION_SPECS), each field named;
        # values are stored converted (floats, tuples)
        for name in _OPTION_FIELDS:
            value = check_option(name, getattr(self, name), where=name)
            object.__setattr__(self, name, value)
        frac = check_number(self.demand_fraction, "demand_fraction", gt=0.0, le=1.0)
        object.__setattr__(self, "demand_fraction", frac)
        level = check_number(self.injection_level, "injection_level", ge=0.0, le=1.0)
        object.__setattr__(self, "injection_level", level)
        until = check_number(self.injection_until_s, "injection_until_s", inf=True)
        object.__setattr__(self, "injection_until_s", until)


# the RunSetup fields that are environment options of the same name
_OPTION_FIELDS = (
    "speed_kmh", "mu_contaminated", "background", "sections", "load_factor", "pad_factor",
    "gradient_permille", "axle_mu_factor", "recovery_basis", "extra_brake_force_N",
)  # fmt: skip


def draw_run_setup(
    rail: RailConfig,
    rng: np.random.Generator,
    speed_kmh: float,
    **fixed: object,
) -> RunSetup:
    """Draw the adhesion level and spatial pattern of ``rail`` (its configured distribution).

    ``fixed`` sets any other ``RunSetup`` field exactly (and overrides drawn ones).
    """
    lo, hi = rail.mu_contaminated_range
    mu = float(rng.uniform(lo, hi)) if hi > lo else lo
    names = list(rail.patterns)
    weights = np.array([rail.patterns[n] for n in names], dtype=float)
    pattern = names[int(rng.choice(len(names), p=weights / weights.sum()))]
    # a rough stop length on this adhesion, to place steps and patches where the train runs
    v = speed_kmh * KMH
    stop_m = v * v / (2.0 * G * max(0.6 * mu, 0.02))
    c = rail.contamination
    background, sections = c, ()
    if pattern == "step_up":  # low -> high adhesion
        x = float(rng.uniform(0.2, 0.6)) * stop_m
        background, sections = 0.0, ((-1e9, x, c),)
    elif pattern == "step_down":  # high -> low adhesion
        x = float(rng.uniform(0.1, 0.4)) * stop_m
        background, sections = c, ((-1e9, x, 0.0),)
    elif pattern == "patches":
        background, secs, x = 0.0, [], -50.0
        while x < stop_m and len(secs) < L.MAX_SECTIONS:
            length = float(rng.uniform(20.0, 150.0))
            secs.append((x, x + length, c))
            x += length + float(rng.uniform(10.0, 80.0))
        sections = tuple(secs)
    setup = RunSetup(
        speed_kmh=speed_kmh, rail=rail, mu_contaminated=mu, background=background, sections=sections
    )
    return dataclasses.replace(setup, **fixed) if fixed else setup


def _layout(vehicle: VehicleConfig, body_scale: float, rest_scale: float) -> TrainLayout:
    return TrainLayout(
        cars=tuple(
            Car(c.body_mass_kg * body_scale, c.cog_height_m, c.bogies[0], c.bogies[1])
            for c in vehicle.cars
        ),
        bogies=tuple(
            Bogie(
                b.position_m,
                b.wheelbase_m,
                max(b.frame_mass_kg * rest_scale, 1e-9),
                b.frame_cog_height_m,
                b.pivot_height_m,
                b.n_axles,
            )
            for b in vehicle.bogies
        ),
        wheelset_mass_kg=max(vehicle.wheelset_mass_kg * rest_scale, 1e-9),
        wheel_radius_m=vehicle.wheel_radius_m,
    )


@dataclass
class VehicleArrays:
    """Per-axle constants of a vehicle, split into body-mass and rest parts (linear in mass)."""

    n_axles: int
    offsets_m: np.ndarray
    static_body_N: np.ndarray
    static_rest_N: np.ndarray
    transfer_body: np.ndarray
    transfer_rest: np.ndarray
    body_mass_kg: float
    rest_mass_kg: float
    stiffness_ref_N: np.ndarray  # axle Kalker stiffness at the nominal static load
    load_ref_N: np.ndarray
    brake_gain: np.ndarray  # N m / bar per axle: friction brake, times the ED blend on motor axles
    p_threshold_bar: float
    valve_of_axle: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @classmethod
    def from_config(cls, vehicle: VehicleConfig) -> VehicleArrays:
        body = _layout(vehicle, 1.0, 0.0)
        rest = _layout(vehicle, 0.0, 1.0)
        sb, tb = body.axle_loads()
        sr, tr = rest.axle_loads()
        nominal = sb + sr
        ct = vehicle.contact
        wheel = kalker_longitudinal_stiffness_N(
            nominal / 2.0,
            vehicle.wheel_radius_m,
            ct.rail_crown_radius_m,
            ct.wheel_transverse_radius_m,
            ct.youngs_modulus_Pa,
            ct.poisson,
        )
        gain, p_th = vehicle.brake.linear_torque()
        # the ED brake follows the friction brake (blending): it scales the axle's torque gain
        # so that full demand gives the friction torque plus F_ed r
        full_friction = gain * (vehicle.brake.p_max_bar - p_th)
        ed_N = np.repeat([b.ed_brake_force_kN * 1e3 for b in vehicle.bogies],
                         [b.n_axles for b in vehicle.bogies])  # fmt: skip
        gains = gain * (1.0 + ed_N * vehicle.wheel_radius_m / full_friction)
        if vehicle.brake.valve_group == "bogie":
            valve = np.repeat(np.arange(len(vehicle.bogies)), [b.n_axles for b in vehicle.bogies])
        else:
            valve = np.arange(vehicle.n_axles)
        return cls(
            n_axles=vehicle.n_axles,
            offsets_m=_layout(vehicle, 1.0, 1.0).axle_offsets_m(),
            static_body_N=sb,
            static_rest_N=sr,
            transfer_body=tb,
            transfer_rest=tr,
            body_mass_kg=sum(c.body_mass_kg for c in vehicle.cars),
            rest_mass_kg=_layout(vehicle, 0.0, 1.0).mass_kg,
            stiffness_ref_N=2.0 * np.asarray(wheel, dtype=float),
            load_ref_N=nominal,
            brake_gain=gains,
            p_threshold_bar=p_th,
            valve_of_axle=valve.astype(np.int64),
        )


class TrainSim:
    """``n_envs`` braking runs of one vehicle, advanced together.

    Substep ``dt_s`` (default 1 ms: see docs/physics.md for the convergence figures) and
    control period ``control_period_s`` (20 ms, the BCU cycle). A wheel whose sliding speed
    exceeds ``max(slide_threshold_kmh, slide_threshold_rel V)`` counts as sliding in the metrics
    (time sliding, longest slide): a slide deeper than a WSP's working slip, which a WSP ends
    within a second or two; held for long, it overheats and wears the tread.
    """

    def __init__(
        self,
        vehicle: VehicleConfig,
        n_envs: int = 1,
        dt_s: float = 1e-3,
        control_period_s: float = 0.02,
        cell_dx_m: float = 0.25,
        v_eps_mps: float = 0.1,
        slide_threshold_kmh: float = 3.0,
        slide_threshold_rel: float = 0.2,
    ) -> None:
        n_sub = round(control_period_s / dt_s)
        if n_sub < 1 or abs(n_sub * dt_s - control_period_s) > 1e-9:
            raise ValueError("control_period_s must be a whole number of substeps dt_s")
        if vehicle.brake.valve_dead_time_s > control_period_s:
            raise ValueError(
                f"brake.valve_dead_time_s ({vehicle.brake.valve_dead_time_s} s) must not exceed "
                f"the control period ({control_period_s} s)"
            )
        self.vehicle = vehicle
        self.arrays = VehicleArrays.from_config(vehicle)
        self.n_envs = n_envs
        self.n_axles = na = self.arrays.n_axles
        self.dt_s = dt_s
        self.n_sub = n_sub
        self.control_period_s = control_period_s
        self.cell_dx_m = cell_dx_m
        self.v_eps_mps = v_eps_mps
        self.slide_threshold_kmh = slide_threshold_kmh
        self.slide_threshold_rel = slide_threshold_rel
        train_length = float(self.arrays.offsets_m[-1])
        n_cells = math.ceil(train_length / cell_dx_m) + 4
        self.env_par = np.zeros((n_envs, L.N_EP))
        self.axle_par = np.zeros((n_envs, na, L.N_AP))
        self.sections = np.zeros((n_envs, L.MAX_SECTIONS, 3))
        self.env_state = np.zeros((n_envs, L.N_ES))
        self.axle_state = np.zeros((n_envs, na, L.N_AS))
        self.field = np.zeros((n_envs, n_cells))
        self.env_acc = np.zeros((n_envs, L.N_EA))
        self.axle_acc = np.zeros((n_envs, na, L.N_AA))
        self.cmd = np.ones((n_envs, na))
        self.initial_energy_J = np.zeros(n_envs)
        self.setups: list[RunSetup | None] = [None] * n_envs

    # ---- configuration ---------------------------------------------------------------------

    def configure(self, env: int, setup: RunSetup) -> None:
        """Write the parameters of run ``setup`` into row ``env`` (takes effect at ``reset``)."""
        va, veh, brake = self.arrays, self.vehicle, self.vehicle.brake
        rail = setup.rail
        ep = self.env_par[env]
        f = setup.load_factor
        mass = va.body_mass_kg * f + va.rest_mass_kg
        ep[L.EP_MASS] = mass
        ep[L.EP_GRADE_ACC] = G * math.sin(math.atan(setup.gradient_permille / 1000.0))
        res = veh.resistance
        ep[L.EP_DAVIS_A] = res.a_N
        ep[L.EP_DAVIS_B] = res.b_N_per_mps
        ep[L.EP_DAVIS_C] = res.c_N_per_mps2
        ep[L.EP_P_MAX] = brake.p_max_bar * setup.demand_fraction
        ep[L.EP_DEMAND_DELAY] = brake.demand_delay_s
        ep[L.EP_DEMAND_RISE] = brake.demand_rise_s * setup.demand_fraction
        ep[L.EP_FILL_DECAY] = decay_factor(brake.fill_tau_s, self.dt_s)
        ep[L.EP_FILL_RATE] = brake.fill_rate_bar_per_s
        ep[L.EP_VENT_DECAY] = decay_factor(brake.vent_tau_s, self.dt_s)
        ep[L.EP_VENT_RATE] = brake.vent_rate_bar_per_s
        ep[L.EP_VALVE_DEAD] = brake.valve_dead_time_s
        ep[L.EP_PAD_SCALE] = setup.pad_factor
        ep[L.EP_PAD_SLOPE] = brake.pad_speed_coeff_per_kmh * 3.6
        ep[L.EP_PAD_VREF] = brake.pad_ref_speed_kmh * KMH
        ep[L.EP_LAW] = LAW_NAMES[rail.law]
        ep[L.EP_MU_CLEAN] = rail.mu_clean
        mu_cont = rail.mu_contaminated if setup.mu_contaminated is None else setup.mu_contaminated
        ep[L.EP_MU_CONT] = mu_cont
        ep[L.EP_LP0 : L.EP_LP3 + 1] = rail.law_vector()
        rec = rail.recovery
        ep[L.EP_REC_GAIN] = rec.gain
        ep[L.EP_W_LIM] = rec.w_lim if math.isfinite(rec.w_lim) else 1e301
        ep[L.EP_W_MAX] = rec.w_max if math.isfinite(rec.w_max) else 1e302
        ep[L.EP_REC_BASIS] = REC_BASIS_NAMES[setup.recovery_basis or rec.basis]
        ep[L.EP_RF_B0 : L.EP_RF_A2 + 1] = tustin_second_order(rec.tau_s, rec.zeta, self.dt_s)
        ep[L.EP_E_CLEAN] = min(rail.clean_energy_J_per_m, 1e300)
        ep[L.EP_PASS_REMOVAL] = rail.pass_removal
        ep[L.EP_CELL_DX] = self.cell_dx_m
        ep[L.EP_C_BACKGROUND] = rail.contamination if setup.background is None else setup.background
        ep[L.EP_INJ_LEVEL] = setup.injection_level
        ep[L.EP_INJ_UNTIL] = setup.injection_until_s
        ep[L.EP_N_SECTIONS] = len(setup.sections)
        self.sections[env] = 0.0
        if setup.sections:
            self.sections[env, : len(setup.sections)] = np.asarray(setup.sections, dtype=float)
        ep[L.EP_V_EPS] = self.v_eps_mps
        ep[L.EP_EXTRA_BRAKE_N] = setup.extra_brake_force_N
        ep[L.EP_SLIDE_THRESH] = self.slide_threshold_kmh * KMH
        ep[L.EP_SLIDE_REL] = self.slide_threshold_rel
        ep[L.EP_STIFF_FACTOR] = rail.creep_stiffness_factor

        ap = self.axle_par[env]
        static = va.static_body_N * f + va.static_rest_N
        ap[:, L.AP_RADIUS] = veh.wheel_radius_m
        ap[:, L.AP_INERTIA] = veh.wheelset_inertia_kgm2
        ap[:, L.AP_N_STATIC] = static
        ap[:, L.AP_K_TRANSFER] = va.transfer_body * f + va.transfer_rest
        # Q^(2/3) by the C library's pow (physics.libm: not numpy's, which depends on the CPU)
        ap[:, L.AP_STIFF] = va.stiffness_ref_N * elementwise(_load_power, static / va.load_ref_N)
        ap[:, L.AP_BRAKE_GAIN] = va.brake_gain
        ap[:, L.AP_P_THRESH] = va.p_threshold_bar
        ap[:, L.AP_OFFSET] = va.offsets_m
        if setup.axle_mu_factor is not None:
            if len(setup.axle_mu_factor) != self.n_axles:
                raise ValueError(
                    f"axle_mu_factor: {len(setup.axle_mu_factor)} values for {self.n_axles} axles"
                )
            ap[:, L.AP_MU_FACTOR] = setup.axle_mu_factor
        else:
            ap[:, L.AP_MU_FACTOR] = 1.0
        ap[:, L.AP_CYL_VOLUME_L] = brake.cylinder_volume_l
        self.setups[env] = setup

    def reset(self, envs: np.ndarray | list[int] | None = None) -> None:
        """Start the configured runs of ``envs`` (all by default): brake application at t = 0."""
        ids = range(self.n_envs) if envs is None else envs
        for e in ids:
            setup = self.setups[e]
            if setup is None:
                raise RuntimeError(f"environment {e} reset before configure()")
            v0 = setup.speed_kmh * KMH
            self.env_state[e] = 0.0
            self.env_state[e, L.ES_V] = v0
            self.axle_state[e] = 0.0
            self.axle_state[e, :, L.AS_OMEGA] = v0 / self.axle_par[e, :, L.AP_RADIUS]
            self.axle_state[e, :, L.AS_N] = self.axle_par[e, :, L.AP_N_STATIC]
            self.axle_state[e, :, L.AS_CMD] = 1.0
            self.axle_state[e, :, L.AS_CELL] = L.NO_CELL
            self.env_acc[e] = 0.0
            self.axle_acc[e] = 0.0
            self.cmd[e] = 1.0
            reset_field(self.env_par, self.sections, self.env_state, self.field, e)
            # the friction level each axle stands on (read by observers before the first step)
            cells = np.floor(-self.axle_par[e, :, L.AP_OFFSET] / self.cell_dx_m).astype(np.int64)
            cont = self.field[e, cells % self.field.shape[1]]
            for k in range(self.n_axles):
                self.axle_state[e, k, L.AS_MU_LEVEL] = friction_level(
                    self.env_par, e, cont[k], self.axle_par[e, k, L.AP_MU_FACTOR]
                )
            self.axle_state[e, :, L.AS_CONT] = cont
            self.initial_energy_J[e] = self.kinetic_energy_J()[e]

    # ---- stepping --------------------------------------------------------------------------

    def step(self, cmd: np.ndarray | None = None) -> None:
        """Advance all runs by one control period with valve commands ``cmd`` (n_envs, n_axles).

        ``cmd[e, k]`` in [0, 1] asks for that fraction of the demand; ``layout.CMD_HOLD`` holds.
        """
        self.axle_state[:, :, L.AS_CMD] = self.cmd
        if cmd is not None:
            self.cmd[...] = cmd
        step_batch(
            self.n_sub,
            self.dt_s,
            self.cmd,
            self.env_par,
            self.axle_par,
            self.sections,
            self.env_state,
            self.axle_state,
            self.field,
            self.env_acc,
            self.axle_acc,
        )

    # ---- read-out --------------------------------------------------------------------------

    @property
    def speed_mps(self) -> np.ndarray:
        return self.env_state[:, L.ES_V]

    @property
    def position_m(self) -> np.ndarray:
        return self.env_state[:, L.ES_X]

    @property
    def time_s(self) -> np.ndarray:
        return self.env_state[:, L.ES_T]

    @property
    def stopped(self) -> np.ndarray:
        return self.env_state[:, L.ES_STOPPED] > 0.0

    @property
    def wheel_speed_mps(self) -> np.ndarray:
        return self.axle_state[:, :, L.AS_OMEGA] * self.axle_par[:, :, L.AP_RADIUS]

    @property
    def pressure_bar(self) -> np.ndarray:
        return self.axle_state[:, :, L.AS_P]

    def demand_bar(self) -> np.ndarray:
        """Demand pressure (bar) of every run now (``brake.demand_bar``)."""
        return demand_pressures(self.env_par, self.time_s)

    def kinetic_energy_J(self) -> np.ndarray:
        v = self.speed_mps
        om = self.axle_state[:, :, L.AS_OMEGA]
        rot = 0.5 * np.sum(self.axle_par[:, :, L.AP_INERTIA] * om * om, axis=1)
        return 0.5 * self.env_par[:, L.EP_MASS] * v * v + rot

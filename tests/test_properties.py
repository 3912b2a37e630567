"""Property-based tests: random vehicles, rails, pressures and speeds never break the physics."""

from __future__ import annotations

import dataclasses

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from wsp_env.core.config import load_rail, load_vehicle
from wsp_env.core.simulator import RunSetup, TrainSim
from wsp_env.physics import layout as L

BASE = load_vehicle("uic_z1")
RAILS = {name: load_rail(name) for name in ("dry", "wet", "soap", "oil", "leaves", "soap_etr1000")}


@st.composite
def scenarios(draw):
    mass_scale = draw(st.floats(0.3, 3.0))
    radius = draw(st.floats(0.3, 0.65))
    inertia = draw(st.floats(20.0, 600.0))
    gain = draw(st.floats(200.0, 20000.0))
    brake = dataclasses.replace(
        BASE.brake,
        torque_gain_Nm_per_bar=gain,
        fill_rate_bar_per_s=draw(st.floats(0.5, 50.0)),
        vent_rate_bar_per_s=draw(st.floats(0.5, 50.0)),
        fill_tau_s=draw(st.floats(0.0, 1.0)),
        vent_tau_s=draw(st.floats(0.0, 1.0)),
        demand_rise_s=draw(st.floats(0.0, 5.0)),
    )
    cars = tuple(
        dataclasses.replace(c, body_mass_kg=c.body_mass_kg * mass_scale) for c in BASE.cars
    )
    vehicle = dataclasses.replace(
        BASE, wheel_radius_m=radius, wheelset_inertia_kgm2=inertia, brake=brake, cars=cars
    )
    rail = RAILS[draw(st.sampled_from(sorted(RAILS)))]
    setup = RunSetup(
        speed_kmh=draw(st.floats(1.0, 350.0)),
        rail=rail,
        mu_contaminated=draw(st.floats(0.01, 0.5)),
        gradient_permille=draw(st.floats(-40.0, 40.0)),
        pad_factor=draw(st.floats(0.5, 1.5)),
        load_factor=draw(st.floats(0.5, 1.5)),
    )
    seed = draw(st.integers(0, 2**31 - 1))
    return vehicle, setup, seed


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenarios())
def test_random_runs_stay_physical(case):
    vehicle, setup, seed = case
    sim = TrainSim(vehicle, n_envs=1)
    sim.configure(0, setup)
    sim.reset()
    rng = np.random.default_rng(seed)
    for _ in range(150):  # 3 s with random commands, holds included
        cmd = rng.uniform(-0.3, 1.0, size=(1, 4))
        sim.step(cmd)
        state = sim.axle_state[0]
        assert np.isfinite(state).all() and np.isfinite(sim.env_state).all()
        assert (state[:, L.AS_OMEGA] >= 0.0).all(), "a wheel turned backwards under braking"
        assert (state[:, L.AS_P] <= sim.demand_bar()[0] + 1e-9).all(), "pressure above demand"
        assert (state[:, L.AS_P] >= 0.0).all()
        assert sim.speed_mps[0] >= 0.0
        # the friction limit: |F| <= mu_max N with the axle's current normal load
        mu_max = max(sim.env_par[0, L.EP_MU_CLEAN], sim.env_par[0, L.EP_MU_CONT])
        assert (state[:, L.AS_N] > 0).all()
        assert (np.abs(state[:, L.AS_F]) <= mu_max * state[:, L.AS_N] * (1 + 1e-9)).all()
        if sim.stopped[0]:
            break
    assert np.isfinite(sim.axle_acc).all() and np.isfinite(sim.env_acc).all()

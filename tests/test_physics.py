"""Physics core against physics: analytic stops, energy balance, convergence, published numbers."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import instant_brake, run_to_stop, single
from scipy.integrate import solve_ivp

from wsp_env.core.config import load_rail, load_vehicle
from wsp_env.core.metrics import run_metrics
from wsp_env.core.simulator import RunSetup, TrainSim
from wsp_env.physics import layout as L

KMH = 1 / 3.6


def rigid_body_decel(veh) -> float:
    """Deceleration of a train whose wheels roll: sum(T/r) / (M + sum J/r^2); the motor axles'
    torque includes their blended ED brake (``ed_brake_force_kN`` at the wheel)."""
    gain, p_th = veh.brake.linear_torque()
    n, r, J = veh.n_axles, veh.wheel_radius_m, veh.wheelset_inertia_kgm2
    ed_N = sum(b.ed_brake_force_kN * 1e3 * b.n_axles for b in veh.bogies)
    force = n * gain * (veh.brake.p_max_bar - p_th) / r + ed_N
    arrays = TrainSim(veh).arrays
    m = arrays.body_mass_kg + arrays.rest_mass_kg
    return force / (m + n * J / r**2)


@pytest.mark.parametrize("vehicle_id", ["uic_z1", "etr1000"])
def test_dry_rail_stop_matches_rigid_body(vehicle_id):
    """Brake well below the adhesion limit, no resistance: V^2 / (2a) within 0.5%.

    0.5% leaves room for the creepage the wheels need to transmit the force (~0.1%) and the
    last substep; the load-dependent creep slope does not change the rigid-body result.
    """
    veh = instant_brake(vehicle_id)
    sim = single(veh, "dry", 120.0)
    run_to_stop(sim)
    a = rigid_body_decel(veh)
    v0 = 120 * KMH
    assert sim.position_m[0] == pytest.approx(v0**2 / (2 * a), rel=5e-3)
    assert sim.env_state[0, L.ES_T_STOP] == pytest.approx(v0 / a, rel=5e-3)
    m = run_metrics(sim)
    assert m["max_lock_s"] == 0.0
    assert all(ax["mean_sliding_kmh"] < 0.5 for ax in m["axles"])


def test_dry_rail_stop_with_resistance_matches_ode():
    """With running resistance the stop matches the rigid-body ODE integrated by scipy."""
    veh = instant_brake("uic_z1", resistance=True)
    sim = single(veh, "dry", 160.0)
    run_to_stop(sim)
    gain, p_th = veh.brake.linear_torque()
    torque = gain * (veh.brake.p_max_bar - p_th)
    res = veh.resistance
    m_eff = sim.env_par[0, L.EP_MASS] + 4 * veh.wheelset_inertia_kgm2 / veh.wheel_radius_m**2

    def rhs(_t, y):
        v = max(y[0], 0.0)
        return [
            -(
                4 * torque / veh.wheel_radius_m
                + res.a_N
                + res.b_N_per_mps * v
                + res.c_N_per_mps2 * v * v
            )
            / m_eff,
            v,
        ]

    stop = lambda _t, y: y[0]  # noqa: E731
    stop.terminal = True
    ref = solve_ivp(rhs, (0, 100), [160 * KMH, 0.0], events=stop, rtol=1e-10, atol=1e-10)
    assert sim.position_m[0] == pytest.approx(ref.y[1, -1], rel=5e-3)


def _energy_error(sim: TrainSim) -> float:
    return run_metrics(sim)["energy_balance_rel_error"]


@pytest.mark.parametrize("rail", ["dry", "soap", "oil", "leaves"])
def test_energy_balance_over_a_stop(rail):
    """Kinetic energy lost = brake + sliding + resistance work, within 0.5% (we get ~1e-10).

    Run with valve commands that vent and refill at random, so that wheels lock and recover.
    """
    veh = load_vehicle("uic_z1")
    sim = single(veh, rail, 140.0)
    rng = np.random.default_rng(3)
    cmds = rng.uniform(0, 1, size=(20000, 1, 4)) ** 0.3
    run_to_stop(sim, lambda n, s: cmds[n])
    m = run_metrics(sim)
    assert abs(m["energy_balance_rel_error"]) < 5e-3
    assert m["sliding_energy_kJ"] > 0
    if rail != "dry":
        assert m["max_lock_s"] > 0 or m["sliding_energy_kJ"] > 100


def test_brake_cannot_exceed_demand_and_wsp_only_reduces(rng):
    veh = load_vehicle("uic_z1")
    sim = single(veh, "soap", 120.0)
    for _ in range(400):
        cmd = rng.uniform(-1.0, 1.0, size=(1, 4))  # negatives = hold
        sim.step(cmd)
        assert (sim.pressure_bar <= sim.demand_bar()[:, None] + 1e-9).all()


@pytest.mark.parametrize(
    "rail,pattern",
    [("soap", "none"), ("soap", "pulse"), ("leaves", "pulse")],
)
def test_convergence_against_20x_finer_substep(rail, pattern):
    """Stopping distance at 1 ms within 0.2% of 0.05 ms, in low-adhesion stops with sliding."""
    veh = load_vehicle("uic_z1")
    dists = []
    for dt in (1e-3, 5e-5):
        sim = single(veh, rail, 120.0, dt_s=dt)

        def cmd(n, s, pattern=pattern):
            if pattern == "none":
                return None
            # a crude WSP: vent for 0.3 s every 1.2 s on alternate axles
            phase = (n * 0.02) % 1.2
            c = np.ones((1, 4))
            if phase < 0.3:
                c[0, (int(n * 0.02 / 1.2) % 2) :: 2] = 0.0
            return c

        run_to_stop(sim, cmd)
        m = run_metrics(sim)
        assert max(a["sliding_energy_kJ"] for a in m["axles"]) > 50  # heavy sliding indeed
        dists.append(sim.position_m[0])
    assert dists[0] == pytest.approx(dists[1], rel=2e-3)


def test_stiff_wheel_is_stable_down_to_standstill():
    """No chatter: on dry rail the wheel speed follows the train to a clean stop."""
    veh = load_vehicle("uic_z1")
    sim = single(veh, "dry", 30.0)
    slips = []
    n = run_to_stop(sim, lambda n, s: slips.append(s.speed_mps[0] - s.wheel_speed_mps[0].copy()))
    slips = np.array(slips)
    assert n < 2000
    # creep needed to carry the brake force: small and of one sign, never oscillating
    assert (slips[10:] > -1e-3).all()
    assert np.abs(slips).max() < 0.05


def test_batch_equals_singles():
    """A batch of runs steps exactly like the same runs one by one (no cross-talk)."""
    veh = load_vehicle("uic_z1")
    setups = [
        RunSetup(100.0, load_rail("soap"), mu_contaminated=0.07),
        RunSetup(140.0, load_rail("oil")),
        RunSetup(80.0, load_rail("dry"), gradient_permille=-10.0),
    ]
    batch = TrainSim(veh, n_envs=3)
    for i, s in enumerate(setups):
        batch.configure(i, s)
    batch.reset()
    singles = []
    for s in setups:
        one = TrainSim(veh, n_envs=1)
        one.configure(0, s)
        one.reset()
        singles.append(one)
    rng = np.random.default_rng(0)
    for _ in range(300):
        cmd = rng.uniform(0, 1, size=(3, 4))
        batch.step(cmd)
        for i, one in enumerate(singles):
            one.step(cmd[i : i + 1])
    for i, one in enumerate(singles):
        np.testing.assert_array_equal(batch.axle_state[i], one.axle_state[0])
        np.testing.assert_array_equal(batch.env_state[i], one.env_state[0])


def test_load_transfer_moves_load_forward_and_conserves_it():
    for vid in ("uic_z1", "e402b", "etr1000", "regiolis"):
        sim = TrainSim(load_vehicle(vid))
        k = sim.arrays.transfer_body + sim.arrays.transfer_rest
        assert abs(k.sum()) < 1e-6 * np.abs(k).max()
        assert k[0] > 0  # the leading axle gains load under braking
        static = sim.arrays.static_body_N + sim.arrays.static_rest_N
        mass = sim.arrays.body_mass_kg + sim.arrays.rest_mass_kg
        assert static.sum() == pytest.approx(mass * 9.80665, rel=1e-9)


def test_regiolis_jakobs_axles_carry_about_20_t():
    sim = TrainSim(load_vehicle("regiolis"))
    loads_t = (sim.arrays.static_body_N + sim.arrays.static_rest_N) / 9.80665 / 1000
    assert loads_t.size == 16
    assert 17 < loads_t.mean() < 21  # seed 000 §2: "approximately 20 tons"


def test_etr1000_disc_chain_reproduces_seed000_eq5():
    """The Eqs. 3-4 chain of the ETR 1000 config matches Eq. 5 within 1% over 1-3.8 bar."""
    from wsp_env.physics.brake import DiscBrakeChain

    chain = DiscBrakeChain(**dataclasses.asdict(load_vehicle("etr1000").brake.disc_chain))
    for p in np.linspace(1.0, 3.8, 8):
        assert chain.clamp_force_N(p) / 1e3 == pytest.approx((p - 0.174) / 0.1565, rel=1e-2)
    gain, p_th = chain.linear_form()
    assert chain.torque_Nm(3.0) == pytest.approx(gain * (3.0 - p_th), rel=1e-12)


def test_gradient_and_pad_friction_change_the_stop():
    veh = instant_brake("uic_z1")
    base = single(veh, "dry", 100.0)
    run_to_stop(base)
    uphill = single(veh, "dry", 100.0, gradient_permille=20.0)
    run_to_stop(uphill)
    weak_pads = single(veh, "dry", 100.0, pad_factor=0.8)
    run_to_stop(weak_pads)
    assert uphill.position_m[0] < base.position_m[0]
    assert weak_pads.position_m[0] == pytest.approx(base.position_m[0] / 0.8, rel=5e-3)


def test_air_is_counted_when_venting():
    veh = load_vehicle("uic_z1")
    sim = single(veh, "soap", 120.0)
    for _ in range(250):
        sim.step()  # full application (5 s)
    assert run_metrics(sim)["air_litres"] == 0.0
    p = sim.pressure_bar[0].copy()
    for _ in range(100):
        sim.step(np.zeros((1, 4)))  # vent everything
    vol = veh.brake.cylinder_volume_l
    expected = vol * (p - sim.pressure_bar[0]).sum() / 1.01325
    # rel 1e-4: during the valve dead time the cylinders still creep up toward the demand
    assert run_metrics(sim)["air_litres"] == pytest.approx(expected, rel=1e-4)
    assert run_metrics(sim)["longest_vent_s"] > 0.5

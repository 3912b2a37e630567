"""The traction phase (seed 002 §3.1.4, §5.3): positive torque, negative creep, the anti-skid
device, and the parts of the E402B test (Tables 9-10) the model reproduces."""

from __future__ import annotations

import json

import numpy as np

from wsp_env.cli import main
from wsp_env.core.config import load_rails, load_vehicle
from wsp_env.core.simulator import RunSetup, TrainSim
from wsp_env.physics import layout as L
from wsp_env.rig.traction import run_traction
from wsp_env.validation.checks import seed002_traction_check
from wsp_env.validation.targets import TABLE10_M


def test_traction_on_dry_rail_is_rigid_body_acceleration():
    """Dry rail, a torque far below adhesion: the train accelerates at n C / r / M_eff less the
    running resistance (the wheelsets' inertia added to the mass), the creep is negative and
    tiny. Tolerance 0.5 %: the resistance is evaluated at the mean speed."""
    veh = load_vehicle("e402b")
    sim = TrainSim(veh, n_envs=1)
    sim.configure(0, RunSetup(speed_kmh=20.0, rail=load_rails()["dry"]))
    sim.reset([0])
    sim.env_par[0, L.EP_EXT_TORQUE] = 1.0
    sim.axle_state[0, :, L.AS_EXT_TORQUE] = 5000.0
    v0 = sim.speed_mps[0]
    for _ in range(250):  # 5 s
        sim.step()
    v1 = sim.speed_mps[0]
    r, j, n = veh.wheel_radius_m, veh.wheelset_inertia_kgm2, veh.n_axles
    mass = sim.env_par[0, L.EP_MASS] + n * j / r**2
    v_mid = 0.5 * (v0 + v1)
    res = veh.resistance
    resist = res.a_N + res.b_N_per_mps * v_mid + res.c_N_per_mps2 * v_mid**2
    expected = (n * 5000.0 / r - resist) / mass
    assert abs((v1 - v0) / 5.0 / expected - 1.0) < 0.005
    slip = sim.speed_mps[0] - sim.wheel_speed_mps[0]
    assert np.all(slip < 0.0) and np.all(slip > -0.05)


def test_antiskid_stops_the_spin_and_gains_distance():
    free = run_traction(no_antiskid=True).summary
    guarded = run_traction().summary
    # without the device the unloaded leading axles spin away (tens of km/h)
    assert min(free["mean_sliding_kmh"]) < -20.0
    # with it every axle creeps or slips a few km/h, never spins, and the start is longer
    slide = np.array(guarded["mean_sliding_kmh"])
    assert np.all(slide < 0.0) and np.all(slide > -4.0)
    assert guarded["distance_m"] > free["distance_m"]


def test_seed002_traction_tables_9_and_10():
    """Table 10's span at the documented 20 s; Table 9: every axle's mean sliding inside the
    T1-T2 envelope widened by 0.5 km/h, axle 4 the least sliding (load transfer and the rail
    the leading axles cleaned) and axle 1 the most."""
    check = seed002_traction_check()
    assert TABLE10_M[0] <= check["distance_m"] <= TABLE10_M[1]
    lo, hi = (np.array(x) for x in check["table9_envelope_kmh"])
    slide = np.array(check["mean_sliding_kmh"])
    assert np.all((lo <= slide) & (slide <= hi)), (slide, lo, hi)
    assert check["axle4_least_sliding"] and check["passed"]
    assert slide[0] == slide.min()  # the leading axle


def test_traction_recovery_is_seldom_reached_as_seed002_says():
    """Seed 002 §5.3.2: in the traction test the recovery is not reached (low sliding energy).
    Eq. 10 as written (specific sliding against the wheel's speed, J/m) puts W_lim at ~8 % of
    slip: the axles pass it only in the slips at low speed (measured 21 / 5 / 9 / 3 % of the
    test on axles 1-4); the sliding-power reading (W) would pass it 47 / 24 / 32 / 3 %."""
    from wsp_env.rig.traction import seed002_rail

    rail = seed002_rail()
    sim = TrainSim(load_vehicle("e402b"), n_envs=1)
    sim.configure(0, RunSetup(speed_kmh=5.0, rail=rail))
    n_static = sim.axle_par[0, :, L.AP_N_STATIC]
    assert np.all(n_static > 150e3)  # ~218 kN: 89 t on four axles
    rec = run_traction().record
    v = rec["v_train_kmh"][:, None] / 3.6
    wheel = rec["v_axle_kmh"] / 3.6
    mu = np.abs(rec["mu"])
    specific = mu * n_static * np.abs(wheel - v) / np.maximum(wheel, 0.1)  # Eq. 10, J/m
    above = (specific > rail.recovery.w_lim).mean(axis=0)
    assert np.all(above < 0.25) and np.all(above[1:] < 0.1), above
    power = mu * n_static * np.abs(wheel - v)  # W: the braking tables' reading
    assert np.all((power > rail.recovery.w_lim).mean(axis=0)[:3] > 2.0 * above[:3])


def test_traction_cli(tmp_path, capsys):
    js = tmp_path / "t.json"
    assert main(["traction", "--duration-s", "5", "--json", str(js)]) == 0
    s = json.loads(js.read_text())
    assert s["distance_m"] > 5.0 / 3.6 * 5.0 and len(s["mean_sliding_kmh"]) == 4
    capsys.readouterr()
    bad = tmp_path / "bad.yaml"
    bad.write_text("slip_abs_kmh: -1\n")
    assert main(["traction", "--antiskid-config", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "slip_abs_kmh" in err

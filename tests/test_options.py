"""One validation layer for environment options, suite cases, RunSetup and the env's arguments:
the bounds of ``config.OPTION_SPECS`` (shared with the YAML schema), one-line errors naming the
option, and stepping before reset refused."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from wsp_env.core.braking import OPTION_KEYS, BrakingCore
from wsp_env.core.config import (
    OPTION_SPECS,
    PATTERNS,
    ConfigError,
    RailConfig,
    check_option,
    check_options,
    field_bounds,
    load_rail,
    load_vehicle,
)
from wsp_env.core.simulator import RunSetup
from wsp_env.envs import WSPBrakingEnv, WSPBrakingVectorEnv
from wsp_env.evaluation import CaseConfig, SuiteConfig, load_suite
from wsp_env.evaluation.suites import expand

UIC = load_vehicle("uic_z1")
NAN, INF = math.nan, math.inf


def _one_line_naming(err: BaseException, name: str) -> None:
    msg = str(err)
    assert name in msg and "\n" not in msg, msg


# ---- the table -----------------------------------------------------------------------------


def test_option_table_is_the_env_options_and_reuses_the_yaml_bounds():
    assert OPTION_KEYS == tuple(OPTION_SPECS)
    assert OPTION_SPECS["mu_contaminated"].bounds == field_bounds(RailConfig, "mu_contaminated")
    assert OPTION_SPECS["background"].bounds == field_bounds(RailConfig, "contamination")
    assert OPTION_SPECS["pattern"].bounds["choices"] == PATTERNS


def test_check_option_converts_and_names_the_field():
    assert check_option("speed_kmh", 120) == 120.0 and check_option("speed_kmh", "80") == 80.0
    assert check_option("speed_kmh", np.float32(90.0), UIC) == 90.0
    assert check_option("speed_kmh", np.array(70.0), UIC) == 70.0  # a 0-d array
    assert check_option("mu_contaminated", None) is None  # the rail's nominal level
    assert check_option("axle_mu_factor", np.ones(4), UIC) == (1.0, 1.0, 1.0, 1.0)
    assert check_option("sections", [[-INF, 5, 1]]) == ((-INF, 5.0, 1.0),)
    assert check_option("pattern", "patches") == "patches"
    with pytest.raises(
        ConfigError, match=r"^options\.mu_contaminated: must be in \[0\.001, 1\], got nan$"
    ):
        check_option("mu_contaminated", NAN)
    with pytest.raises(
        ConfigError, match=r"^--mu-contaminated: must be in \[0\.001, 1\], got 1e\+09$"
    ):
        check_option("mu_contaminated", 1e9, where="--mu-contaminated")
    with pytest.raises(ConfigError, match=r"^options\.speed_kmh: 250 km/h exceeds uic_z1's maxi"):
        check_option("speed_kmh", 250.0, UIC)
    assert check_option("speed_kmh", 250.0) == 250.0  # without a vehicle: no maximum
    with pytest.raises(ConfigError, match=r"axle_mu_factor: expected 4 entries"):
        check_option("axle_mu_factor", [1.0, 1.0], UIC)
    with pytest.raises(ConfigError, match=r"^options\.colour: unknown option"):
        check_option("colour", "red")
    with pytest.raises(ValueError, match=r"^options\.load_factor: must be in \(0, 3\]"):
        check_options({"load_factor": -1.0})


# ---- reset(options=...) ---------------------------------------------------------------------

BAD_OPTIONS = [
    ("mu_contaminated", NAN),
    ("mu_contaminated", -0.1),
    ("mu_contaminated", 5.0),
    ("mu_contaminated", 0.0),
    ("mu_contaminated", 1e-20),  # no rail: the creep laws give NaN forces
    ("pattern", "unifrom"),
    ("pattern", 3),
    ("axle_mu_factor", [1.0, -1.0, 1.0, 1.0]),
    ("axle_mu_factor", [1.0, 1.0, 1.0]),
    ("axle_mu_factor", [1.0, 1.0, 1.0, 2.5]),
    ("axle_mu_factor", [1.0, 1.0, 1e-20, 1.0]),
    ("axle_mu_factor", [1.0, NAN, 1.0, 1.0]),
    ("axle_mu_factor", "1111"),
    ("gradient_permille", 1e6),
    ("gradient_permille", -101.0),
    ("gradient_permille", NAN),
    ("speed_kmh", 1e9),
    ("speed_kmh", 200.1),
    ("speed_kmh", 0.0),
    ("speed_kmh", -10.0),
    ("speed_kmh", NAN),
    ("speed_kmh", INF),
    ("speed_kmh", "fast"),
    ("speed_kmh", None),
    ("speed_kmh", True),
    ("load_factor", 0.0),
    ("load_factor", -1.0),
    ("load_factor", INF),
    ("load_factor", NAN),
    ("pad_factor", 0.0),
    ("pad_factor", NAN),
    ("pad_factor", INF),
    ("demand", "full"),
    ("demand", None),
    ("sections", [(0.0, 10.0)]),
    ("sections", [(10.0, 0.0, 1.0)]),
    ("sections", [(0.0, 10.0, 1.5)]),
    ("sections", [(0.0, NAN, 1.0)]),
    ("sections", [(0.0, 10.0, 1.0)] * 17),
    ("sections", "0,10,1"),
    ("sections", 5),
    ("extra_brake_force_N", NAN),
    ("extra_brake_force_N", INF),
    ("extra_brake_force_N", -1.0),
    ("background", 1.5),
    ("background", -0.1),
    ("background", NAN),
    ("recovery_basis", "joules"),
    ("rail", "custard"),
    ("rail", 3),
]


@pytest.fixture(scope="module")
def env():
    return WSPBrakingEnv()


@pytest.mark.parametrize("name,value", BAD_OPTIONS)
def test_bad_option_is_one_line_naming_it(env, name, value):
    with pytest.raises(ValueError) as err:
        env.reset(seed=0, options={"rail": "soap", name: value})
    assert str(err.value).startswith(f"options.{name}"), str(err.value)
    _one_line_naming(err.value, f"options.{name}")


def test_mu_contaminated_message_and_the_env_still_usable(env):
    with pytest.raises(
        ValueError, match=r"^options\.mu_contaminated: must be in \[0\.001, 1\], got nan$"
    ):
        env.reset(options={"mu_contaminated": NAN})
    env.reset(seed=1, options={"rail": "soap", "mu_contaminated": 0.07})
    _, reward, *_ = env.step(np.zeros(4, dtype=np.float32))
    assert math.isfinite(reward)


def _in_range(name: str, top: float = 1e300):
    """Any finite value the table allows for number option ``name`` (``top`` where unbounded)."""
    b = OPTION_SPECS[name].bounds
    low = b.get("gt", b.get("ge", -top))
    return st.floats(low, b.get("le", top), exclude_min="gt" in b, allow_nan=False)


def _valid_options():
    n = UIC.n_axles
    level = _in_range("background")
    end = st.floats(allow_nan=False)
    section = st.tuples(end, end, level).filter(lambda s: s[1] > s[0])
    factors = OPTION_SPECS["axle_mu_factor"].bounds
    return st.fixed_dictionaries(
        {},
        optional={
            "speed_kmh": _in_range("speed_kmh", UIC.max_speed_kmh),
            "rail": st.sampled_from(["soap", "dry", "wet", "oil", "leaves"]),
            "mu_contaminated": _in_range("mu_contaminated"),
            "pattern": st.sampled_from(PATTERNS),
            "load_factor": _in_range("load_factor"),
            "pad_factor": _in_range("pad_factor"),
            "gradient_permille": _in_range("gradient_permille"),
            "demand": st.sampled_from(["emergency", "service"]),
            "sections": st.lists(section, max_size=4),
            "axle_mu_factor": st.lists(
                st.floats(factors["ge"], factors["le"]), min_size=n, max_size=n
            ),
            "recovery_basis": st.sampled_from(["rail_metre", "wheel_metre", "sliding_power"]),
            "background": level,
            "extra_brake_force_N": _in_range("extra_brake_force_N"),
        },
    )


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(opts=_valid_options(), seed=st.integers(0, 2**16), action=st.floats(-1.0, 1.0))
def test_any_in_range_options_are_accepted_and_give_finite_rewards(env, opts, seed, action):
    obs, info = env.reset(seed=seed, options=opts)
    assert np.isfinite(obs).all()
    for key in ("speed_kmh", "mu_contaminated", "load_factor", "gradient_permille"):
        if key in opts:
            assert info["scenario"][key] == pytest.approx(opts[key])
    for _ in range(10):
        obs, reward, terminated, truncated, _ = env.step(np.full(4, action, dtype=np.float32))
        assert math.isfinite(reward) and np.isfinite(obs).all()
        if terminated or truncated:
            break


_NUMBER_OPTIONS = [k for k, s in OPTION_SPECS.items() if s.kind == "number"]


@st.composite
def _out_of_range(draw):
    name = draw(st.sampled_from(_NUMBER_OPTIONS))
    b = OPTION_SPECS[name].bounds
    bad = [st.just(NAN), st.just(INF), st.just(-INF)]
    if "gt" in b:
        bad.append(st.floats(max_value=b["gt"], allow_nan=False, allow_infinity=False))
    if "ge" in b:
        bad.append(
            st.floats(max_value=b["ge"], exclude_max=True, allow_nan=False, allow_infinity=False)
        )
    if "le" in b:
        bad.append(
            st.floats(min_value=b["le"], exclude_min=True, allow_nan=False, allow_infinity=False)
        )
    if name == "speed_kmh":
        bad.append(st.floats(min_value=UIC.max_speed_kmh, exclude_min=True, allow_infinity=False))
    return name, draw(st.one_of(bad))


@settings(
    max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(case=_out_of_range())
def test_any_out_of_range_number_is_refused_with_the_field_named(env, case):
    name, value = case
    with pytest.raises(ValueError) as err:
        env.reset(options={name: value})
    _one_line_naming(err.value, f"options.{name}")


def test_vector_env_refuses_bad_options_too():
    venv = WSPBrakingVectorEnv(num_envs=2)
    with pytest.raises(ValueError, match=r"^options\.pattern: 'unifrom' is not one of"):
        venv.reset(seed=0, options={"pattern": "unifrom"})


# ---- RunSetup -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "field,value",
    [
        ("mu_contaminated", NAN),
        ("load_factor", INF),
        ("gradient_permille", 1e6),
        ("axle_mu_factor", (1.0, -1.0)),
        ("extra_brake_force_N", -5.0),
        ("background", 2.0),
        ("demand_fraction", 1.5),
        ("injection_level", NAN),
        ("recovery_basis", "joules"),
        ("sections", ((0.0, 1.0, 0.5, 9.0),)),
    ],
)
def test_run_setup_names_the_field(field, value):
    with pytest.raises(ValueError) as err:
        RunSetup(120.0, load_rail("soap"), **{field: value})
    assert str(err.value).startswith(field)
    _one_line_naming(err.value, field)
    with pytest.raises(ValueError, match=r"^speed_kmh: "):
        RunSetup(NAN, load_rail("soap"))


# ---- constructor arguments -------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs,name",
    [
        ({"max_time_s": -5.0}, "max_time_s"),
        ({"max_time_s": 0.0}, "max_time_s"),
        ({"max_time_s": NAN}, "max_time_s"),
        ({"max_time_s": INF}, "max_time_s"),
        ({"max_time_s": "long"}, "max_time_s"),
        ({"substep_s": 0.0}, "substep_s"),
        ({"substep_s": -1e-3}, "substep_s"),
        ({"substep_s": NAN}, "substep_s"),
        ({"control_period_s": 0.0}, "control_period_s"),
        ({"control_period_s": INF}, "control_period_s"),
        ({"control_period_s": 0.0205}, "substep_s"),  # the substep does not divide it
        ({"control_period_s": 0.02, "substep_s": 0.03}, "substep_s"),
        ({"substep_s": 1e-12}, "substep_s"),  # 2e10 substeps a period: hours per step
        ({"max_time_s": 1e9}, "max_time_s"),
        ({"control_period_s": 5.0, "substep_s": 1e-3}, "control_period_s"),
        ({"accelerometer_bias_mps2": -1.0}, "accelerometer_bias_mps2"),
        ({"scenario": {"speed_kmh": [40.0, 250.0]}}, "scenario.speed_kmh[1]"),
        ({"scenario": {"gradient_permille": [-5.0, 500.0]}}, "scenario.gradient_permille[1]"),
    ],
)
def test_bad_constructor_argument_is_one_line_naming_it(kwargs, name):
    with pytest.raises(ValueError) as err:
        WSPBrakingEnv(**kwargs)
    assert str(err.value).startswith(name), str(err.value)
    _one_line_naming(err.value, name)


def test_n_envs_must_be_positive():
    with pytest.raises(ValueError, match=r"^n_envs: "):
        BrakingCore(0)


# ---- stepping before reset ------------------------------------------------------------------


def test_step_before_reset_raises_instead_of_nan():
    env = WSPBrakingEnv()
    with pytest.raises(RuntimeError, match="step before reset"):
        env.step(np.zeros(4, dtype=np.float32))
    env.reset(seed=0)
    _, reward, *_ = env.step(np.zeros(4, dtype=np.float32))
    assert math.isfinite(reward)


def test_core_step_needs_every_env_reset_once():
    core = BrakingCore(3)
    actions = np.zeros((3, 4))
    core.reset_env(0, seed=0)
    core.reset_env(2, seed=2)
    with pytest.raises(RuntimeError, match=r"step before reset.*environment 1"):
        core.step(actions)
    core.reset_env(1, seed=1)
    core.step(actions)
    assert np.isfinite(core.terms).all()
    venv = WSPBrakingVectorEnv(num_envs=2)
    with pytest.raises(RuntimeError, match="step before reset"):
        venv.step(np.zeros((2, 4), dtype=np.float32))


def test_a_restored_core_steps_without_reset():
    core = BrakingCore(2)
    for e in range(2):
        core.reset_env(e, seed=e)
    core.step(np.zeros((2, 4)))
    other = BrakingCore(2)
    other.load_state_dict(core.state_dict())
    other.step(np.zeros((2, 4)))
    core.step(np.zeros((2, 4)))
    np.testing.assert_array_equal(other.obs, core.obs)
    fresh = BrakingCore(2)
    fresh.load_state_dict(BrakingCore(2).state_dict())  # a state of a core never reset
    with pytest.raises(RuntimeError, match="step before reset"):
        fresh.step(np.zeros((2, 4)))
    old = core.state_dict()  # a checkpoint from before a version's new column: one clear line
    old["core"]["wsp"] = old["core"]["wsp"][:, :-1]
    n_w = old["core"]["wsp"].shape[1]
    with pytest.raises(ValueError, match=rf"state: wsp has shape \(2, {n_w}\), this core's is"):
        BrakingCore(2).load_state_dict(old)


# ---- scenario suites ------------------------------------------------------------------------


def _write_suite(tmp_path, cases: str):
    path = tmp_path / "suite.yaml"
    path.write_text(f"name: s\ndescription: d\nseeds: [0]\ncases:\n{cases}")
    return path


@pytest.mark.parametrize(
    "cases,field",
    [
        (
            "  - {name: a, rail: soap, speeds_kmh: [120]}\n"
            "  - {name: a, rail: oil, speeds_kmh: [80]}\n",
            "cases[1].name: 'a' repeats cases[0]",
        ),
        ("  - {name: a, rail: soap, speeds_kmh: [.inf]}\n", "cases[0].speeds_kmh: 'inf'"),
        ("  - {name: a, rail: soap, speeds_kmh: [.nan]}\n", "cases[0].speeds_kmh: 'nan'"),
        ("  - {name: a, rail: soap, speeds_kmh: [-5]}\n", "cases[0].speeds_kmh: '-5'"),
        ("  - {name: a, rail: soap, speeds_kmh: [fast]}\n", "cases[0].speeds_kmh: 'fast'"),
        (
            "  - {name: a, rail: soap, speeds_kmh: [120], mu_contaminated: 5}\n",
            "cases[0].mu_contaminated",
        ),
        (
            "  - {name: a, rail: soap, speeds_kmh: [120], gradient_permille: 1000}\n",
            "cases[0].gradient_permille",
        ),
        (
            "  - {name: a, rail: soap, speeds_kmh: [120], axle_mu_factor: [1, 1, 1, 3]}\n",
            "cases[0].axle_mu_factor",
        ),
        (
            "  - {name: a, rail: soap, speeds_kmh: [120], sections: [[0, 10]]}\n",
            "cases[0].sections[0]",
        ),
        (
            "  - {name: a, rail: soap, speeds_kmh: [120], pattern: unifrom}\n",
            "cases[0].pattern",
        ),
    ],
)
def test_bad_suite_is_refused_at_load(tmp_path, cases, field):
    path = _write_suite(tmp_path, cases)
    with pytest.raises(ConfigError) as err:
        load_suite(str(path))
    msg = str(err.value)
    assert msg.startswith(str(path)) and field in msg and "\n" not in msg, msg


def test_suite_speed_above_the_vehicle_maximum_is_refused_at_expand():
    suite = load_suite("quick")
    big = SuiteConfig(
        name="quick",
        description="",
        seeds=(0,),
        cases=(CaseConfig(name="soap_low", rail="soap", speeds_kmh=("1e9",)),),
    )
    with pytest.raises(
        ConfigError,
        match=r"^suite quick: case soap_low: speed 1e\+09 km/h exceeds uic_z1's "
        r"maximum 200 km/h$",
    ):
        expand(big, UIC)
    assert len(expand(suite, UIC)) == len(expand(suite, load_vehicle("regiolis")))
    with pytest.raises(ConfigError, match="suite heldout: case soap_mid_laden: speed 170 km/h"):
        expand(load_suite("heldout"), load_vehicle("regiolis"))  # a 160 km/h train


def test_suite_case_checked_against_its_vehicle_at_expand():
    case = CaseConfig(name="c", rail="soap", speeds_kmh=("120",), axle_mu_factor=(1.0,) * 4)
    suite = SuiteConfig(name="s", description="", seeds=(0,), cases=(case,))
    assert len(expand(suite, UIC)) == 1
    with pytest.raises(ConfigError, match=r"^suite s: case c: axle_mu_factor: expected 32 entr"):
        expand(suite, load_vehicle("etr1000"))


def test_suite_runs_of_one_name_are_refused_or_one_run():
    # 'max' equal to a listed speed is the same run: kept once (en15595 on a 160 km/h train)
    same = CaseConfig(name="c", rail="soap", speeds_kmh=("max", "160", "120"))
    suite = SuiteConfig(name="s", description="", seeds=(0, 1), cases=(same,))
    runs = expand(suite, load_vehicle("regiolis"))
    assert [r.scenario for r in runs] == ["c_160", "c_160", "c_120", "c_120"]
    # different speeds under one name would merge in the results
    near = CaseConfig(name="c", rail="soap", speeds_kmh=("120", "120.2"))
    suite = SuiteConfig(name="s", description="", seeds=(0,), cases=(near,))
    with pytest.raises(ConfigError, match=r"^suite s: case c: speed 120\.2 makes run c_120"):
        expand(suite, UIC)


@pytest.mark.parametrize(
    "name", ["quick", "en15595", "heldout", "tuning", "validation", "seed002_braking"]
)
def test_shipped_suites_load_and_expand(name):
    suite = load_suite(name)
    assert expand(suite, UIC)

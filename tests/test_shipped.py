"""The shipped policies (agents/pretrained): each loads by name, carries what the README says
it carries, and beats the frozen classical WSP on a small fixed set of held-out scenarios (the
first seed of every `heldout` scenario: every family once, on the vehicle the policy was
trained for), through the evaluation's code path: shorter mean stop and no more sliding
energy."""

from __future__ import annotations

import dataclasses
import functools
import json
import shutil
import statistics
from typing import Any

import pytest

from wsp_env.core.config import load_vehicle
from wsp_env.evaluation import load_suite, run_suite
from wsp_env.policy import make_policy, model_metadata, pretrained_dir, shipped_policies

SHIPPED = shipped_policies()


def test_something_ships():
    assert SHIPPED, "agents/pretrained holds no policy"


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_policy_files(name):
    folder = pretrained_dir()
    for suffix in (".zip", ".vecnormalize.pkl", ".yaml", ".json", "_learning_curve.png"):
        assert (folder / f"{name}{suffix}").exists(), suffix
    info = json.loads((folder / f"{name}.json").read_text())
    assert info["wall_time_s"] > 0 and info["env_steps_per_s"] > 0
    assert "wsp-env train --config" in (folder / f"{name}.yaml").read_text()


@functools.cache
def _heldout_firsts(vehicle: str) -> tuple[Any, list[dict]]:
    """The suite on ``vehicle`` and the classical WSP's runs of it (once a vehicle)."""
    vmax = load_vehicle(vehicle).max_speed_kmh
    suite = load_suite("heldout")
    # a speed above the vehicle's maximum runs at its maximum (the Regiolis: 160 km/h)
    cases = tuple(
        dataclasses.replace(c, speeds_kmh=tuple(
            s if s == "max" or float(s) <= vmax else "max" for s in c.speeds_kmh))
        for c in suite.cases
    )  # fmt: skip
    suite = dataclasses.replace(suite, seeds=suite.seeds[:1], cases=cases)
    classical, _ = run_suite(vehicle, suite, make_policy("classical"), record="none")
    return suite, classical


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_policy_beats_the_classical_wsp_on_heldout_firsts(name):
    policy = make_policy(name)
    vehicle = policy.vehicle or "uic_z1"  # the vehicle it learned on
    suite, classical = _heldout_firsts(vehicle)
    learned, _ = run_suite(vehicle, suite, policy, record="none")
    assert len(learned) == len(classical) == len(suite.cases) + 1  # soap_mid has two speeds

    def mean(rs, key):
        return statistics.fmean(r[key] for r in rs)

    assert mean(learned, "stopping_distance_m") < mean(classical, "stopping_distance_m")
    assert mean(learned, "sliding_energy_kJ") <= mean(classical, "sliding_energy_kJ")
    assert all(r["stopped"] for r in learned)


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_policy_needs_its_normalisation(name, tmp_path):
    """Every shipped model loads normalised, and copied without its statistics file it is
    refused in one line. The models shipped since the ``obs_normalization`` field record it
    themselves. ``ppo_bc_uic_z1``'s metadata predates the field: the config it was trained with
    (``NAME.yaml`` beside it) tells, so it is refused copied with that config; copied alone,
    nothing tells: it loads as models written before the field always did."""
    folder = pretrained_dir()
    assert model_metadata(folder / f"{name}.zip")["obs_normalization"] is True
    assert make_policy(name).normalisation() is not None
    shutil.copy(folder / f"{name}.zip", tmp_path / f"{name}.zip")
    own = model_metadata(tmp_path / f"{name}.zip")["obs_normalization"]
    if name == "ppo_bc_uic_z1":
        assert own is None
        assert make_policy(str(tmp_path / f"{name}.zip")).normalisation() is None
        shutil.copy(folder / f"{name}.yaml", tmp_path / f"{name}.yaml")
    else:
        assert own is True
    with pytest.raises(ValueError, match=rf"{name}\.vecnormalize\.pkl is missing"):
        make_policy(str(tmp_path / f"{name}.zip"))

"""The shipped policies (agents/pretrained): each loads by name, carries what the README says
it carries, and beats the frozen classical WSP on a small fixed set of held-out scenarios (the
first seed of every `heldout` scenario: every family once), through the evaluation's code
path: shorter mean stop and no more sliding energy."""

from __future__ import annotations

import dataclasses
import json
import shutil
import statistics

import pytest

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


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_policy_beats_the_classical_wsp_on_heldout_firsts(name):
    suite = load_suite("heldout")
    suite = dataclasses.replace(suite, seeds=suite.seeds[:1])
    classical, _ = run_suite("uic_z1", suite, make_policy("classical"), record="none")
    learned, _ = run_suite("uic_z1", suite, make_policy(name), record="none")
    assert len(learned) == len(classical) == len(suite.cases) + 1  # soap_mid has two speeds

    def mean(rs, key):
        return statistics.fmean(r[key] for r in rs)

    assert mean(learned, "stopping_distance_m") < mean(classical, "stopping_distance_m")
    assert mean(learned, "sliding_energy_kJ") <= mean(classical, "sliding_energy_kJ")
    assert all(r["stopped"] for r in learned)


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_policy_needs_its_normalisation(name, tmp_path):
    """The shipped model's metadata predates the ``obs_normalization`` field: the config it was
    trained with (``NAME.yaml`` beside it) tells, so it loads normalised, and copied with that
    config but without its statistics file it is refused in one line. Copied alone, nothing
    tells: it loads as models written before the field always did."""
    folder = pretrained_dir()
    assert model_metadata(folder / f"{name}.zip")["obs_normalization"] is True
    assert make_policy(name).normalisation() is not None
    shutil.copy(folder / f"{name}.zip", tmp_path / f"{name}.zip")
    assert model_metadata(tmp_path / f"{name}.zip")["obs_normalization"] is None
    assert make_policy(str(tmp_path / f"{name}.zip")).normalisation() is None
    shutil.copy(folder / f"{name}.yaml", tmp_path / f"{name}.yaml")
    with pytest.raises(ValueError, match=rf"{name}\.vecnormalize\.pkl is missing"):
        make_policy(str(tmp_path / f"{name}.zip"))

"""Individual identification as the seed's section 5.3: embedded records by name, the seed's
numerical example as the seed ran it, and C and K converging along a deck walk."""

from __future__ import annotations

import json

import numpy as np
import pytest

from workbench import datasets
from workbench.cli.main import main
from workbench.errors import InputError, UsageError
from workbench.inference.pipeline.prefixes import identify_on_prefixes
from workbench.records.io import load_record


def test_names_resolve_to_embedded_records_and_local_files_win(tmp_path, monkeypatch):
    assert {"treadmill", "seed_individual_deck", "seed_numerical_example"} <= set(datasets.names())
    monkeypatch.chdir(tmp_path)
    assert datasets.named("seed_numerical_example") == "seed_numerical_example"
    assert datasets.named("no_such_record") is None
    assert datasets.named(["treadmill"]) is None  # a list of records is not a name
    (tmp_path / "treadmill").write_text("time,grf\n")
    assert datasets.named("treadmill") is None  # the user's own file is never shadowed
    with pytest.raises(UsageError, match="no embedded record is called"):
        datasets.settings("no_such_record")


def test_the_numerical_example_carries_the_force_model_it_was_made_with():
    settings = datasets.settings("seed_numerical_example")
    flat = settings.to_json()
    assert (flat["harmonics"], flat["pacing_hz"], flat["pieces"]) == (10, 0.5, "whole")
    assert (flat["time_basis"], flat["highpass_hz"], flat["obs_noise"]) == ("absolute", 0, "seed")
    # Flags win over the record's own settings; a walk has the defaults.
    assert datasets.settings("seed_numerical_example", harmonics=12).to_json()["harmonics"] == 12
    walk = datasets.settings("seed_individual").to_json()
    assert walk == datasets.settings("treadmill").to_json()
    # Its force is the seed's eq. 24, not a walking GRF: it dips below zero, and loading it
    # by name accepts that (with a warning) where loading the file by path refuses it.
    record = datasets.load("seed_numerical_example")
    assert record.grf_n.min() < 0
    assert any("below zero" in w for w in record.metadata["warnings"])
    with pytest.raises(InputError, match="below zero"):
        load_record(datasets.dataset_path("seed_numerical_example"))


@pytest.mark.slow
def test_identify_runs_the_numerical_example_by_name(capsys):
    """The seed's section 4 as the seed set it up; exact posterior, so the bands are exact."""
    code = main(
        ["identify", "seed_numerical_example", "--method", "exact", "--no-force-check", "--json"]
    )
    text = capsys.readouterr().out
    out = json.loads(text, parse_constant=lambda name: pytest.fail(f"{name} is not JSON"))
    assert code == 0
    # One piece: no spread over steps, but the load factor's band is the posterior of that
    # piece's load factor given the data, mixed over (C, K).
    assert out["blf_step_sd"][0] is None
    assert all(sd is not None and sd > 0.0 for sd in out["posterior_sd"]["blf"])
    truth = datasets.load("seed_numerical_example").metadata["truth"]
    for key in ("stiffness_n_per_m", "damping_ns_per_m"):
        lo, hi = out["interval_95"][key]
        assert lo <= truth[key] <= hi, key
        # The seed's 10 % observation noise: a band of a few per cent, not the prior's.
        assert hi - lo < 0.05 * truth[key], key
    assert out["identifiability"]["identified_stiffness"]
    assert out["settings"]["harmonics"] == 10 and out["settings"]["time_basis"] == "absolute"


@pytest.mark.slow
def test_c_and_k_converge_along_the_deck_walk():
    """Short prefixes are flagged, not drawn as estimates; the whole walk holds the truth."""
    record = datasets.load("seed_individual_deck")
    truth = record.metadata["truth"]
    conv = identify_on_prefixes(record, datasets.settings("seed_individual_deck"), (30.0, 4.0))
    assert conv.time_s.tolist() == [4.0, 30.0]
    assert conv.identified.tolist() == [False, True]
    assert conv.levels[0] == "not identified"
    assert conv.first_identified_s == 30.0
    for j, key in enumerate(("damping_ns_per_m", "stiffness_n_per_m")):
        lo, hi = conv.interval[-1, j]
        assert lo <= truth[key] <= hi, key
        # Identified means informative: the band is a fraction of the prior's width.
        assert hi - lo < 0.5 * truth[key], key
    obj = conv.to_json()
    assert obj["identified"] == [False, True] and np.isfinite(obj["time_s"]).all()
    with pytest.raises(UsageError, match="prefix lengths must lie in"):
        identify_on_prefixes(record, datasets.settings("seed_individual_deck"), (40.0,))

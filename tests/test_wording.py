"""Sentences to users: parameters in words, agreement, counts, p-values; diagnose and hsi text."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.test_hsi import _crowd
from tests.walks import simulated_walk
from workbench.cli import main
from workbench.records.io import save_record
from workbench.wording import count, join_words, p_value, parameter_words, signed, verb


def test_parameters_are_named_in_words():
    assert parameter_words("stiffness_n_per_m") == "stiffness K"
    assert parameter_words("damping_ns_per_m") == "damping C"
    assert join_words(["damping C"]) == "damping C"
    assert join_words(["damping C", "stiffness K"]) == "damping C and stiffness K"
    assert join_words(["a", "b", "c"]) == "a, b and c"


def test_verbs_and_nouns_agree_with_the_count():
    assert verb(1, "sits", "sit") == "sits" and verb(2, "sits", "sit") == "sit"
    assert count(1, "piece") == "1 piece"
    assert count(34, "piece") == "34 pieces"
    assert count(0, "crossing") == "0 crossings"


def test_a_p_value_that_underflowed_is_printed_as_a_bound():
    assert p_value(0.0) == "< 1e-300"
    assert p_value(3.61e-56) == "3.61e-56"
    assert p_value(0.4567, 2) == "0.46"
    assert p_value(float("nan")) == "not computed"


@pytest.fixture(scope="module")
def walk_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("diag") / "walk.csv"
    save_record(simulated_walk(4, 12.0).record, path)
    return path


def test_a_signed_value_below_the_printed_precision_has_one_sign():
    # A score of -4e-7 and one of +4e-7 are the same printed number on every machine.
    assert signed(-4e-7) == signed(4e-7) == signed(0.0) == signed(-0.0) == "+0.000"
    assert signed(-0.0123) == "-0.012" and signed(0.0126) == "+0.013"
    assert signed(-0.04, 1) == "+0.0" and signed(1.25, 1) == "+1.2"


def test_diagnose_names_the_record_and_ranks_candidates_by_score(walk_csv, capsys):
    assert main(["diagnose", str(walk_csv), "--no-one-step"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"Model criticism of {walk_csv}"
    assert out[1].startswith("baseline: held-out RMSE")
    rows = [line for line in out if re.match(r"^[* ] \w+\s+score [+-]", line)]
    assert len(rows) >= 5
    scores = [float(re.search(r"score ([+-][\d.]+)", r).group(1)) for r in rows]
    untestable = ["not testable" in r for r in rows]
    # Untestable candidates (this record has no ground motion) come last ...
    assert untestable == sorted(untestable) and untestable[-1]
    # ... and the rest by score, highest first.
    testable = [s for s, u in zip(scores, untestable, strict=True) if not u]
    assert testable == sorted(testable, reverse=True)


def test_hsi_names_its_counts_as_crossings_per_comfort_class(tmp_path, capsys):
    peds = tmp_path / "peds.csv"
    _crowd(3, seed=8).to_csv(peds, index=False)
    args = ["hsi", "--pedestrians", str(peds), "--crossings", "3", "--dt", "0.01", "--seed", "2"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert out.startswith("3 single crossings of a ")
    lines = [line for line in out.splitlines() if "per comfort class" in line]
    assert len(lines) == 2  # the coupled SMDs and the moving forces
    for line in lines:
        classes = line.split("crossings per comfort class: ")[1]
        counts = re.findall(
            r"(maximum comfort|mean comfort|minimum comfort|unacceptable) (\d+)", classes
        )
        assert [c for c, _ in counts] == [
            "maximum comfort",
            "mean comfort",
            "minimum comfort",
            "unacceptable",
        ]
        assert sum(int(n) for _, n in counts) == 3  # every crossing in one class
    assert "comfort maximum" not in out and "moving_force" not in out

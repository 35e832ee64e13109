"""Hardening of the command line: options refused up front, one sentence, exit 2.

Every case here once ended as an internal error (exit 3), a silent acceptance or a message
that pointed the wrong way; each is checked the way a user meets it, through ``main``.
"""

from __future__ import annotations

import argparse

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from workbench.cli import build_parser, main
from workbench.cli.common import floats, seed_int

PROPERTY = settings(max_examples=200, deadline=None, derandomize=True, database=None)


def run_cli(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def usage_error(argv, capsys) -> str:
    """Run ``argv``, which argparse must refuse; return its stderr."""
    with pytest.raises(SystemExit) as exc:
        main([str(a) for a in argv])
    assert exc.value.code == 2
    _, err = capsys.readouterr()
    assert "Traceback" not in err
    return err


# -- --seed -----------------------------------------------------------------------------------
SEED_COMMANDS = {
    "identify": ["identify", "rec.csv"],
    "crosscheck": ["crosscheck", "rec.csv"],
    "sensitivity": ["sensitivity", "rec.csv", "--out", "s"],
    "sample": ["sample", "--n", "3", "--out", "s.csv"],
    "hsi": ["hsi"],
    "demo": ["demo"],
    "batch": ["batch", "manifest.csv", "--out", "b"],
    "simulate": ["simulate", "--out", "w.csv"],
    "diagnose": ["diagnose", "rec.csv"],
    "compare": ["compare", "rec.csv", "--effects", "heel_impact"],
}


@pytest.mark.parametrize("command", sorted(SEED_COMMANDS))
def test_negative_seed_is_refused_before_any_work(command, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing may be written; if it were, not into the repo
    err = usage_error([*SEED_COMMANDS[command], "--seed", "-1"], capsys)
    assert (
        err.strip()
        .splitlines()[-1]
        .endswith("argument --seed: '-1' is negative; a seed is a whole number of 0 or more")
    )
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", sorted(SEED_COMMANDS))
def test_every_seed_option_uses_the_shared_seed_type(command):
    parser = build_parser()
    args = parser.parse_args([*SEED_COMMANDS[command], "--seed", "12345678901234567890"])
    assert args.seed == 12345678901234567890


@PROPERTY
@given(text=st.one_of(st.integers().map(str), st.text(max_size=12)))
def test_seed_type_returns_a_non_negative_int_or_refuses(text):
    try:
        value = seed_int(text)
    except argparse.ArgumentTypeError as err:
        assert "whole number of 0 or more" in str(err) and "\n" not in str(err)
        return
    assert isinstance(value, int) and value >= 0 and value == int(text)


# -- negative lists ---------------------------------------------------------------------------
@PROPERTY
@given(values=st.lists(st.floats(-10, 10, allow_nan=False), min_size=1, max_size=4))
def test_lists_starting_with_a_negative_number_reach_the_option(values):
    text = ",".join(repr(v) for v in values)
    args = build_parser().parse_args(["simulate", "--out", "w.csv", "--blf", text])
    assert args.blf == pytest.approx(tuple(values))
    assert floats(text) == pytest.approx(tuple(values))


def test_an_option_after_a_negative_list_is_still_an_option():
    args = build_parser().parse_args(["simulate", "--blf", "-0.4,0.1", "--out", "w.csv"])
    assert args.blf == (-0.4, 0.1) and args.out == "w.csv"


def test_a_negative_list_is_judged_by_the_command_not_by_argparse(tmp_path, capsys):
    code, _, err = run_cli(["simulate", "--out", tmp_path / "w.csv", "--blf", "-0.4,0.1"], capsys)
    assert code == 2, err
    assert "expected one argument" not in err
    assert "--blf" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "w.csv").exists()

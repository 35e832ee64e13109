"""Hardening of the command line: options refused up front, one sentence, exit 2.

Every case here once ended as an internal error (exit 3), a silent acceptance or a message
that pointed the wrong way; each is checked the way a user meets it, through ``main``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
from pathlib import Path

import pandas as pd
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


# -- results tables that population and report cannot fit -------------------------------------
def _results(n: int = 12, seed: int = 3) -> pd.DataFrame:
    from workbench.population.sampler import sample_pedestrians

    table = sample_pedestrians(n, seed=seed).assign(path=[f"r{i:02d}.csv" for i in range(n)])
    table["identified_damping"] = True
    table["identified_stiffness"] = True
    table["identifiability"] = "well identified"
    return table


def _batch_folder(tmp_path: Path, table: pd.DataFrame) -> Path:
    folder = tmp_path / "batch"
    folder.mkdir()
    table.to_csv(folder / "results.csv", index=False)
    return folder


@pytest.mark.parametrize("command", ["population", "report"])
def test_one_shared_pacing_is_refused_naming_the_file(command, tmp_path, capsys):
    folder = _batch_folder(tmp_path, _results().assign(pacing_hz=1.8))
    code, out, err = run_cli([command, folder, "--out", tmp_path / "o"], capsys)
    assert code == 2, err
    assert out == "" and len(err.strip().splitlines()) == 1, err
    assert str(folder / "results.csv") in err
    assert "share one pacing (1.8 Hz)" in err and "other pacings" in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", ["population", "report"])
def test_text_in_a_pacing_cell_is_refused_naming_the_cell(command, tmp_path, capsys):
    table = _results()
    table["pacing_hz"] = table["pacing_hz"].astype(object)
    table.loc[4, "pacing_hz"] = "1,8"
    folder = _batch_folder(tmp_path, table)
    code, _, err = run_cli([command, folder, "--out", tmp_path / "o"], capsys)
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1, err
    assert (
        f"{folder / 'results.csv'}, column 'pacing_hz', record 5 (r04.csv): the value '1,8'" in err
    )
    assert "plain number" in err


def test_no_identified_record_points_to_keep_not_identified(tmp_path, capsys):
    folder = _batch_folder(tmp_path, _results().assign(identified_stiffness=False))
    code, _, err = run_cli(["population", folder, "--out", tmp_path / "o"], capsys)
    assert code == 2, err
    assert "12 excluded because C or K is not identified" in err
    assert "pass --keep-not-identified" in err and "'keep_not_identified'" not in err
    argv = ["population", folder, "--out", tmp_path / "o", "--keep-not-identified"]
    assert run_cli(argv, capsys)[0] == 0


FITTED = ["pacing_hz", "natural_frequency_hz", "damping_ratio", "blf1", "blf2", "blf3"]


@settings(max_examples=25, deadline=None, derandomize=True, database=None)
@given(
    edits=st.lists(
        st.tuples(
            st.integers(0, 11),
            st.sampled_from([*FITTED, "identified_stiffness", "path"]),
            st.one_of(
                st.sampled_from(["", "nan", "inf", "-1", "0", "1.8", "n/a", "1,8", "True"]),
                st.floats(allow_nan=True, allow_infinity=True).map(repr),
                st.text(alphabet="0123456789.,-eE naif", max_size=6),
            ),
        ),
        max_size=6,
    ),
    one_pacing=st.booleans(),
)
def test_edited_results_tables_fit_or_give_one_sentence(edits, one_pacing):
    table = _results().assign(pacing_hz=1.8) if one_pacing else _results()
    table = table.astype(object)
    for row, column, text in edits:
        table.loc[row, column] = text
    with tempfile.TemporaryDirectory() as folder:
        batch = _batch_folder(Path(folder), table)
        out = io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            code = main(["population", str(batch), "--out", str(Path(folder) / "o")])
    text = out.getvalue()
    assert code in (0, 2), text
    if code == 2:
        lines = text.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("workbench: error: "), text

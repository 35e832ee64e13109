"""Hardening of the command line: options refused up front, one sentence, exit 2.

Every case here once ended as an internal error (exit 3), a silent acceptance or a message
that pointed the wrong way; each is checked the way a user meets it, through ``main``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
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


# -- batch: confinement, exit status, workers -------------------------------------------------
def _manifest(folder: Path, *paths: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    manifest = folder / "manifest.csv"
    manifest.write_text("path,mass_kg\n" + "".join(f"{p},70\n" for p in paths))
    return manifest


@pytest.mark.parametrize("outside", ["../secret.csv", "ABSOLUTE", "records/../../secret.csv"])
def test_manifest_paths_outside_its_folder_are_refused(outside, tmp_path, capsys):
    (tmp_path / "secret.csv").write_text("time,grf\n")
    if outside == "ABSOLUTE":
        outside = str(tmp_path / "secret.csv")
    manifest = _manifest(tmp_path / "study", "records/a.csv", outside)
    out = tmp_path / "out"
    code, _, err = run_cli(["batch", manifest, "--out", out], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert f"{manifest}, line 3, column 'path'" in err
    assert "outside the manifest's folder" in err and "--allow-outside-paths" in err
    assert not out.exists()  # refused before anything was opened or written


def test_allow_outside_paths_reads_them_and_the_flag_reaches_the_loader(tmp_path, capsys):
    from workbench.records.io import load_manifest

    manifest = _manifest(tmp_path / "study", "inside/a.csv", "../b.csv")
    entries = load_manifest(manifest, allow_outside_paths=True)
    assert [e.path.name for e in entries] == ["a.csv", "b.csv"]
    assert build_parser().parse_args(["batch", "m.csv", "--out", "o"]).allow_outside_paths is False
    args = build_parser().parse_args(
        ["sensitivity", "m.csv", "--out", "o", "--allow-outside-paths"]
    )
    assert args.allow_outside_paths is True
    # A link placed in the folder on purpose is the user's choice: the check reads the text.
    (tmp_path / "study" / "link").symlink_to(tmp_path)
    assert load_manifest(_manifest(tmp_path / "study", "link/b.csv"))[0].path.name == "b.csv"


def test_batch_with_failed_records_exits_4_and_says_where_paths_start(tmp_path, capsys):
    manifest = _manifest(tmp_path / "study", "records/missing.csv")
    out = tmp_path / "out"
    code, stdout, err = run_cli(["batch", manifest, "--out", out, "--json"], capsys)
    assert code == 4, err
    summary = json.loads(stdout)
    assert (summary["done"], summary["failed"]) == (0, 1)
    reason = summary["failed_records"][0]["reason"]
    assert reason.startswith("records/missing.csv, whole file: the record file does not exist")
    assert "relative paths start from the manifest's folder" in reason
    assert "current folder" not in reason
    assert summary["timings"] == str(out / "timings.csv")
    assert (out / "timings.csv").read_text().startswith("path,status,elapsed_s\n")
    assert "elapsed_s" not in (out / "results.csv").read_text()


def test_exit_status_4_is_documented():
    contracts = (Path(__file__).parents[1] / "docs" / "contracts.md").read_text()
    assert "| 4 | `batch` finished but could not identify every record" in contracts


@pytest.mark.parametrize("command", ["batch", "sensitivity", "hsi"])
def test_more_workers_than_cores_warns_once(command, tmp_path, capsys, monkeypatch):
    import os

    monkeypatch.setattr(os, "sched_getaffinity", lambda _: {0, 1}, raising=False)

    def argv(workers: str) -> list:
        out = tmp_path / f"out{workers}"
        return {
            "batch": ["batch", _manifest(tmp_path, "missing.csv"), "--out", out],
            "sensitivity": ["sensitivity", tmp_path / "absent.csv", "--out", out],
            "hsi": ["hsi", "--crossings", "0"],  # refused after the warning: nothing runs
        }[command] + ["--workers", workers]

    _, _, err = run_cli(argv("12"), capsys)
    warnings = [line for line in err.splitlines() if "warning" in line]
    assert warnings == [
        "workbench: warning: --workers 12 is more than the 2 cores this computer lets the "
        "workbench use, so the workers share them and run no faster; give --workers 2 or fewer"
    ], err
    _, _, err = run_cli(argv("2"), capsys)
    assert "warning" not in err


# -- messages that pointed the wrong way ------------------------------------------------------
@pytest.mark.parametrize("duration", ["inf", "nan", "-inf"])
def test_simulate_non_finite_duration_says_so(duration, tmp_path, capsys):
    code, _, err = run_cli(
        ["simulate", "--out", tmp_path / "w.csv", "--duration", duration], capsys
    )
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert f"--duration {duration}: give the record's length as a finite number" in err
    assert "shorter" not in err


def test_simulate_outside_the_identification_prior_warns(tmp_path, capsys):
    argv = ["simulate", "--out", tmp_path / "w.csv", "--duration", "4", "--pacing", "1.8"]
    code, _, err = run_cli([*argv, "--damping-ratio", "2"], capsys)
    assert code == 0, err
    assert err.strip().splitlines() == [
        "workbench: warning: --damping-ratio 2 is outside 0.05-0.9, the prior range of "
        "'workbench identify' (--prior modal), which therefore cannot recover it from this record"
    ]
    code, _, err = run_cli(
        [*argv, "--natural-frequency-hz", "0.5", "--damping-ratio", "0.3"], capsys
    )
    assert code == 0 and "--natural-frequency-hz 0.5 is outside 1-4 Hz" in err
    code, _, err = run_cli([*argv, "--damping-ratio", "0.9"], capsys)
    assert code == 0 and "warning" not in err


@pytest.mark.parametrize(
    ("argv", "computation"),
    [
        (["sample", "--n", "3"], "workbench.population.sampler.sample_pedestrians"),
        (["simulate"], "workbench.synth.simulate.simulate_walking"),
    ],
)
def test_unwritable_out_is_found_before_the_computation(argv, computation, tmp_path, capsys):
    module, name = computation.rsplit(".", 1)
    pytest.importorskip(module)

    def never(*_, **__):
        raise AssertionError("the computation ran before --out was checked")

    monkeypatch = pytest.MonkeyPatch()
    monkeypatch.setattr(f"{module}.{name}", never)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    try:
        code, _, err = run_cli([*argv, "--out", blocker / "sub" / "x.csv"], capsys)
    finally:
        monkeypatch.undo()
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert f"--out {blocker / 'sub' / 'x.csv'}: {blocker} is a file" in err
    assert ".tmp" not in err


@pytest.mark.parametrize("command", ["batch", "population", "report", "identify", "hsi"])
def test_out_that_is_a_file_is_refused_up_front(command, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    argv = {
        "batch": ["batch", tmp_path / "absent.csv"],
        "population": ["population", tmp_path],
        "report": ["report", tmp_path],
        "identify": ["identify", tmp_path / "absent.csv"],
        "hsi": ["hsi"],
    }[command]
    code, _, err = run_cli([*argv, "--out", blocker], capsys)
    assert code == 2, err
    assert err.strip() == f"workbench: error: --out {blocker}: this is a file, not a folder; " + (
        "choose a folder you can write to"
    )


def test_a_failed_write_names_the_file_not_its_temporary_name():
    from workbench.cli.main import _written_name

    assert _written_name("/data/out/.x.csv.5u8lbaiy.tmp") == "/data/out/x.csv"
    assert _written_name("/data/out/x.csv") == "/data/out/x.csv"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["sample", "--n", "3", "--laws"], "give the population.json"),
        (["hsi", "--structure"], "give the structure's JSON file"),
    ],
)
def test_an_input_folder_is_not_told_to_be_writable(argv, message, tmp_path, capsys):
    out = ["--out", tmp_path / "s.csv"] if argv[0] == "sample" else []
    code, _, err = run_cli([*argv, tmp_path, *out], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert f"{tmp_path}, whole file: this is a folder; {message}" in err
    assert "write to" not in err


@pytest.mark.parametrize(
    ("flag", "value", "message"),
    [
        ("--walkers", "3", "'3' walkers cannot be split in two equal halves"),
        ("--walkers", "1", "'1' walkers cannot be split in two equal halves"),
        ("--ensembles", "1", "'1' is too few; the convergence check (R-hat) compares ensembles"),
    ],
)
def test_crosscheck_speaks_of_its_flags_before_any_work(flag, value, message, tmp_path, capsys):
    # The record does not exist: the option must be refused before anything is loaded.
    err = usage_error(["crosscheck", tmp_path / "absent.csv", flag, value], capsys)
    assert f"argument {flag}: {message}" in err
    assert "n_walkers" not in err and "n_ensembles" not in err


@pytest.mark.parametrize(
    "command", ["inspect", "identify", "crosscheck", "diagnose", "sensitivity"]
)
@pytest.mark.parametrize("value", ["-1", "1e-9", "5", "nan"])
def test_highpass_range_is_the_same_for_every_command(command, value, tmp_path, capsys):
    extra = ["--out", tmp_path / "o"] if command == "sensitivity" else []
    argv = [command, tmp_path / "absent.csv", *extra, "--highpass-hz", value]
    code, _, err = run_cli(argv, capsys)
    assert code == 2, err
    assert err.startswith(
        f"workbench: error: --highpass-hz {float(value):g} is outside 0.02-0.6 Hz"
    )
    assert "absent.csv" not in err  # refused before the record was looked at
    assert not (tmp_path / "o").exists()


def test_hsi_density_and_flow_together_are_refused(capsys):
    argv = ["hsi", "--crowd", "stream", "--density", "0.1", "--flow", "0.5"]
    code, _, err = run_cli(argv, capsys)
    assert code == 2
    assert "--density and --flow both set the size of the stream" in err
    assert "give one of them" in err

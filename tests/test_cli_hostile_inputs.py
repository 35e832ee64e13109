"""Hostile inputs refused in one sentence naming the file or flag and the fix (exit 2).

Each case once ended in an internal error, a silently wrong number or a flag ignored without
a word; every refusal here comes before the long computation, so the tests stay cheap.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.cli_helpers import never, refused, run_cli


# -- a settings file: a value of the wrong kind names the file and the key --------------------
@pytest.mark.parametrize(
    ("line", "key"),
    [
        ('harmonics = "ten"', "'harmonics'"),
        ("particles = 2.5", "'particles'"),
        ("force_check = 1", "'force_check'"),
        ("seed = true", "'seed'"),
    ],
)
def test_a_config_value_of_the_wrong_kind_names_the_file_and_key(line, key, tmp_path, capsys):
    config = tmp_path / "settings.toml"
    config.write_text(line + "\n", encoding="utf-8")
    err = refused(["identify", "seed_individual", "--config", config], capsys)
    assert str(config) in err and f"key {key}" in err and "write for example" in err
    assert "invalid literal" not in err


def test_a_config_value_out_of_range_names_the_key_not_a_flag(tmp_path, capsys):
    config = tmp_path / "settings.toml"
    config.write_text("harmonics = 99\n", encoding="utf-8")
    err = refused(["identify", "seed_individual", "--config", config], capsys)
    assert f"{config}, key 'harmonics'" in err and "between 1 and 40" in err
    assert "--harmonics" not in err  # the user gave no such flag


# -- results tables: nothing to fit, or records counted twice ----------------------------------
def _results(n: int = 12, seed: int = 3) -> pd.DataFrame:
    from workbench.population.sampler import sample_pedestrians

    table = sample_pedestrians(n, seed=seed).assign(path=[f"r{i:02d}.csv" for i in range(n)])
    table["identified_damping"] = True
    table["identified_stiffness"] = True
    table["identifiability"] = "well identified"
    return table


@pytest.mark.parametrize("command", ["population", "report"])
def test_a_header_only_results_table_is_refused(command, tmp_path, capsys):
    folder = tmp_path / "batch"
    folder.mkdir()
    _results().iloc[:0].to_csv(folder / "results.csv", index=False)
    err = refused([command, folder, "--out", tmp_path / "out"], capsys)
    assert "results.csv" in err and "holds no records" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", ["population", "report"])
def test_repeated_rows_are_refused_not_counted_as_new_walkers(command, tmp_path, capsys):
    folder = tmp_path / "batch"
    folder.mkdir()
    table = _results()
    pd.concat([table, table.iloc[[4]]]).to_csv(folder / "results.csv", index=False)
    err = refused([command, folder, "--out", tmp_path / "out"], capsys)
    assert "rows 5, 13 of the table" in err and "record r04.csv appears on 2 rows" in err
    assert not (tmp_path / "out").exists()


# -- hsi: flags that would give an internal error, a wrong number or be ignored ---------------
@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--at", "0"], "--at 0 m is a support or a node of every mode kept"),
        (["--at", "50"], "--at 50 m is a support or a node of every mode kept"),
        (["--comfort-limits", "nan,1,2"], "--comfort-limits nan,1,2: give three finite"),
        (["--comfort-limits", "0.5,inf,2"], "--comfort-limits 0.5,inf,2: give three finite"),
        (["--frequency", "1e6"], "--frequency 1e+06: a first mode at 1e+06 Hz needs a time step"),
        (["--frequency", "30", "--dt", "0.005"], "at most 0.00333 s"),
        (["--structure", "s.json", "--span", "3"], "--span describes the simply supported beam"),
        (["--structure", "s.json", "--modes", "2", "--width", "3"], "--modes, --width describe"),
    ],
)
def test_hsi_refuses_flags_it_cannot_honour(argv, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("workbench.hsi.montecarlo.run_monte_carlo", never)
    structure = {
        "span_m": 40,
        "frequencies_hz": [2.0],
        "damping_ratios": [0.005],
        "modal_masses_kg": [10000],
    }
    (tmp_path / "s.json").write_text(json.dumps(structure), encoding="utf-8")
    err = refused(["hsi", "--crossings", "1", *argv], capsys)
    assert message in err


def test_hsi_at_a_moving_point_and_resolved_frequency_still_run(capsys):
    # The checks above must not refuse ordinary input: a quarter point, 30 Hz at 0.003 s.
    argv = ["hsi", "--crossings", "1", "--duration", "5", "--json"]
    code, out, err = run_cli([*argv, "--at", "12.5", "--frequency", "30", "--dt", "0.003"], capsys)
    assert code == 0, err
    assert json.loads(out)["structure"]["frequencies_hz"] == [30.0]


# -- records that are no walk: every command that identifies or compares refuses them --------
def _not_a_walk(folder: Path, kind: str) -> Path:
    t = np.arange(0.0, 12.0, 0.005)
    weight = 70.0 * 9.81
    if kind == "standing":  # a person standing on the plate: weight and sensor noise
        grf = weight + 2.0 * np.random.default_rng(0).standard_normal(t.size)
    elif kind == "sine":  # a shaker at 10 Hz, far above walking's pacing
        grf = weight + 300.0 * np.sin(2 * np.pi * 10.0 * t)
    else:  # a constant force: a plate that sees nothing move
        grf = np.full(t.size, weight)
    path = folder / f"{kind}.csv"
    pd.DataFrame({"time": t, "grf": grf}).to_csv(path, index=False)
    return path


@pytest.mark.parametrize(
    ("kind", "message"),
    [
        ("standing", "far less than walking does"),
        ("sine", "outside the 0.8-3.5 Hz of walking"),
    ],
)
@pytest.mark.parametrize("command", ["compare", "diagnose"])
def test_criticism_refuses_a_record_that_is_no_walk(command, kind, message, tmp_path, capsys):
    path = _not_a_walk(tmp_path, kind)
    extra = ["--effects", "gait_asymmetry"] if command == "compare" else ["--no-one-step"]
    err = refused([command, path, "--mass", "70", *extra], capsys)
    assert str(path) in err and message in err


@pytest.mark.parametrize("kind", ["constant", "standing", "sine"])
def test_sensitivity_refuses_a_record_that_is_no_walk_before_the_study(
    kind, tmp_path, capsys, monkeypatch
):
    monkeypatch.setattr("workbench.sensitivity.study.run_sensitivity", never)
    path = _not_a_walk(tmp_path, kind)
    argv = ["sensitivity", path, "--mass", "70", "--out", tmp_path / "study"]
    err = refused([*argv, "--factors", "harmonics", "--replicates", "1"], capsys)
    assert str(path) in err
    assert not (tmp_path / "study").exists()


# -- JSON on stdout and in files: a number that does not exist is null ------------------------
def test_json_output_writes_null_for_non_finite_numbers(tmp_path, capsys):
    import argparse

    from workbench.cli.common import emit
    from workbench.fileutil import atomic_write_json

    def strict(text):  # the standard's JSON: no NaN or Infinity tokens
        return json.loads(text, parse_constant=lambda c: pytest.fail(f"bare {c} in JSON"))

    obj = {"peak": float("nan"), "limits": np.array([0.5, np.inf]), "n": np.int64(3)}
    emit(argparse.Namespace(json=True), obj, "text")
    assert strict(capsys.readouterr().out) == {"peak": None, "limits": [0.5, None], "n": 3}
    path = atomic_write_json(tmp_path / "x.json", {"slope": -np.inf, "sd": 0.25})
    assert strict(path.read_text(encoding="utf-8")) == {"slope": None, "sd": 0.25}


# -- an empty output path would write into the current folder ---------------------------------
@pytest.mark.parametrize(
    "argv",
    [
        ["demo", "--out", ""],
        ["identify", "seed_individual", "--out", ""],
        ["simulate", "--out", " "],
        ["sample", "--n", "3", "--out", ""],
        ["hsi", "--crossings", "1", "--out", ""],
        ["hsi", "--crossings", "1", "--records", ""],
    ],
)
def test_an_empty_output_path_is_refused(argv, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("workbench.hsi.montecarlo.run_monte_carlo", never)
    err = refused(argv, capsys)
    flag = "--records" if "--records" in argv else "--out"
    assert f"{flag} is empty, which would write into the current folder" in err
    assert list(tmp_path.iterdir()) == []


# -- counts checked against the budgets before anything is allocated ---------------------------
@pytest.mark.parametrize(
    ("argv", "computation", "estimate"),
    [
        (
            ["identify", "seed_individual", "--method", "rbpf", "--particles", "2e9"],
            "workbench.inference.pipeline.identification.identify",
            "--particles 2000000000 needs about 1.34e+03 GB of memory",
        ),
        (
            ["crosscheck", "seed_individual", "--walkers", "1e8"],
            "workbench.cli.common.load",
            "4 ensembles of 100000000 walkers needs about 640 GB of memory",
        ),
        (
            ["hsi", "--modes", "1e9"],
            "workbench.hsi.structure.simply_supported_beam",
            "hsi with 1000000000 modes needs about 3.2e+10 GB of memory",
        ),
        (
            ["recovery", "--records", "1e9", "--out", "rec"],
            "workbench.population.recovery.run_recovery",
            "recovery of 1000000000 records at 1 setting(s) needs about",
        ),
        (
            ["sensitivity", "seed_individual", "--replicates", "1e9", "--out", "s"],
            "workbench.sensitivity.study.run_sensitivity",
            "(25 settings x 1000000000 replicates x 1 records) needs about",
        ),
    ],
)
def test_runaway_counts_are_refused_before_any_allocation(
    argv, computation, estimate, tmp_path, capsys, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(computation, never)
    err = refused(argv, capsys)
    assert estimate in err and "add --no-limits to run it anyway" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("text", "value"), [("256", 256), ("1e6", 1_000_000), ("2E9", 2_000_000_000), ("4.0", 4)]
)
def test_counts_may_be_written_in_exponent_form(text, value):
    from workbench.cli.common import positive_int

    assert positive_int(text) == value


@pytest.mark.parametrize("text", ["1.5", "nan", "inf", "ten", "0", "-1e3"])
def test_counts_that_are_not_whole_and_positive_are_refused(text):
    import argparse

    from workbench.cli.common import positive_int

    with pytest.raises(argparse.ArgumentTypeError, match=r"whole number|at least 1"):
        positive_int(text)


def test_ordinary_counts_pass_the_count_checks():
    import argparse

    from workbench.cli.common import check_budget, check_particles
    from workbench.inference.pipeline.settings import IdentifySettings

    # A pf of 100 000 particles (25 times the seed's) is well inside the memory budget.
    args = argparse.Namespace(no_limits=False, json=True)
    check_particles(args, IdentifySettings.from_flat(method="pf", particles=100_000))
    check_budget(args, "x", "y", memory_gb=8.0 * (2.0 * 1000) ** 2 / 1e9)  # 1000 modes: 32 MB


@pytest.mark.parametrize(
    ("command", "extra", "computation"),
    [
        ("inspect", [], "workbench.records.inspection.inspect_record"),
        ("diagnose", ["--no-one-step"], "workbench.diagnostics.criticism.prepare"),
        ("compare", ["--effects", "gait_asymmetry"], "workbench.diagnostics.criticism.prepare"),
        ("crosscheck", [], "workbench.records.inspection.inspect_record"),
    ],
)
def test_every_one_record_command_checks_the_record_size(
    command, extra, computation, tmp_path, capsys, monkeypatch
):
    from workbench.cli import budgets as cli_budgets

    # As identify's guard (test_work_guards): the budget lowered so that 400 samples are over.
    monkeypatch.setattr(cli_budgets, "IDENTIFY_BASE_BYTES", 0.0)
    monkeypatch.setattr(cli_budgets, "MEMORY_BUDGET_GB", 0.001)
    monkeypatch.setattr(computation, never)
    rec = tmp_path / "walk.csv"
    t = np.arange(400) / 200.0
    pd.DataFrame({"time": t, "grf": 700 + 100 * np.sin(11 * t)}).to_csv(rec, index=False)
    err = refused([command, rec, "--mass", "70", *extra], capsys)
    assert f"{command} on walk (400 samples) needs about 0.00204 GB of memory" in err
    # --no-limits lifts it: the run reaches the computation (here a stand-in that stops it).
    _, _, err = run_cli([command, rec, "--mass", "70", *extra, "--no-limits"], capsys)
    assert "needs about" not in err and "the computation started" in err


# -- a filter's flag given to a method that ignores it: a warning, the run goes on -------------
@pytest.mark.parametrize(
    ("flags", "warnings"),
    [
        ({"particles": 500}, ["the exact method ignores --particles"]),
        ({"method": "rbpf", "force_proposal": "prior"}, ["the rbpf method ignores --force"]),
        (
            {"particles": 500, "force_proposal": "prior"},
            ["ignores --particles", "ignores --force-proposal"],
        ),
        ({"method": "pf", "particles": 500, "force_proposal": "prior"}, []),
        ({"method": "rbpf", "particles": 500}, []),
    ],
)
def test_flags_the_method_ignores_are_warned_about(flags, warnings, capsys):
    import argparse

    from workbench.cli.common import identify_settings

    settings = identify_settings(argparse.Namespace(record="walk.csv", **flags))
    err = capsys.readouterr().err
    assert settings.method.name == flags.get("method", "exact")
    assert len(err.strip().splitlines()) == len(warnings), err
    for warning in warnings:
        assert f"workbench: warning: {warning}" in err or warning in err


# -- laws and recovery results that would put numbers on nothing -------------------------------
def test_laws_with_an_implausible_scatter_are_refused_naming_the_key(tmp_path, capsys):
    from workbench.population.laws import PopulationLaws

    laws = PopulationLaws().to_json()
    laws["laws"]["natural_frequency_hz"]["residual_sd"] = 1e6
    path = tmp_path / "laws.json"
    path.write_text(json.dumps(laws), encoding="utf-8")
    err = refused(["sample", "--laws", path, "--n", "3", "--out", tmp_path / "p.csv"], capsys)
    assert str(path) in err and "laws.natural_frequency_hz.residual_sd = 1e+06" in err
    assert not (tmp_path / "p.csv").exists()
    # The seed's own laws, and a scatter ten times theirs, still read.
    laws["laws"]["natural_frequency_hz"]["residual_sd"] = 1.5
    assert PopulationLaws.from_json(laws).natural_frequency_hz.residual_sd == 1.5


def _recovery(slope: str) -> str:
    law = '{"slope": %s, "intercept": 1.4, "residual_sd": 0.15}'
    return (
        '{"truth": {"laws": {"natural_frequency_hz": '
        + law % slope
        + ', "damping_ratio": '
        + law % "-0.2"
        + '}}, "recovered": {}, "verdict": {"pipeline": {"natural_frequency_hz": '
        '{"slope": "recovered"}}}}'
    )


@pytest.mark.parametrize(
    ("slope", "message"),
    [
        ("NaN", "NaN is not a number JSON allows"),
        ("null", "key truth.laws.natural_frequency_hz.slope: the true value None"),
        ('"0.3"', "key truth.laws.natural_frequency_hz.slope: the true value '0.3'"),
    ],
)
def test_a_recovery_with_no_true_slope_is_refused_not_reported_recovered(slope, message, tmp_path):
    from workbench.errors import InputError
    from workbench.reporting.recovery import read_recovery

    path = tmp_path / "recovery.json"
    path.write_text(_recovery(slope), encoding="utf-8")
    with pytest.raises(InputError, match=r"recovery\.json") as err:
        read_recovery(tmp_path)
    assert message in str(err.value)
    path.write_text(_recovery("0.3"), encoding="utf-8")
    assert read_recovery(tmp_path)["truth"]["laws"]["natural_frequency_hz"]["slope"] == 0.3


# -- one record under several spellings in a manifest is identified once ----------------------
@pytest.mark.parametrize("spelling", ["./r1.csv", "sub/up/r1.csv", "sub/../r1.csv"])
def test_a_manifest_naming_one_record_twice_is_refused(spelling, tmp_path, capsys, monkeypatch):
    from workbench.records.manifest import load_manifest

    (tmp_path / "r1.csv").write_text("time,grf\n0,700\n", encoding="utf-8")
    (tmp_path / "r2.csv").write_text("time,grf\n0,700\n", encoding="utf-8")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "up").symlink_to("..")  # a link back to the manifest's folder
    manifest = tmp_path / "manifest.csv"
    manifest.write_text(f"path\nr1.csv\nr2.csv\n{spelling}\n", encoding="utf-8")
    monkeypatch.setattr("workbench.inference.pipeline.identification.identify", never)
    err = refused(["batch", manifest, "--out", tmp_path / "out"], capsys)
    assert f"{manifest}, line 4, column 'path'" in err
    assert f"the record '{spelling}' is the file 'r1.csv' of line 2" in err
    # Distinct files, one of them missing (a failure of its row later), still load.
    manifest.write_text("path\nr1.csv\nr2.csv\nmissing.csv\n", encoding="utf-8")
    assert [e.path.name for e in load_manifest(manifest)] == ["r1.csv", "r2.csv", "missing.csv"]


# -- an input path that cannot be read is named as an input, not blamed on --out --------------
@pytest.mark.parametrize(
    "argv",
    [
        ["identify", "seed_individual", "--config", "{folder}"],
        ["hsi", "--crossings", "1", "--pedestrians", "{folder}"],
        ["hsi", "--crossings", "1", "--structure", "{folder}"],
        ["hsi", "--crossings", "1", "--laws", "{folder}"],
    ],
)
def test_a_folder_given_as_an_input_file_is_named_as_such(argv, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("workbench.hsi.montecarlo.run_monte_carlo", never)
    folder = tmp_path / "inputs"
    folder.mkdir()
    err = refused([a.format(folder=folder) for a in argv], capsys)
    assert f"{folder}, whole file: this is a folder" in err
    assert "choose a folder you can write to" not in err


def test_crosscheck_time_is_estimated_from_the_steps_and_walkers(capsys, monkeypatch):
    from workbench.cli import budgets as cli_budgets

    monkeypatch.setattr(cli_budgets, "TIME_BUDGET_MIN", 0.1)  # 6 s
    monkeypatch.setattr("workbench.inference.pipeline.identification.identify", never)
    # Two steps (about 235 samples) with 4 x 32 walkers: about 4.5 s, under; 2 x 1000: 70 s.
    argv = ["crosscheck", "seed_individual", "--max-steps", "2"]
    _, _, err = run_cli(argv, capsys)
    assert "the computation started" in err
    err = refused([*argv, "--ensembles", "2", "--walkers", "1000"], capsys)
    assert "crosscheck of 2 steps of seed_individual with 2000 walkers in all" in err

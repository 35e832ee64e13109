"""Flags every record-reading command shares: --allow-negative-force; --seed of criticism."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.cli import build_parser, main
from workbench.errors import InputError
from workbench.records.io import load_record, save_record
from workbench.records.validation import NEGATIVE_FORCE_ACCEPTED

G = 9.81

#: Every subcommand that reads records, with the arguments it needs besides the record.
RECORD_COMMANDS = {
    "inspect": [],
    "identify": [],
    "crosscheck": [],
    "diagnose": [],
    "compare": ["--effects", "heel_impact"],
    "batch": ["--out", "somewhere"],
    "sensitivity": ["--out", "somewhere"],
}


def negative_force_record(path: Path, mass: float = 70.0) -> Path:
    """A walking-like benchmark force that dips to about -10 % of body weight every step."""
    t = np.arange(0.0, 12.0, 1.0 / 200.0)
    w = 2 * np.pi * 1.8 * t
    grf = mass * G * (1 + 1.1 * np.sin(w) + 0.05 * np.sin(2 * w + 1.0))
    rows = [f"{float(a)!r},{float(b)!r}" for a, b in zip(t, grf, strict=True)]
    path.write_text("time,grf\n" + "\n".join(rows) + "\n")
    path.with_suffix(".json").write_text(json.dumps({"mass_kg": mass}))
    return path


def run_cli(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("command", sorted(RECORD_COMMANDS))
def test_every_record_command_accepts_allow_negative_force(command):
    args = build_parser().parse_args(
        [command, "rec.csv", *RECORD_COMMANDS[command], "--allow-negative-force"]
    )
    assert args.allow_negative_force is True
    default = build_parser().parse_args([command, "rec.csv", *RECORD_COMMANDS[command]])
    assert default.allow_negative_force is False


def test_negative_force_is_refused_without_the_flag(tmp_path, capsys):
    path = negative_force_record(tmp_path / "benchmark.csv")
    code, out, err = run_cli(["inspect", path], capsys)
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("workbench: error: ")
    assert "benchmark.csv" in lines[0]
    assert "push" in lines[0]
    assert "--allow-negative-force" in lines[0]


def test_negative_force_passes_with_the_flag_as_a_warning(tmp_path, capsys):
    path = negative_force_record(tmp_path / "benchmark.csv")
    code, out, err = run_cli(["inspect", path, "--allow-negative-force", "--json"], capsys)
    assert code == 0, err
    obj = json.loads(out)
    assert obj["steps"] >= 3
    accepted = [w for w in obj["warnings"] if NEGATIVE_FORCE_ACCEPTED in w]
    assert len(accepted) == 1
    assert "benchmark.csv" in accepted[0]
    assert "warning" in err and NEGATIVE_FORCE_ACCEPTED in err


def test_negative_force_keyword_of_the_loader(tmp_path):
    path = negative_force_record(tmp_path / "benchmark.csv")
    with pytest.raises(InputError, match="allow-negative-force"):
        load_record(path)
    record = load_record(path, allow_negative_force=True)
    assert float(np.min(record.grf_n)) < 0.0
    assert any(NEGATIVE_FORCE_ACCEPTED in w for w in record.metadata["warnings"])


def test_negative_force_flag_reaches_identify(tmp_path, capsys):
    path = negative_force_record(tmp_path / "benchmark.csv")
    code, _, err = run_cli(["identify", path, "--method", "exact", "--json"], capsys)
    assert code == 2 and "--allow-negative-force" in err
    code, out, err = run_cli(
        ["identify", path, "--method", "exact", "--json", "--allow-negative-force"], capsys
    )
    assert code == 0, err
    assert "stiffness_n_per_m" in json.dumps(json.loads(out))
    assert NEGATIVE_FORCE_ACCEPTED in err


# -- --seed of diagnose and compare -----------------------------------------------------------
@pytest.fixture(scope="module")
def walk(tmp_path_factory) -> Path:
    from workbench.synth.simulate import simulate_walking

    sim = simulate_walking(mass_kg=70.0, pacing_hz=1.8, duration_s=12.0, seed=4)
    path = tmp_path_factory.mktemp("seed") / "walk.csv"
    save_record(sim.record, path)
    return path


def test_diagnose_seed_is_accepted_and_reproducible(walk, capsys):
    code, first, err = run_cli(["diagnose", walk, "--seed", "3", "--json"], capsys)
    assert code == 0, err
    code, second, err = run_cli(["diagnose", walk, "--seed", "3", "--json"], capsys)
    assert code == 0, err
    assert json.loads(first) == json.loads(second)
    assert "posterior_predictive" in json.loads(first)


def test_compare_seed_is_accepted_and_reproducible(walk, capsys):
    argv = ["compare", walk, "--effects", "heel_impact", "--json"]
    code, first, err = run_cli([*argv, "--seed", "5"], capsys)
    assert code == 0, err
    code, second, err = run_cli([*argv, "--seed", "5"], capsys)
    assert code == 0, err
    assert json.loads(first) == json.loads(second)
    # compare's cross-validation draws nothing random: the seed does not change it.
    code, default, err = run_cli(argv, capsys)
    assert code == 0, err
    assert json.loads(default) == json.loads(first)


def test_criticism_seed_defaults_to_zero():
    for command, extra in (("diagnose", []), ("compare", ["--effects", "heel_impact"])):
        assert build_parser().parse_args([command, "rec.csv", *extra]).seed == 0


# -- the demo's warnings ----------------------------------------------------------------------
def test_demo_warnings_name_the_record_once():
    from workbench.datasets import embedded_path
    from workbench.demo import warning_bullets
    from workbench.records.inspection import inspect_record

    # As the demo loads it: the label is the subject, so inspection warnings start with it.
    record = load_record(embedded_path("insole"), mass_kg=83.0, subject="insole")
    insp = inspect_record(record)
    assert any(w.startswith("insole: ") for w in insp.warnings)
    bullets = warning_bullets([("insole", insp)])
    assert len(bullets) == len(insp.warnings)
    assert all(b.startswith("insole: ") for b in bullets)
    assert not any(b.startswith("insole: insole: ") for b in bullets)


def test_library_errors_name_the_parameter_and_the_command_line_the_flag(tmp_path, capsys):
    from workbench.errors import UsageError
    from workbench.population.batch import run_batch
    from workbench.sensitivity.design import parse_factors

    # A Python caller reads the parameter of the function it called ...
    with pytest.raises(UsageError, match=r"^'factors': 'bogus' is not a sensitivity factor"):
        parse_factors("obs_noise_ddu,bogus")
    with pytest.raises(UsageError, match=r"^'workers' must be at least 1, got 0") as err:
        run_batch(tmp_path / "manifest.csv", tmp_path / "out", workers=0)
    assert "--" not in str(err.value)
    # ... and the same mistake on the command line reads the flag.
    argv = ["sensitivity", tmp_path / "rec.csv", "--out", tmp_path / "s", "--factors", "bogus"]
    code, _, err_text = run_cli(argv, capsys)
    assert code == 2 and "--factors: 'bogus' is not a sensitivity factor" in err_text
    assert "'factors'" not in err_text
    argv = ["batch", tmp_path / "manifest.csv", "--out", tmp_path / "b", "--workers", "0"]
    code, _, err_text = run_cli(argv, capsys)
    assert code == 2 and "--workers must be at least 1, got 0" in err_text
    assert "'workers'" not in err_text

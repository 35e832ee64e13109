"""Work guards: runaway inputs are refused up front with their estimate and ``--no-limits``.

Each guard is exercised on a small input with the budget lowered in-process, so the refused
run and the lifted one both stay cheap; the estimates themselves are checked on the inputs
that once ran away (nothing is run for those: the refusal comes before any work).
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.cli_helpers import run_cli
from workbench.cli import budgets as cli_budgets
from workbench.errors import UsageError, check_seed
from workbench.inference.pipeline.settings import IdentifySettings


def refused(argv, capsys) -> str:
    code, _, err = run_cli(argv, capsys)
    assert code == 2, err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    assert "add --no-limits to run it anyway" in err
    return err


# -- the inputs of the issue, refused by their estimates at the shipped budgets ----------------
@pytest.mark.parametrize(
    ("argv", "estimate"),
    [
        (["hsi", "--modes", "1000"], "min of computing, over the 30 min budget"),
        (["hsi", "--crowd", "stream", "--density", "100"], "GB of memory, over the 2 GB budget"),
        (["sample", "--n", "10000000", "--out", "p.csv"], "GB of memory, over the 2 GB budget"),
    ],
)
def test_runaway_inputs_are_refused_before_any_work(argv, estimate, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)

    def never(*_, **__):
        raise AssertionError("the computation started")

    monkeypatch.setattr("workbench.hsi.montecarlo.run_monte_carlo", never)
    monkeypatch.setattr("workbench.population.sampler.sample_pedestrians", never)
    err = refused(argv, capsys)
    assert estimate in err
    assert list(tmp_path.iterdir()) == []


def test_identify_on_a_ten_million_sample_record_is_estimated_over_the_budget():
    from workbench.cli.common import IDENTIFY_BASE_BYTES, IDENTIFY_BYTES_PER_SAMPLE

    # The estimate grows with the record: a 10 M-row record is far over 2 GB, a minute of
    # 1 kHz walking far under.
    assert (IDENTIFY_BASE_BYTES + IDENTIFY_BYTES_PER_SAMPLE * 10_000_000) / 1e9 > 20
    assert (IDENTIFY_BASE_BYTES + IDENTIFY_BYTES_PER_SAMPLE * 60_000) / 1e9 < 1


# -- each guard on a small input, the budget lowered; --no-limits lifts it ---------------------
def test_sample_guard_and_no_limits(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cli_budgets, "MEMORY_BUDGET_GB", 0.1)  # below the interpreter's share
    out = tmp_path / "p.csv"
    err = refused(["sample", "--n", "5", "--out", out], capsys)
    assert "sample --n 5 needs about 0.14 GB of memory, over the 0.1 GB budget" in err
    assert not out.exists()
    code, _, err = run_cli(["sample", "--n", "5", "--out", out, "--no-limits"], capsys)
    assert code == 0, err
    assert len(out.read_text().splitlines()) == 6


def test_hsi_memory_guard_grows_with_the_stream(capsys, monkeypatch):
    monkeypatch.setattr(cli_budgets, "MEMORY_BUDGET_GB", 0.3)
    small = ["hsi", "--crowd", "stream", "--duration", "2", "--crossings", "1", "--json"]
    # 0.5 P/m^2 fits in 0.3 GB; 20 P/m^2 (a 4000-unknown eigen-analysis) does not.
    code, _, err = run_cli([*small, "--density", "0.5"], capsys)
    assert code == 0, err
    err = refused([*small, "--density", "20"], capsys)
    assert "hsi with a stream of 20 P/m^2 over 2 s, 1 mode(s) and 1 crossing(s)" in err
    assert "over the 0.3 GB budget" in err


def test_hsi_time_guard_grows_with_the_modes_and_no_limits_lifts_it(capsys, monkeypatch):
    monkeypatch.setattr(cli_budgets, "TIME_BUDGET_MIN", 1e-4)  # 6 ms
    argv = ["hsi", "--crossings", "1", "--span", "5", "--json"]
    code, _, err = run_cli([*argv, "--modes", "1"], capsys)  # 1 mode: about 0.3 ms
    assert code == 0, err
    err = refused([*argv, "--modes", "40"], capsys)  # 40 modes: about 20 ms
    assert "40 mode(s) and 1 crossing(s)" in err and "over the 0.0001 min budget" in err
    code, _, err = run_cli([*argv, "--modes", "40", "--no-limits"], capsys)
    assert code == 0, err


def test_identify_guard_uses_the_record_length(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cli_budgets, "IDENTIFY_BASE_BYTES", 0.0)
    monkeypatch.setattr(cli_budgets, "MEMORY_BUDGET_GB", 0.001)  # 1 MB: under 200 samples
    rec = tmp_path / "walk.csv"
    t = np.arange(400) / 200.0
    rec.write_text("time,grf\n" + "".join(f"{x:.3f},{700 + 100 * np.sin(11 * x):.3f}\n" for x in t))

    def never(*_, **__):
        raise AssertionError("the identification started")

    monkeypatch.setattr("workbench.inference.pipeline.identification.identify", never)
    err = refused(["identify", rec, "--mass", "70"], capsys)
    assert "identify on walk (400 samples) needs about 0.00204 GB of memory" in err


def test_long_work_that_goes_ahead_says_so_from_its_start(capsys):
    import argparse

    args = argparse.Namespace(no_limits=False, json=False)
    cli_budgets.check_budget(args, "hsi with 5 mode(s)", "fix", memory_gb=0.2, minutes=3)
    assert capsys.readouterr().err == "workbench: hsi with 5 mode(s): about 3 min estimated\n"
    cli_budgets.check_budget(args, "quick", "fix", minutes=0.5)
    assert capsys.readouterr().err == ""


def test_no_limits_is_documented():
    from pathlib import Path

    contracts = (Path(__file__).resolve().parents[1] / "docs" / "contracts.md").read_text()
    assert "--no-limits" in contracts


# -- seeds given to the Python API --------------------------------------------------------------
@pytest.mark.parametrize("seed", [-1, 1.5, True, "3"])
def test_public_functions_refuse_a_bad_seed_in_one_sentence(seed):
    from workbench.hsi.montecarlo import CrossingSpec, run_monte_carlo
    from workbench.hsi.structure import simply_supported_beam
    from workbench.population.sampler import sample_pedestrians
    from workbench.population.study import study_plan

    spec = CrossingSpec(simply_supported_beam(50, 500, 2, 0.005), sample_pedestrians)
    for call, name in (
        (lambda: sample_pedestrians(3, seed=seed), "sample_pedestrians: "),
        (lambda: study_plan(seed=seed), "study_plan: "),
        (lambda: run_monte_carlo(spec, 1, seed=seed), "run_monte_carlo: "),
        (lambda: IdentifySettings(seed=seed), ""),
    ):
        with pytest.raises(UsageError, match=rf"^{name}'seed' must be a whole number of 0 or"):
            call()


def test_the_seed_check_takes_numpy_integers():
    assert check_seed(np.int64(7)) == 7
    assert type(check_seed(np.uint32(7))) is int

"""A cohort crossing a footbridge again and again: the two levels of spread the hierarchical
population model fits are those drawn (between walkers the laws' residual sds, within a
walker the crossing spread), one crossing's pedestrians are distinct people, and the records
of ``workbench hsi --cohort`` group by walker."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from workbench import load_record
from workbench.errors import UsageError
from workbench.hsi.pedestrians import validate_pedestrians
from workbench.population.cohort import CohortSampler, draw_cohort, walker_name
from workbench.population.laws import PopulationLaws
from workbench.population.recovery_design import CROSSING_PACING_SD_HZ, CROSSING_SD
from workbench.records.manifest import load_manifest

LAWS = PopulationLaws()


def _sd_band(sd: float, n: int) -> float:
    """Four standard errors of a sample sd of n normal draws (se ~ sd / sqrt(2 (n - 1)))."""
    return 4.0 * sd / math.sqrt(2.0 * (n - 1))


def test_walkers_differ_by_the_laws_residual_sds() -> None:
    cohort = draw_cohort(4000, seed=1)
    assert list(cohort["walker_id"]) == list(range(4000))
    for law in ("natural_frequency_hz", "damping_ratio", "blf1"):
        sd = getattr(LAWS, law).residual_sd
        got = cohort[f"{law}_offset"].std(ddof=1)
        assert abs(got - sd) < _sd_band(sd, len(cohort)), law
    for law in ("blf2", "blf3"):
        lognormal = getattr(LAWS, law)
        logs = np.log(cohort[f"{law}_median"])
        # Mean of n normal draws: four standard errors.
        assert abs(logs.mean() - lognormal.mu) < 4 * lognormal.sigma / math.sqrt(len(cohort))
        assert abs(logs.std(ddof=1) - lognormal.sigma) < _sd_band(lognormal.sigma, len(cohort))
    pd.testing.assert_frame_equal(draw_cohort(50, seed=1), draw_cohort(50, seed=1))
    with pytest.raises(UsageError, match="at least 1"):
        draw_cohort(0, seed=1)


def test_a_walkers_crossings_spread_by_the_crossing_sd() -> None:
    sampler = CohortSampler.from_laws(1, seed=2)
    (walker,) = sampler.cohort.itertuples(index=False)
    table = pd.concat([sampler(40, seed=s) for s in range(50)], ignore_index=True)
    validate_pedestrians(table)  # the simulator's contract
    assert set(table["walker_id"]) == {0}
    assert (table["mass_kg"] == walker.mass_kg).all()
    n = len(table)
    # The pacing is truncated to the laws' pacing range: the truncated normal's exact sd.
    p, mean = LAWS.pacing, walker.mean_pacing_hz
    lo, hi = ((b - mean) / CROSSING_PACING_SD_HZ for b in (p.low_hz, p.high_hz))
    exact = stats.truncnorm(lo, hi, loc=mean, scale=CROSSING_PACING_SD_HZ).std()
    assert abs(table["pacing_hz"].std(ddof=1) - exact) < _sd_band(CROSSING_PACING_SD_HZ, n)
    for law in ("natural_frequency_hz", "damping_ratio", "blf1"):
        own = getattr(LAWS, law).mean(table["pacing_hz"]) + getattr(walker, f"{law}_offset")
        spread = table[law] - own
        sd = CROSSING_SD[law]
        assert abs(spread.mean()) < 4 * sd / math.sqrt(n), law
        assert abs(spread.std(ddof=1) - sd) < _sd_band(sd, n), law
    for law in ("blf2", "blf3"):
        logs = np.log(table[law] / getattr(walker, f"{law}_median"))
        assert abs(logs.std(ddof=1) - CROSSING_SD[law]) < _sd_band(CROSSING_SD[law], n)


def test_a_crossings_pedestrians_are_distinct_while_the_cohort_lasts() -> None:
    sampler = CohortSampler.from_laws(7, seed=3)
    for seed in range(5):
        ids = sampler(7, seed=seed)["walker_id"].to_numpy()
        assert sorted(ids) == list(range(7))
        ids = sampler(16, seed=seed)["walker_id"].to_numpy()
        assert sorted(ids[:7]) == sorted(ids[7:14]) == list(range(7))
    pd.testing.assert_frame_equal(sampler(9, seed=4), sampler(9, seed=4))


def test_cli_cohort_records_group_by_walker(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from workbench.cli import main

    out = tmp_path / "recs"
    args = ["hsi", "--span", "20", "--dt", "0.01", "--seed", "5", "--crowd", "stream"]
    args += ["--flow", "0.4", "--duration", "15", "--crossings", "3", "--cohort", "4"]
    assert main([*args, "--records", str(out), "--records-crossings", "3", "--json"]) == 0
    json.loads(capsys.readouterr().out)
    entries = load_manifest(out / "manifest.csv")
    truth = pd.read_csv(out / "truth.csv")
    assert len(entries) == len(truth) >= 6
    subjects = [e.subject for e in entries]
    assert set(subjects) <= {walker_name(i) for i in range(4)}
    # Each person crossed more than once, and their files are named by crossing and place.
    assert max(subjects.count(s) for s in set(subjects)) >= 2
    for e, row in zip(entries, truth.itertuples(index=False), strict=True):
        assert e.path.stem == f"crossing{row.crossing:04d}_walker{row.walker:03d}"
        assert e.subject == walker_name(row.walker_id) == row.subject
    # One walker's records share the walker's body mass: the same person.
    assert (truth.groupby("subject")["mass_kg"].nunique() == 1).all()
    with pytest.raises(SystemExit):
        main(["hsi", "--cohort", "0"])
    assert main(["hsi", "--cohort", "3", "--pedestrians", str(out / "truth.csv")]) != 0
    assert "--cohort draws its walkers from the laws" in capsys.readouterr().err


def test_the_footbridge_study_keeps_whole_crossings_only(tmp_path: Path) -> None:
    """Walkers caught at a stream window's edge are skipped with the reason, not written as
    fragments a batch cannot identify; the rest load with their walker as subject."""
    from workbench.hsi.cohort_study import footbridge_cohort_records

    written = footbridge_cohort_records(
        tmp_path / "study", walkers=6, crossings=2, seed=4, duration_s=30.0, min_record_s=12.0
    )
    entries = load_manifest(tmp_path / "study" / "manifest.csv")
    assert len(entries) == len(written.records) >= 3
    assert written.skipped, "a 30 s window always cuts some walker short"
    for e in entries:
        assert load_record(e.path).duration_s >= 12.0
        assert e.subject in {walker_name(i) for i in range(6)}
    assert all("shorter than the study's 12 s" in s["reason"] for s in written.skipped)

"""Population laws: OLS, normality tests, lognormal fits, exclusion, and the synthetic study."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from workbench.cli import main
from workbench.errors import UsageError
from workbench.population.batch import run_batch
from workbench.population.fit import fit_population
from workbench.population.laws import PopulationLaws
from workbench.population.sampler import sample_pedestrians
from workbench.population.study import STUDY_SETTINGS, StudyDesign, study_plan, write_study


def _table(n, seed, **overrides):
    peds = sample_pedestrians(n, seed=seed)
    table = peds.rename(columns={}).assign(path=[f"r{i:04d}.csv" for i in range(n)])
    table["identified_damping"] = True
    table["identified_stiffness"] = True
    table["identifiability"] = "well identified"
    for k, v in overrides.items():
        table[k] = v
    return table


def test_fit_recovers_sampled_laws():
    fit = fit_population(_table(3000, seed=2))
    laws = PopulationLaws()
    s = fit.population_json
    for key in ("natural_frequency_hz", "damping_ratio", "blf1"):
        law, true = s["laws"][key], getattr(laws, key)
        assert law["slope_ci"][0] < true.slope < law["slope_ci"][1]
        assert law["intercept_ci"][0] < true.intercept < law["intercept_ci"][1]
        assert law["residual_sd"] == pytest.approx(true.residual_sd, rel=0.05)
        # Normal residuals: neither test rejects.
        assert law["residuals"]["normal_at_5pct"]
    for key in ("blf2", "blf3"):
        ln, true = s["lognormal"][key], getattr(laws, key)
        assert ln["mu_ci"][0] < true.mu < ln["mu_ci"][1]
        assert ln["sigma_ci"][0] < true.sigma < ln["sigma_ci"][1]
        assert ln["preferred_by_aic"] == "lognormal"
        assert ln["ks_p"] > 0.05
    # Bands: prediction band contains the confidence band, and about 95 % of the records.
    b = fit.bands[fit.bands.law == "natural_frequency_hz"]
    assert (b.pi_low < b.ci_low).all() and (b.ci_high < b.pi_high).all()
    r = fit.used["natural_frequency_hz_residual"]
    z = np.abs(r) / s["laws"]["natural_frequency_hz"]["residual_sd"]
    assert 0.93 < np.mean(z < 1.96) < 0.97
    assert s["records_used"] == 3000 and s["records_excluded"] == 0
    json.dumps(s, allow_nan=False)


def test_normality_tests_reject_skewed_residuals():
    rng = np.random.default_rng(5)
    table = _table(600, seed=3)
    table["natural_frequency_hz"] = 0.3 * table.pacing_hz + 1.4 + rng.exponential(0.1, 600)
    law = fit_population(table).population_json["laws"]["natural_frequency_hz"]
    assert law["residuals"]["shapiro_p"] < 0.01
    assert law["residuals"]["anderson_darling_p"] < 0.01
    assert not law["residuals"]["normal_at_5pct"]


def test_gev_preferred_when_data_are_gev():
    from scipy import stats

    table = _table(2000, seed=4)
    table["blf2"] = stats.genextreme.rvs(0.3, loc=0.06, scale=0.01, size=2000, random_state=1)
    table = table[table.blf2 > 0]
    assert fit_population(table).population_json["lognormal"]["blf2"]["preferred_by_aic"] == "gev"


def test_not_identified_and_nan_records_are_excluded():
    table = _table(40, seed=6)
    table.loc[:4, "identified_stiffness"] = False
    table.loc[:4, "natural_frequency_hz"] = 9.0  # a prior corner: must not enter the fit
    table.loc[5, "blf2"] = np.nan
    fit = fit_population(table)
    assert fit.population_json["records_used"] == 34
    assert fit.population_json["records_excluded"] == 6
    assert sorted(fit.excluded.path) == [f"r{i:04d}.csv" for i in range(6)]
    assert "not identified" in fit.excluded.reason.iloc[0]
    assert fit.population_json["laws"]["natural_frequency_hz"]["residual_sd"] < 0.3
    kept = fit_population(table, keep_not_identified=True)
    assert kept.population_json["records_used"] == 39
    with pytest.raises(UsageError, match="fewer than"):
        fit_population(table.iloc[:8])
    with pytest.raises(UsageError, match="blf3"):
        fit_population(table.drop(columns=["blf3"]))


def test_population_cli(tmp_path, capsys):
    batch = tmp_path / "batch"
    batch.mkdir()
    _table(200, seed=8).to_csv(batch / "results.csv", index=False)
    assert main(["population", str(batch), "--out", str(tmp_path / "pop"), "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    for key in ("natural_frequency_hz", "damping_ratio", "blf1"):
        law = obj["laws"][key]
        assert {"slope", "intercept", "slope_ci", "intercept_ci", "residual_sd"} <= set(law)
        assert len(law["slope_ci"]) == len(law["intercept_ci"]) == 2
    assert {"mu", "sigma"} <= set(obj["lognormal"]["blf2"]) and "blf3" in obj["lognormal"]
    assert obj["records_used"] == 200 and obj["records_excluded"] == 0
    written = json.loads((tmp_path / "pop" / "population.json").read_text())
    laws = PopulationLaws.from_json(written)
    assert laws.blf2.mu == pytest.approx(obj["lognormal"]["blf2"]["mu"])
    assert main(["population", str(tmp_path / "nothing"), "--out", str(tmp_path / "x")]) == 2
    assert "results.csv" in capsys.readouterr().err


@pytest.mark.slow
def test_synthetic_study_recovers_generating_laws(tmp_path):
    """End to end: generate a reduced study, identify it in batch, fit, cover the truth."""
    design = StudyDesign(n_male=5, n_female=3, n_records=None, duration_s=3.0)
    plan = study_plan(design, seed=2026)
    assert len(plan) == 8 * 11
    manifest = write_study(plan, tmp_path / "study", design)
    from workbench.inference.pipeline.settings import IdentifySettings

    settings = IdentifySettings.from_flat(**STUDY_SETTINGS, particles=16, force_check=False, seed=1)
    summary = run_batch(manifest, tmp_path / "batch", settings=settings, workers=2)
    assert summary.failed == 0
    results = pd.read_csv(summary.results_csv)
    fit = fit_population(results).to_json()
    assert fit["records_excluded"] == 0
    laws = PopulationLaws()
    for key in ("natural_frequency_hz", "damping_ratio", "blf1"):
        law, true = fit["laws"][key], getattr(laws, key)
        assert law["slope_ci"][0] < true.slope < law["slope_ci"][1], key
        assert law["intercept_ci"][0] < true.intercept < law["intercept_ci"][1], key
    for key in ("blf2", "blf3"):
        ln, true = fit["lognormal"][key], getattr(laws, key)
        assert ln["mu_ci"][0] < true.mu < ln["mu_ci"][1], key
        assert ln["sigma_ci"][0] < true.sigma < ln["sigma_ci"][1], key
    # The identification is precise enough not to blur the laws: per-record f_n errors
    # are small against the population's residual sd.
    truth = plan.assign(path="records/" + plan.record + ".csv").set_index("path")
    err = results.set_index("path").natural_frequency_hz - truth.natural_frequency_hz
    assert err.abs().max() < 0.5 * laws.natural_frequency_hz.residual_sd


def test_records_identified_through_a_deck_are_counted_and_reported(tmp_path):
    from types import SimpleNamespace

    from workbench.reporting.population import population_report
    from workbench.result_rows import c_and_k_source

    kinds = ["deck transmissibility"] * 30 + ["time history, rigid floor"] * 20
    table = _table(50, seed=4, c_and_k_from=kinds)
    table.loc[0, "identified_stiffness"] = False  # one deck record not used
    fit = fit_population(table)
    assert fit.population_json["records_through_surface"] == 29
    assert "29 with C and K from a deck's transmissibility" in fit.summary()
    files = population_report(table, fit, tmp_path)
    text = Path(files["markdown"]).read_text(encoding="utf-8")
    assert "30 deck transmissibility, 20 time history, rigid floor" in text
    assert "29 of the 49 records in the fits were identified through the deck" in text

    # Where a result row says C and K came from.
    from workbench.inference.core import SurfaceReport

    def result(surface):
        report = None if surface is None else SurfaceReport(sentence="", **surface)
        return SimpleNamespace(surface=report)

    assert c_and_k_source(result({"model": "coupled", "c_and_k_from": "transmissibility"})) == (
        "deck transmissibility"
    )
    assert c_and_k_source(result({"model": "coupled", "c_and_k_from": "time history"})) == (
        "time history, surface coupled"
    )
    assert c_and_k_source(result({"model": "ignored (rigid floor)"})) == (
        "time history, surface ignored"
    )
    assert c_and_k_source(result({"model": "rigid floor (no ground_acc)"})) == (
        "time history, rigid floor"
    )
    assert c_and_k_source(result(None)) == "time history, rigid floor"

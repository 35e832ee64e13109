"""The population report with the hierarchical laws beside the two-stage OLS, and the
recovery that judges both fits.

The fast tests build a hierarchical fit from known draws (so that the report's numbers can
be recomputed here from the draws); the slow ones run the batch, the fits and
``workbench report`` on a small deck batch whose records keep their posteriors.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from workbench.population.batch_hierarchy import BatchLaws
from workbench.population.fit import fit_population
from workbench.population.hierarchy import HierarchicalFit, _parameter_names
from workbench.population.recovery import (
    LINEAR_LAWS,
    _hierarchical_recovered,
    hierarchical_verdicts,
    truth_laws,
)
from workbench.population.recovery_text import NOT_RUN, recovery_text
from workbench.population.sampler import sample_pedestrians
from workbench.population.walker import WalkerFit
from workbench.reporting.population import SEED_TABLE2, population_report, table2_rows
from workbench.reporting.recovery import read_recovery, recovery_conclusions, recovery_section

# The law values the synthetic posteriors are centred on: (law, parameter) -> (mean, sd).
CENTRES = {
    "slope": {"natural_frequency_hz": (0.31, 0.05), "damping_ratio": (-0.2, 0.03),
              "blf1": (0.41, 0.02)},
    "intercept_at_ref": {"natural_frequency_hz": (1.92, 0.02), "damping_ratio": (0.49, 0.01),
                         "blf1": (0.35, 0.01)},
    "mu": {"blf2": (-2.9, 0.05), "blf3": (-3.0, 0.05)},
    "residual_sd": {"natural_frequency_hz": (0.15, 0.02), "damping_ratio": (0.05, 0.005),
                    "blf1": (0.05, 0.005), "blf2": (0.4, 0.04), "blf3": (0.4, 0.04)},
    "walker_sd": {law: (0.05, 0.01) for law in
                  ("natural_frequency_hz", "damping_ratio", "blf1", "blf2", "blf3")},
}  # fmt: skip


def _fit(seed: int, *, effects: bool = False, records: int = 40, walkers: int = 40):
    """A HierarchicalFit of normal draws about :data:`CENTRES` (intercept derived per draw)."""
    rng = np.random.default_rng(seed)
    names = _parameter_names(effects)
    draws = np.empty((2, 500, len(names)))
    for i, name in enumerate(names):
        law, par = name.split(".")
        if par == "intercept":
            continue
        mean, sd = CENTRES[par][law]
        draws[:, :, i] = mean + sd * rng.standard_normal((2, 500))
        if par == "residual_sd" or par == "walker_sd":
            draws[:, :, i] = np.abs(draws[:, :, i])
    for law in LINEAR_LAWS:
        at_ref, slope = names.index(f"{law}.intercept_at_ref"), names.index(f"{law}.slope")
        draws[:, :, names.index(f"{law}.intercept")] = (
            draws[:, :, at_ref] - 1.8 * draws[:, :, slope]
        )
    d = len(names)
    return HierarchicalFit(
        names, draws, np.full(d, 1.002), np.full(d, 900.0), np.full(d, 800.0),
        records, walkers, effects, seed=seed,
    )  # fmt: skip


def _results(n: int = 120) -> pd.DataFrame:
    peds = sample_pedestrians(n, seed=5)
    peds["path"] = [f"r{i:03d}.csv" for i in range(n)]
    peds["subject"] = [f"P{i % 6:02d}" for i in range(n)]
    peds["identified_damping"] = True
    peds["identified_stiffness"] = True
    peds["identifiability"] = "well identified"
    peds["natural_frequency_hz_sd"] = 0.05
    peds["damping_ratio_sd"] = 0.02
    return peds


LEFT_OUT = pd.DataFrame(
    {
        "path": ["a.csv", "b.csv", "c.csv"],
        "reason": [
            "C and K follow the force model's misfit (the force-model check failed)",
            "no stored posterior (the particle filters keep none; identify with the exact method)",
            "C and K follow the force model's misfit (the force-model check failed)",
        ],
    }
)


def test_the_report_shows_both_fits_rows_laws_left_out_and_walker_panels(tmp_path):
    """Table 2's hierarchical row is the fit's posterior-mean law and its f_n and zeta at
    f_p 1.5 and 2.5 Hz; the laws table holds the posterior means; the left-out table counts
    each reason as BatchLaws does; left_out.csv lists every record; the figures are drawn."""
    results = _results()
    ols = fit_population(results, source="test")
    fit = _fit(1, records=117, walkers=6)
    laws = BatchLaws(fit, LEFT_OUT)
    p01 = results[results.subject == "P01"]
    walker = WalkerFit(
        "P01", _fit(2, records=len(p01) - 1, walkers=1), p01.pacing_hz.to_numpy()[1:],
        pd.DataFrame({"path": [p01.path.iloc[0]], "reason": ["no stored posterior"]}),
    )  # fmt: skip
    out = tmp_path / "report"
    files = population_report(results, ols, out, hierarchical=laws, walkers=[walker])
    table2 = pd.read_csv(out / "table2.csv")
    assert len(table2) == len(SEED_TABLE2) + 2
    hier, two_stage = table2.iloc[-2], table2.iloc[-1]
    assert hier.iloc[0] == "This study, hierarchical (117 records of 6 walkers)"
    assert two_stage.iloc[0] == "This study, two-stage OLS (120 records)"
    p = fit.params
    for col, law in ((2, "natural_frequency_hz"), (3, "damping_ratio")):
        slope, intercept = p[f"{law}.slope"], p[f"{law}.intercept"]
        # The posterior mean of the intercept at f_p = 0 is that of the law's value at the
        # reference pacing less 1.8 times the slope's (the mean is linear).
        assert intercept == pytest.approx(p[f"{law}.intercept_at_ref"] - 1.8 * slope, abs=1e-12)
        sign = "+" if intercept >= 0 else "-"
        assert hier.iloc[col].startswith(f"{slope:.4f} f_p {sign} {abs(intercept):.4f} (")
        lo, hi = (slope * f + intercept for f in (1.5, 2.5))
        assert f"({lo:.2f}-{hi:.2f}" in hier.iloc[col]
    ols_fn = ols.population_json["laws"]["natural_frequency_hz"]
    assert two_stage.iloc[2].startswith(f"{ols_fn['slope']:.4f} f_p")
    # The laws table: posterior means with their equal-tailed 95 % intervals.
    table = pd.read_csv(out / "hierarchical_laws.csv")
    ci = fit.conf_int(0.05)
    row = table.iloc[0]
    assert float(row["slope"]) == pytest.approx(p["natural_frequency_hz.slope"], rel=1e-3)
    lo, hi = ci.loc["natural_frequency_hz.slope"]
    assert row["slope 95 %"] == f"[{lo:.4g}, {hi:.4g}]"
    assert float(table.iloc[3]["intercept or mu"]) == pytest.approx(p["blf2.mu"], rel=1e-3)
    assert list(table["walker sd [95 %]"]) == ["not fitted"] * 5
    # Left out: the counts per reason are BatchLaws', every record is in the CSV.
    md = (out / "report.md").read_text()
    for reason, n in LEFT_OUT["reason"].value_counts().items():
        assert f"| {reason} | {n} |" in md
    left = pd.read_csv(out / "left_out.csv")
    assert left.to_dict(orient="list") == LEFT_OUT.to_dict(orient="list")
    assert "The hierarchical fit used 117 records of 6 walkers" in md
    assert "3 records left out" in md
    for png in ("population_hierarchical.png", "population_walkers.png"):
        assert (out / png).stat().st_size > 10_000 and files[png] == str(out / png)
    assert "Walkers' own laws" in md


def test_without_a_hierarchical_fit_the_row_says_why(tmp_path):
    """Not given: the row and the section say so; a BatchLaws without a fit: its reason.
    Table 2 from a summary alone (as the demo builds it) keeps one "This study" row."""
    results = _results(60)
    ols = fit_population(results, source="test")
    p01 = results[results.subject == "P01"]
    walker = WalkerFit("P01", _fit(2), p01.pacing_hz.to_numpy(), LEFT_OUT.iloc[0:0])
    files = population_report(results, ols, tmp_path / "a", walkers=[walker])
    # The walker panels need no population fit of the hierarchical kind (the OLS law is drawn).
    assert "population_walkers.png" in files and "population_hierarchical.png" not in files
    row = pd.read_csv(tmp_path / "a" / "table2.csv").iloc[-2]
    assert row.iloc[0] == "This study, hierarchical"
    assert row.iloc[2].startswith("not fitted: no hierarchical fit was given to this report")
    assert not (tmp_path / "a" / "left_out.csv").exists()
    assert "--no-hierarchical" in (tmp_path / "a" / "report.md").read_text()
    none = BatchLaws(None, LEFT_OUT, "3 record(s) given, fewer than the 5 a population fit needs")
    population_report(results, ols, tmp_path / "b", hierarchical=none)
    row = pd.read_csv(tmp_path / "b" / "table2.csv").iloc[-2]
    assert row.iloc[2] == "not fitted: 3 record(s) given, fewer than the 5 a population fit needs"
    assert len(pd.read_csv(tmp_path / "b" / "left_out.csv")) == 3
    assert not (tmp_path / "b" / "hierarchical_laws.csv").exists()
    rows = table2_rows(ols.population_json)
    assert len(rows) == len(SEED_TABLE2) + 1 and rows[-1][0] == "This study"


def _recompute(truth, recovered):
    """The verdicts from the intervals and the truth, by the module docstring's rules."""
    out = {}
    for law in LINEAR_LAWS:
        fl = recovered["laws"][law]
        tl = getattr(truth, law)
        out[law] = {}
        for par in ("slope", "intercept", "residual_sd"):
            lo, hi = fl[f"{par}_ci"]
            true = getattr(tl, par)
            if lo <= true <= hi:
                out[law][par] = "recovered"
            elif par == "slope" and true == 0.0:
                out[law][par] = "manufactured"
            else:
                out[law][par] = "biased"
    for law in ("blf2", "blf3"):
        fl, tl = recovered["lognormal"][law], getattr(truth, law)
        out[law] = {
            par: "recovered" if fl[f"{par}_ci"][0] <= getattr(tl, par) <= fl[f"{par}_ci"][1]
            else "biased"
            for par in ("mu", "sigma")
        }  # fmt: skip
    return out


@pytest.mark.parametrize("truth_name", ["seed", "constant"])
def test_hierarchical_verdicts_follow_the_posterior_intervals(truth_name):
    """Against the seed's truth the synthetic posterior (centred near it) recovers the
    slopes; against the constant truth (no slope) the f_n and zeta slopes, whose intervals
    exclude zero, are manufactured. Residual sds are judged without walker effects, not
    with them; every verdict is recomputed here from the intervals."""
    truth = truth_laws(truth_name)
    recovered = _hierarchical_recovered(_fit(3))
    assert recovered["laws"]["natural_frequency_hz"]["n"] == 40
    lo, hi = recovered["lognormal"]["blf2"]["sigma_ci"]
    assert lo < 0.4 < hi  # sigma is the residual sd of log BLF2
    verdicts = hierarchical_verdicts(truth, recovered)
    assert verdicts == _recompute(truth, recovered)
    if truth_name == "seed":
        assert verdicts["natural_frequency_hz"]["slope"] == "recovered"
    else:
        assert verdicts["natural_frequency_hz"]["slope"] == "manufactured"
        assert verdicts["damping_ratio"]["slope"] == "manufactured"
    with_effects = _hierarchical_recovered(_fit(3, effects=True, walkers=8))
    v = hierarchical_verdicts(truth, with_effects)
    assert {v[law]["residual_sd"] for law in LINEAR_LAWS} == {"not judged"}
    assert "walker_sd_ci" in with_effects["laws"]["blf1"]
    none = hierarchical_verdicts(truth, {"error": "no record"})
    assert {par for law in none.values() for par in law.values()} == {"not fitted"}


def _old_recovery() -> dict:
    from tests.test_recovery import _recovery_json

    return _recovery_json()


def test_an_old_recovery_without_the_hierarchical_part_reads_and_says_not_run(tmp_path):
    """A recovery.json written before the hierarchical fit reads as before; its text,
    section and conclusions say the hierarchical fit was not run, and the conclusions keep
    their two-stage sentences."""
    (tmp_path / "recovery.json").write_text(json.dumps(_old_recovery()), encoding="utf-8")
    obj = read_recovery(tmp_path)
    assert "hierarchical" not in obj
    text = recovery_text(obj)
    assert f"hierarchical    {NOT_RUN}" in text
    assert "hierarchical fit: not run" in text
    tables = [b for b in recovery_section([obj]).blocks if not isinstance(b, str | list)]
    last = tables[0].rows[-1]
    assert last[2:] == [
        "hierarchical",
        "not run",
        "truth 0.3049; not run",
        "truth -0.2116; not run",
    ]
    lines = recovery_conclusions([obj], {})
    assert len(lines) == 3 and "The f_n slope is recovered" in lines[0]


def test_a_recovery_with_both_fits_words_which_slope_is_a_finding():
    """With the part, one sentence per law says what each fit did, from the verdicts."""
    obj = _old_recovery()
    truth = truth_laws("seed")
    recovered = _hierarchical_recovered(_fit(4))
    # Make the two-stage f_n slope manufactured-looking: biased against the seed's 0.3049.
    obj["recovered"]["pipeline"]["laws"]["natural_frequency_hz"]["slope_ci"] = [0.6, 0.9]
    obj["verdict"]["pipeline"]["natural_frequency_hz"]["slope"] = "biased"
    obj["hierarchical"] = {
        "recovered": recovered,
        "verdict": hierarchical_verdicts(truth, recovered),
        "records_left_out": 2,
        "left_out_reasons": {"no stored posterior": 2},
        "left_out": [],
        "convergence": {"rhat_max": 1.002, "ess_bulk_min": 800.0, "ess_tail_min": 700.0,
                        "flagged": []},
    }  # fmt: skip
    lines = recovery_conclusions([obj], {"natural_frequency_hz": {"slope": 0.5}})
    assert len(lines) == 3
    assert "the hierarchical fit recovers it" in lines[0]
    assert "the two-stage fit biases it" in lines[0]
    assert "read the hierarchical fit's f_n slope as the finding" in lines[0]
    assert "either fit's zeta slope can be read as a finding" in lines[1]
    text = recovery_text(obj)
    assert "hierarchical fit: 40 records of 40 walkers used (no walker effects), 2 left out" in text
    assert "ESS min 700" in text and "residual sd" in text


@pytest.mark.slow
def test_workbench_report_on_a_batch_with_posteriors_writes_the_new_sections(
    walker_batch, tmp_path, capsys
):
    """On the walker batch (six deck crossings of one walker and a rigid walk whose
    force-model check fails), ``workbench report`` fits the hierarchical laws and the
    walker's own: Table 2's hierarchical row is the JSON's posterior means, the rigid walk
    is left out with its reason, the walker has its panel; --no-hierarchical skips it."""
    from workbench.cli import main

    out, subject, _ = walker_batch
    code = main(["report", str(out), "--out", str(tmp_path / "r"), "--json"])
    assert code == 0
    obj = json.loads(capsys.readouterr().out)
    hier = obj["hierarchical"]
    assert hier["fit"]["records_used"] == 6 and hier["records_left_out"] == 1
    assert "predictive_draws" not in hier["fit"]
    assert [w["subject"] for w in obj["walkers"]] == [subject]
    assert obj["walkers"][0]["records_used"] == 6
    row = pd.read_csv(tmp_path / "r" / "table2.csv").iloc[-2]
    assert row.iloc[0] == "This study, hierarchical (6 records of 1 walker)"
    fn = hier["fit"]["laws"]["natural_frequency_hz"]
    slope, intercept = fn["slope"]["mean"], fn["intercept"]["mean"]
    sign = "+" if intercept >= 0 else "-"
    assert row.iloc[2].startswith(f"{slope:.4f} f_p {sign} {abs(intercept):.4f} (")
    left = pd.read_csv(tmp_path / "r" / "left_out.csv")
    assert list(left["path"]) == ["records/rigid.csv"]
    assert "force-model check failed" in left["reason"].iloc[0]
    md = (tmp_path / "r" / "report.md").read_text()
    assert "Hierarchical laws from every usable record's likelihood" in md
    assert "(population_walkers.png)" in md and "(population_hierarchical.png)" in md
    code = main(["report", str(out), "--out", str(tmp_path / "s"), "--no-hierarchical"])
    text = capsys.readouterr().out
    assert code == 0 and "skipped (--no-hierarchical)" in text
    assert not (tmp_path / "s" / "left_out.csv").exists()


@pytest.fixture(scope="module")
def walker_batch(tmp_path_factory):
    from tests.test_record_posteriors import make_walker_batch

    return make_walker_batch(tmp_path_factory.mktemp("walker"))


def test_walker_panels_draw_no_estimate_graded_not_identified() -> None:
    """A weak deck record counts in the walker's fit through its likelihood, but its point
    estimate is not drawn: only records whose C and K are identified get a marker, and a
    record the walker fit left out gets none."""
    from types import SimpleNamespace

    from workbench.reporting.population_hierarchy import _walker_records

    results = pd.DataFrame(
        {
            "path": ["a.csv", "b.csv", "c.csv", "d.csv"],
            "subject": ["w1", "w1", "w1", "w2"],
            "pacing_hz": [1.9, 1.7, 1.8, 1.8],
            "natural_frequency_hz": [2.0, 2.1, 2.2, 2.3],
            "identified_stiffness": [True, True, False, True],
            "identified_damping": [True, True, True, True],
        }
    )
    walker = SimpleNamespace(
        subject="w1", left_out=pd.DataFrame({"path": ["b.csv"], "reason": ["left out"]})
    )
    assert list(_walker_records(results, walker)["path"]) == ["a.csv"]
    # Flags read back as text, or missing, are read as the fit reads them: "False" and a
    # missing flag are not identified.
    as_text = results.assign(
        identified_stiffness=["True", "True", "False", "True"],
        identified_damping=["True", "True", "True", None],
    )
    assert list(_walker_records(as_text, walker)["path"]) == ["a.csv"]
    assert (
        list(
            _walker_records(as_text, SimpleNamespace(subject="w2", left_out=walker.left_out[:0]))[
                "path"
            ]
        )
        == []
    )

import json

import pandas as pd
import pytest

from workbench.cli import main
from workbench.population.sampler import sample_pedestrians
from workbench.reporting.population import SEED_TABLE2


def test_report_cli_writes_table2_figures_and_self_contained_html(tmp_path, capsys):
    peds = sample_pedestrians(300, seed=12)
    peds["path"] = [f"r{i:03d}.csv" for i in range(300)]
    peds["subject"] = [f"P{i % 20:02d}" for i in range(300)]
    peds["identified_damping"] = [i >= 7 for i in range(300)]
    peds["identified_stiffness"] = True
    peds["identifiability"] = ["not identified" if i < 7 else "well identified" for i in range(300)]
    batch = tmp_path / "batch"
    batch.mkdir()
    peds.to_csv(batch / "results.csv", index=False)
    out = tmp_path / "report"
    assert main(["report", str(batch), "--out", str(out), "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert obj["records_used"] == 293 and obj["records_excluded"] == 7
    table2 = pd.read_csv(out / "table2.csv")
    # A row per fit; from a results table alone the hierarchical one says why it is absent.
    assert len(table2) == len(SEED_TABLE2) + 2
    assert table2.iloc[-1, 0] == "This study, two-stage OLS (293 records)"
    assert table2.iloc[-2, 0] == "This study, hierarchical"
    assert table2.iloc[-2, 2].startswith("not fitted: no hierarchical fit was given")
    fn = obj["laws"]["natural_frequency_hz"]
    lo, hi = (fn["slope"] * f + fn["intercept"] for f in (1.5, 2.5))
    assert f"({lo:.2f}-{hi:.2f} at f_p 1.5-2.5 Hz)" in table2.iloc[-1, 2]
    laws = pd.read_csv(out / "laws.csv")
    assert list(laws["law"]) == ["natural frequency f_n [Hz]", "damping ratio zeta", "BLF1"]
    assert len(pd.read_csv(out / "lognormal.csv")) == 2
    html = (out / "index.html").read_text()
    md = (out / "report.md").read_text()
    pngs = ("population_laws.png", "population_residuals.png", "population_blf.png")
    for png in (*pngs, "population_participant.png"):
        assert (out / png).stat().st_size > 10_000
        assert f"({png})" in md
        assert f'src="{png}"' not in html
    assert html.count('src="data:image/png;base64,') == 4
    assert "7 excluded: C or K not identified" in md
    assert "Van Nimmen 2015" in md and "This study" in html


@pytest.mark.parametrize("argv", [["report"], ["population"]])
def test_missing_results_is_a_user_error(tmp_path, capsys, argv):
    assert main([*argv, str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "results.csv" in capsys.readouterr().err

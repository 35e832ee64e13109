import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from workbench.cli import main
from workbench.errors import UsageError
from workbench.population.laws import LinearLaw, LognormalLaw, PopulationLaws
from workbench.population.sampler import COLUMNS, GRAVITY_M_S2, sample_pedestrians

N = 20000


@pytest.fixture(scope="module")
def table() -> pd.DataFrame:
    return sample_pedestrians(N, seed=7)


def _truncnorm_moments(mean, sd, low, high):
    d = stats.truncnorm((low - mean) / sd, (high - mean) / sd, loc=mean, scale=sd)
    return d.mean(), d.var()


def test_columns_and_exact_relations(table):
    assert tuple(table.columns) == COLUMNS
    assert len(table) == N
    m, fn, zeta = table.mass_kg, table.natural_frequency_hz, table.damping_ratio
    np.testing.assert_allclose(table.stiffness_n_per_m, m * (2 * np.pi * fn) ** 2, rtol=1e-12)
    np.testing.assert_allclose(
        table.damping_ns_per_m, 2 * zeta * np.sqrt(table.stiffness_n_per_m * m), rtol=1e-12
    )
    np.testing.assert_allclose(table.speed_m_s, table.pacing_hz * table.step_length_m)
    # Round trip from K, C back to f_n and zeta (docs/science.md 1 conversions).
    k, c = table.stiffness_n_per_m, table.damping_ns_per_m
    np.testing.assert_allclose(np.sqrt(k / m) / (2 * np.pi), fn, rtol=1e-12)
    np.testing.assert_allclose(c / (2 * np.sqrt(k * m)), zeta, rtol=1e-12)
    for i in (1, 2, 3):
        ph = table[f"phase{i}_rad"]
        assert ph.min() >= 0 and ph.max() < 2 * np.pi
        # Uniform phases: mean pi, variance pi^2/3.
        assert abs(ph.mean() - np.pi) < 4 * np.pi / np.sqrt(3 * N)
    assert GRAVITY_M_S2 == 9.81


def test_mass_and_pacing_match_their_distributions(table):
    laws = PopulationLaws()
    ms = laws.mass
    m1, v1 = _truncnorm_moments(ms.male_mean_kg, ms.male_sd_kg, ms.male_low_kg, ms.male_high_kg)
    m2, v2 = _truncnorm_moments(
        ms.female_mean_kg, ms.female_sd_kg, ms.female_low_kg, ms.female_high_kg
    )
    w = ms.male_fraction
    mean = w * m1 + (1 - w) * m2
    var = w * (v1 + m1**2) + (1 - w) * (v2 + m2**2) - mean**2
    assert abs(table.mass_kg.mean() - mean) < 4 * np.sqrt(var / N)
    assert table.mass_kg.min() >= ms.female_low_kg and table.mass_kg.max() <= ms.male_high_kg
    p = laws.pacing
    pm, pv = _truncnorm_moments(p.mean_hz, p.sd_hz, p.low_hz, p.high_hz)
    assert abs(table.pacing_hz.mean() - pm) < 4 * np.sqrt(pv / N)
    assert table.pacing_hz.between(1.5, 2.25).all()


@pytest.mark.parametrize(
    ("column", "law"),
    [
        ("natural_frequency_hz", PopulationLaws().natural_frequency_hz),
        ("damping_ratio", PopulationLaws().damping_ratio),
        ("blf1", PopulationLaws().blf1),
    ],
)
def test_linear_laws_recovered_by_regression(table, column, law):
    import statsmodels.api as sm

    fit = sm.OLS(table[column].to_numpy(), sm.add_constant(table.pacing_hz.to_numpy())).fit()
    lo, hi = fit.conf_int(alpha=0.001).T
    assert lo[1] < law.slope < hi[1]
    assert lo[0] < law.intercept < hi[0]
    # Residual sd: its sampling sd is about sd / sqrt(2 N).
    assert abs(np.sqrt(fit.scale) - law.residual_sd) < 4 * law.residual_sd / np.sqrt(2 * N)


def test_lognormal_blfs_and_step_length(table):
    laws = PopulationLaws()
    for col, law in (("blf2", laws.blf2), ("blf3", laws.blf3)):
        logs = np.log(table[col])
        assert abs(logs.mean() - law.mu) < 4 * law.sigma / np.sqrt(N)
        assert abs(logs.std() - law.sigma) < 4 * law.sigma / np.sqrt(2 * N)
        # Independent of pacing, as the seed found.
        assert abs(stats.pearsonr(table.pacing_hz, logs)[0]) < 4 / np.sqrt(N)
    sl = laws.step_length
    resid = table.step_length_m - (sl.slope_m_per_hz * table.pacing_hz + sl.intercept_m)
    assert abs(resid.mean()) < 4 * sl.residual_sd_m / np.sqrt(N)
    assert abs(resid.std() - sl.residual_sd_m) < 4 * sl.residual_sd_m / np.sqrt(2 * N)


def test_seed_fixes_the_table_and_laws_change_it():
    a = sample_pedestrians(50, seed=3)
    pd.testing.assert_frame_equal(a, sample_pedestrians(50, seed=3))
    assert not a.equals(sample_pedestrians(50, seed=4))
    laws = PopulationLaws().replace(
        natural_frequency_hz=LinearLaw(0.0, 2.5, 0.0), blf2=LognormalLaw(np.log(0.1), 0.0)
    )
    b = sample_pedestrians(50, seed=3, laws=laws)
    np.testing.assert_allclose(b.natural_frequency_hz, 2.5)
    np.testing.assert_allclose(b.blf2, 0.1)


def test_from_json_reads_the_population_contract():
    obj = {
        "laws": {
            "natural_frequency_hz": {"slope": 0.3, "intercept": 1.4, "residual_sd": 0.1},
            "damping_ratio": {"slope": -0.2, "intercept": 0.85, "residual_sd": 0.04},
            "blf1": {"slope": 0.4, "intercept": -0.38, "residual_sd": 0.03},
        },
        "lognormal": {"blf2": {"mu": -2.9, "sigma": 0.3}, "blf3": {"mu": -3.0, "sigma": 0.35}},
    }
    laws = PopulationLaws.from_json(obj)
    assert laws.damping_ratio == LinearLaw(-0.2, 0.85, 0.04)
    assert laws.blf3 == LognormalLaw(-3.0, 0.35)
    back = PopulationLaws.from_json(json.loads(json.dumps(laws.to_json())))
    assert back.natural_frequency_hz == laws.natural_frequency_hz
    del obj["lognormal"]["blf3"]
    with pytest.raises(UsageError, match="blf3"):
        PopulationLaws.from_json(obj)
    with pytest.raises(UsageError):
        sample_pedestrians(0, seed=1)


def test_sample_cli(tmp_path, capsys):
    out = tmp_path / "peds.csv"
    assert main(["sample", "--n", "40", "--out", str(out), "--seed", "5", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    table = pd.read_csv(out)
    assert summary["n"] == 40 and tuple(table.columns) == COLUMNS
    np.testing.assert_allclose(table.to_numpy(), sample_pedestrians(40, seed=5).to_numpy(), 1e-9)
    laws_file = tmp_path / "pop.json"
    laws_file.write_text(json.dumps({"laws": {}}))
    assert main(["sample", "--n", "3", "--out", str(out), "--laws", str(laws_file)]) == 2
    assert "natural_frequency_hz" in capsys.readouterr().err

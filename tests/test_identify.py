"""``workbench identify``: the JSON contract, settings, honesty flags, and the real records."""

from __future__ import annotations

import json

import numpy as np
import pytest

from workbench.cli import main
from workbench.datasets import embedded_path
from workbench.inference.core.results import SCALAR_KEYS
from workbench.inference.pipeline.identification import identify
from workbench.inference.pipeline.settings import IdentifySettings
from workbench.records.io import load_record, save_record
from workbench.synth.simulate import simulate_walking

CONTRACT = {
    "mass_kg",
    "pacing_hz",
    "method",
    "stiffness_n_per_m",
    "damping_ns_per_m",
    "natural_frequency_hz",
    "damping_ratio",
    "blf",
    "posterior_sd",
    "identifiability",
    "steps",
}


@pytest.fixture(scope="module")
def short_record(tmp_path_factory):
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=12.0,
        sample_rate_hz=100.0,
        noise_sd_n=2.0,
        start="rest",
        seed=4,
    )
    path = tmp_path_factory.mktemp("id") / "walk.csv"
    save_record(sim.record, path)
    return path, sim.truth


def test_identify_json_contract(short_record, capsys, tmp_path):
    path, _ = short_record
    code = main(
        [
            "identify",
            str(path),
            "--particles",
            "64",
            "--obs-noise",
            "seed",
            "--harmonics",
            "4",
            "--json",
            "--out",
            str(tmp_path / "out"),
        ]
    )
    out, err = capsys.readouterr()
    assert code == 0, err
    r = json.loads(out)
    assert CONTRACT <= r.keys()
    assert r["method"] == "exact"  # the default
    # Graded not identified, a number is null and kept under conditional_on_prior_box.
    kept = r["conditional_on_prior_box"]
    ident = r["identifiability"]
    if r["blf"] is None:
        assert not (ident["identified_damping"] and ident["identified_stiffness"])
    assert len(r["blf"] or kept["blf"]["estimate"]) == 4
    assert set(r["posterior_sd"]) >= {
        "stiffness_n_per_m",
        "damping_ns_per_m",
        "natural_frequency_hz",
        "damping_ratio",
        "blf",
    }
    assert r["identifiability"]["sentence"]
    assert r["noise"]["obs_fraction"] == pytest.approx(0.10)
    # Derived quantities are consistent with K, C and M.
    value = {key: kept[key]["estimate"] if r[key] is None else r[key] for key in SCALAR_KEYS}
    assert all((r[key] is None) == (key in kept) for key in SCALAR_KEYS)
    k, c, m = value["stiffness_n_per_m"], value["damping_ns_per_m"], r["mass_kg"]
    f_n = np.sqrt(k / m) / (2 * np.pi)
    assert value["natural_frequency_hz"] == pytest.approx(f_n, rel=0.02)
    assert value["damping_ratio"] == pytest.approx(c / (2 * np.sqrt(k * m)), rel=0.05)
    assert (tmp_path / "out" / "index.html").exists()
    assert r["netcdf"].endswith(".nc")


def test_netcdf_round_trip(short_record, tmp_path):
    import xarray as xr

    path, _ = short_record
    res = identify(
        load_record(path),
        settings=IdentifySettings.from_flat(particles=32, obs_noise=0.1, harmonics=3),
    )
    nc = res.to_netcdf(tmp_path / "r.nc")
    with xr.open_dataset(nc, engine="scipy") as ds:
        assert ds["piece_coefficients_mean"].shape == (res.problem.n_pieces, 7)
        # The per-step load factors the reported BLFs average (mixed over C and K).
        np.testing.assert_allclose(ds["piece_load_factors"].mean("piece"), res.blf, rtol=1e-12)
        stored = json.loads(ds.attrs["workbench_result_json"])
    assert stored == json.loads(json.dumps(res.to_json(), default=float))


def test_config_file_and_flag_precedence(tmp_path):
    cfg = tmp_path / "s.toml"
    cfg.write_text('method = "exact"\nharmonics = 6\nobs_noise = "seed"\nseed = 3\n')
    s = IdentifySettings.from_toml(cfg, harmonics=8, method=None)
    assert (s.method.name, s.model.harmonics, s.noise.obs_noise, s.seed) == ("exact", 8, "seed", 3)
    # The flat form (the --config file keys) round-trips.
    assert IdentifySettings.from_flat(**s.to_json()) == s


@pytest.mark.parametrize(
    ("text", "needle"),
    [("metod = 'pf'\n", "metod"), ("method = \n", "TOML"), ("method = 'kalman'\n", "kalman")],
)
def test_bad_config_is_one_sentence(tmp_path, capsys, short_record, text, needle):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    code = main(["identify", str(short_record[0]), "--config", str(cfg)])
    err = capsys.readouterr().err
    assert code == 2
    assert needle in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("value", ["lots", "-0.1", "2"])
def test_bad_obs_noise_is_one_sentence(capsys, short_record, value):
    code = main(["identify", str(short_record[0]), "--obs-noise", value])
    err = capsys.readouterr().err
    assert code == 2 and "--obs-noise" in err


def test_prior_bound_posterior_is_not_called_identified(short_record):
    """A posterior squeezed against the box edge must not be reported as an estimate."""
    from workbench.inference.core.problem import StiffnessDampingPrior

    path, truth = short_record
    settings = IdentifySettings.from_flat(particles=64, obs_noise=0.02, harmonics=4, method="rbpf")
    rec = load_record(path)
    from workbench.inference.pipeline.identification import compile_problem, identify_problem
    from workbench.inference.pipeline.noise import apply_noise_setting
    from workbench.records.inspection import inspect_record

    problem = compile_problem(inspect_record(rec), settings)
    # A box that excludes the true stiffness (far above it): the posterior piles at its floor.
    k = truth["stiffness_n_per_m"]
    problem = problem.with_prior(StiffnessDampingPrior((100.0, 3000.0), (3 * k, 4 * k)))
    problem, _ = apply_noise_setting(problem, 0.02)
    res = identify_problem(problem, settings)
    from workbench.inference.pipeline import grade

    res = grade(res, settings.replace(force_check=False))
    assert "stiffness_n_per_m" in res.parameters_at_prior_bound
    assert res.identifiability["level"] == "not identified"
    assert not res.to_json()["diagnostics"]["trustworthy"]
    # Said in words, the verb agreeing with how many parameters sit there, and once.
    sentence = res.identifiability["sentence"]
    agreeing = "sits" if len(res.parameters_at_prior_bound) == 1 else "sit"
    assert f"stiffness K {agreeing} at the edge of the prior box" in sentence
    assert not any("_per_m" in text for text in (sentence, *res.warnings))
    assert res.summary().count(sentence) == 1


@pytest.mark.slow
def test_real_insole_record_identifies(capsys):
    code = main(["identify", str(embedded_path("insole")), "--mass", "83", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    r = json.loads(out)
    assert CONTRACT <= r.keys()
    # The insole is graded not identified (tests/test_not_identified.py): its numbers are
    # under conditional_on_prior_box, null where estimates go.
    kept = r["conditional_on_prior_box"]
    blf = r["blf"] if r["blf"] is not None else kept["blf"]["estimate"]
    assert len(blf) == 10 and all(np.isfinite(blf))
    assert r["identifiability"]["sentence"]
    f_n = r["interval_95"]["natural_frequency_hz"] or kept["natural_frequency_hz"]["interval_95"]
    assert all(np.isfinite(f_n))


@pytest.mark.slow
def test_real_treadmill_steady_segment_identifies(tmp_path, capsys):
    """One steady-speed stretch of the treadmill trial (about 2.2 Hz, 75-100 s)."""
    rec = load_record(embedded_path("treadmill")).slice(75.0, 100.0)
    path = tmp_path / "treadmill_fast.csv"
    save_record(rec.replace(metadata={}), path)
    code = main(["identify", str(path), "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    r = json.loads(out)
    assert 2.0 < r["pacing_hz"] < 2.4
    assert r["identifiability"]["sentence"]

"""The Python API a researcher writes in a notebook: one model, method objects, results."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import workbench as wb
from workbench.errors import UsageError, WorkbenchError
from workbench.inference.pipeline.settings import IdentifySettings
from workbench.synth.simulate import simulate_walking

MASS_KG = 70.0


@pytest.fixture(scope="module")
def walk() -> wb.Record:
    """12 s of walking from rest (70 kg, 1.8 Hz, 100 Hz), which carries C and K."""
    sim = simulate_walking(
        mass_kg=MASS_KG,
        pacing_hz=1.8,
        duration_s=12.0,
        sample_rate_hz=100,
        noise_sd_n=3.0,
        start="rest",
        seed=21,
    )
    return sim.record


@pytest.fixture(scope="module")
def result(walk: wb.Record) -> wb.IdentificationResult:
    model = wb.SMDModel(harmonics=4) + wb.effects.GaitAsymmetry()
    return wb.identify(walk, model, method=wb.RBPF(n_particles=64), seed=3, force_check=False)


def test_errors_are_value_errors() -> None:
    assert issubclass(WorkbenchError, ValueError)
    with pytest.raises(ValueError, match="n_particles"):
        wb.RBPF(n_particles=1)


def test_methods_are_objects_with_their_own_options() -> None:
    assert wb.RBPF().n_particles == 256 and wb.PF().n_particles == 4000
    assert wb.PF(force_proposal="prior").force_proposal == "prior"
    with pytest.raises(UsageError, match="force_proposal"):
        wb.PF(force_proposal="blind")
    with pytest.raises(UsageError, match="resampling"):
        wb.RBPF(resampling="lottery")
    with pytest.raises(dataclasses.FrozenInstanceError):
        wb.RBPF().n_particles = 3  # type: ignore[misc]


def test_settings_split_into_parts_and_keep_the_flat_keys() -> None:
    flat = IdentifySettings.from_flat(
        method="pf", particles=500, harmonics=6, obs_noise="seed", highpass_hz=0.2, seed=4
    )
    assert flat.method == wb.PF(n_particles=500)
    assert flat.model.harmonics == 6 and flat.noise.obs_noise == "seed"
    assert flat.preprocessing.highpass_hz == 0.2 and flat.seed == 4
    assert flat.state_fraction == 0.005  # the seed's process noise for its filter
    assert IdentifySettings.from_flat(**flat.to_json()) == flat
    # Another method takes its own default count unless one is given.
    assert flat.replace(method="rbpf").n_particles == 256
    assert flat.replace(method="rbpf", particles=32).n_particles == 32
    assert flat.replace(method="exact").n_particles == 0
    with pytest.raises(UsageError, match="metod"):
        IdentifySettings.from_flat(metod="pf")
    with pytest.raises(UsageError, match="seed"):
        IdentifySettings(seed=-1)


def test_the_model_describes_the_force() -> None:
    model = wb.SMDModel.from_modal(
        75.0, 2.5, 0.4, harmonics=1, pacing_hz=2.0, force_coefficients_n=(0.0, 0.0, 300.0)
    )
    t = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(model.biomechanical_force_n(t), 300.0 * np.sin(4 * np.pi * t))
    assert model.blf is not None
    assert model.blf[0] == pytest.approx(300.0 / (75.0 * wb.G_M_S2))
    with pytest.raises(UsageError, match="force_coefficients_n"):
        wb.SMDModel(harmonics=2, force_coefficients_n=(1.0, 2.0))
    with pytest.raises(UsageError, match="time_basis"):
        wb.SMDModel(time_basis="calendar")
    with pytest.raises(UsageError, match="not known"):
        wb.SMDModel(mass_kg=70).biomechanical_force_n(t)


def test_record_slice(walk: wb.Record) -> None:
    part = walk.slice(2.0, 5.0)
    assert part.time_s[0] >= 2.0 and part.time_s[-1] < 5.0
    assert part.mass_kg == MASS_KG and part.n_samples == 300
    with pytest.raises(UsageError, match="start before its end"):
        walk.slice(5.0, 2.0)
    with pytest.raises(UsageError, match="fewer than two samples"):
        walk.slice(100.0, 200.0)


def test_embedded_records_by_name() -> None:
    rec = wb.datasets.load("treadmill")
    assert rec.mass_kg == pytest.approx(77.3) and rec.duration_s > 140
    assert "seed_individual" in wb.datasets.names()
    with pytest.raises(ValueError, match="treadmill"):
        wb.datasets.load("escalator")


def test_identify_takes_a_model_and_a_method(
    walk: wb.Record, result: wb.IdentificationResult
) -> None:
    # The same identification by name and by object, with the same seed, is the same.
    again = wb.identify(
        walk,
        wb.SMDModel(harmonics=4) + wb.effects.GaitAsymmetry(),
        method="rbpf",
        seed=3,
        force_check=False,
        settings=IdentifySettings.from_flat(method="rbpf", particles=64),
    )
    np.testing.assert_array_equal(again.draws, result.draws)
    assert result.model is not None and result.model.mass_kg == MASS_KG
    assert result.settings["effects"] == ["gait_asymmetry"]
    with pytest.raises(UsageError, match="SMDModel"):
        wb.identify(walk, IdentifySettings())  # type: ignore[arg-type]
    with pytest.raises(UsageError, match="give the mass once"):
        wb.identify(walk, wb.SMDModel(mass_kg=80.0))


def test_results_are_statsmodels_like(result: wb.IdentificationResult) -> None:
    params, bse, ci = result.params, result.bse, result.conf_int()
    assert list(params.index[:4]) == [
        "stiffness_n_per_m",
        "damping_ns_per_m",
        "natural_frequency_hz",
        "damping_ratio",
    ]
    assert {"blf1", "blf4", "gait_asymmetry.a_half_n"} <= set(params.index)
    assert list(bse.index) == list(params.index) and list(ci.index) == list(params.index)
    for key in ("stiffness_n_per_m", "damping_ratio"):
        assert params[key] == pytest.approx(result.estimates[key])
        assert bse[key] == pytest.approx(result.posterior_sd[key])
    assert (ci["lower"] < params).all() and (params < ci["upper"]).all()
    narrow = result.conf_int(alpha=0.5)
    assert ((narrow["upper"] - narrow["lower"]) < (ci["upper"] - ci["lower"])).all()
    assert result.effects is not None
    effect = result.effects.parameters["gait_asymmetry"]["a_half_n"]
    assert params["gait_asymmetry.a_half_n"] == pytest.approx(effect["mean"])
    fitted = result.fitted_model
    assert fitted.stiffness_n_per_m == pytest.approx(params["stiffness_n_per_m"])
    assert fitted.effects["gait_asymmetry"].values["a_half_n"] == pytest.approx(effect["mean"])
    assert "SMD identification (rbpf)" in result.summary()


def test_results_are_immutable(result: wb.IdentificationResult) -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.method = "pf"  # type: ignore[misc]
    changed = result.replace(identifiability={"level": "not identified"})
    assert changed.identifiability == {"level": "not identified"}
    assert result.identifiability != changed.identifiability


def test_inference_data_carries_the_weighted_posterior(result: wb.IdentificationResult) -> None:
    idata = result.to_inference_data(n_draws=4000)
    post = idata.posterior
    assert post.sizes["chain"] == 1 and post.sizes["draw"] == 4000
    assert {"stiffness_n_per_m", "damping_ratio"} <= set(post.data_vars)
    # Systematic resampling keeps the weighted mean to a small fraction of the sd.
    for key in ("stiffness_n_per_m", "damping_ns_per_m"):
        draws = post[key].values.ravel()
        assert abs(draws.mean() - result.estimates[key]) < 0.05 * result.posterior_sd[key]
    assert idata.observed_data["u_ddot_m_s2"].size == result.problem.n_samples
    assert idata.attrs["method"] == "rbpf"


def test_the_simulator_takes_the_model() -> None:
    """Simulating a model gives the walk its flat arguments give, draw for draw."""
    model = wb.SMDModel.from_modal(
        72.0,
        2.6,
        0.3,
        harmonics=2,
        pacing_hz=1.9,
        force_coefficients_n=(0.0, 10.0, 250.0, 0.0, 60.0),
    ) + wb.effects.CubicStiffness(k3_n_per_m3=4e5)
    kwargs = {"duration_s": 4.0, "sample_rate_hz": 100, "seed": 5}
    by_model = wb.simulate_walking(model=model, **kwargs)
    by_args = wb.simulate_walking(
        mass_kg=72.0,
        natural_frequency_hz=2.6,
        damping_ratio=0.3,
        pacing_hz=1.9,
        coefficients=(0.0, 10.0, 250.0, 0.0, 60.0),
        effects=[wb.effects.CubicStiffness(k3_n_per_m3=4e5)],
        **kwargs,
    )
    np.testing.assert_array_equal(by_model.record.grf_n, by_args.record.grf_n)
    assert by_model.model.effects == model.effects
    assert by_model.model.stiffness_n_per_m == pytest.approx(model.stiffness_n_per_m)
    with pytest.raises(UsageError, match="given both"):
        wb.simulate_walking(model=model, damping_ratio=0.2)


def test_replace_changes_only_the_part_a_key_belongs_to() -> None:
    """What the flat form cannot hold survives a change of another key."""
    base = IdentifySettings(
        method=wb.Exact(n_draws=100),
        preprocessing=wb.Preprocessing(highpass_hz=0.2, rescale_to_mass=True),
        model=wb.SMDModel(mass_kg=70.0, harmonics=5),
    )
    changed = base.replace(seed=3, harmonics=6, obs_noise="seed")
    assert changed.method == wb.Exact(n_draws=100)
    assert changed.preprocessing == base.preprocessing
    assert changed.model.mass_kg == 70.0 and changed.model.harmonics == 6
    assert changed.seed == 3 and changed.noise.obs_noise == "seed"
    # A method's own options survive a change of another of its options.
    pf = IdentifySettings(method=wb.PF(n_particles=900, force_proposal="prior"))
    assert pf.replace(resampling="residual").method == wb.PF(
        n_particles=900, force_proposal="prior", resampling="residual"
    )


def test_options_of_another_method_are_carried_through_a_switch() -> None:
    rbpf = IdentifySettings.from_flat(method="rbpf", force_proposal="prior")
    assert rbpf.to_json()["force_proposal"] == "prior"  # reported as given
    assert rbpf.replace(method="pf").method == wb.PF(force_proposal="prior")
    # The particle count is null in the JSON when the method runs its default.
    assert IdentifySettings().to_json()["particles"] is None
    assert IdentifySettings.from_flat(method="rbpf", particles=64).to_json()["particles"] == 64
    # The default method, exact, has no particles: a count given to it is not reported.
    assert IdentifySettings.from_flat(particles=64).to_json()["particles"] is None
    assert IdentifySettings.from_flat(rescale_to_mass=True).preprocessing.rescale_to_mass


def test_the_mass_of_the_settings_model_is_reconciled(walk: wb.Record) -> None:
    heavy = IdentifySettings(model=wb.SMDModel(mass_kg=2 * MASS_KG, harmonics=4))
    with pytest.raises(UsageError, match="give the mass once"):
        wb.identify(walk, settings=heavy)
    massless = walk.replace(mass_kg=None)
    res = wb.identify(
        massless.slice(0.0, 6.0),
        settings=IdentifySettings(model=wb.SMDModel(mass_kg=MASS_KG, harmonics=4)),
        method=wb.RBPF(n_particles=16),
        force_check=False,
    )
    assert res.mass_kg == MASS_KG


def test_the_fitted_model_walks(result: wb.IdentificationResult) -> None:
    fitted = result.fitted_model
    assert fitted.pacing_hz == pytest.approx(result.problem.pacing_hz)
    assert fitted.force_coefficients_n is not None
    np.testing.assert_allclose(
        fitted.force_coefficients_n, result.piece_coefficients_mean[:, :9].mean(axis=0)
    )
    walk = wb.simulate_walking(model=fitted, duration_s=3.0, sample_rate_hz=100, seed=1)
    assert walk.record.mass_kg == MASS_KG


def test_one_piece_models_keep_the_inspection_where_the_record_has_footfalls(
    walk: wb.Record,
) -> None:
    """The footfall-free path is taken only when the record has no usable footfalls."""
    heavy_force = walk.replace(grf_n=1.12 * walk.grf_n)
    whole = wb.SMDModel(harmonics=4, pieces="whole", pacing_hz=1.8)
    res = wb.identify(heavy_force, whole, method=wb.RBPF(n_particles=16), force_check=False)
    assert any("static balance" in w or "body weight" in w for w in res.inspection_warnings)
    from workbench.synth.simulate import seed_numerical_example

    bench = seed_numerical_example(duration_s=3.0).record
    model = wb.SMDModel(harmonics=10, pieces="whole", time_basis="absolute", pacing_hz=0.5)
    res = wb.identify(
        bench,
        model,
        method=wb.Exact(n_draws=200),
        preprocessing=wb.Preprocessing(highpass_hz=0.0),
        force_check=False,
    )
    assert any("one piece at the stated pacing" in w for w in res.inspection_warnings)

"""Identification with effects: shared effect coefficients in the force basis (issue 5)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from workbench.cli import main
from workbench.errors import UsageError
from workbench.inference.core.problem import build_problem
from workbench.inference.methods.exact import exact_posterior
from workbench.inference.methods.rbpf import run_rbpf
from workbench.inference.pipeline.effect_terms import effect_posterior, effect_terms, with_effects
from workbench.inference.pipeline.settings import IdentifySettings
from workbench.models.effects import CubicStiffness, EffectContext
from workbench.models.smd import SMDModel
from workbench.records.io import save_record
from workbench.records.preprocess import preprocess
from workbench.synth.simulate import SEED_EXAMPLE_TERMS, simulate_smd, simulate_walking

DURATION_S = 4.0


def _seed_problem(k3_n_per_m3: float):
    """The seed's numerical example (75 kg, f_n 2.5 Hz, zeta 0.4, 1 kHz) with a cubic spring."""
    model = SMDModel.from_modal(75.0, 2.5, 0.4, harmonics=10)
    if k3_n_per_m3:
        model = model + CubicStiffness(k3_n_per_m3=k3_n_per_m3)
    time_s = np.arange(round(DURATION_S / 0.001)) * 0.001

    def force(t):
        return sum(a * np.sin(w * np.pi * np.asarray(t)) for a, w in SEED_EXAMPLE_TERMS)

    ctx = EffectContext(step_start_s=np.arange(0.0, DURATION_S + 2.0, 2.0))
    sim = simulate_smd(model, force, time_s, pacing_hz=0.5, context=ctx)
    com = preprocess(sim.record, highpass_hz=0)
    problem = build_problem(
        com,
        None,
        pieces="whole",
        pacing_hz=0.5,
        time_basis="absolute",
        harmonics=10,
        obs_fraction=0.01,
        state_fraction=0.0,
    )
    truth = np.array([model.damping_ns_per_m, model.stiffness_n_per_m])
    return problem, truth


_AUGMENTED: dict[float, tuple] = {}


def _augmented(k3: float):
    """Problem, truth, effect terms and augmented problem, built once per k3 for this module."""
    if k3 not in _AUGMENTED:
        problem, truth = _seed_problem(k3)
        terms = effect_terms(problem, [CubicStiffness()])
        _AUGMENTED[k3] = (problem, truth, terms, with_effects(problem, terms)[0])
    return _AUGMENTED[k3]


@pytest.mark.slow
@pytest.mark.parametrize("k3", [2e6, 0.0])
def test_exact_with_cubic_stiffness_recovers_k3_and_keeps_c_k(k3):
    """A cubic spring (k3 u^2 about 10 % of K) is recovered within 4 sd and 1 %; C and K stay
    in their bands. With no cubic spring the 95 % band of k3 holds 0."""
    problem, truth, terms, augmented = _augmented(k3)
    assert terms.names == ("cubic_stiffness.k3_n_per_m3",)
    assert augmented.coefficient_names[-1] == "cubic_stiffness.k3_n_per_m3"
    post = exact_posterior(augmented)
    msg = f"C, K {post.mean} +- {post.sd}, truth {truth}"
    assert np.all(np.abs(post.mean - truth) < 3.0 * post.sd), msg
    draws = post.sample(1000, np.random.default_rng(0))
    est = effect_posterior(problem, terms, draws, np.full(draws.shape[0], 1e-3))
    k3_post = est["cubic_stiffness"]["k3_n_per_m3"]
    msg = f"k3 {k3_post}, truth {k3}"
    lo, hi = k3_post["ci95"]
    if k3:
        assert abs(k3_post["mean"] - k3) < 4.0 * k3_post["sd"], msg
        assert abs(k3_post["mean"] / k3 - 1) < 0.01, msg
        # The data pin k3 far below its prior width.
        assert k3_post["sd"] < 0.01 * k3_post["prior_sd"], msg
    else:
        assert lo < 0.0 < hi, msg


@pytest.mark.slow
def test_rbpf_accepts_effect_columns():
    """The Rao-Blackwellised filter runs on the augmented basis and reports every column."""
    _, _, _, augmented = _augmented(2e6)
    out = run_rbpf(augmented, n_particles=32, seed=1)
    assert out.piece_coefficients_mean.shape == (1, 22)
    k3 = out.piece_coefficients_mean[0, -1]
    assert abs(k3 / 2e6 - 1) < 0.02, k3


@pytest.fixture(scope="module")
def walk_csv(tmp_path_factory):
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=10.0,
        sample_rate_hz=100.0,
        noise_sd_n=2.0,
        start="rest",
        seed=4,
    )
    path = tmp_path_factory.mktemp("eff") / "walk.csv"
    save_record(sim.record, path)
    return path


@pytest.mark.slow
@pytest.mark.parametrize("method", ["pf", "rbpf"])
def test_identify_effects_json(walk_csv, capsys, method):
    code = main(
        [
            "identify",
            str(walk_csv),
            "--method",
            method,
            "--particles",
            "64" if method == "rbpf" else "200",
            "--obs-noise",
            "seed",
            "--harmonics",
            "4",
            "--effects",
            "gait_asymmetry",
            "--no-force-check",
            "--json",
        ]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    # A filter whose C or K is graded not identified keeps the effect's numbers under
    # conditional_on_prior_box (the force given C and K), null where estimates go.
    effects = out["effects"] or out["conditional_on_prior_box"]["effects"]
    assert (out["effects"] is None) == ("effects" in out["conditional_on_prior_box"])
    asym = effects["gait_asymmetry"]
    assert set(asym) == {"a_half_n", "b_half_n", "a_3half_n", "b_3half_n"}
    for entry in asym.values():
        assert entry["sd"] > 0 and entry["ci95"][0] < entry["mean"] < entry["ci95"][1]
        # No asymmetry was simulated: every band holds zero.
        assert entry["ci95"][0] < 0.0 < entry["ci95"][1], asym
    assert out["settings"]["effects"] == ["gait_asymmetry"]


def test_unknown_effect_is_one_sentence(walk_csv, capsys):
    code = main(["identify", str(walk_csv), "--effects", "wobble", "--json"])
    assert code == 2
    err = capsys.readouterr().err
    assert "wobble" in err and "Traceback" not in err
    with pytest.raises(UsageError):
        IdentifySettings.from_flat(effects=("cubic_stiffness", "cubic_stiffness"))


def test_effect_columns_of_the_catalogue(walk_csv):
    """Every catalogue effect gives named columns; state-acting ones use the observed u, u'."""
    from workbench.inference.pipeline.identification import compile_problem
    from workbench.models.effects import (
        BaseMotion,
        GaitAsymmetry,
        HeelImpact,
        PacingDrift,
        QuadraticDamping,
        StiffnessDrift,
    )
    from workbench.records.inspection import inspect_record
    from workbench.records.io import load_record

    rec = load_record(walk_csv)
    problem = compile_problem(inspect_record(rec), IdentifySettings.from_flat(harmonics=4))
    u, v, t = problem.y[:, 0], problem.y[:, 1], problem.time_s
    ground = 0.5 * np.sin(2 * np.pi * 2.7 * t)
    effects = [
        GaitAsymmetry(),
        CubicStiffness(),
        QuadraticDamping(),
        HeelImpact(decay_s=0.02),
        PacingDrift(),
        StiffnessDrift(),
        BaseMotion(),
    ]
    terms = effect_terms(problem, effects, ground_acc_m_s2=ground)
    assert terms.columns.shape == (problem.n_samples, 4 + 1 + 1 + 1 + 4 + 2 + 2)
    assert terms.names[4] == "cubic_stiffness.k3_n_per_m3"
    assert terms.names[6] == "heel_impact.impact_n"
    # Force columns are minus the left-hand-side terms.
    np.testing.assert_allclose(terms.columns[:, 4], -(u**3))
    np.testing.assert_allclose(terms.columns[:, 5], -np.abs(v) * v)
    np.testing.assert_allclose(terms.columns[:, 11:13], -np.column_stack([t * u, t * v]))
    # The heel pulse peaks (at 1) decay_s after every footfall of the problem's steps.
    first = problem.piece_starts[1]
    lag = round(0.02 / problem.dt_s)
    assert terms.columns[first + lag, 6] == pytest.approx(1.0, abs=1e-9)
    assert np.all(terms.prior_sd > 0)
    with pytest.raises(UsageError, match="ground"):
        effect_terms(problem, [BaseMotion()])

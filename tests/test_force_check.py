"""The force-model check: it passes where the force model is right and flags misfit."""

from __future__ import annotations

import re

import numpy as np
import pytest

from workbench.errors import UsageError
from workbench.inference.core.problem import build_problem, seed_example_problem
from workbench.inference.pipeline.force_check import force_model_check, with_step_drift
from workbench.records.inspection import inspect_record
from workbench.synth.simulate import simulate_walking


def _walk(i: int, *, variability: bool):
    """Record ``i`` of analyses/coverage_study.py's sets (30 s, 100 Hz)."""
    kwargs = {} if variability else {"amplitude_sd": 0, "phase_sd_rad": 0, "step_duration_sd": 0}
    pacing = 1.5 + 0.8 * ((7 * i) % 20) / 19
    sim = simulate_walking(
        mass_kg=55.0 + 40.0 * i / 19,
        pacing_hz=pacing,
        duration_s=30.0,
        sample_rate_hz=100,
        noise_sd_n=2.0 + 3.0 * ((3 * i) % 20) / 19,
        start="rest" if i % 2 == 0 else "steady",
        seed=100 + i,
        **kwargs,
    )
    truth = np.array([sim.truth["damping_ns_per_m"], sim.truth["stiffness_n_per_m"]])
    return sim, pacing, truth


def test_step_drift_extends_the_basis_with_local_time() -> None:
    problem, _ = seed_example_problem(duration_s=2.0)
    rich = with_step_drift(problem, 3)
    m = problem.n_coefficients
    assert rich.basis.shape == (problem.n_samples, m + 6)
    np.testing.assert_array_equal(rich.basis[:, :m], problem.basis)
    local = np.arange(problem.n_samples) / problem.n_samples - 0.5
    np.testing.assert_allclose(rich.basis[:, m], problem.basis[:, 1] * local)
    np.testing.assert_allclose(rich.basis[:, m + 5], problem.basis[:, 6] * local)
    np.testing.assert_array_equal(rich.force_prior.sd_n[m:], problem.force_prior.sd_n[1:7])
    with pytest.raises(UsageError, match="modulated_harmonics"):
        with_step_drift(problem, 0)


@pytest.mark.slow
def test_passes_on_the_seed_example() -> None:
    """The force of eq. 24 is in the basis: the richer model finds the same (C, K)."""
    problem, truth = seed_example_problem(obs_fraction=0.01)
    check = force_model_check(problem)
    assert check.passed, check.to_json()
    assert np.all(check.z < 3.0)
    ref = np.array([truth["damping_ns_per_m"], truth["stiffness_n_per_m"]])
    np.testing.assert_allclose(check.reference_mode, ref, rtol=0.01)
    assert "do not move" in check.sentence


@pytest.mark.slow
@pytest.mark.parametrize("i", [0, 3])
def test_flags_the_misfit_of_simulated_walks(i: int) -> None:
    """Step-to-step variability splined through the steps is not a per-piece Fourier force.

    The reference mode lands far from the truth (a corner of the prior box) and the richer
    model moves it by many sd; the check must say so.
    """
    sim, _, truth = _walk(i, variability=True)
    insp = inspect_record(sim.record, highpass_hz=0.15)
    problem = build_problem(insp.com, insp.steps, obs_fraction=0.02, state_fraction=0.0)
    check = force_model_check(problem)
    assert not check.passed, check.to_json()
    assert np.any(np.abs(check.reference_mode - truth) > 0.2 * truth), check.to_json()
    assert re.search(r"\bdepends? on the force model", check.sentence), check.sentence
    assert check.to_json()["dependent"] == {
        "damping": bool(check.dependent[0]),
        "stiffness": bool(check.dependent[1]),
    }


@pytest.mark.slow
def test_passes_when_the_walk_is_in_the_model_class() -> None:
    """A periodic walk from rest, one piece at the true pacing, u'' observed: no flag."""
    sim, pacing, truth = _walk(0, variability=False)
    insp = inspect_record(sim.record, highpass_hz=0.0)
    problem = build_problem(
        insp.com,
        None,
        pieces="whole",
        time_basis="absolute",
        pacing_hz=pacing,
        obs_fraction=0.015,
        state_fraction=0.0,
        observe="acc",
    )
    check = force_model_check(problem)
    assert check.passed, check.to_json()
    np.testing.assert_allclose(check.reference_mode, truth, rtol=0.02)


def test_bad_threshold_is_a_usage_error() -> None:
    problem, _ = seed_example_problem(duration_s=1.0)
    with pytest.raises(UsageError, match="threshold"):
        force_model_check(problem, threshold=0.0)


def test_a_flag_on_one_parameter_marks_both_not_identified(monkeypatch) -> None:
    """C and K are estimated jointly: when the check moves one, neither is identified."""
    from dataclasses import replace

    import workbench.inference.pipeline.force_check as fc
    from workbench.inference.pipeline import gather_evidence, grade_identifiability, identify
    from workbench.inference.pipeline.settings import IdentifySettings

    sim, _, _ = _walk(0, variability=True)
    settings = IdentifySettings.from_flat(
        particles=32, obs_noise=0.1, harmonics=3, force_check=False
    )
    result = identify(sim.record.slice(0.0, 8.0), settings=settings)
    assert "force_model_check" not in result.identifiability
    fake = fc.ForceModelCheck(
        reference_mode=np.array([700.0, 9000.0]),
        rich_mode=np.array([1500.0, 9100.0]),
        reference_sd=np.array([10.0, 100.0]),
        rich_sd=np.array([40.0, 300.0]),
        z=np.array([20.0, 0.4]),
        dependent=np.array([True, False]),
        threshold=3.0,
        modulated_harmonics=3,
        sentence="C depends on the force model",
    )
    monkeypatch.setattr(fc, "force_model_check", lambda _problem: fake)
    evidence = gather_evidence(result, settings.replace(force_check=True))
    assert evidence.force_check is fake and evidence.force_check_skipped is None
    # The check's rule alone, without the prior-edge and collapse findings.
    ident = grade_identifiability(replace(evidence, at_prior_bound=(), collapsed=False))
    assert ident["level"] == "not identified"
    assert not ident["identified_damping"] and not ident["identified_stiffness"]
    assert "estimated jointly" in ident["sentence"]
    assert ident["force_model_check"]["z"] == [20.0, 0.4]

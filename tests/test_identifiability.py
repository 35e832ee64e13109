"""Identifiability measures: levels, sentences, force correlations, the seed example's fact."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from workbench.errors import UsageError
from workbench.inference.core.identifiability import (
    MOSTLY_PRIOR_CONTRACTION,
    WELL_IDENTIFIED_CONTRACTION,
    force_correlation,
    identifiability_report,
)

PRIOR_SD = np.array([900.0, 12000.0])


def report_for(contraction_c: float, contraction_k: float, **kw):
    return identifiability_report(
        PRIOR_SD * np.array([contraction_c, contraction_k]), PRIOR_SD, **kw
    )


# -- levels ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("contraction", "level", "identified"),
    [
        (0.04, "well identified", True),
        (WELL_IDENTIFIED_CONTRACTION * 0.999, "well identified", True),
        (WELL_IDENTIFIED_CONTRACTION, "weakly identified", True),
        (0.35, "weakly identified", True),
        (MOSTLY_PRIOR_CONTRACTION, "weakly identified", True),
        (MOSTLY_PRIOR_CONTRACTION * 1.001, "mostly prior", False),
        (0.7, "mostly prior", False),
        (1.0, "mostly prior", False),
    ],
)
def test_level_of_each_parameter(contraction: float, level: str, identified: bool) -> None:
    r = report_for(contraction, contraction)
    assert r.level_damping == r.level_stiffness == r.level == level
    assert r.identified_damping is r.identified_stiffness is identified
    assert r.contraction_damping == pytest.approx(contraction, rel=1e-12)


def test_overall_level_is_the_worse_one_and_sentence_names_both() -> None:
    r = report_for(0.7, 0.04)
    assert (r.level_stiffness, r.level_damping, r.level) == (
        "well identified",
        "mostly prior",
        "mostly prior",
    )
    assert r.identified_stiffness and not r.identified_damping
    assert r.sentence == (
        "K is well identified (posterior sd is 4 % of the prior's); C is mostly prior: its "
        "posterior sd is 70 % of the prior's, so the reported value says more about the prior "
        "range than about this record."
    )
    r2 = report_for(0.3, 0.1)
    assert r2.level == "weakly identified"
    assert "C is weakly identified (posterior sd is 30 % of the prior's)" in r2.sentence


def test_correlations_are_named_only_when_they_matter() -> None:
    quiet = report_for(0.3, 0.1, ck_correlation=0.5, max_force_correlation=(0.6, 0.99))
    # K is well identified: its dependence on the coefficients is not a problem to report.
    assert "correlated" not in quiet.sentence and "trade" not in quiet.sentence
    loud = report_for(0.6, 0.3, ck_correlation=-0.95, max_force_correlation=(0.97, 0.92))
    assert "strongly correlated (rho = -0.95)" in loud.sentence
    assert "C (max |rho| = 0.97) and K (max |rho| = 0.92) trade off" in loud.sentence
    # Correlations never change the level.
    assert loud.level_damping == "mostly prior" and loud.level_stiffness == "weakly identified"


def test_thresholds_are_arguments_and_to_json_is_plain() -> None:
    r = report_for(0.3, 0.3, well_identified=0.4, mostly_prior=0.6)
    assert r.level == "well identified"
    payload = r.to_json()
    json.dumps(payload, allow_nan=False)
    assert payload["ck_correlation"] is None  # unknown, not NaN
    assert payload["thresholds"]["well_identified_contraction"] == 0.4
    assert set(payload) >= {
        "level",
        "sentence",
        "identified_damping",
        "identified_stiffness",
        "contraction_damping",
        "contraction_stiffness",
        "max_force_correlation_damping",
        "max_force_correlation_stiffness",
    }


def test_mode_on_the_prior_edge_is_mostly_prior() -> None:
    r = report_for(0.3, 0.01, on_prior_edge=(False, True))
    assert r.level_stiffness == "mostly prior" and not r.identified_stiffness
    assert r.level_damping == "weakly identified"
    assert "K is mostly prior: its posterior is piled against the edge of the prior box" in (
        r.sentence
    )
    assert r.to_json()["on_prior_edge"] == {"damping": False, "stiffness": True}
    with pytest.raises(UsageError):
        report_for(0.3, 0.3, on_prior_edge=(True,))


def test_nan_contraction_claims_nothing() -> None:
    r = identifiability_report((np.nan, 10.0), PRIOR_SD)
    assert r.level_damping == "mostly prior" and not r.identified_damping


@pytest.mark.parametrize(
    "kwargs",
    [
        {"posterior_sd": (1.0,), "prior_sd": PRIOR_SD},
        {"posterior_sd": (1.0, 2.0), "prior_sd": (0.0, 1.0)},
        {"posterior_sd": (1.0, 2.0), "prior_sd": PRIOR_SD, "well_identified": 0.6},
    ],
)
def test_bad_arguments_are_usage_errors(kwargs) -> None:
    with pytest.raises(UsageError):
        identifiability_report(**kwargs)


# -- force correlation ----------------------------------------------------------------------
def test_force_correlation_matches_law_of_total_covariance() -> None:
    # (C, K) on three points with weights; E[theta | C, K] linear, Var constant: the joint
    # correlation has a closed form.
    c = np.array([400.0, 500.0, 600.0])
    k = np.array([9000.0, 12000.0, 9000.0])  # uncorrelated with C under w
    w = np.array([0.25, 0.5, 0.25])
    a, s = 2.0, 150.0
    mu = np.zeros((3, 2, 3))
    mu[:, 0, 0] = a * c  # piece 0, coefficient 0 follows C
    mu[:, 1, 2] = -0.01 * k  # piece 1, coefficient 2 follows K (negatively)
    var = np.full_like(mu, s**2)
    fc = force_correlation(c, k, w, mu, var, ("a0", "a1", "b1"))
    var_c = np.sum(w * (c - w @ c) ** 2)
    expected = a * var_c / (np.sqrt(var_c) * np.sqrt(s**2 + a**2 * var_c))
    assert fc.damping[0, 0] == pytest.approx(expected, rel=1e-12)
    assert fc.damping_between[0, 0] == pytest.approx(1.0, rel=1e-12)
    # Coefficients that do not vary with (C, K) have no defined between-correlation and a
    # zero joint one.
    assert np.isnan(fc.damping_between[0, 1])
    assert np.isnan(fc.damping[0, 1]) or fc.damping[0, 1] == 0.0
    assert fc.max_damping == pytest.approx(max(expected, abs(fc.damping[1, 2])), rel=1e-12)
    assert fc.argmax_stiffness == (1, "b1")
    assert fc.stiffness[1, 2] < 0
    # The joint correlation is never larger than the between-draws one.
    both = np.isfinite(fc.damping_between)
    assert np.all(np.abs(fc.damping[both]) <= np.abs(fc.damping_between[both]) + 1e-12)


def test_force_correlation_rejects_bad_shapes() -> None:
    with pytest.raises(UsageError):
        force_correlation([1.0], [2.0], [1.0], np.zeros((2, 1, 3)), np.zeros((2, 1, 3)))
    with pytest.raises(UsageError):
        force_correlation([1.0], [2.0], [0.0], np.zeros((1, 1, 3)), np.zeros((1, 1, 3)))


# -- the seed example's identifiability fact (docs/science.md 4) --------------------------------
def _window(com, t0_s: float, t1_s: float):
    sl = (com.time_s >= t0_s - 1e-9) & (com.time_s < t1_s - 1e-9)
    return dataclasses.replace(
        com,
        time_s=com.time_s[sl],
        acc_m_s2=com.acc_m_s2[sl],
        vel_m_s=com.vel_m_s[sl],
        disp_m=com.disp_m[sl],
        grf_n=None if com.grf_n is None else com.grf_n[sl],
    )


@pytest.mark.slow
def test_seed_example_transient_identifies_and_steady_state_does_not() -> None:
    """0-10 s (start-up transient) against 2-12 s (transient gone), same length and noise.

    docs/science.md 4: least squares on 0-20 s recovers C and K; after the transient
    ``K u + C u'`` lies in the span of the 0.5 Hz Fourier basis and they cannot be told
    apart from the force. The exact posterior must not call the second window well
    identified.

    What the posterior does there is not "flat = prior box", though: the noise model and
    the force prior are part of the model. With the seed's process noise (0.5 % of the RMS
    per sample) the likelihood of the steady window piles (C, K) into the lower corner of
    the prior box with a narrow posterior; with a hundredth of that process noise K still
    piles onto the lower face (C about 1100 +- 130). The default ForcePrior (sd 0.5 M g / i)
    is narrow for eq. 24's force (b3 .. b8 lie 2.4-4.3 prior sd out), so once the data
    stop informing (C, K), the force prior pulls them. The report catches this through the
    mode on the prior box's face, which makes a parameter "mostly prior".
    """
    from workbench.inference.core.problem import build_problem
    from workbench.inference.methods.exact import exact_posterior
    from workbench.records.preprocess import preprocess
    from workbench.synth.simulate import seed_numerical_example

    sim = seed_numerical_example(duration_s=12.0)
    com = preprocess(sim.record, highpass_hz=0)
    truth = np.array([sim.truth["damping_ns_per_m"], sim.truth["stiffness_n_per_m"]])
    reports = {}
    for name, (t0, t1) in {"transient": (0.0, 10.0), "steady": (2.0, 12.0)}.items():
        problem = build_problem(
            _window(com, t0, t1),
            None,
            pieces="whole",
            pacing_hz=0.5,
            time_basis="absolute",
            harmonics=10,
            obs_fraction=0.01,
        )
        post = exact_posterior(problem)
        reports[name] = (post, post.identifiability)
    post_t, rep_t = reports["transient"]
    post_s, rep_s = reports["steady"]
    msg = (
        f"transient: mean {post_t.mean}, contraction {post_t.contraction}, {rep_t.level}; "
        f"steady: mean {post_s.mean}, contraction {post_s.contraction}, {rep_s.level}, "
        f"mode on the prior edge {rep_s.on_prior_edge}, notes {post_s.notes}"
    )
    print(msg)
    assert rep_t.level == "well identified", msg
    assert not any(rep_t.on_prior_edge), msg
    assert np.all(np.abs(post_t.mean / truth - 1) < 0.02), msg
    assert rep_s.level != "well identified", msg
    assert not (rep_s.identified_damping and rep_s.identified_stiffness), msg

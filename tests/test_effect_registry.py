"""One effect registry: specs, an effect's own criticism and identification columns, results."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Iterator

import numpy as np
import pytest

from workbench.diagnostics.criticism import (
    CATALOGUE,
    Comparison,
    candidate_effects,
    compare,
    diagnose,
    prepare,
)
from workbench.errors import UsageError
from workbench.inference.core.problem import build_problem
from workbench.inference.pipeline.effect_terms import effect_terms
from workbench.models import (
    CubicStiffness,
    Effect,
    EffectContext,
    GaitAsymmetry,
    HeelImpact,
    Parameter,
    SMDModel,
    register_effect,
    unregister_effect,
)
from workbench.models.effects import Effects, parse_effect_specs, split_effect_specs
from workbench.records.preprocess import preprocess
from workbench.synth import simulate_walking


# -- specs ----------------------------------------------------------------------------------
def test_from_spec_reads_name_and_parameters() -> None:
    assert Effect.from_spec("cubic_stiffness") == CubicStiffness()
    assert Effect.from_spec(" cubic_stiffness:k3_n_per_m3=2e6 ") == CubicStiffness(k3_n_per_m3=2e6)
    both = GaitAsymmetry(a_half_n=20.0, b_half_n=-10.0)
    assert Effect.from_spec("gait_asymmetry:a_half_n=20:b_half_n=-10") == both
    # The syntax of simulate --effect: parameters separated by commas.
    assert Effect.from_spec("gait_asymmetry:a_half_n=20,b_half_n=-10") == both
    assert CubicStiffness.from_spec("cubic_stiffness:k3_n_per_m3=1") == CubicStiffness(
        k3_n_per_m3=1.0
    )


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        ("wobble", "'wobble' is not known; use one of"),
        ("wobble:k=1", "'wobble' is not known"),
        (":k3_n_per_m3=1", "does not start with an effect name"),
        ("cubic_stiffness:k3", "'k3' is not of the form PARAMETER=NUMBER"),
        ("cubic_stiffness:k3=1", "cubic_stiffness has no parameter 'k3'; use one of k3_n_per_m3"),
        ("cubic_stiffness:k3_n_per_m3=big", "the value of 'k3_n_per_m3' ('big') is not a number"),
        ("cubic_stiffness:k3_n_per_m3=1:k3_n_per_m3=2", "'k3_n_per_m3' is given twice"),
        ("cubic_stiffness:k3_n_per_m3=inf", "must be finite"),
    ],
)
def test_bad_spec_is_one_sentence_naming_the_part(spec: str, words: str) -> None:
    with pytest.raises(UsageError, match=re.escape(words)) as err:
        Effect.from_spec(spec)
    assert "\n" not in str(err.value)


def test_from_spec_on_a_subclass_needs_its_name() -> None:
    with pytest.raises(UsageError, match="names 'gait_asymmetry', not 'cubic_stiffness'"):
        CubicStiffness.from_spec("gait_asymmetry")


def test_parse_effect_specs_reads_lists() -> None:
    text = "gait_asymmetry:a_half_n=20,b_half_n=10,cubic_stiffness"
    assert split_effect_specs(text) == ["gait_asymmetry:a_half_n=20,b_half_n=10", "cubic_stiffness"]
    effects = parse_effect_specs(text)
    assert effects == Effects([GaitAsymmetry(a_half_n=20, b_half_n=10), CubicStiffness()])
    assert parse_effect_specs(None) == Effects()
    assert parse_effect_specs(" , ") == Effects()
    assert parse_effect_specs(["cubic_stiffness:k3_n_per_m3=5", HeelImpact()]).names == (
        "cubic_stiffness",
        "heel_impact",
    )
    assert parse_effect_specs(CubicStiffness()).names == ("cubic_stiffness",)
    with pytest.raises(UsageError, match=r"^--effects wobble: effect 'wobble' is not known"):
        parse_effect_specs("wobble", where="--effects")
    with pytest.raises(UsageError, match="start with a parameter"):
        parse_effect_specs("k3_n_per_m3=1,cubic_stiffness")
    with pytest.raises(UsageError, match="added twice"):
        parse_effect_specs("cubic_stiffness,cubic_stiffness")


# -- a user-written effect needs nothing but @register_effect -------------------------------
class SwayCoupling(Effect):
    """User-written linear effect: the force follows ``u`` times the pacing's phase."""

    name = "sway_coupling"
    reason = "the error follows u cos(phi): the spring's force changes over the step"
    parameters = (Parameter("k_sway_n_per_m", "N/m", 0.0, "sway coupling"),)

    def regressors(self, u, v, t_s, context=None):  # type: ignore[no-untyped-def]
        u, _, t = self.broadcast(u, v, t_s)
        return (u * np.cos(context.step_phase_rad(t)))[..., None]


class StiffStop(Effect):
    """User-written nonlinear effect without criticism columns."""

    name = "stiff_stop"
    linear = False
    parameters = (Parameter("k_stop_n_per_m", "N/m", 0.0, "stop stiffness"),)

    def force(self, u, v, t_s, theta=None, context=None):  # type: ignore[no-untyped-def]
        u, _, _ = self.broadcast(u, v, t_s)
        (k,) = self.split_theta(theta)
        return k * np.maximum(u - 0.05, 0.0)


@pytest.fixture
def user_effects() -> Iterator[None]:
    register_effect(SwayCoupling)
    register_effect(StiffStop)
    try:
        yield
    finally:
        unregister_effect("sway_coupling")
        unregister_effect("stiff_stop")


def _walk(effects=()):  # type: ignore[no-untyped-def]
    return simulate_walking(
        duration_s=24.0,
        sample_rate_hz=200.0,
        noise_sd_n=5.0,
        seed=7,
        pacing_hz=1.9,
        mass_kg=70.0,
        start="steady",
        effects=effects,
    ).record


def test_user_effect_is_a_candidate_and_a_compare_row(user_effects: None) -> None:
    names = [e.name for e in candidate_effects()]
    assert names[: len(CATALOGUE)] == list(CATALOGUE)
    assert "sway_coupling" in names
    assert "stiff_stop" not in names  # nonlinear without criticism columns
    with pytest.raises(UsageError, match="'stiff_stop' cannot be criticised"):
        candidate_effects("stiff_stop")
    data = prepare(_walk())
    # Its default criticism columns are its regressors on the measured state.
    cols = SwayCoupling().criticism_columns(data)
    assert cols is not None
    np.testing.assert_allclose(
        cols[:, 0],
        data.disp_m
        * np.cos(EffectContext(step_start_s=data.footfall_times_s).step_phase_rad(data.time_s)),
    )
    diag = diagnose(data, folds=5)
    mine = next(c for c in diag.candidates if c.effect == "sway_coupling")
    assert mine.testable and "; ; " not in mine.evidence
    rows = compare(data, ["sway_coupling:k_sway_n_per_m=3"], folds=5)
    assert [r.model for r in rows] == ["baseline", "baseline + sway_coupling"]
    assert candidate_effects("sway_coupling") == (SwayCoupling(),)


def test_user_effect_in_identification(user_effects: None) -> None:
    com = preprocess(_walk(), highpass_hz=0.15)
    problem = build_problem(com, None, pieces="whole", pacing_hz=1.9, harmonics=3)
    terms = effect_terms(problem, ["sway_coupling", HeelImpact(decay_s=0.02)])
    assert terms.names == ("sway_coupling.k_sway_n_per_m", "heel_impact.impact_n")
    cols, names = SwayCoupling().identification_columns(
        problem.y[:, 0], problem.y[:, 1], problem.time_s, EffectContext(step_start_s=[0.0, 1e3])
    )
    assert cols.shape == (problem.n_samples, 1) and names == ("sway_coupling.k_sway_n_per_m",)
    with pytest.raises(UsageError, match="nonlinear in its parameters"):
        effect_terms(problem, [StiffStop()])


# -- the current model and the results --------------------------------------------------------
@pytest.fixture(scope="module")
def data():  # type: ignore[no-untyped-def]
    return prepare(_walk([HeelImpact(impact_n=200.0, decay_s=0.015)]))


def test_diagnose_and_compare_take_the_model(data) -> None:  # type: ignore[no-untyped-def]
    model = SMDModel(mass_kg=70.0, harmonics=6) + HeelImpact()
    by_model = diagnose(data, model, folds=5)
    by_names = diagnose(data, effects=["heel_impact"], folds=5)
    assert by_model.to_json() == by_names.to_json()
    assert by_model.current_effects == ("heel_impact",)
    assert diagnose(data, SMDModel(harmonics=4), folds=5).baseline["harmonics"] == 4
    with pytest.raises(UsageError, match="given twice"):
        diagnose(data, model, effects=["heel_impact"])
    with pytest.raises(UsageError, match="must be an SMDModel"):
        diagnose(data, ["heel_impact"])  # type: ignore[arg-type]
    rows = compare(data, model, folds=5)
    assert rows.to_json() == compare(data, ["heel_impact"], folds=5).to_json()
    more = compare(data, ["gait_asymmetry"], model=model, folds=5)
    assert [r.model for r in more][-1] == "baseline + heel_impact + gait_asymmetry"


def test_results_are_immutable_with_summaries(data) -> None:  # type: ignore[no-untyped-def]
    diag = diagnose(data, folds=5)
    assert diag.to_dict() == diag.to_json()
    text = diag.summary()
    for word in ("baseline held-out RMSE", "separable", "heel_impact", "verdict: "):
        assert word in text
    with pytest.raises(dataclasses.FrozenInstanceError):
        diag.verdict = "x"  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        diag.candidates[0].significant = False  # type: ignore[misc]
    assert isinstance(diag.candidates, tuple)
    assert isinstance(diag.candidates[0].to_json()["indistinguishable_from"], list)
    rows = compare(data, ["heel_impact", "gait_asymmetry"], folds=5)
    assert isinstance(rows, Comparison) and len(rows) == 3
    assert rows[0].model == "baseline" and len(rows[1:]) == 2
    assert rows.to_json() == {"rows": [r.to_dict() for r in rows]}
    assert "baseline + heel_impact" in rows.summary()
    with pytest.raises(dataclasses.FrozenInstanceError):
        rows[0].score = 0.0  # type: ignore[misc]


def test_one_step_residuals_join_a_copy(data) -> None:  # type: ignore[no-untyped-def]
    diag = diagnose(data, candidates=[], folds=5)

    class OneStep:
        rmse_n = 1.0

        def to_dict(self):  # type: ignore[no-untyped-def]
            return {"one_step_rmse_n": 1.0}

    one = OneStep()
    joined = diag.with_one_step(one)
    assert joined.one_step is one and joined.baseline["one_step_rmse_n"] == 1.0
    assert diag.one_step is None and "one_step_rmse_n" not in diag.baseline
    with pytest.raises(dataclasses.FrozenInstanceError):
        diag.one_step = one  # type: ignore[misc]

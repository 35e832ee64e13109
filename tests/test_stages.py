"""The stages of identify, run one by one, and the one grading step.

``identify`` is the stages in order (workbench.inference.pipeline), so running them by hand
must give the same result: the same draws, the same route, the same graded report and the
same JSON. The grading step reproduces the order of its rules: the force-model check, the
deck's rule (which keeps an earlier "not identified") and the prior-edge or collapse rule
(which says its own sentence and appends a failed check's).
"""

from __future__ import annotations

import json
import pickle
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import workbench as wb
from workbench.inference import pipeline as stages
from workbench.inference.pipeline.force_check import ForceModelCheck
from workbench.inference.pipeline.grading import CHECK_NOT_APPLICABLE, GradingEvidence

CASES = {
    # A rigid floor, a particle filter and the force-model check (which fails here).
    "rigid": ("seed_individual", 8.0, wb.SMDModel(harmonics=4), wb.RBPF(64)),
    # An effect: its columns join the force basis, its posterior is reported.
    "effect": (
        "seed_individual",
        8.0,
        wb.SMDModel(harmonics=4) + wb.effects.GaitAsymmetry(),
        wb.RBPF(32),
    ),
    # A deck read through its transmissibility although the rbpf was asked for.
    "deck": ("seed_individual_deck", 15.0, wb.SMDModel(harmonics=4), wb.RBPF(32)),
    # The same deck with the joint surface model: the time history, surface coupled.
    "deck joint": (
        "seed_individual_deck",
        15.0,
        wb.SMDModel(harmonics=4, surface="joint"),
        wb.Exact(n_draws=400),
    ),
}


def _by_hand(record: wb.Record, settings: stages.IdentifySettings) -> wb.IdentificationResult:
    prepared = stages.prepare(record, settings)
    problem = stages.compile_problem(prepared, settings)
    problem, noise = stages.set_noise(problem, settings)
    problem, effects = stages.add_effects(problem, prepared, settings)
    route = stages.choose_route(problem, settings)
    result = stages.run_route(
        problem, route, settings, prepared=prepared, effects=effects, noise=noise
    )
    return stages.grade(result, settings)


#: Cases that take over ten seconds (an effect's pilot fit, the joint deck's exact grid).
SLOW = {"effect", "deck joint"}


@pytest.mark.parametrize(
    "case", [pytest.param(c, marks=[pytest.mark.slow] if c in SLOW else []) for c in CASES]
)
def test_the_stages_by_hand_give_what_identify_gives(case: str) -> None:
    name, seconds, model, method = CASES[case]
    record = wb.datasets.load(name).slice(0, seconds)
    settings = stages.IdentifySettings(model=model, method=method, seed=2)
    res = wb.identify(record, settings=settings)
    hand = _by_hand(record, settings)
    np.testing.assert_array_equal(hand.draws, res.draws)
    np.testing.assert_array_equal(hand.weights, res.weights)
    assert hand.route == res.route
    assert hand.identifiability == res.identifiability
    assert list(hand.identifiability) == list(res.identifiability)
    assert json.dumps(hand.to_json(), default=float) == json.dumps(res.to_json(), default=float)
    # Batch work sends results between processes, models with effects included.
    back = pickle.loads(pickle.dumps(res))
    assert back.model == res.model
    assert json.dumps(back.to_json(), default=float) == json.dumps(res.to_json(), default=float)
    # The typed parts say what ran and where C and K came from.
    assert res.route is not None and res.surface is not None
    assert res.route.requested_method == method.name
    assert res.surface.to_json() == res.to_json()["surface"] or res.not_identified
    if case == "deck":
        assert res.route.through_surface and res.route.method == "exact" == res.method
        assert res.route.bins == res.to_json()["surface"]["transmissibility"]["bins"]
        assert res.filter_results is None and res.grid_results is not None
        assert "force_model_check" not in res.identifiability
    else:
        assert res.route.c_and_k_from == "time history"
        assert res.surface.c_and_k_from in (None, "time history")
        assert res.method == method.name
        assert "force_model_check" in res.identifiability
    if method.name == "rbpf" and not res.route.through_surface:
        assert res.filter_results is not None and res.grid_results is None
        assert res.filter_results.n_particles == method.n_particles
        assert res.to_json()["diagnostics"]["n_particles"] == method.n_particles
        assert not res.filter_results.collapse_on_few_ancestors  # the rbpf's moves renew values
    if case == "effect":
        assert res.effects is not None
        assert set(res.effects.to_json()) == {"gait_asymmetry", "pilot"}
    else:
        assert res.effects is None and "effects" not in res.to_json()


def _check(passed: bool) -> ForceModelCheck:
    return ForceModelCheck(
        reference_mode=np.array([700.0, 9000.0]),
        rich_mode=np.array([1500.0, 9100.0]),
        reference_sd=np.array([10.0, 100.0]),
        rich_sd=np.array([40.0, 300.0]),
        z=np.array([0.5, 0.4]) if passed else np.array([20.0, 0.4]),
        dependent=np.array([not passed, False]),
        threshold=3.0,
        modulated_harmonics=3,
        sentence="C does not depend on the force model" if passed else "C moved 20 sd",
    )


METHOD_REPORT = {
    "level": "well identified",
    "sentence": "K and C are well identified.",
    "identified_damping": True,
    "identified_stiffness": True,
    "level_damping": "well identified",
}
NOTHING = GradingEvidence(
    method_report=METHOD_REPORT,
    force_check=None,
    force_check_skipped=CHECK_NOT_APPLICABLE,
    deck_only_near_gait_harmonics=False,
    force_redrawn_every_step=True,
    at_prior_bound=(),
    collapsed=False,
)


def test_grading_keeps_the_method_report_when_no_rule_applies() -> None:
    report = stages.grade_identifiability(NOTHING)
    assert report == METHOD_REPORT and list(report) == list(METHOD_REPORT)
    passed = stages.grade_identifiability(replace(NOTHING, force_check=_check(True)))
    assert list(passed) == [*METHOD_REPORT, "force_model_check"]
    assert passed["level"] == "well identified" and passed["force_model_check"]["passed"]


def test_grading_applies_its_rules_in_order() -> None:
    failed = replace(NOTHING, force_check=_check(False), force_check_skipped=None)
    report = stages.grade_identifiability(failed)
    assert report["level"] == "not identified"
    assert (
        report["sentence"]
        == "Not identified: C moved 20 sd; the other is estimated jointly with it."
    )
    assert not report["identified_damping"] and not report["identified_stiffness"]
    # An earlier "not identified" keeps its sentence against the deck's rule.
    deck = replace(failed, deck_only_near_gait_harmonics=True)
    assert stages.grade_identifiability(deck) == report
    only_deck = stages.grade_identifiability(replace(NOTHING, deck_only_near_gait_harmonics=True))
    assert only_deck["sentence"].startswith("Not identified: the deck moved only near")
    # ... which is about a force redrawn every step.
    whole = replace(NOTHING, deck_only_near_gait_harmonics=True, force_redrawn_every_step=False)
    assert stages.grade_identifiability(whole) == METHOD_REPORT
    # The prior-edge rule says its own sentence and appends the failed check's.
    bound = stages.grade_identifiability(replace(deck, at_prior_bound=("stiffness_n_per_m",)))
    assert bound["sentence"].startswith("Not identified: stiffness K sits at the edge")
    assert bound["sentence"].endswith(" Also, C moved 20 sd.")
    assert list(bound) == [*METHOD_REPORT, "force_model_check"]
    collapsed = stages.grade_identifiability(replace(NOTHING, collapsed=True))
    assert collapsed["sentence"].startswith("Not identified: the particle cloud collapsed,")
    assert "Also" not in collapsed["sentence"]
    # A method report without a level gets the keys in the order the rules write them.
    empty = stages.grade_identifiability(replace(NOTHING, method_report={}, collapsed=True))
    assert list(empty) == ["level", "sentence", "identified_damping", "identified_stiffness"]


def test_the_guide_runs_the_stages_one_by_one(capsys: pytest.CaptureFixture[str]) -> None:
    """The block of docs/guide/identify.md, "The stages one by one", runs and says what the
    page says it prints."""
    page = (Path(__file__).parents[1] / "docs" / "guide" / "identify.md").read_text("utf-8")
    section = page.split("## The stages one by one", 1)[1]
    block = re.search(r"```python\n(.*?)```", section, re.S)
    assert block is not None
    scope: dict[str, object] = {}
    exec(compile(block.group(1), "identify.md", "exec"), scope)  # its asserts compare
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "rbpf exact transmissibility"
    assert "whatever method was asked for (rbpf here)" in lines[1]
    assert lines[2] == CHECK_NOT_APPLICABLE

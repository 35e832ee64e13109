"""The JSON comparison of ``analyses/behaviour_check.py`` (no workbench command is run)."""

from __future__ import annotations

import copy
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "analyses" / "behaviour_check.py"


@pytest.fixture(scope="module")
def bc() -> ModuleType:
    spec = importlib.util.spec_from_file_location("analyses_behaviour_check", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while being built
    spec.loader.exec_module(module)
    return module


TREE = {
    "method": "exact",
    "stiffness_n_per_m": 8940.123456789,
    "blf": [0.212, 0.042, 0.049],
    "identifiability": {"level": "well identified", "contraction_damping": 0.026828},
    "warnings": ["C moves from 193.1 to 2624 (21 sd)"],
    "loglik": 80490.02026659624,
    "near_zero": 1e-17,
    "missing": None,
}


def _copy(tree):
    return copy.deepcopy(tree)


def test_identical_trees(bc):
    result = bc.compare_trees(TREE, _copy(TREE))
    assert result.status == "identical"
    assert result.leaves == 11
    assert bc.describe(result).startswith("identical")


def test_rounding_level_difference_is_accepted(bc):
    after = _copy(TREE)
    after["loglik"] *= 1 + 3e-12
    after["near_zero"] = -4e-17  # under the absolute floor: not the largest relative
    result = bc.compare_trees(TREE, after)
    assert result.status == "rounding"
    assert result.max_rel_key == "loglik"
    assert "loglik" in bc.describe(result)


def test_last_printed_digit_flip_is_rounding(bc):
    before = bc.load_json('{"x": 0.026828, "s": "moves C from 193.1 to 2624"}')
    after = bc.load_json('{"x": 0.026829, "s": "moves C from 193.2 to 2624"}')
    result = bc.compare_trees(before, after)
    assert result.status == "rounding", result.differences
    assert result.printed == ["x", "s#0"]


def test_round_constant_is_not_excused_by_printing(bc):
    # A prior bound printed 0.05 that becomes 0.06 is a change, not a rounding flip.
    result = bc.compare_trees(bc.load_json('{"lo": 0.05}'), bc.load_json('{"lo": 0.06}'))
    assert result.status == "different"


def test_real_difference_is_reported_with_its_key(bc):
    after = _copy(TREE)
    after["identifiability"]["contraction_damping"] = 0.03
    after["warnings"] = ["C moves from 150.0 to 2624 (30 sd)"]
    result = bc.compare_trees(TREE, after)
    assert result.status == "different"
    assert result.differences[0].startswith("identifiability.contraction_damping")
    assert result.differences[1].startswith("warnings[0]")
    assert "DIFFERENT (identifiability.contraction_damping" in bc.describe(result)


def test_changed_wording_is_different(bc):
    after = _copy(TREE)
    after["identifiability"]["level"] = "mostly prior"
    assert bc.compare_trees(TREE, after).differences == [
        "identifiability.level: 'well identified' -> 'mostly prior'"
    ]


def test_ignored_keys_are_ignored(bc):
    before = {**TREE, "elapsed_s": 12.5, "version": "0.1.0"}
    after = {**_copy(TREE), "elapsed_s": 99.0, "version": "0.2.0"}
    assert bc.compare_trees(before, after).status == "identical"
    # Present on one side only is fine too: a timing field may be added by the change.
    assert bc.compare_trees(TREE, {**_copy(TREE), "elapsed_s": 1.0}).status == "identical"
    assert bc.IGNORED_KEYS.get("elapsed_s")  # with its reason


def test_structure_change_is_reported(bc):
    after = _copy(TREE)
    del after["method"]
    after["extra"] = 1
    after["blf"] = after["blf"][:2]
    after["missing"] = 0.0
    differences = bc.compare_trees(TREE, after).differences
    assert differences[0] == "<root>: keys only before ['method'], only after ['extra']"
    assert "blf: length 3 -> 2" in differences
    assert any(d.startswith("missing: NoneType None -> float") for d in differences)


def test_nested_list_of_dicts_keys(bc):
    before = {"steps": [{"z": 1.0}, {"z": 2.0}]}
    after = {"steps": [{"z": 1.0}, {"z": 2.5}]}
    assert bc.compare_trees(before, after).differences == ["steps[1].z: 2.0 -> 2.5"]


def test_tolerances_are_settable(bc):
    after = _copy(TREE)
    after["loglik"] *= 1 + 1e-5
    assert bc.compare_trees(TREE, after).status == "different"
    assert bc.compare_trees(TREE, after, rtol=1e-4).status == "rounding"


def test_near_zero_values_are_not_the_largest_relative_difference(bc):
    after = {**_copy(TREE), "near_zero": -4e-17}
    result = bc.compare_trees(TREE, after)
    assert result.status == "rounding"
    assert result.floored == ["near_zero"] and result.max_rel_key == ""
    assert "under the absolute floor at near_zero" in bc.describe(result)


def _run(bc, code, stdout="", stderr=""):
    return bc.Run(code, stdout, stderr, 1.0, None)


def test_judge_one_sided_failure_and_missing_flag(bc):
    case = bc.Case("seed_individual", "identify", ("identify", "seed_individual", "--json"))
    ok = _run(bc, 0, '{"k": 1.0}')
    failed = _run(bc, 1, "", "Traceback ...\nValueError: boom")
    outcome = bc.judge(case, ok, failed, {}, 1e-6, 1e-9)
    assert outcome.status == "different" and "exit 0 -> 1" in outcome.detail
    assert "ValueError: boom" in outcome.detail
    missing = _run(bc, 2, "", "workbench: error: unrecognized arguments: --max-steps")
    assert bc.judge(case, missing, ok, {}, 1e-6, 1e-9).status == "not comparable"
    assert bc.judge(case, ok, _run(bc, None), {}, 1e-6, 1e-9).detail == "timed out (after)"
    assert bc.judge(case, ok, _run(bc, 0, '{"k": 1.0}'), {}, 1e-6, 1e-9).status == "identical"

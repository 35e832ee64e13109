"""A quantity graded not identified is never shown as an estimate (Python, text, JSON).

The fast tests grade a real identification differently (the report is the only input of the
presentation) and check every view; the slow ones run ``workbench identify`` on the embedded
records the workbench grades not identified.
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

import numpy as np
import pytest

import workbench as wb
from workbench.cli import output as cli_output
from workbench.cli.main import main
from workbench.inference.core.results import CONDITIONAL_KEY, SCALAR_KEYS
from workbench.synth.simulate import simulate_walking

ROW_LABELS = {
    "stiffness_n_per_m": "K [N/m]",
    "damping_ns_per_m": "C [N s/m]",
    "natural_frequency_hz": "natural frequency [Hz]",
    "damping_ratio": "damping ratio",
}


@pytest.fixture(scope="module")
def result() -> wb.IdentificationResult:
    """12 s of walking from rest, which identifies C and K (as in tests/test_api.py)."""
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=12.0,
        sample_rate_hz=100,
        noise_sd_n=3.0,
        start="rest",
        seed=21,
    )
    model = wb.SMDModel(harmonics=4) + wb.effects.GaitAsymmetry()
    return wb.identify(sim.record, model, method=wb.RBPF(n_particles=64), seed=3, force_check=False)


def _graded(result: wb.IdentificationResult, **report: Any) -> wb.IdentificationResult:
    return result.replace(identifiability={**result.identifiability, **report})


def _row(text: str, key: str) -> str:
    """The text table's row of ``key``, after its label (which holds the unit's brackets)."""
    (line,) = [ln for ln in text.splitlines() if ln.startswith(ROW_LABELS[key])]
    return line[len(ROW_LABELS[key]) :]


def test_an_identified_result_shows_every_number(result: wb.IdentificationResult) -> None:
    assert result.identifiability["identified_damping"]
    assert result.identifiability["identified_stiffness"]
    assert result.not_identified == []
    assert result.params.notna().all() and result.conf_int().notna().all().all()
    out = result.to_json()
    assert out[CONDITIONAL_KEY] == {}
    for key in SCALAR_KEYS:
        assert out[key] == pytest.approx(result.estimates[key])
        assert out["interval_95"][key] == pytest.approx(list(result.interval()[key]))
    assert out["blf"] == pytest.approx(list(result.blf))
    assert "not identified" not in result.summary()


def test_c_not_identified_hides_c_zeta_and_the_force_but_keeps_k(
    result: wb.IdentificationResult,
) -> None:
    graded = _graded(result, identified_damping=False, level="not identified")
    hidden = {"damping_ns_per_m", "damping_ratio"}
    assert {graded.grade(k) for k in hidden} == {"not identified"}
    assert graded.grade("stiffness_n_per_m") == "well identified"
    # The BLFs and the effect's coefficients are the force given C and K.
    assert graded.grade("blf1") == graded.grade("gait_asymmetry.a_half_n") == "not identified"
    assert set(graded.not_identified) == set(result.params.index) - {
        "stiffness_n_per_m",
        "natural_frequency_hz",
    }

    params, bse, ci = graded.params, graded.bse, graded.conf_int()
    assert params[graded.not_identified].isna().all() and bse[graded.not_identified].isna().all()
    assert ci.loc[graded.not_identified].isna().all().all()
    assert params["stiffness_n_per_m"] == pytest.approx(result.estimates["stiffness_n_per_m"])
    assert list(ci.loc["stiffness_n_per_m"]) == pytest.approx(
        list(result.interval()["stiffness_n_per_m"])
    )
    # The withheld numbers are kept, named conditional, equal to what was withheld.
    kept = graded.conditional_on_prior_box()
    assert list(kept.index) == graded.not_identified
    assert kept.loc["damping_ns_per_m", "estimate"] == pytest.approx(
        result.estimates["damping_ns_per_m"]
    )
    assert kept.loc["blf1", "estimate"] == pytest.approx(result.blf[0])

    out = json.loads(json.dumps(graded.to_json()))  # strict JSON: no NaN
    for key in hidden:
        assert out[key] is None and out["posterior_sd"][key] is None
        assert out["interval_95"][key] is None
        cond = out[CONDITIONAL_KEY][key]
        assert cond["estimate"] == pytest.approx(result.estimates[key])
        assert cond["interval_95"] == pytest.approx(list(result.interval()[key]))
        lo, hi = cond["prior_range"]
        assert lo < cond["estimate"] < hi
    assert out["interval_95"]["stiffness_n_per_m"] == pytest.approx(
        list(result.interval()["stiffness_n_per_m"])
    )
    assert out["blf"] is None and out["posterior_sd"]["blf"] is None and out["effects"] is None
    assert out[CONDITIONAL_KEY]["blf"]["estimate"] == pytest.approx(list(result.blf))
    assert "gait_asymmetry" in out[CONDITIONAL_KEY]["effects"]

    text = graded.summary()
    c_lo, c_hi = result.interval()["damping_ns_per_m"]
    for number in (result.estimates["damping_ns_per_m"], c_lo, c_hi):
        assert f"{number:.1f}" not in text
    for key in hidden:
        assert "not identified" in _row(text, key) and "prior range" in _row(text, key)
        assert "[" not in _row(text, key)
    assert not re.search(r"^BLF\d", text, re.M)
    k_lo, k_hi = result.interval()["stiffness_n_per_m"]
    assert f"[{k_lo:.0f}, {k_hi:.0f}]" in _row(text, "stiffness_n_per_m")


def test_the_prior_range_is_the_box_in_each_quantity(result: wb.IdentificationResult) -> None:
    (c_lo, c_hi), (k_lo, k_hi) = (
        result.problem.prior.damping_ns_per_m,
        result.problem.prior.stiffness_n_per_m,
    )
    m = result.mass_kg
    assert result.prior_range("stiffness_n_per_m") == (k_lo, k_hi)
    f_lo, f_hi = result.prior_range("natural_frequency_hz")
    assert (2 * math.pi * f_lo) ** 2 * m == pytest.approx(k_lo)
    assert (2 * math.pi * f_hi) ** 2 * m == pytest.approx(k_hi)
    # Every corner of the (C, K) box lies within the damping ratio's range.
    z_lo, z_hi = result.prior_range("damping_ratio")
    corners = [c / (2 * np.sqrt(k * m)) for c in (c_lo, c_hi) for k in (k_lo, k_hi)]
    assert min(corners) == pytest.approx(z_lo) and max(corners) == pytest.approx(z_hi)


def test_weakly_identified_keeps_its_numbers_with_the_grade(
    result: wb.IdentificationResult,
) -> None:
    graded = _graded(result, level_damping="weakly identified", level="weakly identified")
    assert graded.not_identified == []
    assert graded.grade("damping_ratio") == "weakly identified"
    assert graded.grade("natural_frequency_hz") == "well identified"
    row = _row(graded.summary(), "damping_ns_per_m")
    assert f"{result.estimates['damping_ns_per_m']:.1f}" in row and "weakly identified" in row
    assert "weakly identified" not in _row(graded.summary(), "stiffness_n_per_m")
    assert graded.to_json()["interval_95"]["damping_ns_per_m"] is not None


def _identify_cli(
    name: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> tuple[dict[str, Any], str]:
    """``workbench identify NAME --json``: the JSON printed and the text it would print."""
    texts: list[str] = []
    real_emit = cli_output.emit

    def emit(args: Any, obj: dict[str, Any], text: str) -> None:
        texts.append(text)
        real_emit(args, obj, text)

    monkeypatch.setattr(cli_output, "emit", emit)
    assert main(["identify", name, "--json"]) == 0
    return json.loads(capsys.readouterr().out), texts[0]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["insole", "seed_individual", "treadmill"])
def test_embedded_records_graded_not_identified_print_no_estimate(
    name: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    out, text = _identify_cli(name, capsys, monkeypatch)
    ident = out["identifiability"]
    assert not ident["identified_damping"] and not ident["identified_stiffness"]
    for key in SCALAR_KEYS:
        assert out[key] is None and out["interval_95"][key] is None, key
        cond = out[CONDITIONAL_KEY][key]
        row = _row(text, key)
        assert "not identified" in row and "[" not in row, row
        lo, hi = cond["interval_95"]
        assert f"[{lo:.0f}, {hi:.0f}]" not in text and f"[{lo:.3f}, {hi:.3f}]" not in text
    assert out["blf"] is None and len(out[CONDITIONAL_KEY]["blf"]["estimate"]) == 10
    assert not re.search(r"^BLF\d", text, re.M)


def test_the_deck_route_repeats_no_withheld_number_in_its_surface_report() -> None:
    """On a deck record C and K come from the transmissibility, whose block repeats them."""
    deck = wb.identify(wb.datasets.load("seed_individual_deck"), wb.SMDModel(harmonics=6), seed=1)
    assert deck.not_identified == []
    frf = deck.to_json()["surface"]["transmissibility"]
    assert frf["interval_95"]["stiffness_n_per_m"] is not None
    graded = _graded(deck, identified_stiffness=False, level="not identified")
    out = graded.to_json()
    frf = out["surface"]["transmissibility"]
    for key in ("stiffness_n_per_m", "natural_frequency_hz", "damping_ratio"):
        assert frf["estimates"][key] is None and frf["interval_95"][key] is None, key
        # The bound's efficiency is the withheld sd over the bound's: withheld too.
        assert frf["information_bound"]["efficiency"][key] is None, key
        assert out[CONDITIONAL_KEY][key]["estimate"] == pytest.approx(deck.estimates[key])
    assert frf["estimates"]["damping_ns_per_m"] == pytest.approx(deck.estimates["damping_ns_per_m"])
    assert frf["information_bound"]["efficiency"]["damping_ns_per_m"] > 0


def test_the_identification_report_shows_no_number_for_what_is_not_identified(
    result: wb.IdentificationResult, tmp_path: Any
) -> None:
    from workbench.reporting.document import Report
    from workbench.reporting.identification import identification_section

    graded = _graded(result, identified_stiffness=False, level="not identified")
    report = Report("identification")
    report.add(identification_section(graded, tmp_path, "walk"))
    report.write(tmp_path)
    rows = {
        line.split("|")[1].strip(): line
        for line in (tmp_path / "report.md").read_text(encoding="utf-8").splitlines()
        if line.startswith("| ")
    }
    for label in ("K [N/m]", "natural frequency [Hz]", "damping ratio", "BLF1"):
        assert "not identified" in rows[label], rows[label]
    assert f"{result.estimates['stiffness_n_per_m']:.4g}" not in rows["K [N/m]"]
    assert "prior range" in rows["K [N/m]"]
    c = result.estimates["damping_ns_per_m"]
    assert rows["C [N s/m]"].split("|")[2].strip() == f"{c:.4g}"

"""Recovery of population laws: verdict rules, the deck-aware footfalls, a small recovery run.

The recovery run's population seed (0) and batch seed (0) were fixed before the run was
first looked at.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from workbench.errors import UsageError
from workbench.inference.settings import IdentifySettings
from workbench.population.recovery import (
    RecoveryDesign,
    law_verdicts,
    recovery_plan,
    run_recovery,
    truth_laws,
)
from workbench.records.footfalls import without_surface
from workbench.records.preprocess import preprocess
from workbench.records.steps import segment_steps
from workbench.reporting.recovery import recovery_conclusions, recovery_section
from workbench.synth.hidden import hidden_effect_walk


def _fit(fn_slope_ci, fn_int_ci, z_slope_ci, z_int_ci):
    def law(s, i):
        return {"slope_ci": list(s), "intercept_ci": list(i)}

    return {
        "natural_frequency_hz": law(fn_slope_ci, fn_int_ci),
        "damping_ratio": law(z_slope_ci, z_int_ci),
    }


def test_verdicts_follow_the_intervals():
    constant = truth_laws("constant")  # slopes 0, intercepts 2.85 and 0.29
    fit = _fit((0.6, 1.2), (2.0, 3.0), (-0.1, 0.1), (0.31, 0.4))
    v = law_verdicts(constant, fit)
    assert v["natural_frequency_hz"] == {"slope": "manufactured", "intercept": "recovered"}
    assert v["damping_ratio"] == {"slope": "recovered", "intercept": "biased"}
    seed = truth_laws("seed")  # f_n slope 0.3049: an interval without it is biased
    v = law_verdicts(seed, _fit((0.6, 1.2), (1.0, 1.5), (-0.3, -0.1), (0.8, 0.9)))
    assert v["natural_frequency_hz"]["slope"] == "biased"
    assert v["damping_ratio"] == {"slope": "recovered", "intercept": "recovered"}
    assert law_verdicts(seed, None)["damping_ratio"]["slope"] == "not fitted"


def test_truths_and_bad_names():
    zhang = truth_laws("zhang")
    assert zhang.natural_frequency_hz.slope == pytest.approx(1.1043)
    assert zhang.natural_frequency_hz.intercept == 0.0
    assert zhang.damping_ratio.mean(2.0) == pytest.approx(0.30)
    with pytest.raises(UsageError, match="neither one of seed, constant, zhang"):
        truth_laws("wang")
    with pytest.raises(UsageError, match="n_records"):
        RecoveryDesign(zhang, n_records=4)


def test_plan_spans_the_metronome_rates_and_keeps_decks_off_the_harmonics():
    plan = recovery_plan(RecoveryDesign(truth_laws("constant"), n_records=24), seed=3)
    assert sorted(set(plan["pacing_hz"])) == [1.5, 1.65, 1.75, 1.8, 1.95, 2.0, 2.1, 2.25]
    ratio = plan["deck_frequency_hz"] / plan["pacing_hz"]
    assert (((ratio >= 1.15) & (ratio <= 1.35)) | ((ratio >= 1.65) & (ratio <= 1.85))).all()
    rigid = recovery_plan(RecoveryDesign(truth_laws("constant"), "rigid", 24), seed=3)
    # The same walkers on either floor.
    assert np.array_equal(rigid["natural_frequency_hz"], plan["natural_frequency_hz"])
    assert rigid["deck_kind"].isna().all()


def test_without_surface_removes_the_deck_and_keeps_the_walker():
    fs, n = 100.0, 3000
    t = np.arange(n) / fs
    walker = 3.0 * np.cos(2 * np.pi * 1.5 * t) + 1.0 * np.cos(2 * np.pi * 3.0 * t + 0.4)
    deck = 0.8 * np.sin(2 * np.pi * 1.98 * t)
    # The body's response to the deck: a gain and a phase lag at the deck's frequency.
    response = 1.6 * 0.8 * np.sin(2 * np.pi * 1.98 * t - 0.7)
    cleaned = without_surface(walker + response, deck, fs)
    inner = slice(200, n - 200)
    assert np.sqrt(np.mean((cleaned - walker)[inner] ** 2)) < 0.02 * np.sqrt(np.mean(walker**2))


def test_ordinary_decks_keep_their_footfalls():
    # The criticism's deck walks (0.3-1 m/s^2 between the harmonics), seeds 0-9: the pacing
    # found without the deck's part changes no footfall (they are placed on the acceleration
    # itself), so results on such records are those of before.
    for seed in range(10):
        rec = hidden_effect_walk([], seed, kind="deck").record
        com = preprocess(rec, highpass_hz=0.15)
        plain = segment_steps(com, pacing_hz=rec.pacing_hz, min_steps=6)
        aware = segment_steps(
            com, pacing_hz=rec.pacing_hz, min_steps=6, surface_acc_m_s2=rec.ground_acc_m_s2
        )
        assert np.array_equal(plain.boundaries, aware.boundaries), seed


@pytest.mark.slow
def test_small_recovery_on_decks_recovers_the_seed_law(tmp_path):
    # The seed's laws (f_n well above f_p). The zhang law, f_n = 1.1043 f_p, puts the walker
    # at resonance with its own first harmonic: some of its simulated walks lift off (GRF
    # below zero), and batch reports those records as failed.
    design = RecoveryDesign(
        truth_laws("seed"), "deck", n_records=16, ranges={"duration_s": (12.0, 14.0)}
    )
    settings = IdentifySettings().replace(seed=0)
    res = run_recovery(tmp_path / "r", design, settings, seed=0)
    obj = res.to_json()
    assert obj["records"]["simulated"] == 16
    fit = obj["recovered"]["pipeline"]
    assert fit["records_used"] >= 12
    assert obj["verdict"]["pipeline"]["natural_frequency_hz"]["slope"] == "recovered"
    assert obj["verdict"]["pipeline"]["damping_ratio"]["slope"] == "recovered"
    # Written atomically, and a resumed run identifies nothing again and gives the same.
    stored = json.loads((tmp_path / "r" / "recovery.json").read_text())
    assert stored["verdict"] == obj["verdict"]
    again = run_recovery(tmp_path / "r", design, settings, seed=0, resume=True).to_json()
    assert again["recovered"] == obj["recovered"]
    with pytest.raises(UsageError, match="already holds a recovery"):
        run_recovery(tmp_path / "r", design, settings, seed=0)
    # The report's wording follows the verdict.
    lines = recovery_conclusions([obj], fit["laws"])
    assert any("slope is recovered on deck floors" in line for line in lines)
    assert recovery_section([obj]).title == "What this pipeline recovers"

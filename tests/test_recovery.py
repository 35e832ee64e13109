"""Recovery of population laws: verdict rules, the deck-aware footfalls, a small recovery run.

The recovery run's population seed (0) and batch seed (0) were fixed before the run was
first looked at.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from workbench.errors import UsageError
from workbench.inference.pipeline.settings import IdentifySettings
from workbench.population.recovery import (
    RecoveryDesign,
    law_verdicts,
    recovery_plan,
    run_recovery,
    truth_laws,
)
from workbench.records.footfalls import without_surface
from workbench.records.preprocess import preprocess
from workbench.records.steps import check_split, segment_steps
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


def test_ordinary_decks_keep_their_footfalls_on_the_walkers_event():
    # The criticism's deck walks (0.3-1 m/s^2 between the harmonics), seeds 0-9: with the
    # deck's response taken out, every boundary is within 0.1 step of the true event of its
    # step (the peak of the walker's pacing component, docs/science.md 2), and the steps
    # keep the walker's rhythm.
    from tests.test_footfall_split import boundary_errors

    for seed in range(10):
        rec = hidden_effect_walk([], seed, kind="deck").record
        com = preprocess(rec, highpass_hz=0.15)
        aware = segment_steps(
            com, pacing_hz=rec.pacing_hz, min_steps=6, surface_acc_m_s2=rec.ground_acc_m_s2
        )
        assert np.all(boundary_errors(rec, aware) < 0.1), seed
        assert check_split(aware).off_rhythm.size == 0, seed


def test_paired_slope_change_is_exact_for_a_setting_that_moves_nothing():
    from workbench.population.recovery import _paired_slope_change

    rng = np.random.default_rng(5)
    pacing = np.repeat([1.5, 1.75, 2.0, 2.25], 5)
    base = pd.DataFrame(
        {
            "path": [f"r{i}.csv" for i in range(pacing.size)],
            "pacing_hz": pacing,
            "natural_frequency_hz": 2.85 + 0.15 * rng.standard_normal(pacing.size),
            "damping_ratio": 0.29 + 0.05 * rng.standard_normal(pacing.size),
            "identified_damping": True,
            "identified_stiffness": True,
        }
    )
    same = _paired_slope_change(base, base.copy())  # no statsmodels warning (errors here)
    assert same["records"] == pacing.size and same["over"] == "identified in both"
    assert same["natural_frequency_hz"] == {"change": 0.0, "change_ci": [0.0, 0.0], "moves": False}
    # A setting that tilts every record's f_n by 0.2 Hz per Hz of pacing, plus 0.01 Hz noise.
    tilted = base.copy()
    tilted["natural_frequency_hz"] += 0.2 * (pacing - 1.8) + 0.01 * rng.standard_normal(pacing.size)
    moved = _paired_slope_change(base, tilted)["natural_frequency_hz"]
    lo, hi = moved["change_ci"]
    assert moved["moves"] and lo < 0.2 < hi and hi - lo < 0.05


def test_a_strong_deck_is_not_taken_for_the_pacing():
    """A 1.5 Hz walker on a 1 m/s^2 RMS sine deck at 1.3 f_p (seeds 0-3, all of them).

    The deck outweighs the walker's first harmonic in the walking band. With the deck's
    acceleration in the record, its linear response is taken out first; without it, the
    split first follows the deck, finds a median step that is a pure sinusoid (no step
    shape), notches the line out and follows the walker. Either way the steps are the
    walker's and the spectral pacing is not the deck's.
    """
    from workbench.records.steps import estimate_pacing
    from workbench.synth.decks import SineDeck
    from workbench.synth.simulate import simulate_walking

    duration_s, pacing_hz = 24.0, 1.5
    true_steps = duration_s * pacing_hz - 1  # whole steps between the first and last footfall
    for seed in range(4):
        rec = simulate_walking(
            mass_kg=70.0, pacing_hz=pacing_hz, duration_s=duration_s,
            natural_frequency_hz=2.3, damping_ratio=0.35, blf=(0.25, 0.08, 0.06),
            start="steady", seed=seed, noise_sd_n=5.0, sample_rate_hz=100.0,
            ground_acc_m_s2=SineDeck(1.0, 1.3 * pacing_hz, 0.3),
        ).record  # fmt: skip
        com = preprocess(rec)
        plain = segment_steps(com)
        aware = segment_steps(com, surface_acc_m_s2=rec.ground_acc_m_s2)
        for steps in (plain, aware):
            assert abs(steps.n_steps - true_steps) <= 0.1 * true_steps, seed
            assert steps.pacing_hz == pytest.approx(pacing_hz, rel=0.03), seed
        assert estimate_pacing(com, plain).spectral_pacing_hz == pytest.approx(pacing_hz, rel=0.03)


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

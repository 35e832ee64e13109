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
from workbench.population.laws import LinearLaw
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


def _load_factor_fit(blf1_slope_ci, blf1_int_ci, blf2_mu_ci, blf2_sigma_ci):
    """A fit whose f_n and zeta are beside the point, with the load-factor intervals given."""
    laws = _fit((0.0, 1.0), (0.0, 3.0), (-1.0, 1.0), (0.0, 1.0))
    laws["blf1"] = {"slope_ci": list(blf1_slope_ci), "intercept_ci": list(blf1_int_ci)}
    lognormal = {
        "blf2": {"mu_ci": list(blf2_mu_ci), "sigma_ci": list(blf2_sigma_ci)},
        # BLF3's truth: mu log(0.05) = -2.9957, sigma 0.4.
        "blf3": {"mu_ci": [-3.1, -2.9], "sigma_ci": [0.41, 0.6]},
    }
    return laws, lognormal


def test_load_factor_verdicts_follow_the_intervals():
    # The documented truth: BLF1 = 0.41 f_p - 0.3895, log BLF2 ~ N(log 0.055 = -2.9004, 0.4).
    seed = truth_laws("seed")
    laws, lognormal = _load_factor_fit((0.3, 0.5), (-0.5, -0.4), (-2.95, -2.85), (0.3, 0.5))
    v = law_verdicts(seed, laws, lognormal)
    assert v["blf1"] == {"slope": "recovered", "intercept": "biased"}  # -0.3895 > -0.4
    assert v["blf2"] == {"mu": "recovered", "sigma": "recovered"}
    assert v["blf3"] == {"mu": "recovered", "sigma": "biased"}  # 0.4 below [0.41, 0.6]
    # Intervals beside the truth on either side are biased, whatever the parameter.
    laws, lognormal = _load_factor_fit((0.42, 0.6), (-0.39, 0.0), (-2.9, -2.8), (0.1, 0.39))
    v = law_verdicts(seed, laws, lognormal)
    assert v["blf1"] == {"slope": "biased", "intercept": "recovered"}
    assert v["blf2"] == {"mu": "biased", "sigma": "biased"}


def test_a_load_factor_slope_made_from_nothing_is_manufactured():
    # Walkers whose first load factor does not depend on pacing: BLF1 0.3 at every pacing.
    flat = truth_laws("seed").replace(blf1=LinearLaw(slope=0.0, intercept=0.3, residual_sd=0.04))
    laws, lognormal = _load_factor_fit((0.05, 0.2), (0.1, 0.2), (-3.0, -2.8), (0.3, 0.5))
    assert law_verdicts(flat, laws, lognormal)["blf1"] == {
        "slope": "manufactured",
        "intercept": "biased",
    }
    laws, lognormal = _load_factor_fit((-0.05, 0.2), (0.25, 0.35), (-3.0, -2.8), (0.3, 0.5))
    assert law_verdicts(flat, laws, lognormal)["blf1"] == {
        "slope": "recovered",
        "intercept": "recovered",
    }
    # A lognormal law has no slope: an interval beside its mu is biased, never manufactured.
    assert law_verdicts(flat, laws, lognormal)["blf3"]["sigma"] == "biased"


def test_load_factor_laws_a_fit_does_not_hold_are_not_fitted():
    seed = truth_laws("seed")
    laws, _ = _load_factor_fit((0.3, 0.5), (-0.5, -0.3), (-3.0, -2.8), (0.3, 0.5))
    v = law_verdicts(seed, laws)  # no lognormal fit given
    assert v["blf1"] == {"slope": "recovered", "intercept": "recovered"}
    assert v["blf2"] == v["blf3"] == {"mu": "not fitted", "sigma": "not fitted"}
    # An f_n and zeta fit alone (a fit of an earlier version) judges no load factor.
    v = law_verdicts(seed, _fit((0.2, 0.4), (1.0, 1.5), (-0.3, -0.1), (0.8, 0.9)))
    assert v["natural_frequency_hz"] == {"slope": "recovered", "intercept": "recovered"}
    assert v["blf1"] == {"slope": "not fitted", "intercept": "not fitted"}
    v = law_verdicts(seed, None)
    assert {par for law in v.values() for par in law.values()} == {"not fitted"}
    assert set(v) == {"natural_frequency_hz", "damping_ratio", "blf1", "blf2", "blf3"}


def _recovery_json(with_load_factors: bool = True) -> dict:
    """A recovery.json object by hand: a deck run of the seed truth, every fit the same."""
    laws = {
        "natural_frequency_hz": {
            "slope": 0.29, "intercept": 1.36, "slope_ci": [0.06, 0.52],
            "intercept_ci": [0.93, 1.79], "residual_sd": 0.15, "n": 58,
        },
        "damping_ratio": {
            "slope": -0.245, "intercept": 0.963, "slope_ci": [-0.328, -0.162],
            "intercept_ci": [0.807, 1.12], "residual_sd": 0.05, "n": 58,
        },
    }  # fmt: skip
    truth = truth_laws("seed")
    fit = {"laws": laws, "records_used": 58, "records_excluded": 2}
    obj = {
        "truth": {"source": truth.source, "floor": "deck", "laws": {}},
        "settings": {"method": "exact", "obs_noise": "auto"},
        "records": {"simulated": 60, "processed": 60, "failed": 0, "not_identified": 2},
        "recovered": {"pipeline": fit, "flags_ignored": fit, "sample": {"laws": laws}},
    }
    for law in ("natural_frequency_hz", "damping_ratio", "blf1"):
        tl = getattr(truth, law)
        obj["truth"]["laws"][law] = {"slope": tl.slope, "intercept": tl.intercept}
    if with_load_factors:
        laws["blf1"] = {
            "slope": 0.9, "intercept": -1.2, "slope_ci": [0.7, 1.1],
            "intercept_ci": [-1.6, -0.8], "residual_sd": 0.05, "n": 58,
        }  # fmt: skip
        fit["lognormal"] = {
            law: {"mu": -2.95, "sigma": 0.42, "mu_ci": [-3.06, -2.84], "sigma_ci": [0.35, 0.51],
                  "n": 58}
            for law in ("blf2", "blf3")
        }  # fmt: skip
        obj["recovered"]["sample"]["lognormal"] = fit["lognormal"]
        obj["truth"]["lognormal"] = {
            law: {"mu": getattr(truth, law).mu, "sigma": getattr(truth, law).sigma}
            for law in ("blf2", "blf3")
        }
    else:
        del obj["truth"]["laws"]["blf1"]
    verdict = law_verdicts(truth, laws, fit.get("lognormal"))
    obj["verdict"] = {which: verdict for which in ("pipeline", "flags_ignored", "sample")}
    return obj


def test_recovery_text_report_and_conclusions_carry_the_load_factor_verdicts(tmp_path):
    from workbench.population.recovery_text import recovery_text

    obj = _recovery_json()
    obj["records"]["errors"] = {
        "pacing_hz": {"off_by_over_5pct": "3/60", "off_by_over_5pct_identified": "2/58"}
    }
    text = recovery_text(obj)
    assert "pacing: 3/60 records identified more than 5 % off" in text
    assert "(2/58 of those with C and K identified)" in text
    # BLF1 0.41 f_p - 0.3895 came back as 0.9 [0.7, 1.1]: biased; BLF3's mu -2.9957 is held.
    assert "BLF1: truth slope 0.41, intercept -0.3895" in text
    assert (
        "pipeline        n=58   slope 0.9 [0.7, 1.1] biased; intercept -1.2 [-1.6, -0.8] biased"
        in text
    )
    assert "BLF3 lognormal: truth mu -2.996, sigma 0.4" in text
    assert "mu -2.95 [-3.06, -2.84] recovered; sigma 0.42 [0.35, 0.51] recovered" in text
    # The Table-2 report's section gains a load-factor table; its conclusions a BLF1 sentence.
    tables = [b for b in recovery_section([obj]).blocks if not isinstance(b, str | list)]
    assert [tables[0].columns[-2:], tables[1].columns[-3:]] == [
        ["f_n slope", "zeta slope"], ["BLF1 slope", "BLF2 mu", "BLF3 mu"]
    ]  # fmt: skip
    assert tables[1].rows[0][3:] == [
        "truth 0.41; 0.9 [0.7, 1.1] biased",
        "truth -2.9; -2.95 [-3.06, -2.84] recovered",
        "truth -2.996; -2.95 [-3.06, -2.84] recovered",
    ]
    lines = recovery_conclusions([obj], {"blf1": {"slope": 0.8}})
    assert "The BLF1 slope is biased on deck floors" in lines[2]
    assert "came back as 0.9 [0.7, 1.1] (this report: slope 0.8)" in lines[2]
    # A recovery written before the load factors were judged reads and words as before.
    old = _recovery_json(with_load_factors=False)
    assert "BLF" not in recovery_text(old)
    assert len(recovery_conclusions([old], {})) == 2
    assert len([b for b in recovery_section([old]).blocks if not isinstance(b, str)]) == 1
    # A load-factor truth that is not a number is refused, as an f_n one is.
    from workbench.errors import InputError
    from workbench.reporting.recovery import read_recovery

    obj["truth"]["lognormal"]["blf2"]["sigma"] = None
    (tmp_path / "recovery.json").write_text(json.dumps(obj), encoding="utf-8")
    with pytest.raises(InputError, match=r"key truth\.lognormal\.blf2\.sigma"):
        read_recovery(tmp_path)


def test_record_errors_count_the_records_whose_pacing_is_wrong():
    from workbench.population.recovery import _record_errors

    laws = ("natural_frequency_hz", "damping_ratio", "blf1", "blf2", "blf3")
    plan = pd.DataFrame({"path": ["a", "b", "c", "d"], "pacing_hz": [1.5, 1.8, 2.0, 2.25]})
    for i, law in enumerate(laws):
        plan[law] = 0.1 * (i + 1)
    results = plan.copy()
    # b's pacing is the deck's (1.3 times its own), c's is 4 % off; d is not identified.
    results["pacing_hz"] = [1.5, 2.34, 2.08, 2.25]
    results["blf1"] = [0.33, 0.05, 0.3, 0.3]  # errors +0.03, -0.25, 0, 0
    for law in laws[:2]:
        results[f"{law}_sd"] = 0.01
    results["natural_frequency_hz"] += [0.0, 0.05, 0.0, 0.0]  # b's band misses its truth
    results["identified_damping"] = [True, True, True, False]
    results["identified_stiffness"] = True
    err = _record_errors(plan, results)
    assert err["pacing_hz"]["off_by_over_5pct"] == "1/4"
    assert err["pacing_hz"]["off_by_over_5pct_identified"] == "1/3"
    assert err["pacing_hz"]["median_error"] == pytest.approx(0.04)
    assert err["blf1"]["median_error_identified"] == pytest.approx(0.0)
    assert err["blf1"]["median_error"] == pytest.approx(0.0)
    assert "band_holds_truth_identified" not in err["blf1"]
    assert err["natural_frequency_hz"]["band_holds_truth_identified"] == "2/3"
    assert err["damping_ratio"]["band_holds_truth_identified"] == "3/3"


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
    # The load-factor laws are judged on the same records, against the documented truth.
    assert obj["truth"]["laws"]["blf1"]["slope"] == 0.41
    assert obj["truth"]["lognormal"]["blf3"]["sigma"] == 0.4
    for law, pars in (("blf1", ("slope", "intercept")), ("blf2", ("mu", "sigma"))):
        assert set(obj["verdict"]["pipeline"][law]) == set(pars), law
        assert fit["laws" if law == "blf1" else "lognormal"][law]["n"] == fit["records_used"]
    # Written atomically, and a resumed run identifies nothing again and gives the same.
    stored = json.loads((tmp_path / "r" / "recovery.json").read_text())
    assert stored["verdict"] == obj["verdict"]
    again = run_recovery(tmp_path / "r", design, settings, seed=0, resume=True).to_json()
    assert again["recovered"] == obj["recovered"]
    with pytest.raises(UsageError, match="already holds a recovery"):
        run_recovery(tmp_path / "r", design, settings, seed=0)
    # The hierarchical fit of the same batch's stored posteriors, judged the same way: every
    # verdict follows from its interval and the truth (each record its own walker, so the
    # residual sds are judged against the truth's), every record used or left out.
    part = obj["hierarchical"]
    rec = part["recovered"]
    assert rec["records_used"] + part["records_left_out"] == obj["records"]["processed"]
    assert rec["walkers"] == rec["records_used"] and rec["walker_effects"] is False
    truth = design.truth
    for law in ("natural_frequency_hz", "damping_ratio", "blf1"):
        for par in ("slope", "intercept", "residual_sd"):
            lo, hi = rec["laws"][law][f"{par}_ci"]
            held = lo <= getattr(getattr(truth, law), par) <= hi
            assert (part["verdict"][law][par] == "recovered") == held, (law, par)
    for law in ("blf2", "blf3"):
        for par in ("mu", "sigma"):
            lo, hi = rec["lognormal"][law][f"{par}_ci"]
            held = lo <= getattr(getattr(truth, law), par) <= hi
            assert (part["verdict"][law][par] == "recovered") == held, (law, par)
    assert part["convergence"]["rhat_max"] < 1.05
    assert stored["hierarchical"]["verdict"] == part["verdict"]
    assert "hierarchical    n=16" in res.summary()
    # The report's wording follows the verdicts of both fits.
    lines = recovery_conclusions([obj], fit["laws"])
    words = {"recovered": "recovers", "biased": "biases", "manufactured": "manufactures"}
    for line, law in zip(lines, ("natural_frequency_hz", "damping_ratio", "blf1"), strict=True):
        hier = words[part["verdict"][law]["slope"]]
        two = words[obj["verdict"]["pipeline"][law]["slope"]]
        assert f"the hierarchical fit {hier} it" in line and f"the two-stage fit {two} it" in line
    assert recovery_section([obj]).title == "What this pipeline recovers"

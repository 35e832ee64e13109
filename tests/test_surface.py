"""The walking surface in the model: M u'' + C (u' - z') + K (u - z) = F_bio (science.md 6)."""

from __future__ import annotations

import dataclasses
import json
import re

import numpy as np
import pytest

import workbench as wb
from workbench.cli import main
from workbench.errors import UsageError
from workbench.inference import pipeline as stages
from workbench.inference.core.problem import ForcePrior, build_problem
from workbench.inference.kalman import filter as kf
from workbench.inference.pipeline import IdentifySettings, gather_evidence, grade_identifiability
from workbench.inference.pipeline.grading import CHECK_OFF
from workbench.inference.surface.frf import (
    MARGIN_BINS,
    deck_spectra,
    surface_transmissibility,
)
from workbench.records.inspection import inspect_record
from workbench.records.io import save_record
from workbench.records.preprocess import preprocess
from workbench.records.surface import surface_motion
from workbench.synth import deck_walk
from workbench.synth.simulate import simulate_walking

MASS, FN, ZETA, PACING = 70.0, 2.8, 0.30, 1.8
DECK_HZ, DECK_AMP = 3.1, 0.5


def _deck(t: np.ndarray) -> np.ndarray:
    return DECK_AMP * np.sin(2 * np.pi * DECK_HZ * np.asarray(t))


@pytest.fixture(scope="module")
def periodic_deck_walk():
    """A 20 s walk whose force the whole-record basis describes exactly, on a 3.1 Hz deck."""
    return simulate_walking(
        mass_kg=MASS,
        natural_frequency_hz=FN,
        damping_ratio=ZETA,
        pacing_hz=PACING,
        duration_s=20.0,
        sample_rate_hz=200.0,
        noise_sd_n=2.0,
        step_duration_sd=0.0,
        amplitude_sd=0.0,
        phase_sd_rad=0.0,
        ground_acc_m_s2=_deck,
        start="steady",
        seed=3,
    )


WHOLE = wb.SMDModel(harmonics=3, pieces="whole", time_basis="absolute", pacing_hz=PACING)


def test_the_problem_is_relative_to_the_surface_with_its_inertial_load(periodic_deck_walk):
    insp = inspect_record(periodic_deck_walk.record)
    surface = surface_motion(insp.record)
    rigid = build_problem(insp.com, insp.steps)
    deck = build_problem(insp.com, insp.steps, surface=surface)
    assert deck.surface is not None and rigid.surface is None
    lo = int(insp.steps.boundaries[0])
    n = deck.n_samples
    z = np.column_stack([surface.disp_m, surface.vel_m_s, surface.acc_m_s2])[lo : lo + n]
    np.testing.assert_allclose(deck.absolute_y, rigid.y, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(deck.y, rigid.y - z, rtol=0, atol=1e-15)
    np.testing.assert_allclose(deck.surface_force_n, -MASS * z[:, 2])
    # The noise refers to the measured (absolute) response whatever the frame.
    np.testing.assert_array_equal(deck.rms, rigid.rms)
    assert rigid.surface_force_n is None


def test_the_surface_is_integrated_like_the_body(periodic_deck_walk):
    rec = periodic_deck_walk.record
    surface = surface_motion(rec)
    # The same chain on the surface acceleration written as a GRF gives the same numbers.
    as_grf = rec.replace(grf_n=MASS * (wb.G_M_S2 + rec.ground_acc_m_s2))
    com = preprocess(as_grf)
    np.testing.assert_allclose(surface.acc_m_s2, com.acc_m_s2, atol=1e-12)
    np.testing.assert_allclose(surface.vel_m_s, com.vel_m_s, atol=1e-12)
    np.testing.assert_allclose(surface.disp_m, com.disp_m, atol=1e-12)
    assert surface_motion(rec.replace(ground_acc_m_s2=None)) is None


@pytest.mark.parametrize("discretisation", ["foh", "euler"])
def test_deck_loglik_equals_the_dense_filter(periodic_deck_walk, discretisation):
    insp = inspect_record(periodic_deck_walk.record)
    problem = build_problem(insp.com, insp.steps, harmonics=3, surface=surface_motion(insp.record))
    truth = periodic_deck_walk.truth
    c, k = truth["damping_ns_per_m"], truth["stiffness_n_per_m"]
    dense = kf.dense_kalman_loglik(problem, c, k, discretisation=discretisation)
    fast = kf.record_loglik(problem, [c], [k], discretisation=discretisation)
    assert fast.loglik[0] == pytest.approx(dense.loglik, rel=1e-7)


def test_the_relative_frame_equals_the_fixed_frame_with_the_surface_as_input(periodic_deck_walk):
    """An independent check of the change of frame.

    In the fixed frame the surface acts as the force ``K z + C z'``: two basis columns whose
    coefficients are held at (K, C). The likelihood of the absolute observations under that
    model must equal the relative frame's, up to the discretisation of the two inputs.
    """
    insp = inspect_record(periodic_deck_walk.record)
    surface = surface_motion(insp.record)
    whole = {"pieces": "whole", "pacing_hz": PACING, "harmonics": 3}
    deck = build_problem(insp.com, None, surface=surface, **whole)
    truth = periodic_deck_walk.truth
    for c, k in ((truth["damping_ns_per_m"], truth["stiffness_n_per_m"]), (900.0, 15000.0)):
        fixed = build_problem(insp.com, None, **whole)
        fixed = fixed.with_noise(deck.noise)
        zcols = np.column_stack([surface.disp_m, surface.vel_m_s])
        fp = fixed.force_prior
        fixed = dataclasses.replace(
            fixed,
            basis=np.ascontiguousarray(np.column_stack([fixed.basis, zcols])),
            force_prior=ForcePrior(
                np.concatenate([fp.mean_n, [k, c]]),
                np.concatenate([fp.sd_n, [1e-9 * k, 1e-9 * c]]),
            ),
        )
        ll_rel = kf.record_loglik(deck, [c], [k]).loglik[0]
        ll_abs = kf.record_loglik(fixed, [c], [k]).loglik[0]
        # Scale: how much the likelihood changes for a 10 % change of K.
        scale = abs(ll_rel - kf.record_loglik(deck, [c], [1.1 * k]).loglik[0])
        assert abs(ll_rel - ll_abs) < 0.01 * scale


JOINT = WHOLE.replace(surface="joint")


@pytest.mark.slow
def test_a_deck_pins_c_and_k_and_the_methods_agree(periodic_deck_walk):
    """The joint time-history model, where the force model describes the walk exactly."""
    rec = periodic_deck_walk.record
    exact = wb.identify(rec, JOINT, method=wb.Exact(), seed=0, force_check=False)
    truth = periodic_deck_walk.truth
    ci = exact.interval()
    for name in ("natural_frequency_hz", "damping_ratio"):
        lo, hi = ci[name]
        assert lo <= truth[name] <= hi, (name, truth[name], ci[name])
    assert exact.posterior_sd["natural_frequency_hz"] < 0.02 * FN
    surface = exact.surface
    assert surface is not None and surface.model == "coupled"
    assert surface.information is not None
    info = surface.information["damping_ns_per_m"]
    assert info["local_sd_with_surface"] < info["local_sd_rigid_floor"]
    sd = exact.posterior_sd
    rbpf = wb.identify(rec, JOINT, method=wb.RBPF(256), seed=1, force_check=False)
    for name in ("natural_frequency_hz", "damping_ratio"):
        gap = abs(rbpf.estimates[name] - exact.estimates[name])
        assert gap < 0.5 * sd[name], ("rbpf", name, gap, sd[name])
    # The seed-faithful PF: with the force coefficients drawn once for the whole record
    # and never moved, its cloud collapses onto one ancestor (docs/validation/deck.md measures its
    # likelihood estimate thousands of nats off). It must then agree or say it cannot be read;
    # a number printed as an estimate far from exact is what must not happen.
    pf = wb.identify(rec, JOINT, method=wb.PF(2000), seed=1, force_check=False)
    gaps = [
        abs(pf.estimates[name] - exact.estimates[name]) / sd[name]
        for name in ("natural_frequency_hz", "damping_ratio")
    ]
    assert np.all(np.isfinite(gaps)), gaps  # a NaN estimate must not pass as agreement
    if max(gaps) >= 0.5:
        assert pf.identifiability["level"] == "not identified", (gaps, pf.identifiability)
        assert "collapsed" in pf.identifiability["sentence"]
    # The same record with the surface ignored: the deck's response becomes force, and the
    # posterior misses the truth or is wide; a confident wrong answer is what must not happen.
    rigid = wb.identify(rec, WHOLE.replace(surface="rigid"), method=wb.Exact(), force_check=False)
    assert rigid.surface is not None and rigid.surface.model == "ignored (rigid floor)"
    lo, hi = rigid.interval()["natural_frequency_hz"]
    assert not (lo <= truth["natural_frequency_hz"] <= hi)


def test_transmissibility_recovers_c_and_k_from_the_deck_alone(periodic_deck_walk):
    insp = inspect_record(periodic_deck_walk.record)
    problem = build_problem(insp.com, insp.steps, surface=surface_motion(insp.record))
    frf = surface_transmissibility(problem)
    assert frf is not None
    truth = periodic_deck_walk.truth
    for name in ("natural_frequency_hz", "damping_ratio"):
        lo, hi = frf.interval_95[name]
        assert lo <= truth[name] <= hi, (name, truth[name], frf.interval_95[name])
    # Informative, not the prior box's spread: a 0.5 m/s^2 deck fixes f_n to about 1 %.
    assert frf.posterior_sd["natural_frequency_hz"] < 0.02 * FN
    assert frf.posterior_sd["damping_ratio"] < 0.1 * ZETA
    # The deck's main lobe (four bins each side of its line) and the neighbours the taper
    # correlates with it (MARGIN_BINS), nothing further.
    bin_hz = float(np.min(np.diff(frf.frequency_hz)))
    assert np.all(np.abs(frf.frequency_hz - DECK_HZ) < (5 + MARGIN_BINS) * bin_hz)
    rigid = build_problem(insp.com, insp.steps)
    assert surface_transmissibility(rigid) is None


def test_the_deck_driven_spectrum_is_exact_for_an_analytic_response(periodic_deck_walk):
    """Three deck sines at off-bin frequencies and the body's exact steady-state answer."""
    insp = inspect_record(periodic_deck_walk.record)
    problem = build_problem(insp.com, insp.steps, surface=surface_motion(insp.record))
    assert problem.surface is not None
    t = problem.time_s
    k = MASS * (2 * np.pi * FN) ** 2
    c = 2 * ZETA * np.sqrt(k * MASS)
    z2 = np.zeros_like(t)
    u2 = np.zeros_like(t)
    for amp, hz, phase in ((0.3, 2.63, 0.4), (0.2, 3.071, 1.9), (0.25, 4.217, -0.7)):
        w = 2 * np.pi * hz
        tr = (k + 1j * w * c) / (k - w * w * MASS + 1j * w * c)
        z2 += amp * np.cos(w * t + phase)
        u2 += amp * np.abs(tr) * np.cos(w * t + phase + np.angle(tr))
    surface = dataclasses.replace(problem.surface, acc_m_s2=z2)
    y = problem.y.copy()
    y[:, 2] = u2 - z2  # the problem's y is relative: absolute u'' = y + z
    analytic = dataclasses.replace(problem, surface=surface, y=y)
    spectra = deck_spectra(analytic)
    assert spectra is not None and spectra.frequency_hz.size >= 6
    # The bins the deck drives (the neighbours the likelihood adds hold only leakage).
    driven = spectra.deck_power > 1e-3 * spectra.deck_power.max()
    assert driven.sum() >= 6
    model = spectra.deck_driven(c, k)[0][driven]
    body = spectra.body[driven]
    err = np.abs(model - body) / np.abs(body)
    assert np.max(err) < 0.01, err
    # A 5 % change of K moves the prediction by far more than that error.
    moved = spectra.deck_driven(c, 1.05 * k)[0][driven]
    assert np.max(np.abs(moved - body) / np.abs(body)) > 5 * np.max(err)


@pytest.mark.slow
def test_transmissibility_bands_hold_the_truth_on_deck_walks():
    """deck_walk seeds 0-19 (fixed in advance): at most three identified walks whose bands of
    f_n and zeta do not both hold the truth, and the decks of 0.2 m/s^2 or more whose centre
    is more than 0.2 f_p from a gait harmonic are identified (one may fail).

    Two 95 % bands hold together less often than one: on the 101 identified records of
    ``analyses/deck_bound.py`` both held on 93 % (docs/validation/deck-information.md). At
    that rate and about 12 identified walks, four or more misses happen in under 1 % of runs
    (three in about 4 %).
    """
    held, identified, strong_away, strong_away_ok = 0, 0, 0, 0
    for seed in range(20):
        sim = deck_walk(seed)
        insp = inspect_record(sim.record)
        problem = build_problem(insp.com, insp.steps, surface=surface_motion(insp.record))
        frf = surface_transmissibility(problem)
        deck = sim.truth["ground_motion"]
        ratio = deck.get("frequency_hz", deck.get("centre_hz")) / problem.pacing_hz
        away = deck["rms_m_s2"] >= 0.2 and abs(ratio - round(ratio)) > 0.2
        strong_away += away
        if frf is None or frf.level not in ("well identified", "weakly identified"):
            continue
        identified += 1
        strong_away_ok += away
        ci = frf.interval_95
        held += all(
            ci[n][0] <= sim.truth[n] <= ci[n][1] for n in ("natural_frequency_hz", "damping_ratio")
        )
    assert identified >= 8, identified
    assert identified - held <= 3, (held, identified)
    assert strong_away_ok >= strong_away - 1, (strong_away_ok, strong_away)


def test_the_default_reads_c_and_k_from_the_transmissibility():
    sim = deck_walk(2)
    res = wb.identify(sim.record, seed=0)
    surface = res.surface.to_json()
    assert surface["c_and_k_from"] == "transmissibility"
    route = res.route
    assert route.requested_method == "exact" and route.method == "exact"  # the default
    assert route.c_and_k_from == "transmissibility"
    assert route.bins == surface["transmissibility"]["bins"]
    assert list(route.band_hz) == surface["transmissibility"]["band_hz"]
    assert res.identifiability["level"] == "well identified"
    assert "force_model_check" not in res.identifiability
    ci = res.interval()
    for name in ("natural_frequency_hz", "damping_ratio"):
        assert ci[name][0] <= sim.truth[name] <= ci[name][1], (name, ci[name])
    assert "transmissibility" in surface["sentence"]
    assert "posterior sd of f_n is" in surface["sentence"]
    # C and K came from the deck alone, and the report says so.
    info = surface["information"]
    assert all(v["fraction_from_surface"] == 1.0 for v in info.values())
    assert info["natural_frequency_hz"]["local_sd_with_surface"] == pytest.approx(
        res.posterior_sd["natural_frequency_hz"]
    )
    # Every method reads C and K from the same transmissibility posterior, so they agree.
    for method in ("pf", "exact"):
        other = wb.identify(sim.record, method=method, seed=0)
        # What was asked for is kept; what ran is the exact grid, and the route says why.
        assert other.route.requested_method == method and other.route.method == "exact"
        assert other.method == "exact"
        assert f"whatever method was asked for ({method} here)" in other.route.reason
        for name in ("natural_frequency_hz", "damping_ratio"):
            assert other.estimates[name] == pytest.approx(res.estimates[name], rel=1e-9)


def test_the_advice_on_more_vibration_follows_the_deck_information_scaling():
    """The sentence's advice assumes sd(f_n) ~ 1 / (RMS sqrt(length)), the bound's scaling; a
    deck four times stronger on the same walk (seeds 0-2, stated in advance) cuts the sd
    about fourfold (docs/validation/deck-information.md measures the length)."""
    from workbench.inference.surface.information import enough_vibration

    walker = {
        "mass_kg": 70.0,
        "natural_frequency_hz": 2.8,
        "damping_ratio": 0.3,
        "pacing_hz": 1.8,
        "deck_frequency_hz": 3.1,
        "deck_kind": "narrowband",
        "duration_s": 30.0,
    }
    ratios = []
    for seed in range(3):
        sds = []
        for rms in (0.3, 1.2):
            sim = deck_walk(seed, deck_rms_m_s2=rms, **walker)
            insp = inspect_record(sim.record)
            problem = build_problem(insp.com, insp.steps, surface=surface_motion(insp.record))
            frf = surface_transmissibility(problem)
            assert frf is not None and frf.level == "well identified"
            sds.append(frf.posterior_sd["natural_frequency_hz"])
        ratios.append(sds[0] / sds[1])
    assert 2.5 < float(np.median(ratios)) < 6.0, ratios
    assert enough_vibration(0.3, 0.02, "well identified", 0.018, 30.0) == "."
    # sd 12 % at 0.1 m/s^2 over 30 s: four times the deck, or sixteen times the record.
    advice = enough_vibration(0.1, 0.12, "weakly identified", 0.10, 30.0)
    assert "about 0.4 m/s^2 RMS" in advice and "about 16 times as long" in advice
    assert "(about 480 s of steady walking)" in advice
    # A posterior narrowed below the bound by the prior box: the bound sets the advice.
    assert "at least 0.4 m/s^2" in enough_vibration(0.02, 0.28, "mostly prior", 0.6, 20.0)


def test_base_motion_is_not_counted_twice(periodic_deck_walk):
    model = WHOLE + wb.effects.BaseMotion()
    with pytest.raises(UsageError, match="count it twice"):
        wb.identify(periodic_deck_walk.record, model, method=wb.Exact(), force_check=False)


def _run(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def test_rigid_floor_flag_and_the_surface_section(tmp_path, periodic_deck_walk, capsys):
    path = tmp_path / "deck.csv"
    save_record(periodic_deck_walk.record.replace(mass_kg=MASS), path)
    common = [
        "identify",
        str(path),
        "--pieces",
        "whole",
        "--time-basis",
        "absolute",
        "--pacing",
        str(PACING),
        "--harmonics",
        "3",
        "--method",
        "exact",
        "--no-force-check",
        "--json",
    ]
    coupled = _run(common, capsys)
    rigid = _run([*common, "--rigid-floor"], capsys)
    assert coupled["surface"]["model"] == "coupled"
    assert coupled["settings"]["surface"] == "coupled"
    assert rigid["surface"]["model"] == "ignored (rigid floor)"
    assert rigid["settings"]["surface"] == "rigid"
    assert coupled["surface"]["transmissibility"]["estimates"]["natural_frequency_hz"] > 0
    joint = _run([*common, "--surface", "joint"], capsys)
    assert joint["settings"]["surface"] == "joint"
    assert joint["surface"]["c_and_k_from"] == "time history"
    assert joint["method"] == "exact"
    code = main([str(a) for a in [*common, "--rigid-floor", "--surface", "joint"]])
    _, err = capsys.readouterr()
    assert code != 0
    assert "--rigid-floor contradicts --surface joint" in err
    assert "Traceback" not in err


#: Deck walks of the criticism test (stated before any result was seen).
CRITICISM_SEEDS = range(8)


def test_criticism_couples_the_surface_and_the_rigid_floor_misses_it():
    """With the surface in the model the baseline's K and C act on u - z and base_motion is
    not a candidate; the rigid-floor model leaves the surface out, and diagnose names it on
    every walk whose deck reaches 0.2 m/s^2 RMS. Coupled, nothing is a false alarm (at most
    one of the eight walks, none of which hides an effect)."""
    from workbench.diagnostics.criticism import compare, diagnose, prepare

    strong = named = alarms = 0
    for seed in CRITICISM_SEEDS:
        sim = deck_walk(seed)
        data = prepare(sim.record)
        coupled = diagnose(data)
        rigid = diagnose(data, model=wb.SMDModel(surface="rigid"))
        assert coupled.baseline["surface"] == "coupled"
        assert rigid.baseline["surface"] == "ignored (rigid floor)"
        assert "base_motion" not in [c.effect for c in coupled.candidates]
        alarms += any(c.significant for c in coupled.candidates)
        if sim.truth["ground_motion"]["rms_m_s2"] >= 0.2:
            strong += 1
            top = rigid.candidates[0]
            named += top.effect == "base_motion" and top.significant
            assert "couple the surface" in rigid.verdict, seed
    assert strong >= 4
    assert named == strong
    assert alarms <= 1
    with pytest.raises(UsageError, match="count it twice"):
        compare(data, ["base_motion"])
    with pytest.raises(UsageError, match="contradicts the model's surface"):
        diagnose(data, model=wb.SMDModel(surface="rigid"), surface="coupled")


def test_the_crosscheck_checks_the_joint_filter_on_a_deck_record_when_asked(tmp_path, capsys):
    """With --surface joint, crosscheck compares the joint filter step by step and says that
    identify's default reads C and K from the transmissibility instead; identify
    --crosscheck on the default route says why it cannot check steps, instead of failing."""
    from workbench.cli.crosscheck import _text

    path = tmp_path / "deck.csv"
    save_record(deck_walk(2, duration_s=20.0).record, path)
    argv = ["crosscheck", path, "--surface", "joint", "--max-steps", "3", "--particles", "64"]
    out = _run([*argv, "--json"], capsys)
    assert out["surface"] == "joint"
    assert out["checks"] == "per-step filter"
    assert "joint time-history model" in out["checked"]
    assert "transmissibility" in out["checked"]
    assert len(out["steps"]) == 3
    assert 0.0 <= out["agreement"] <= 1.0
    # The text says the share in words, never as an unrounded fraction.
    text = _text(out)
    agreeing = sum(bool(s["agree"]) for s in out["steps"] if s["converged"])
    compared = sum(s["converged"] for s in out["steps"])
    assert f"{agreeing} of {compared} compared steps ({100 * out['agreement']:.0f} %)" in text
    assert not re.search(r"\d\.\d{5,}", text), text
    code = main([str(a) for a in ["identify", path, "--crosscheck", "--json"]])
    _, err = capsys.readouterr()
    assert code != 0 and "Traceback" not in err
    assert "came from the deck's transmissibility, which has no steps" in err


def test_the_surface_sentence_says_when_its_share_cannot_be_measured():
    """A flat likelihood has no local sd, so no share; the sentence says so in words."""
    from workbench.inference.surface.information import _sentence

    flat = {"local_sd_with_surface": np.inf, "local_sd_rigid_floor": np.inf}
    info = {
        "damping_ns_per_m": {**flat, "fraction_from_surface": np.nan},
        "stiffness_n_per_m": {**flat, "fraction_from_surface": np.nan},
    }
    text = _sentence(0.353, info)
    assert "()" not in text
    assert "too little information on C and K" in text
    assert "could not be measured" in text
    info["stiffness_n_per_m"]["fraction_from_surface"] = 0.9
    text = _sentence(0.353, info)
    assert "too little information on C (90 % of the information on K)" in text


def test_the_rbpf_rejuvenates_always_on_a_deck_and_on_surprise_elsewhere(periodic_deck_walk):
    """The deck's bursts move the joint posterior along the record; "auto" follows them."""
    from workbench.inference.methods.rbpf import run_rbpf
    from workbench.inference.pipeline.identification import compile_problem
    from workbench.inference.pipeline.settings import IdentifySettings

    insp = inspect_record(periodic_deck_walk.record)
    deck, rigid = (
        compile_problem(insp, IdentifySettings(model=JOINT.replace(surface=surface)))
        for surface in ("joint", "rigid")
    )
    assert deck.surface is not None and rigid.surface is None
    chosen = {
        name: run_rbpf(problem, n_particles=16, seed=0).settings["rejuvenate"]
        for name, problem in (("deck", deck), ("rigid", rigid))
    }
    assert chosen == {"deck": "always", "rigid": "surprise"}
    forced = run_rbpf(deck, n_particles=16, seed=0, rejuvenate="surprise")
    assert forced.settings["rejuvenate"] == "surprise"
    with pytest.raises(UsageError, match="rejuvenate"):
        wb.RBPF(rejuvenate="sometimes")


def test_a_deck_only_at_the_gait_harmonics_leaves_c_and_k_not_identified():
    """No bins away from the gait harmonics: the time history alone grades the record.

    On realistic walks it does not pin C and K, and in the footbridge closed loop it called
    wrong numbers identified, so such a record is graded not identified whatever the time
    history's own grade (the later checks are switched off here to see this rule alone).
    """
    sim = simulate_walking(
        mass_kg=70.0,
        natural_frequency_hz=2.0,
        damping_ratio=0.4,
        pacing_hz=2.0,
        duration_s=20.0,
        sample_rate_hz=100.0,
        noise_sd_n=0.5,
        ground_acc_m_s2=lambda t: 0.3 * np.sin(2 * np.pi * 2.0 * np.asarray(t)),
        seed=0,
    )

    def deck_rule_alone(model: wb.SMDModel) -> tuple[wb.IdentificationResult, dict]:
        # The method's own result on its route, graded by the evidence without the
        # prior-edge and collapse findings.
        settings = IdentifySettings(model=model, method=wb.Exact(), seed=0, force_check=False)
        prepared = stages.prepare(sim.record, settings)
        problem, noise = stages.set_noise(stages.compile_problem(prepared, settings), settings)
        route = stages.choose_route(problem, settings)
        res = stages.run_route(problem, route, settings, prepared=prepared, noise=noise)
        evidence = gather_evidence(res, settings)
        assert evidence.force_check is None and evidence.force_check_skipped == CHECK_OFF
        alone = dataclasses.replace(evidence, at_prior_bound=(), collapsed=False)
        return res, grade_identifiability(alone)

    res, report = deck_rule_alone(wb.SMDModel())
    assert res.surface.c_and_k_from == "time history"
    assert "only near the walker's gait harmonics" in res.surface.sentence
    assert res.route.deck_only_near_gait_harmonics and res.route.c_and_k_from == "time history"
    assert "only near the walker's gait harmonics" in res.route.reason
    assert report["level"] == "not identified"
    assert not report["identified_damping"]
    assert not report["identified_stiffness"]
    assert "gait harmonics" in report["sentence"]
    # The same record with a force for the whole record keeps the time history's grade:
    # the rule is about a force redrawn every step.
    whole = wb.SMDModel(harmonics=3, pieces="whole", time_basis="absolute", pacing_hz=2.0)
    res, report = deck_rule_alone(whole)
    assert res.route.deck_only_near_gait_harmonics
    assert "gait harmonics" not in report["sentence"]
    assert report == res.identifiability  # the method's own report, unchanged

"""The deck's information bound, and the transmissibility route against it.

Exact answers: the bound's information matrix against finite differences of the
likelihood it describes; the bound against the sampling sd of the route's estimate over
noise realisations of a record whose model is exactly true (stationary Gaussian noise, a
periodic deck-driven response); the route's posterior sd against the bound on simulated
walks.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from workbench.inference.core.problem import build_problem
from workbench.inference.surface.bound import information_bound
from workbench.inference.surface.frf import (
    correlated_runs,
    deck_spectra,
    gait_noise,
    surface_transmissibility,
)
from workbench.records.inspection import inspect_record
from workbench.records.surface import surface_motion
from workbench.synth import deck_walk
from workbench.synth.simulate import simulate_walking

MASS, FN, ZETA, PACING = 70.0, 2.8, 0.30, 1.8
STIFFNESS = MASS * (2 * np.pi * FN) ** 2
DAMPING = 2 * ZETA * np.sqrt(STIFFNESS * MASS)
DECK_HZ = 3.1


@pytest.fixture(scope="module")
def walk_problem():
    """A 30 s, 50 Hz walk on a 3.1 Hz deck: its problem supplies the spectra's layout."""
    sim = simulate_walking(
        mass_kg=MASS,
        natural_frequency_hz=FN,
        damping_ratio=ZETA,
        pacing_hz=PACING,
        duration_s=30.0,
        sample_rate_hz=50.0,
        ground_acc_m_s2=lambda t: 0.3 * np.sqrt(2) * np.sin(2 * np.pi * DECK_HZ * np.asarray(t)),
        start="steady",
        seed=1,
    )
    insp = inspect_record(sim.record)
    return build_problem(insp.com, insp.steps, surface=surface_motion(insp.record))


def _periodic_response(deck: np.ndarray, dt: float) -> np.ndarray:
    """The body acceleration a periodic deck drives through the SMD (exact, periodic)."""
    spec = np.fft.rfft(deck)
    w = 2 * np.pi * np.fft.rfftfreq(deck.size, dt)
    num = STIFFNESS + 1j * w * DAMPING
    return np.fft.irfft(num / (num - w * w * MASS) * spec, deck.size)


def _with_data(problem, body: np.ndarray):
    """The problem with its absolute body acceleration replaced by ``body``."""
    y = problem.y.copy()
    y[:, 2] = body - problem.surface.acc_m_s2
    return dataclasses.replace(problem, y=y)


def test_the_bound_is_the_curvature_of_the_likelihood_it_describes(walk_problem):
    """The analytic Fisher information 2 Re(G^H S^-1 G) equals minus the Hessian of the
    normal log-likelihood (the taper's correlation, the nugget, the noise level) at
    noise-free data, by central differences. The steps are 1e-3 of C and K: the difference
    error is of order 1e-6 relative, so 1e-4 relative is loose for it and tight for any slip
    in the gradient or the correlation (a factor 2, a run left out)."""
    spectra = dataclasses.replace(deck_spectra(walk_problem), calibration=0.0)
    assert spectra is not None and len(spectra.runs) >= 1
    normal = dataclasses.replace(
        spectra,
        body=spectra.deck_driven(DAMPING, STIFFNESS)[0],
        runs=correlated_runs(spectra.bin_index, float("inf"), spectra.nugget),
    )
    h = np.array([1e-3 * DAMPING, 1e-3 * STIFFNESS])

    def ll(dc: float, dk: float) -> float:
        return float(normal.loglik(None, [DAMPING + dc * h[0]], [STIFFNESS + dk * h[1]])[0])

    hess = np.empty((2, 2))
    hess[0, 0] = (ll(1, 0) - 2 * ll(0, 0) + ll(-1, 0)) / h[0] ** 2
    hess[1, 1] = (ll(0, 1) - 2 * ll(0, 0) + ll(0, -1)) / h[1] ** 2
    hess[0, 1] = hess[1, 0] = (ll(1, 1) - ll(1, -1) - ll(-1, 1) + ll(-1, -1)) / (4 * h[0] * h[1])
    bound = information_bound(spectra, DAMPING, STIFFNESS)
    scale = np.sqrt(np.outer(np.diag(bound.information), np.diag(bound.information)))
    np.testing.assert_allclose(bound.information / scale, -hess / scale, atol=1e-4)


def test_the_bound_without_gain_uncertainty_scales_as_one_over_the_decks_rms(walk_problem):
    """The deck-driven response is linear in the deck: three times the deck, a third of the
    bound's sd, exactly (same noise model, the gain known)."""
    spectra = dataclasses.replace(deck_spectra(walk_problem), calibration=0.0)
    strong = dataclasses.replace(spectra, sources=3.0 * spectra.sources)
    one = information_bound(spectra, DAMPING, STIFFNESS).sd
    three = information_bound(strong, DAMPING, STIFFNESS).sd
    for name in one:
        assert three[name] == pytest.approx(one[name] / 3.0, rel=1e-9)


def test_an_unknown_gain_leaves_the_information_of_its_schur_complement(walk_problem):
    """The bound with the deck channel's complex gain unknown (prior sd 1 %) equals the
    Schur complement of the joint information of (C, K, Re g, Im g), the gain's prior
    added, computed here by central differences of the joint normal log-likelihood at
    noise-free data (steps 1e-3 of C and K, 1e-3 of the gain; 1e-4 relative is loose for
    the differences' error and tight for a slip). A strong gain prior leaves the known-gain
    information; the unknown gain always leaves less."""
    spectra = deck_spectra(walk_problem)
    assert spectra.calibration == pytest.approx(0.01)
    known = dataclasses.replace(spectra, calibration=0.0)
    normal = dataclasses.replace(
        known,
        body=known.deck_driven(DAMPING, STIFFNESS)[0],
        runs=correlated_runs(spectra.bin_index, float("inf"), spectra.nugget),
    )
    base = np.array([DAMPING, STIFFNESS, 0.0, 0.0])
    h = np.array([1e-3 * DAMPING, 1e-3 * STIFFNESS, 1e-3, 1e-3])

    def ll(x: np.ndarray) -> float:
        gain = 1.0 + x[2] + 1j * x[3]
        scaled = dataclasses.replace(normal, sources=normal.sources * gain)
        prior = -(x[2] ** 2 + x[3] ** 2) / spectra.calibration**2
        return float(scaled.loglik(None, [x[0]], [x[1]])[0]) + prior

    hess = np.empty((4, 4))
    for a in range(4):
        for b in range(4):
            ea, eb = np.eye(4)[a] * h[a], np.eye(4)[b] * h[b]
            hess[a, b] = (
                ll(base + ea + eb) - ll(base + ea - eb) - ll(base - ea + eb) + ll(base - ea - eb)
            ) / (4 * h[a] * h[b])
    joint = -hess
    schur = joint[:2, :2] - joint[:2, 2:] @ np.linalg.solve(joint[2:, 2:], joint[2:, :2])
    info = spectra.information(DAMPING, STIFFNESS)
    scale = np.sqrt(np.outer(np.diag(info), np.diag(info)))
    np.testing.assert_allclose(info / scale, schur / scale, atol=1e-4)
    without = known.information(DAMPING, STIFFNESS)
    assert np.all(np.linalg.eigvalsh(without - info) > -1e-9 * np.abs(without).max())


@pytest.mark.slow
def test_the_bound_is_the_scatter_of_the_best_estimate_when_the_model_is_true(walk_problem):
    """30 noise realisations (seeds 0-29, fixed in advance) of a record whose model is exactly
    true: the deck-driven response of the periodic deck plus white Gaussian noise.

    - The posterior mean under the normal likelihood with the true noise level and the
      taper's correlation alone (the best any estimator can use) scatters by the bound's sd
      of f_n, within 35 % (the sd of a sample sd of 30 is 13 %, so 35 % is almost three of
      them).
    - The route's own posterior mean, which must estimate the level and the nugget,
      protects itself with a per-bin Student-t and leaves the channels' common gain
      unknown, scatters by at most 1.6 times the bound (``analyses/deck_bound.py --ideal``
      measures 1.05-1.09 on other seeds; the sample sd's own spread is 13 %).
    """
    from workbench.inference.methods import exact_posterior

    dt = walk_problem.dt_s
    deck = walk_problem.surface.acc_m_s2
    clean = _periodic_response(deck, dt)
    noise_sd = 0.6 * np.std(clean)
    taper_power = float(np.sum(np.square(_blackman_harris(deck.size))))
    best, route, bounds = [], [], []
    for seed in range(30):
        rng = np.random.default_rng(seed)
        problem = _with_data(walk_problem, clean + noise_sd * rng.standard_normal(deck.size))
        spectra = deck_spectra(problem)
        assert spectra is not None
        # White noise: the tapered DFT's variance is the sum of the squared taper, times the
        # noise variance, at every bin.
        true_var = np.full(spectra.frequency_hz.size, noise_sd**2 * taper_power)
        known = dataclasses.replace(
            spectra,
            noise_var=true_var,
            runs=correlated_runs(spectra.bin_index, float("inf"), 1e-6),
        )
        for out, like in ((best, known), (route, spectra)):
            post = exact_posterior(problem, loglik=like.loglik, force_moments=None)
            out.append(post.modal_mean["natural_frequency_hz"])
        bounds.append(
            information_bound(spectra, DAMPING, STIFFNESS, noise_var=true_var, nugget=1e-6).sd[
                "natural_frequency_hz"
            ]
        )
    bound = float(np.median(bounds))
    assert np.std(best, ddof=1) == pytest.approx(bound, rel=0.35), (np.std(best, ddof=1), bound)
    assert np.std(route, ddof=1) < 1.6 * bound, (np.std(route, ddof=1), bound)
    assert abs(np.mean(route) - FN) < 0.6 * bound


def _blackman_harris(n: int) -> np.ndarray:
    from scipy import signal

    return signal.windows.blackmanharris(n, sym=False)


@pytest.mark.slow
def test_the_routes_sd_is_within_a_quarter_of_the_bound_on_deck_walks():
    """Simulated walks with step-to-step variability (deck_walk seeds 0-7, fixed in
    advance), single-mode and narrow-band decks in turn at 0.3 m/s^2 RMS, 1.75 times the
    pacing, 30 s: the route's posterior sd of f_n is within 1.25 times the bound computed
    with the record's true noise (the record minus the true deck-driven response)."""
    ratios = []
    for seed in range(8):
        sim = deck_walk(
            seed,
            deck_kind=("sine", "narrowband")[seed % 2],
            deck_rms_m_s2=0.3,
            deck_frequency_hz=1.75 * PACING,
            pacing_hz=PACING,
            duration_s=30.0,
        )
        insp = inspect_record(sim.record)
        problem = build_problem(insp.com, insp.steps, surface=surface_motion(insp.record))
        frf = surface_transmissibility(problem)
        spectra = deck_spectra(problem)
        assert frf is not None and spectra is not None
        fn, zeta = sim.truth["natural_frequency_hz"], sim.truth["damping_ratio"]
        k = problem.mass_kg * (2 * np.pi * fn) ** 2
        c = 2 * zeta * np.sqrt(k * problem.mass_kg)
        level, nugget = gait_noise(problem, spectra, c, k)
        bound = information_bound(spectra, c, k, noise_var=level, nugget=nugget)
        ratios.append(frf.posterior_sd["natural_frequency_hz"] / bound.sd["natural_frequency_hz"])
    assert max(ratios) <= 1.25, ratios


@pytest.mark.parametrize("offset_bins", [0.0, 0.5])
def test_the_taper_correlation_keeps_a_lines_information(offset_bins):
    """A single line (a single-mode deck's response) in white noise: its tapered DFT over 41
    bins, with the taper's correlation, keeps nearly all the information the untapered DFT
    has (at least 95 %; 98 % on a bin, 96 % half-way between bins); treating the tapered
    bins as independent and dividing by the window's bandwidth of two bins keeps half of it
    (exactly, for any line: the sum of the squared taper lines over the centre line
    squared is the bandwidth)."""
    from workbench.inference.surface.frf import WINDOW_ENBW_BINS

    n, centre = 4096, 100
    t = np.arange(n)
    line = np.exp(2j * np.pi * (centre + offset_bins) * t / n)
    taper = _blackman_harris(n)
    tapered = np.fft.fft(line * taper) / n
    # White noise of unit variance per untapered bin (scaled as the DFT / n above).
    untapered_information = float(np.sum(np.abs(np.fft.fft(line) / n) ** 2)) * n
    bins = np.arange(centre - 20, centre + 21)
    run = correlated_runs(bins, float("inf"), nugget=1e-9)[0]
    noise_var = float(np.sum(taper**2)) / n
    whitened = run.quadratic_form((tapered[bins] / np.sqrt(noise_var))[None])[0] * n
    independent = float(np.sum(np.abs(tapered[bins]) ** 2)) / noise_var / WINDOW_ENBW_BINS * n
    assert whitened / untapered_information > 0.95
    assert independent / untapered_information == pytest.approx(0.5, abs=0.01)


def test_a_deck_identification_reports_its_bound_and_efficiency():
    """The embedded deck record: the JSON's transmissibility carries the bound at the
    posterior mean and the efficiency is the posterior sd over it, parameter by parameter;
    the sentence sets them side by side."""
    import workbench as wb
    from workbench import datasets

    res = wb.identify(datasets.load("seed_individual_deck"), seed=0)
    out = res.to_json()["surface"]
    bound = out["transmissibility"]["information_bound"]
    assert bound["bins"] == res.route.bins
    for name, sd in res.posterior_sd.items():
        if name in bound["bound_sd"]:
            assert bound["efficiency"][name] == pytest.approx(sd / bound["bound_sd"][name])
    rel = bound["bound_sd"]["natural_frequency_hz"] / res.estimates["natural_frequency_hz"]
    assert "information bound (the least sd any estimator can reach" in out["sentence"]
    assert f"is {100 * rel:.2g} %" in out["sentence"]


def test_a_weak_decks_sentence_prints_no_sd_of_what_is_not_identified():
    """A 0.03 m/s^2 deck (deck_walk seed 0, 20 s) leaves f_n mostly prior: the surface
    sentence names the grade and the record's bound, and no posterior sd of f_n."""
    import workbench as wb

    sim = deck_walk(0, deck_rms_m_s2=0.03, deck_frequency_hz=3.1, pacing_hz=PACING, duration_s=20)
    res = wb.identify(sim.record, seed=0)
    assert "natural_frequency_hz" in res.not_identified
    sentence = res.surface.sentence
    assert "f_n is mostly prior" in sentence and "information bound" in sentence
    assert "posterior sd of f_n" not in sentence

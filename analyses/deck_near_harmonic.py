"""Why the deck route's bands miss on decks near a gait harmonic: the four misses measured.

Run: ``python analyses/deck_near_harmonic.py [--seeds 6 9 12 28]`` (a few seconds a walk).

The four ``deck_walk`` walks whose 95 % bands of f_n and zeta miss the truth in
``analyses/deck_coverage.py`` (seeds 6, 9, 12 and 28) all have decks within a fifth of the
pacing of a gait harmonic. For each, this prints what separates a wrong noise model from
a wrong signal model:

- **linearity**: the record with its deck minus the same walk with the deck switched off
  (same seed, so the same gait), against the response ``M T z''`` of the true SMD to the
  deck (``scipy.signal.lsim``); its RMS over the response's, after the first tenth of the
  record. Near zero says the simulated data are exactly the route's model plus the gait;
- **level at the truth**: the residual power at the truth over the route's noise level,
  mean over the bins used (about 1 when the level is right, below 1 when it is high);
- **preference**: the log-likelihood of the route's posterior mean over that of the truth,
  for the route's likelihood and its normal version (whitened with the taper's correlation)
  and, per run of adjacent bins, the normal version's share; with a right model this is
  half a chi-square of two degrees of freedom (above 3 in 5 % of records);
- **wider guards**: the posterior mean and band of f_n with the gait guard at 2 % (the
  default), 4 % and 6 % of k f_p.

Docs: the closing notes of the information-bound issue and docs/validation/deck.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import warnings

import numpy as np
from scipy import signal

import workbench.inference.surface.frf as frf
from workbench.inference.core.problem import build_problem
from workbench.inference.pipeline.identification import identify
from workbench.records.inspection import inspect_record
from workbench.records.surface import surface_motion
from workbench.synth import deck_walk


def truth_ck(sim, mass_kg: float) -> tuple[float, float]:
    fn, zeta = sim.truth["natural_frequency_hz"], sim.truth["damping_ratio"]
    k = mass_kg * (2 * np.pi * fn) ** 2
    return 2 * zeta * np.sqrt(k * mass_kg), k


def linearity(seed: int) -> float:
    sim, off = deck_walk(seed), deck_walk(seed, deck_rms_m_s2=1e-12)
    r, r0 = sim.record, off.record
    n = min(r.n_samples, r0.n_samples)
    c, k = truth_ck(sim, r.mass_kg)
    system = signal.lti([c, k], [r.mass_kg, c, k])
    _, response, _ = signal.lsim(system, r.ground_acc_m_s2[:n], np.arange(n) * r.dt_s)
    driven = r.mass_kg * response
    diff = r.grf_n[:n] - r0.grf_n[:n] - driven
    tail = slice(n // 10, n)
    return float(np.sqrt(np.mean(diff[tail] ** 2)) / np.sqrt(np.mean(driven[tail] ** 2)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[6, 9, 12, 28])
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    for seed in args.seeds:
        sim = deck_walk(seed)
        insp = inspect_record(sim.record)
        problem = build_problem(insp.com, insp.steps, surface=surface_motion(insp.record))
        spectra = frf.deck_spectra(problem)
        if spectra is None:
            print(f"seed {seed}: no deck bins")
            continue
        c, k = truth_ck(sim, problem.mass_kg)
        result = identify(sim.record, seed=0)
        c_hat = result.estimates["damping_ns_per_m"]
        k_hat = result.estimates["stiffness_n_per_m"]
        pacing = float(problem.pacing_hz)
        deck = sim.truth["ground_motion"]
        deck_hz = float(deck.get("frequency_hz", deck.get("centre_hz", math.nan)))
        ratio = deck_hz / pacing
        print(
            f"seed {seed}: {deck['kind']} deck {deck['rms_m_s2']:.2f} m/s^2 at {deck_hz:.2f} Hz, "
            f"{abs(ratio - round(ratio)):.2f} f_p from a gait harmonic; f_n true "
            f"{sim.truth['natural_frequency_hz']:.3f} Hz, route "
            f"{result.estimates['natural_frequency_hz']:.3f} Hz"
        )
        mismatch = linearity(seed)
        print(
            f"  linearity: RMS of (deck - no deck - M T z'') over that of M T z'' = {mismatch:.1e}"
        )
        resid = spectra.body - spectra.deck_driven(c, k)[0]
        level = float(np.mean(np.abs(resid) ** 2 / spectra.noise_var))
        print(f"  level at the truth: mean |r|^2 / level = {level:.2f}")
        normal = dataclasses.replace(
            spectra,
            runs=frf.correlated_runs(spectra.bin_index, float("inf"), spectra.nugget),
            calibration=0.0,
        )
        for name, lik in (("route", spectra), ("normal, whitened", normal)):
            gain = lik.loglik(None, [c_hat], [k_hat])[0] - lik.loglik(None, [c], [k])[0]
            print(f"  preference for the estimate over the truth, {name}: {gain:.2f}")
        scale = np.sqrt(normal.noise_var)
        f = normal.frequency_hz
        for run in normal.runs:
            part = slice(run.start, run.stop)
            at_truth = ((normal.body - normal.deck_driven(c, k)[0]) / scale)[None, part]
            at_hat = ((normal.body - normal.deck_driven(c_hat, k_hat)[0]) / scale)[None, part]
            share = run.quadratic_form(at_truth)[0] - run.quadratic_form(at_hat)[0]
            print(
                f"    run {f[run.start]:.2f}-{f[run.stop - 1]:.2f} Hz ({run.stop - run.start} "
                f"bins): {share:.2f}"
            )
        for spread in (0.02, 0.04, 0.06):
            frf.HARMONIC_SPREAD = spread
            r = identify(sim.record, seed=0)
            lo, hi = r.interval()["natural_frequency_hz"]
            print(
                f"  guard {spread:.0%} of k f_p: f_n {r.estimates['natural_frequency_hz']:.3f} "
                f"[{lo:.3f}, {hi:.3f}], {r.identifiability.get('level')}"
            )
        frf.HARMONIC_SPREAD = 0.02


if __name__ == "__main__":
    main()

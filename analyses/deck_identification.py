"""What the coupled surface recovers, and where the per-step force model still gets in the way.

Run: ``python analyses/deck_identification.py``. Prints

1. a periodic walk on a 3.1 Hz deck (the whole-record force basis describes its force
   exactly): the exact posterior with the surface coupled and with it ignored;
2. realistic deck walks (``deck_walk`` seeds 0-5, step-to-step variability): the grid
   posterior of the joint time-history likelihood of the default per-step model (10
   harmonics redrawn every step) with the surface coupled, observing u, u', u'' and u''
   only, against the truth. This is why the default reads C and K from the transmissibility
   instead; ``analyses/deck_coverage.py`` measures that on 40 walks.

The figures are quoted in docs/validation/deck.md.
"""

from __future__ import annotations

import numpy as np

import workbench as wb
from workbench.inference.core.problem import build_problem
from workbench.inference.kalman.filter import record_loglik
from workbench.inference.pipeline.noise import apply_noise_setting
from workbench.models.conversions import damping_ns_per_m, stiffness_n_per_m
from workbench.records.inspection import inspect_record
from workbench.records.surface import surface_motion
from workbench.synth import deck_walk
from workbench.synth.simulate import simulate_walking

SEEDS = range(6)


def periodic_walk() -> None:
    sim = simulate_walking(
        mass_kg=70.0,
        natural_frequency_hz=2.8,
        damping_ratio=0.3,
        pacing_hz=1.8,
        duration_s=20.0,
        sample_rate_hz=200.0,
        noise_sd_n=2.0,
        step_duration_sd=0.0,
        amplitude_sd=0.0,
        phase_sd_rad=0.0,
        ground_acc_m_s2=lambda t: 0.5 * np.sin(2 * np.pi * 3.1 * np.asarray(t)),
        start="steady",
        seed=3,
    )
    model = wb.SMDModel(harmonics=3, pieces="whole", time_basis="absolute", pacing_hz=1.8)
    print("1. periodic walk, deck 0.5 m/s^2 peak at 3.1 Hz; truth f_n 2.800 Hz, zeta 0.300")
    for surface in ("joint", "rigid"):  # the joint time-history model on its home ground
        res = wb.identify(
            sim.record, model.replace(surface=surface), method=wb.Exact(), force_check=False
        )
        est, ci = res.estimates, res.interval()
        fn, zeta = "natural_frequency_hz", "damping_ratio"
        print(
            f"   {surface:<8} f_n {est[fn]:.3f} [{ci[fn][0]:.3f}, {ci[fn][1]:.3f}] Hz, "
            f"zeta {est[zeta]:.3f} [{ci[zeta][0]:.3f}, {ci[zeta][1]:.3f}]"
        )


def _grid_posterior(problem, mass: float) -> tuple[float, float, float, float]:
    fns, zetas = np.meshgrid(np.linspace(1.2, 4.0, 29), np.linspace(0.05, 0.9, 18))
    k = stiffness_n_per_m(fns.ravel(), mass)
    c = damping_ns_per_m(zetas.ravel(), k, mass)
    ll = record_loglik(problem, c, k).loglik
    w = np.exp(ll - ll.max())
    w /= w.sum()
    mf, mz = w @ fns.ravel(), w @ zetas.ravel()
    sf = np.sqrt(w @ (fns.ravel() - mf) ** 2)
    sz = np.sqrt(w @ (zetas.ravel() - mz) ** 2)
    return mf, sf, mz, sz


def realistic_walks() -> None:
    print("2. realistic deck walks (deck_walk seeds 0-5), joint time-history likelihood")
    print("   seed deck           truth f_n/zeta | per-step model, all | per-step, u'' only")
    for seed in SEEDS:
        sim = deck_walk(seed)
        tr = sim.truth
        insp = inspect_record(sim.record)
        surface = surface_motion(insp.record)
        cells = []
        for observe in ("all", "acc"):
            prob = build_problem(insp.com, insp.steps, surface=surface, observe=observe)
            prob, _ = apply_noise_setting(prob, "auto")
            mf, sf, mz, sz = _grid_posterior(prob, tr["mass_kg"])
            cells.append(f"{mf:.2f}+-{sf:.2f} {mz:.2f}+-{sz:.2f}")
        deck = tr["ground_motion"]
        kind = f"{deck['kind'][:4]} {deck['rms_m_s2']:.2f}@{_hz(deck):.1f}"
        print(
            f"   {seed:>4} {kind:<14} {tr['natural_frequency_hz']:.2f}/{tr['damping_ratio']:.2f}"
            f"     | {cells[0]} | {cells[1]}"
        )


def _hz(deck: dict) -> float:
    return float(deck.get("frequency_hz", deck.get("centre_hz", np.nan)))


if __name__ == "__main__":
    periodic_walk()
    realistic_walks()

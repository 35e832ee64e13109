"""Identification with effects, and the posterior-predictive check, on seeded records.

Usage::

    python analyses/criticism_levels.py

Prints

1. the seed's numerical example (75 kg, f_n 2.5 Hz, zeta 0.4, 1 kHz, 6 s) with a hidden
   cubic spring of several sizes, identified by the exact method with ``cubic_stiffness``
   (:mod:`workbench.inference.effect_terms`): C, K and k3 with posterior sd against the truth;
2. simulated walks (15 s, 100 Hz) without and with a gait asymmetry (60/30 N at f_p/2),
   identified by the rbpf (16 particles, 6 harmonics, the seed's noise), with the
   posterior-predictive p-values of :mod:`workbench.diagnostics.posterior_predictive`
   (49 replicates) and the one-step-ahead scores of :mod:`workbench.diagnostics.predictive`.
"""

from __future__ import annotations

import numpy as np

from workbench.diagnostics.posterior_predictive import posterior_predictive
from workbench.diagnostics.predictive import one_step_from_result
from workbench.inference.effect_terms import effect_posterior, effect_terms, with_effects
from workbench.inference.exact import exact_posterior
from workbench.inference.identify import identify
from workbench.inference.problem import build_problem
from workbench.inference.settings import IdentifySettings
from workbench.models.effects import CubicStiffness, EffectContext, GaitAsymmetry
from workbench.models.smd import SMDModel
from workbench.records.preprocess import preprocess
from workbench.synth.simulate import SEED_EXAMPLE_TERMS, simulate_smd, simulate_walking


def cubic(k3: float, duration_s: float = 6.0) -> None:
    """Identify the seed example with a hidden cubic spring of size k3 [N/m^3]."""
    model = SMDModel.from_modal(75.0, 2.5, 0.4, harmonics=10)
    if k3:
        model = model + CubicStiffness(k3_n_per_m3=k3)
    time_s = np.arange(round(duration_s / 0.001)) * 0.001

    def force(t: np.ndarray) -> np.ndarray:
        return sum(a * np.sin(w * np.pi * np.asarray(t)) for a, w in SEED_EXAMPLE_TERMS)

    ctx = EffectContext(step_start_s=np.arange(0.0, duration_s + 2.0, 2.0))
    sim = simulate_smd(model, force, time_s, pacing_hz=0.5, context=ctx)
    com = preprocess(sim.record, highpass_hz=0)
    problem = build_problem(
        com, None, pieces="whole", pacing_hz=0.5, time_basis="absolute", harmonics=10,
        obs_fraction=0.01, state_fraction=0.0,
    )  # fmt: skip
    terms = effect_terms(problem, [CubicStiffness()])
    augmented, _ = with_effects(problem, terms)
    post = exact_posterior(augmented)
    draws = post.sample(1000, np.random.default_rng(0))
    est = effect_posterior(problem, terms, draws, np.full(draws.shape[0], 1e-3))
    e = est["cubic_stiffness"]["k3_n_per_m3"]
    truth = (model.damping_ns_per_m, model.stiffness_n_per_m)
    print(
        f"k3 {k3:9.3g}: C {post.mean[0]:7.1f} +- {post.sd[0]:4.1f} (truth {truth[0]:.1f}), "
        f"K {post.mean[1]:8.1f} +- {post.sd[1]:5.1f} (truth {truth[1]:.1f}), "
        f"k3 {e['mean']:10.4g} +- {e['sd']:.3g}"
    )


def asymmetry(seed: int, asymmetric: bool) -> None:
    """Posterior-predictive p-values and one-step scores of one simulated walk."""
    effects = [GaitAsymmetry(a_half_n=60.0, b_half_n=30.0)] if asymmetric else []
    sim = simulate_walking(
        duration_s=15.0, sample_rate_hz=100.0, effects=effects, seed=seed, noise_sd_n=3.0
    )
    result = identify(
        sim.record,
        IdentifySettings(particles=16, harmonics=6, obs_noise="seed", force_check=False),
    )
    check = posterior_predictive(result, replicates=49, seed=0).to_dict()
    one = one_step_from_result(result)
    print(
        f"seed {seed} {'asymmetric' if asymmetric else 'symmetric ':<10}: p(sub-harmonic) "
        f"{check['subharmonic_power']['p_value']:.2f}, p(odd/even) "
        f"{check['odd_even_contrast_n']['p_value']:.2f}; one-step RMSE {one.rmse_n:.1f} N, "
        f"Ljung-Box p {one.ljung_box_p:.2g}"
    )


def main() -> int:
    """Run both parts."""
    print("== identification with cubic_stiffness (exact method, seed example + k3 u^3)")
    for k3 in (0.0, 2e6, 1e7):
        cubic(k3)
    print("== posterior-predictive check of left/right asymmetry (rbpf, 49 replicates)")
    for seed in (1, 2, 3, 4):
        for asym in (False, True):
            asymmetry(seed, asym)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

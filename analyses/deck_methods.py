"""Do the methods agree on a deck record? Exact, RBPF and the seed-faithful PF, joint model.

Run: ``python analyses/deck_methods.py`` (about a minute), and
``python analyses/deck_methods.py --crosscheck [surprise] [--sample-rate HZ]`` (about
eight minutes at the record's own 500 Hz): the cross-check of ``deck_walk(2,
duration_s=30)`` (a realistic 30 s walk on a 0.35 m/s^2 narrow-band deck), which checks the
joint time-history RBPF step by step against emcee, with the RBPF's default rejuvenation or
(``surprise``) exact moves only on surprise. ``--sample-rate 100`` simulates the same walk
and deck at 100 Hz, the record of ``tests/test_deck_crosscheck.py``.

A 70 kg walker (f_n 2.8 Hz, zeta 0.30) at 1.8 Hz without step-to-step variability, 12 s at
100 Hz, 10 N GRF noise, on a deck moving at 3.1 Hz with 0.1 and 0.5 m/s^2 peak
acceleration, and on a rigid floor; one force for the whole record (three harmonics on the
record's clock). Each method identifies it with the joint time-history model
(``surface="joint"``: every method runs its own algorithm on the same likelihood; on the
default route C and K come from the transmissibility for every method). Printed: each
method's mean and sd of f_n and zeta and its distance from the exact posterior's mean in
exact posterior sd (agreement: under 0.5); what each method says of its own result; and the PF's
log-likelihood estimate with (C, K) held at exact's mean against the Kalman value. The
figures are quoted in docs/validation/deck.md.
"""

from __future__ import annotations

import time

import numpy as np

import workbench as wb
from workbench.synth.simulate import simulate_walking

PARAMETERS = ("natural_frequency_hz", "damping_ratio")


def crosscheck(rejuvenate: str, sample_rate_hz: float | None = None) -> None:
    from workbench.inference.crosscheck.check import crosscheck as check_steps
    from workbench.synth import deck_walk

    rate = {} if sample_rate_hz is None else {"sample_rate_hz": sample_rate_hz}
    record = deck_walk(2, duration_s=30.0, **rate).record
    method = wb.RBPF(256, rejuvenate=rejuvenate)
    t0 = time.process_time()
    ident = wb.identify(record, wb.SMDModel(surface="joint"), method=method, force_check=False)
    t1 = time.process_time()
    result = check_steps(ident.problem, ident, seed=0, keep_inference_data=False)
    t2 = time.process_time()
    assert ident.filter_results is not None  # an rbpf run
    chosen = ident.filter_results.settings["rejuvenate"]
    print(f"joint model, rbpf rejuvenate={rejuvenate} ({chosen}): agreement {result.agreement:.2f}")
    print(
        f"{ident.problem.n_samples} samples; CPU s: identification {t1 - t0:.1f}, "
        f"cross-check {t2 - t1:.1f}"
    )
    print(result.verdict())
    steps = [s for s in result.steps if s.converged]
    z = np.array([np.max(np.abs(s.z)) for s in steps])
    ratio = np.array([s.sd_ratio for s in steps])
    print(
        f"converged {len(steps)} of {len(result.steps)}; max |z| {z.max():.2f}; "
        f"filter sd / MCMC sd {ratio.min():.2f}-{ratio.max():.2f}"
    )
    print(ident.identifiability["sentence"])


def main() -> None:
    import sys

    if "--crosscheck" in sys.argv[1:]:
        args = sys.argv[1:]
        rate = float(args[args.index("--sample-rate") + 1]) if "--sample-rate" in args else None
        crosscheck("surprise" if "surprise" in args else "auto", rate)
        return
    model = wb.SMDModel(
        harmonics=3, pieces="whole", time_basis="absolute", pacing_hz=1.8, surface="joint"
    )
    for amplitude in (0.1, 0.5, 0.0):
        sim = simulate_walking(
            mass_kg=70.0,
            natural_frequency_hz=2.8,
            damping_ratio=0.3,
            pacing_hz=1.8,
            duration_s=12.0,
            sample_rate_hz=100.0,
            noise_sd_n=10.0,
            step_duration_sd=0.0,
            amplitude_sd=0.0,
            phase_sd_rad=0.0,
            ground_acc_m_s2=(
                None
                if amplitude == 0.0
                else lambda t, a=amplitude: a * np.sin(2 * np.pi * 3.1 * np.asarray(t))
            ),
            start="steady",
            seed=3,
        )
        deck = f"deck {amplitude} m/s^2 at 3.1 Hz" if amplitude else "no deck (rigid floor)"
        print(f"{deck} (truth f_n 2.8 Hz, zeta 0.30):")
        results = {}
        for name, method in (("exact", wb.Exact()), ("rbpf", wb.RBPF(256)), ("pf", wb.PF(4000))):
            res = wb.identify(sim.record, model, method=method, seed=1, force_check=False)
            results[name] = res
            est, sd = res.estimates, res.posterior_sd
            text = ", ".join(f"{p} {est[p]:.3f} +- {sd[p]:.3f}" for p in PARAMETERS)
            print(f"  {name:5s} {text}")
        exact = results["exact"]
        for name in (n for n in results if n != "exact"):
            gaps = [
                abs(results[name].estimates[p] - exact.estimates[p]) / exact.posterior_sd[p]
                for p in PARAMETERS
            ]
            print(f"  {name} - exact, in exact sd: f_n {gaps[0]:.2f}, zeta {gaps[1]:.2f}")
        pf = results["pf"]
        levels = ", ".join(f"{n} {r.identifiability['level']}" for n, r in results.items())
        print(f"  identifiability: {levels}; pf final ancestors {pf.final_ancestors}")
        pf_likelihood_at_exact_mean(sim.record, model, exact)


def pf_likelihood_at_exact_mean(record: wb.Record, model: wb.SMDModel, exact) -> None:
    """Why the PF cannot agree: its likelihood estimate with (C, K) held at exact's mean.

    Given (C, K) the model is linear-Gaussian, so the Kalman filter (Euler, the PF's own
    discretisation) gives the exact value; the PF's estimate over three seeds shows its
    Monte Carlo spread and bias in nats, against the fraction of a nat that separates
    (C, K) one posterior sd apart.
    """
    from workbench.inference.kalman.filter import record_loglik
    from workbench.inference.methods.pf import run_pf

    captured = {}

    def keep(problem):
        captured["problem"] = problem
        return problem

    wb.identify(record, model, method=wb.PF(), seed=1, force_check=False, adjust_noise=keep)
    problem = captured["problem"]
    c, k = exact.estimates["damping_ns_per_m"], exact.estimates["stiffness_n_per_m"]
    kalman = float(record_loglik(problem, [c], [k], discretisation="euler").loglik[0])
    runs = np.array(
        [
            run_pf(problem, n_particles=4000, seed=s, fixed_parameters=(c, k)).loglik
            for s in range(3)
        ]
    )
    print(
        f"  pf log-likelihood at exact's (C, K), seeds 0-2: {runs.mean() - kalman:+.0f} nats "
        f"from the Kalman value (spread {runs.std(ddof=1):.0f} nats)"
    )


if __name__ == "__main__":
    main()

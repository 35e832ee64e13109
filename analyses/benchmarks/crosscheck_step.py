"""Seconds per footstep of the per-step MCMC cross-check, collapsed and joint mode.

Usage: ``python analyses/benchmarks/crosscheck_step.py [--harmonics 10] [--step 5]
[--walkers 32] [--plain-max-steps 5000] [--no-reference] [--no-joint] [--no-record]
[--json]`` (main environment, one pinned core by default, ``--cores N`` to change).

A simulated walk (:func:`~workbench.synth.simulate.simulate_walking`, 70 kg, 1.8 Hz, 10 s at
100 Hz, 3 N noise, from rest, seed 11; seed observation noise, no process noise; n
harmonics). Two parts, all CPU seconds of this pinned process:

One step (``--step``), with a Gaussian prior on (C, K) (10 % above / 5 % below the truth,
sd 25 % / 15 %) inside the problem's prior box; every walker's hand-in is the previous
step's exact hand-over at its own (C, K), from that step's hand-in at the true (C, K).
Sampled by :func:`workbench.inference.crosscheck.mcmc.run_ensembles` (4 ensembles, lockstep):

``reference``
    The named reference: the same collapsed (C, K) posterior with its likelihood from the
    piece Kalman filter (:func:`workbench.inference.kalman.filter.piece_filter`, two pieces per
    call: the previous step for every row's own hand-in, then the step) and the runner's
    defaults (differential-evolution moves, first chunk of 500 steps) -- the cross-check as
    it stood before the closed-form step likelihood.
``collapsed``
    The same posterior with the closed-form step likelihood
    (:class:`workbench.inference.crosscheck.step_model.StepModel`) and the t-fit + DE move mixture
    (:func:`workbench.inference.crosscheck.check.default_moves`).
``joint``
    All ``2 n + 5`` parameters in the non-centred coordinates ``(C, K, eta)`` (the joint
    density plus ``log |det S(C, K)|``), DE moves, ``4 d`` walkers: ``--mode joint``.
``joint-plain``
    The same joint posterior in the plain coordinates ``(C, K, beta)`` with the collapsed
    mode's moves, stopped at ``--plain-max-steps``: why the joint mode is non-centred.

The whole record, ``workbench crosscheck`` as it runs (:func:`~workbench.inference.
crosscheck.crosscheck` against the rbpf with 256 particles, every step, InferenceData kept):

``record-grid``
    The default: the history of every step tabulated on a grid and interpolated, the step
    sampled on the grid's surrogate and checked against its exact likelihood.
``record-all``
    ``history="all"``: every earlier step's exact likelihood per walker (cost per call
    growing with the step index), the exact filtering posterior the grid approximates; the
    largest difference of the per-step means (in MCMC sd) and sds between the two is
    printed.

Printed per row: CPU seconds per footstep, log-density evaluations, chain steps, largest
tau, smallest bulk ESS and ESS per CPU second, the posterior mean and sd of (C, K) (step
rows); and the speed-up of ``collapsed`` over the reference. The issue's target is under 1 s
per step, collapsed, on one core.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from _cores import affinity, pin_cores

_CORES = pin_cores(sys.argv)

import numpy as np  # noqa: E402  (after the thread-pool settings above)

from workbench.inference.core.problem import build_problem  # noqa: E402
from workbench.inference.crosscheck.check import StepTarget, crosscheck, default_moves  # noqa: E402
from workbench.inference.crosscheck.mcmc import run_ensembles  # noqa: E402
from workbench.inference.crosscheck.step_model import StepModel  # noqa: E402
from workbench.inference.kalman import filter as kf  # noqa: E402
from workbench.inference.methods.rbpf import run_rbpf  # noqa: E402
from workbench.records.inspection import inspect_record  # noqa: E402
from workbench.synth.simulate import simulate_walking  # noqa: E402


def step_setup(
    harmonics: int, step: int
) -> tuple[Any, StepModel, StepModel, np.ndarray, np.ndarray, Any]:
    """Return the problem, the step's and the previous step's models, the prior, a hand-in.

    The prior is a mean and sd of (C, K); the hand-in that of the previous step.
    """
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=10.0,
        sample_rate_hz=100,
        noise_sd_n=3.0,
        start="rest",
        seed=11,
    )
    insp = inspect_record(sim.record, highpass_hz=0.15)
    problem = build_problem(insp.com, insp.steps, harmonics=harmonics, state_fraction=0.0)
    truth = np.array([sim.truth["damping_ns_per_m"], sim.truth["stiffness_n_per_m"]])
    xm, xc = kf.initial_state(problem, 1)
    for piece in range(step - 1):
        res = kf.piece_filter(problem, piece, truth[:1], truth[1:], xm, xc)
        xm, xc = res.x_mean_next, res.x_cov_next
    previous = StepModel(problem, step - 1, xm[0], xc[0])
    res = kf.piece_filter(problem, step - 1, truth[:1], truth[1:], xm, xc)
    model = StepModel(problem, step, res.x_mean_next[0], res.x_cov_next[0])
    prior_mean, prior_sd = truth * np.array([1.1, 0.95]), truth * np.array([0.25, 0.15])
    return problem, model, previous, prior_mean, prior_sd, (xm, xc)


class _Reference:
    """The same collapsed target with the piece Kalman filter: two pieces per call.

    The previous piece from its fixed hand-in gives every row its own hand-over, the step's
    piece from there its likelihood -- what :class:`StepTarget` does in closed form.
    """

    def __init__(self, problem: Any, step: int, prior: StepTarget, hand_in: Any) -> None:
        self.problem, self.step, self.prior = problem, step, prior
        self.xm, self.xc = hand_in
        self.calls = 0

    def __call__(self, theta: np.ndarray) -> np.ndarray:
        self.calls += 1
        out = self.prior.log_prior_ck(theta[:, 0], theta[:, 1])
        ok = np.isfinite(out)
        n = int(ok.sum())
        if n:
            c, k = theta[ok, 0], theta[ok, 1]
            hand = kf.piece_filter(
                self.problem,
                self.step - 1,
                c,
                k,
                np.repeat(self.xm, n, axis=0),
                np.repeat(self.xc, n, axis=0),
            )
            out[ok] += kf.piece_filter(
                self.problem, self.step, c, k, hand.x_mean_next, hand.x_cov_next
            ).loglik
        return out


def _record_rows(harmonics: int, seed: int) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """``crosscheck`` over the whole simulated walk: grid (default) and full history."""
    problem = step_setup(harmonics, 1)[0]
    rbpf = run_rbpf(problem, n_particles=256, seed=11)
    rows, results = [], {}
    for name, history in (("record-grid", "grid"), ("record-all", "all")):
        c0 = time.process_time()
        res = crosscheck(problem, rbpf, seed=seed, history=history)
        cpu = time.process_time() - c0
        results[name] = res
        n = len(res.steps)
        ess = min(float(np.min(s.mcmc.ess_bulk)) for s in res.steps)
        errors = [s.surrogate_error for s in res.steps if s.surrogate_error]
        rows.append(
            {
                "mode": name,
                "steps_checked": n,
                "cpu_seconds": cpu,
                "cpu_seconds_per_step": cpu / n,
                "evaluations": sum(s.mcmc.n_evaluations for s in res.steps),
                "chain_steps_mean": float(np.mean([s.mcmc.n_steps for s in res.steps])),
                "tau_max": float(max(np.max(s.mcmc.tau) for s in res.steps)),
                "ess_bulk_min": ess,
                "ess_bulk_per_cpu_s": sum(float(np.min(s.mcmc.ess_bulk)) for s in res.steps) / cpu,
                "converged_steps": sum(s.converged for s in res.steps),
                "agreement": res.agreement,
                "grid": res.settings.get("grid"),
                "surrogate_mean_shift_sd_max": max(
                    (max(e["mean_shift_sd"]) for e in errors), default=None
                ),
                "surrogate_resampled_exact": sum(bool(e["resampled_exact"]) for e in errors),
            }
        )
    grid, full = results["record-grid"].steps, results["record-all"].steps
    shift = max(
        float(np.max(np.abs(g.mcmc_mean - f.mcmc_mean) / f.mcmc_sd))
        for g, f in zip(grid, full, strict=True)
    )
    ratio = max(
        float(np.max(np.abs(g.mcmc_sd / f.mcmc_sd - 1))) for g, f in zip(grid, full, strict=True)
    )
    return rows, {"mean_diff_sd_max": shift, "sd_rel_diff_max": ratio}


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--harmonics", type=int, default=10)
    parser.add_argument("--step", type=int, default=5)
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--walkers", type=int, default=32, help="per ensemble (32)")
    parser.add_argument(
        "--plain-max-steps", type=int, default=5000, help="joint-plain stops here (5000)"
    )
    parser.add_argument("--no-reference", action="store_true", help="skip the reference")
    parser.add_argument("--no-joint", action="store_true", help="skip the joint modes")
    parser.add_argument("--no-record", action="store_true", help="skip the whole record")
    parser.add_argument("--cores", type=int, default=1, help="CPUs (pinned; default 1)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()

    import arviz  # noqa: F401  (imported once here, not inside the first timed run)

    problem, model, previous, centre, scale, hand_in = step_setup(args.harmonics, args.step)
    cov = np.diag(scale**2)
    collapsed = StepTarget(model, centre, cov, problem.prior, previous=previous)
    joint = StepTarget(model, centre, cov, problem.prior, mode="joint", previous=previous)
    plain = StepTarget(
        model, centre, cov, problem.prior, mode="joint", previous=previous, parametrisation="plain"
    )
    reference = _Reference(problem, args.step, collapsed, hand_in)

    # The reference as the cross-check stood before: DE moves and the runner's first chunk
    # of 500 steps; the others as ``workbench crosscheck`` runs them.
    runs: list[tuple[str, Any, Any, Any, int, int, int]] = []
    w = args.walkers
    if not args.no_reference:
        runs.append(("reference", reference, collapsed, "de", 500, w, 20_000))
    runs.append(("collapsed", collapsed, collapsed, default_moves(), 100, w, 20_000))
    if not args.no_joint:
        runs.append(("joint", joint, joint, default_moves("joint"), 100, 4 * joint.n_dim, 20_000))
        runs.append(("joint-plain", plain, plain, default_moves(), 100, w, args.plain_max_steps))
    rows = []
    for name, target, starter, moves, first_chunk, walkers, max_steps in runs:
        target.calls = 0
        walkers = max(walkers, 2 * starter.n_dim + 2)
        c0 = time.process_time()
        res = run_ensembles(
            target,
            lambda rng, s=starter, w=walkers: s.initial(rng, w),
            seed=args.seed,
            n_walkers=walkers,
            min_steps=first_chunk,
            max_steps=max_steps,
            moves=moves,
            param_names=starter.param_names,
        )
        cpu = time.process_time() - c0
        rows.append(
            {
                "mode": name,
                "cpu_seconds": cpu,
                "cpu_seconds_per_step": cpu,
                "evaluations": res.n_evaluations,
                "calls": target.calls,
                "steps": res.n_steps,
                "walkers": walkers,
                "tau_max": float(np.max(res.tau)),
                "ess_bulk_min": float(np.min(res.ess_bulk)),
                "ess_bulk_per_cpu_s": float(np.min(res.ess_bulk)) / cpu,
                "acceptance": float(np.mean(res.acceptance_fraction)),
                "converged": res.converged,
                "mean": res.mean[:2].tolist(),
                "sd": res.sd[:2].tolist(),
            }
        )
    record_rows, record_diff = (
        ([], None) if args.no_record else _record_rows(args.harmonics, args.seed)
    )
    by = {r["mode"]: r for r in rows}
    result = {
        "benchmark": "crosscheck_step",
        "reference": "collapsed posterior with the piece Kalman filter likelihood, DE moves",
        "harmonics": args.harmonics,
        "step": args.step,
        "step_samples": model.length,
        "speedup": (by["reference"]["cpu_seconds"] / by["collapsed"]["cpu_seconds"])
        if "reference" in by
        else None,
        "rows": rows,
        "record": record_rows,
        "record_grid_vs_all": record_diff,
        "environment": {"cores_used": _CORES, "affinity": affinity()},
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(
        f"step {args.step} ({model.length} samples), n = {args.harmonics}, 4 ensembles, "
        f"{_CORES} core(s), CPU seconds; target < 1 s per step (collapsed)"
    )
    print(
        f"{'mode':<12} {'cpu s':>7} {'evals':>8} {'steps':>6} {'tau':>6} {'ESS':>7} "
        f"{'ESS/s':>7} {'acc':>5}  C mean (sd), K mean (sd)"
    )
    for r in rows:
        print(
            f"{r['mode']:<12} {r['cpu_seconds']:>7.2f} {r['evaluations']:>8} {r['steps']:>6} "
            f"{r['tau_max']:>6.1f} {r['ess_bulk_min']:>7.0f} {r['ess_bulk_per_cpu_s']:>7.1f} "
            f"{r['acceptance']:>5.2f}  {r['mean'][0]:.0f} ({r['sd'][0]:.0f}), "
            f"{r['mean'][1]:.0f} ({r['sd'][1]:.0f})" + ("" if r["converged"] else "  NOT CONVERGED")
        )
    if result["speedup"] is not None:
        print(f"collapsed speed-up over the reference (CPU time): {result['speedup']:.1f}x")
    if record_rows:
        print(f"whole record: {record_rows[0]['steps_checked']} steps")
        print(
            f"{'mode':<12} {'cpu s':>7} {'s/step':>7} {'steps':>6} {'tau':>6} {'ESS':>7} "
            f"{'ESS/s':>7} {'conv':>5} {'agree':>6}"
        )
        for r in record_rows:
            print(
                f"{r['mode']:<12} {r['cpu_seconds']:>7.2f} {r['cpu_seconds_per_step']:>7.3f} "
                f"{r['chain_steps_mean']:>6.0f} {r['tau_max']:>6.1f} {r['ess_bulk_min']:>7.0f} "
                f"{r['ess_bulk_per_cpu_s']:>7.0f} {r['converged_steps']:>5} "
                f"{r['agreement']:>6.2f}"
            )
        g = record_rows[0]
        print(
            f"grid: {g['grid']['rebuilds']} builds, largest measured interpolation error "
            f"{g['grid']['max_loglik_error']} (log-lik), {g['grid']['max_hand_over_error_sd']} "
            f"(hand-over sd); surrogate: largest mean shift {g['surrogate_mean_shift_sd_max']:.4f} "
            f"sd, {g['surrogate_resampled_exact']} steps sampled again exactly"
        )
        print(
            f"grid vs all history: means within {record_diff['mean_diff_sd_max']:.3f} sd, "
            f"sds within {100 * record_diff['sd_rel_diff_max']:.1f} %"
        )


if __name__ == "__main__":
    main()

"""Seconds per footstep of the per-step MCMC cross-check, collapsed and joint mode.

Usage: ``python analyses/benchmarks/crosscheck_step.py [--harmonics 10] [--step 5]
[--walkers 32] [--no-reference] [--no-joint] [--json]``
(main environment, one pinned core by default, ``--cores N`` to change).

One footfall step of a simulated walk
(:func:`~workbench.synth.simulate.simulate_walking`, 70 kg, 1.8 Hz, 10 s at 100 Hz, 3 N
noise, from rest, seed 11; seed observation noise, no process noise; n harmonics), with a
Gaussian prior on (C, K) (10 % above / 5 % below the truth, sd 25 % / 15 %) inside the
problem's prior box; every walker's hand-in is the previous step's exact hand-over at its
own (C, K), from that step's hand-in at the true (C, K). Sampled by
:func:`workbench.inference.mcmc.run_ensembles` (4 ensembles, lockstep) in three ways:

``reference``
    The named reference: the same collapsed (C, K) posterior with its likelihood from the
    piece Kalman filter (:func:`workbench.inference.kalman.piece_filter`, two pieces per
    call: the previous step for every row's own hand-in, then the step) and the runner's
    defaults (differential-evolution moves, first chunk of 500 steps) -- the cross-check as
    it stood before the closed-form step likelihood.
``collapsed``
    What ``workbench crosscheck`` runs by default: the same posterior with the closed-form
    step likelihood (:class:`workbench.inference.step_model.StepModel`) and the
    Gaussian-fit + DE move mixture (:func:`workbench.inference.crosscheck.default_moves`).
``joint``
    All ``2 n + 5`` parameters (C, K, hand-in state, force coefficients) sampled
    (``--mode joint``), same moves.

Printed per row: wall and CPU seconds, log-density evaluations (rows), calls, chain steps,
largest tau, smallest bulk ESS and ESS per CPU second, the cost of one call, the posterior
mean and sd of (C, K); and the speed-up of ``collapsed`` over the reference. The issue's
target is under 1 s per step, collapsed, on one core.
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

from workbench.inference import kalman as kf  # noqa: E402
from workbench.inference.crosscheck import StepTarget, default_moves  # noqa: E402
from workbench.inference.mcmc import run_ensembles  # noqa: E402
from workbench.inference.problem import build_problem  # noqa: E402
from workbench.inference.step_model import StepModel  # noqa: E402
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


def _per_call_ms(fn: Any, rows: np.ndarray, repeats: int = 50) -> float:
    t0 = time.process_time()
    for _ in range(repeats):
        fn(rows)
    return (time.process_time() - t0) / repeats * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--harmonics", type=int, default=10)
    parser.add_argument("--step", type=int, default=5)
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--walkers", type=int, default=32, help="per ensemble (32)")
    parser.add_argument("--no-reference", action="store_true", help="skip the reference")
    parser.add_argument("--no-joint", action="store_true", help="skip the joint mode")
    parser.add_argument("--cores", type=int, default=1, help="CPUs (pinned; default 1)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()

    problem, model, previous, centre, scale, hand_in = step_setup(args.harmonics, args.step)
    cov = np.diag(scale**2)
    collapsed = StepTarget(model, centre, cov, problem.prior, previous=previous)
    joint = StepTarget(model, centre, cov, problem.prior, mode="joint", previous=previous)
    reference = _Reference(problem, args.step, collapsed, hand_in)
    probe = collapsed.initial(np.random.default_rng(0), 2 * args.walkers)  # one lockstep call

    # The reference as the cross-check stood before: DE moves and the runner's first chunk
    # of 500 steps; the others as ``workbench crosscheck`` runs them.
    runs: list[tuple[str, Any, Any, Any, int]] = []
    if not args.no_reference:
        runs.append(("reference", reference, collapsed, "de", 500))
    runs.append(("collapsed", collapsed, collapsed, default_moves(), 100))
    if not args.no_joint:
        runs.append(("joint", joint, joint, default_moves(), 100))
    rows = []
    for name, target, starter, moves, first_chunk in runs:
        target.calls = 0
        walkers = max(args.walkers, 2 * starter.n_dim + 2)
        w0, c0 = time.perf_counter(), time.process_time()
        res = run_ensembles(
            target,
            lambda rng, s=starter, w=walkers: s.initial(rng, w),
            seed=args.seed,
            n_walkers=walkers,
            min_steps=first_chunk,
            moves=moves,
            param_names=starter.param_names,
        )
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        call_rows = (
            probe if name != "joint" else joint.initial(np.random.default_rng(0), 2 * walkers)
        )
        rows.append(
            {
                "mode": name,
                "seconds": wall,
                "cpu_seconds": cpu,
                "evaluations": res.n_evaluations,
                "calls": target.calls,
                "steps": res.n_steps,
                "walkers": walkers,
                "tau_max": float(np.max(res.tau)),
                "ess_bulk_min": float(np.min(res.ess_bulk)),
                "ess_bulk_per_cpu_s": float(np.min(res.ess_bulk)) / cpu,
                "ms_per_call": _per_call_ms(target, call_rows),
                "rows_per_call": int(call_rows.shape[0]),
                "converged": res.converged,
                "mean": res.mean[:2].tolist(),
                "sd": res.sd[:2].tolist(),
            }
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
        "environment": {"cores_used": _CORES, "affinity": affinity()},
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(
        f"step {args.step} ({model.length} samples), n = {args.harmonics}, 4 ensembles, "
        f"{_CORES} core(s); target < 1 s per step (collapsed)"
    )
    print(
        f"{'mode':<10} {'wall s':>7} {'cpu s':>7} {'evals':>7} {'calls':>6} {'steps':>6} "
        f"{'tau':>6} {'ESS':>7} {'ESS/s':>7} {'ms/call':>8}  C mean (sd), K mean (sd)"
    )
    for r in rows:
        print(
            f"{r['mode']:<10} {r['seconds']:>7.2f} {r['cpu_seconds']:>7.2f} {r['evaluations']:>7} "
            f"{r['calls']:>6} {r['steps']:>6} {r['tau_max']:>6.1f} {r['ess_bulk_min']:>7.0f} "
            f"{r['ess_bulk_per_cpu_s']:>7.0f} {r['ms_per_call']:>8.2f}  "
            f"{r['mean'][0]:.0f} ({r['sd'][0]:.0f}), {r['mean'][1]:.0f} ({r['sd'][1]:.0f})"
            + ("" if r["converged"] else "  NOT CONVERGED")
        )
    if result["speedup"] is not None:
        print(f"collapsed speed-up over the reference (CPU time): {result['speedup']:.1f}x")


if __name__ == "__main__":
    main()

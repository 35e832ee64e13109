"""Throughput of the seed-faithful particle filter against the ``particles`` library.

Runs :func:`workbench.inference.methods.pf.run_pf` and the ``particles`` library's bootstrap filter
(``particles.SMC(fk=particles.state_space_models.Bootstrap(ssm=..., data=...))``) on the same
model, the same data, with the same number of particles, resampling scheme (systematic) and
ESS threshold (0.5), in the same process, and prints particle-steps per second, their ratio
and the peak memory of each run (``tracemalloc``, which sees numpy's buffers).

The model on the ``particles`` side is the seed's (eqs. 15-23), written as a
``StateSpaceModel`` subclass over the same state ``X = (u, u', C, K, a0, a1, b1, ...)``:
``PX0`` draws u, u' from ``N(0, initial_state_sd^2)``, C, K uniform in the prior box and theta
from the force prior; ``PX(t, xp)`` takes the Euler step of eq. 20 with the basis row of
sample ``t - 1``, adds the process noise of u, u' and the random walk of C, K, and, when
sample ``t`` starts a piece, draws theta afresh (time-dependent ``PX``); ``PY`` is the
Gaussian observation of ``(u, u', u'')``. So that the reference is not handicapped, ``PX``
returns a small custom ``ProbDist`` that draws only the noise the model has (4 normals per
particle, not ``d``) instead of a generic ``MvNormal`` with zero scales for theta; ``PY`` is
the library's ``MvNormal`` with a per-component scale.

A model check runs first: on a short record with (C, K) fixed, both filters' log-likelihood
estimates (mean and spread over repeats) are printed beside the exact Kalman value
(:func:`workbench.inference.kalman.filter.dense_kalman_loglik`, Euler discretisation).

``particles`` needs numpy < 2 (and numba), so this script runs from its own virtual
environment; see ``analyses/benchmarks/README.md``.

Both filters run on one pinned core with single-threaded numerical libraries (``--cores N``
relaxes that; :mod:`_cores` says why it matters: unpinned, the library's small matrix products
oversubscribe the cores and the ratio triples).

Usage::

    .venv-bench/bin/python analyses/benchmarks/pf_throughput.py [--particles 500 2000 8000]
        [--duration 20] [--repeats 3] [--seed 0] [--json]
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.metadata
import json
import math
import os
import platform
import sys
import time
import tracemalloc
from collections.abc import Callable
from typing import Any

from _cores import affinity, pin_cores

_CORES = pin_cores(sys.argv)

import numba  # noqa: E402
import numpy as np  # noqa: E402  (after the thread-pool settings above)

from workbench.inference.core.problem import (  # noqa: E402
    ForcePrior,
    IdentificationProblem,
    NoiseModel,
    build_problem,
)
from workbench.inference.kalman.filter import dense_kalman_loglik  # noqa: E402
from workbench.inference.methods.pf import run_pf  # noqa: E402
from workbench.records.inspection import inspect_record  # noqa: E402
from workbench.synth.simulate import simulate_walking  # noqa: E402

try:
    import particles
    from particles import distributions as dists
    from particles import state_space_models as ssms
except ImportError:  # pragma: no cover - depends on the environment
    particles = None


# -- the seed's model in the particles library ------------------------------------------
if particles is not None:

    class _InitialLaw(dists.ProbDist):
        """Law of X_0: u, u' Gaussian, C, K uniform in the prior box, theta from its prior."""

        def __init__(self, model: SeedSMD):
            self.model = model

        def rvs(self, size: int | None = None) -> np.ndarray:
            mdl, n = self.model, int(size or 1)
            x = np.empty((n, mdl.dim))
            x[:, :2] = mdl.initial_sd * mdl.rng.standard_normal((n, 2))
            if mdl.fixed is None:
                x[:, 2] = mdl.rng.uniform(*mdl.damping_box, size=n)
                x[:, 3] = mdl.rng.uniform(*mdl.stiffness_box, size=n)
            else:
                x[:, 2:4] = mdl.fixed
            x[:, 4:] = mdl.theta_mean + mdl.theta_sd * mdl.rng.standard_normal((n, mdl.m))
            return x

    class _EulerLaw(dists.ProbDist):
        """Law of X_t given X_{t-1}: Euler step (eq. 20) + noise, theta redrawn at piece starts."""

        def __init__(self, model: SeedSMD, t: int, xp: np.ndarray):
            self.model, self.t, self.xp = model, t, xp

        def rvs(self, size: int | None = None) -> np.ndarray:
            mdl, xp = self.model, self.xp
            n = xp.shape[0]
            acc = mdl.acceleration(xp, self.t - 1)
            x = xp.copy()
            x[:, 0] += mdl.dt * xp[:, 1]
            x[:, 1] += mdl.dt * acc
            x[:, : mdl.n_moving] += mdl.move_sd * mdl.rng.standard_normal((n, mdl.n_moving))
            if mdl.is_start[self.t]:
                x[:, 4:] = mdl.theta_mean + mdl.theta_sd * mdl.rng.standard_normal((n, mdl.m))
            return x

    class SeedSMD(ssms.StateSpaceModel):
        """The seed's SMD model (eqs. 15-23) of an :class:`IdentificationProblem`."""

        def __init__(
            self,
            problem: IdentificationProblem,
            fixed: tuple[float, float] | None = None,
            seed: int | None = None,
        ):
            self.problem = problem
            self.rng = np.random.default_rng(seed)
            self.basis = np.ascontiguousarray(problem.basis)
            self.m = problem.n_coefficients
            self.dim = 4 + self.m
            self.mass = problem.mass_kg
            self.dt = problem.dt_s
            self.is_start = problem.piece_start_mask
            noise = problem.noise
            self.initial_sd = noise.initial_state_sd
            self.fixed = fixed
            self.n_moving = 2 if fixed is not None else 4
            self.move_sd = np.concatenate(
                [noise.state_sd, [noise.damping_rw_sd_ns_per_m, noise.stiffness_rw_sd_n_per_m]]
            )[: self.n_moving]
            self.obs_sd = noise.obs_sd
            self.damping_box = problem.prior.damping_ns_per_m
            self.stiffness_box = problem.prior.stiffness_n_per_m
            self.theta_mean = problem.force_prior.mean_n
            self.theta_sd = problem.force_prior.sd_n
            self.eye3 = np.eye(3)

        def acceleration(self, x: np.ndarray, row: int) -> np.ndarray:
            """``(-K u - C u' + b_row theta) / M`` for every particle."""
            force = x[:, 4:] @ self.basis[row]
            return (force - x[:, 3] * x[:, 0] - x[:, 2] * x[:, 1]) / self.mass

        def PX0(self) -> dists.ProbDist:
            """Law of X_0."""
            return _InitialLaw(self)

        def PX(self, t: int, xp: np.ndarray) -> dists.ProbDist:
            """Law of X_t given X_{t-1} = xp."""
            return _EulerLaw(self, t, xp)

        def PY(self, t: int, xp: np.ndarray, x: np.ndarray) -> dists.ProbDist:
            """Law of Y_t given X_t = x: Gaussian around (u, u', u'')."""
            loc = np.column_stack([x[:, 0], x[:, 1], self.acceleration(x, t)])
            return dists.MvNormal(loc=loc, scale=self.obs_sd, cov=self.eye3)

    def run_particles(
        problem: IdentificationProblem,
        n_particles: int,
        seed: int,
        fixed: tuple[float, float] | None = None,
    ) -> Any:
        """Run the particles library's bootstrap filter; returns the finished SMC object."""
        # The library resamples with numpy's global generator; the model draws from its own.
        np.random.seed(seed)  # noqa: NPY002
        fk = ssms.Bootstrap(ssm=SeedSMD(problem, fixed, seed), data=list(problem.y))
        smc = particles.SMC(
            fk=fk, N=n_particles, resampling="systematic", ESSrmin=0.5, collect=None
        )
        smc.run()
        return smc


# -- problems -----------------------------------------------------------------------------
def throughput_problem(duration_s: float, seed: int) -> IdentificationProblem:
    """Simulate a walking record: 100 Hz, n = 10 harmonics, footfall pieces, seed noise."""
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=duration_s,
        sample_rate_hz=100,
        natural_frequency_hz=2.0,
        damping_ratio=0.3,
        noise_sd_n=5.0,
        start="rest",
        seed=seed,
    )
    insp = inspect_record(sim.record, highpass_hz=0.15)
    return build_problem(insp.com, insp.steps, harmonics=10)


def check_problem(seed: int) -> tuple[IdentificationProblem, tuple[float, float]]:
    """Build a short record on which a bootstrap filter's likelihood estimate is precise.

    The same construction as the linear-Gaussian test of ``tests/test_pf.py``: 4 s, two
    harmonics, a force prior centred on the least-squares force, observation noise 50 % and
    process noise 10 % of the RMS of each state.
    """
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=4.0,
        sample_rate_hz=100,
        natural_frequency_hz=2.0,
        damping_ratio=0.3,
        noise_sd_n=5.0,
        start="rest",
        seed=seed,
    )
    insp = inspect_record(sim.record, highpass_hz=0.15)
    problem = build_problem(insp.com, insp.steps, harmonics=2)
    c, k = sim.truth["damping_ns_per_m"], sim.truth["stiffness_n_per_m"]
    force = problem.mass_kg * problem.y[:, 2] + k * problem.y[:, 0] + c * problem.y[:, 1]
    theta = np.linalg.lstsq(problem.basis, force, rcond=None)[0]
    rms = problem.rms
    problem = dataclasses.replace(
        problem,
        force_prior=ForcePrior(theta, np.full(theta.size, 10.0)),
        noise=NoiseModel(0.5 * rms, 0.1 * rms[:2], rms[:2]),
    )
    return problem, (c, k)


def _particles_version() -> str:
    if particles is None:
        return "(absent)"
    try:  # the package's own __version__ lags its releases (0.4 reports "0.3alpha")
        return importlib.metadata.version("particles")
    except importlib.metadata.PackageNotFoundError:
        return str(getattr(particles, "__version__", "?"))


# -- measurement --------------------------------------------------------------------------
@numba.njit(cache=True)
def _draw_normals_jit(rng: np.random.Generator, n: int) -> float:
    total = 0.0
    for _ in range(n):
        total += rng.standard_normal()
    return total


def _draw_normals(rng: np.random.Generator, n: int) -> float:
    return float(_draw_normals_jit(rng, n))


def _best_times(fns: dict[str, Callable[[], Any]], repeats: int) -> dict[str, tuple[float, float]]:
    """Best wall and best CPU time of each function, the functions interleaved per repeat.

    Interleaving exposes every contender to the same spells of load on a shared machine, and
    the CPU time of a single-threaded, pinned process does not count the time another
    process held the core.
    """
    best = {name: [math.inf, math.inf] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            w0, c0 = time.perf_counter(), time.process_time()
            fn()
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            best[name][0] = min(best[name][0], wall)
            best[name][1] = min(best[name][1], cpu)
    return {name: (b[0], b[1]) for name, b in best.items()}


def _peak_mb(fn: Callable[[], Any]) -> float:
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def model_check(seed: int, n_particles: int = 2000, repeats: int = 8) -> dict[str, Any]:
    """Log-likelihood of both filters beside the exact Kalman value, (C, K) fixed."""
    problem, fixed = check_problem(seed + 1)
    exact = float(dense_kalman_loglik(problem, *fixed, discretisation="euler").loglik)
    ours = [
        run_pf(
            problem,
            n_particles=n_particles,
            seed=seed + r,
            fixed_parameters=fixed,
            force_proposal="prior",
        ).loglik
        for r in range(repeats)
    ]
    out: dict[str, Any] = {
        "n_samples": problem.n_samples,
        "n_particles": n_particles,
        "repeats": repeats,
        "exact_kalman_loglik": exact,
        "workbench_mean": float(np.mean(ours)),
        "workbench_sd": float(np.std(ours, ddof=1)),
    }
    if particles is not None:
        ref = [
            float(run_particles(problem, n_particles, seed + r, fixed).logLt)
            for r in range(repeats)
        ]
        out["particles_mean"] = float(np.mean(ref))
        out["particles_sd"] = float(np.std(ref, ddof=1))
    return out


def measure(
    problem: IdentificationProblem, n_particles: int, repeats: int, seed: int
) -> dict[str, Any]:
    """Time and peak memory of both filters at one particle count."""
    steps = n_particles * problem.n_samples

    def ours(proposal: str) -> Any:
        return run_pf(problem, n_particles=n_particles, seed=seed, force_proposal=proposal)

    # Like for like: the library's bootstrap filter regenerates theta from the prior, so the
    # ratio is taken against ours doing the same; the default regression proposal (one
    # regression per piece) is timed beside it.
    # The floor of any filter of this model: the 4 process-noise normals per particle and
    # sample (u, u', C, K), drawn as run_pf draws them (numpy's generator driven from
    # compiled code, one normal at a time).
    rng = np.random.Generator(np.random.SFC64(seed))
    n_normals = 4 * n_particles * problem.n_samples
    fns: dict[str, Callable[[], Any]] = {
        "workbench": lambda: ours("prior"),
        "workbench_regression": lambda: ours("regression"),
        "normals": lambda: _draw_normals(rng, n_normals),
    }
    if particles is not None:
        fns["particles"] = lambda: run_particles(problem, n_particles, seed)
    times = _best_times(fns, repeats)
    ours_s, ours_cpu = times["workbench"]
    row: dict[str, Any] = {
        "n_particles": n_particles,
        "normals_only_s": times["normals"][1],
        "workbench_s": ours_s,
        "workbench_cpu_s": ours_cpu,
        "workbench_particle_steps_per_s": steps / ours_cpu,
        "workbench_peak_mb": _peak_mb(lambda: ours("prior")),
        "workbench_regression_s": times["workbench_regression"][1],
    }
    if particles is not None:
        ref_s, ref_cpu = times["particles"]
        row["particles_s"] = ref_s
        row["particles_cpu_s"] = ref_cpu
        row["particles_particle_steps_per_s"] = steps / ref_cpu
        row["particles_peak_mb"] = _peak_mb(lambda: run_particles(problem, n_particles, seed))
        row["speedup"] = ref_cpu / ours_cpu
        row["speedup_wall"] = ref_s / ours_s
        row["memory_ratio"] = row["particles_peak_mb"] / row["workbench_peak_mb"]
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--particles", type=int, nargs="+", default=[500, 2000, 8000])
    parser.add_argument("--duration", type=float, default=20.0, help="record length [s]")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs (best is kept)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-check", action="store_true", help="skip the model check")
    parser.add_argument(
        "--ours-only", action="store_true", help="run without the particles library"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument(
        "--cores", type=int, default=1, help="CPUs to run on (pinned before numpy; default 1)"
    )
    args = parser.parse_args(argv)
    if particles is None and not args.ours_only:
        print(
            "the particles library is not importable here (it needs numpy < 2); run this script "
            "from the benchmark environment described in analyses/benchmarks/README.md, or "
            "pass --ours-only",
            file=sys.stderr,
        )
        return 2

    problem = throughput_problem(args.duration, args.seed)
    # Warm up both (imports, BLAS threads, numba compilation inside particles).
    run_pf(problem, n_particles=100, seed=args.seed, force_proposal="prior")
    if particles is not None:
        run_particles(problem, 100, args.seed)
    result: dict[str, Any] = {
        "benchmark": "pf_throughput",
        "reference": "particles.SMC(Bootstrap) " + _particles_version(),
        "problem": {
            "source": "simulate_walking 70 kg, 1.8 Hz, f_n 2.0 Hz, zeta 0.3, 100 Hz",
            "n_samples": problem.n_samples,
            "n_pieces": problem.n_pieces,
            "harmonics": problem.harmonics,
            "state_dim": 4 + problem.n_coefficients,
        },
        "settings": {"resampling": "systematic", "ess_threshold": 0.5, "repeats": args.repeats},
        "environment": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "machine": platform.machine(),
            "cores_used": _CORES,
            "affinity": affinity(),
            "load_average": list(os.getloadavg()),
        },
        "rows": [measure(problem, n, args.repeats, args.seed) for n in args.particles],
    }
    if not args.no_check:
        result["model_check"] = model_check(args.seed)

    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    prob = result["problem"]
    print(
        f"Bootstrap particle filter throughput: {prob['n_samples']} samples, "
        f"{prob['n_pieces']} pieces, state dim {prob['state_dim']}, "
        f"reference {result['reference']}, numpy {np.__version__}, {_CORES} core(s) pinned, "
        f"load average {result['environment']['load_average'][0]:.2f}"
    )
    header = (
        f"{'particles':>9} {'workbench s':>12} {'Mpart-steps/s':>14} {'peak MB':>8} | "
        f"{'particles s':>12} {'Mpart-steps/s':>14} {'peak MB':>8} | {'speedup':>7} "
        f"{'wall':>6} {'mem ratio':>9}"
    )
    print(header)
    print("-" * len(header))
    for row in result["rows"]:
        line = (
            f"{row['n_particles']:>9} {row['workbench_cpu_s']:>12.3f} "
            f"{row['workbench_particle_steps_per_s'] / 1e6:>14.3f} "
            f"{row['workbench_peak_mb']:>8.1f} | "
        )
        if "particles_s" in row:
            line += (
                f"{row['particles_cpu_s']:>12.3f} "
                f"{row['particles_particle_steps_per_s'] / 1e6:>14.3f} "
                f"{row['particles_peak_mb']:>8.1f} | {row['speedup']:>6.1f}x "
                f"{row['speedup_wall']:>5.1f}x {row['memory_ratio']:>8.1f}x"
            )
        else:
            line += f"{'-':>12} {'-':>14} {'-':>8} | {'-':>7} {'-':>6} {'-':>9}"
        print(line)
    print("times are CPU seconds (best of the interleaved repeats); 'wall' is the wall-time ratio")
    print(
        "drawing the 4 process-noise normals per particle and sample alone takes "
        + ", ".join(
            f"{row['normals_only_s']:.3f} s ({row['n_particles']})" for row in result["rows"]
        )
    )
    print(
        "workbench s: theta regenerated from the prior, like the library; with the default "
        "regression proposal: "
        + ", ".join(
            f"{row['workbench_regression_s']:.3f} s ({row['n_particles']})"
            for row in result["rows"]
        )
    )
    if "model_check" in result:
        mc = result["model_check"]
        print(
            f"\nModel check ((C, K) fixed, {mc['n_samples']} samples, {mc['n_particles']} "
            f"particles, {mc['repeats']} runs): exact Kalman loglik "
            f"{mc['exact_kalman_loglik']:.3f}; "
            f"workbench {mc['workbench_mean']:.3f} +- {mc['workbench_sd']:.3f}"
            + (
                f"; particles {mc['particles_mean']:.3f} +- {mc['particles_sd']:.3f}"
                if "particles_mean" in mc
                else ""
            )
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

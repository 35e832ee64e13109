"""Seed section 4: the numerical example, identified by pf, rbpf and exact side by side.

Usage::

    python analyses/numerical_example.py [--obs-noise 0.01] [--methods pf,rbpf,exact]
        [--checkpoints 0.1,0.2,...] [--rbpf-trace-until 2] [--pf-particles 4000]
        [--rbpf-particles 256] [--state-noise FRACTION] [--prior modal|seed] [--duration 10]
        [--force-proposal regression|prior]
        [--seed 0] [--out DIR]

The problem is :func:`workbench.inference.core.problem.seed_example_problem`: 75 kg, f_n 2.5 Hz,
damping ratio 0.4 (C = 942.5 N s/m, K = 18505.5 N/m), the input of seed eq. 24 on a 0.5 Hz
basis with n = 10, 10 s at 1 kHz from rest, no high-pass, one piece, noise-free data with an
assumed observation noise of ``--obs-noise`` times the RMS of u, u', u'' (default 0.01, as
the issue's check asks; 0.10 is the seed's own setting). Each method gets the process noise
the workbench gives it by default (:attr:`IdentifySettings.state_fraction`): the seed's
0.5 % of the RMS for the seed-faithful ``pf``, none for ``rbpf`` and ``exact``;
``--state-noise`` sets one value for all. That choice matters: with the seed's 0.5 % the exact
posterior sits 6.5 % (C) and 5.7 % (K) below the truth at 10 % observation noise (3.4 and 4.5
sd) and 0.6 % / 0.7 % below at 1 % (2.7 and 4.7 sd); with none it is within 0.1 % at 10 %
and 0.2 % at 1 % (measured; ``--methods exact --state-noise 0.005``).

Full-record results come from :func:`workbench.inference.pipeline.identification.identify_problem`
(the orchestration behind ``workbench identify``), so estimates, bands, diagnostics and the
identifiability sentence are what a user of the command would get.

Convergence along the record (seed figs. 2-4). What each method carries over time:

- ``pf`` (:class:`~workbench.inference.core.outputs.ParticleFilterOutput`): C and K at every
  sample (``mean``, ``sd``; inside the piece these use the importance-corrected weights of
  the regression proposal, which lean towards the whole piece's posterior early on, see
  :mod:`workbench.inference.methods.pf`; the checkpoint runs are the proper values), but the
  force coefficients only at piece ends -- here once, at the end. Its force coefficients at
  the checkpoints come from re-running the filter on the data up to each checkpoint with the
  same seed: the posterior given y(0..t). With the default regression proposal the force
  draws of such a run are fitted to y(0..t) only, so it is a separate Monte Carlo run, not
  a replay of the full one (with ``force_proposal="prior"`` it would be one).
- ``rbpf``: one trace row per piece end, i.e. one row for this one-piece problem; the
  trace is the filter re-run on the data up to each checkpoint. On a single long piece the
  filter tempers the piece in several steps with exact Metropolis moves, each re-filtering
  the piece from its start, so its cost grows faster than the data (measured with 256
  particles on the rbpf of commit 9d6b2b2: 0.5 s of data 2 s, 2 s 40 s, 5 s 170 s, 10 s
  180-220 s); checkpoints after ``--rbpf-trace-until`` are skipped (the full record is
  always run). The whole default run took about 6 minutes on one core.
- ``exact`` (:class:`~workbench.inference.methods.exact.ExactPosterior`): one posterior, no trace;
  the trace is :func:`~workbench.inference.methods.exact.exact_posterior` on the data up to each
  checkpoint (the posterior given y(0..t), which a filter's estimate at t should match).

The data up to t are the problem's first samples with the noise model unchanged (absolute
standard deviations from the whole record's RMS), see :func:`head`.

Writes to ``--out`` (default ``analyses/out/numerical_example/``, git-ignored):
``numerical_example.json`` (every number printed, the traces at the checkpoints, timings,
diagnostics) and the figures ``convergence_ck.png`` (figs. 2-3), ``convergence_force.png``
(fig. 4) and ``coefficients.png``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from workbench.fileutil import atomic_write_json
from workbench.inference.core.problem import (
    IdentificationProblem,
    StiffnessDampingPrior,
    seed_example_problem,
)
from workbench.inference.core.results import IdentificationResult
from workbench.inference.methods import PF, RBPF
from workbench.inference.methods.exact import exact_posterior
from workbench.inference.methods.pf import run_pf
from workbench.inference.methods.rbpf import run_rbpf
from workbench.inference.pipeline.identification import identify_problem
from workbench.inference.pipeline.settings import IdentifySettings
from workbench.records.record import G_M_S2
from workbench.reporting.figures import save_figure
from workbench.reporting.studies import (
    MethodTrace,
    coefficients_figure,
    force_convergence_figure,
    method_convergence_figure,
    text_table,
)

#: The methods this study compares, in the order of its table: the seed's filter, the
#: Rao-Blackwellised filter and the exact posterior, each run on the record's prefixes by
#: its own function (``_checkpoint_run``), so not every registered method.
STUDIED_METHODS = ("pf", "rbpf", "exact")
SCALARS = (
    ("damping_ns_per_m", "C [N s/m]", "{:.1f}"),
    ("stiffness_n_per_m", "K [N/m]", "{:.0f}"),
    ("natural_frequency_hz", "f_n [Hz]", "{:.4f}"),
    ("damping_ratio", "zeta", "{:.4f}"),
)
DEFAULT_CHECKPOINTS = "0.1,0.2,0.35,0.5,0.75,1,1.5,2,3,5"
DEFAULT_OUT = Path("analyses/out/numerical_example")


def head(problem: IdentificationProblem, n_samples: int) -> IdentificationProblem:
    """Restrict a one-piece problem to its first ``n_samples`` samples.

    Everything else -- noise (absolute sd), priors, basis convention -- is kept, so the
    posterior of the result is the posterior given the data up to that sample.
    """
    if problem.n_pieces != 1:
        raise ValueError("head() is for one-piece problems such as the seed example")
    n = int(n_samples)
    if not 2 <= n <= problem.n_samples:
        raise ValueError(f"n_samples must be in 2..{problem.n_samples}, got {n}")
    return dataclasses.replace(
        problem,
        time_s=problem.time_s[:n],
        y=problem.y[:n],
        basis=problem.basis[:n],
        piece_starts=np.array([0, n], dtype=np.int64),
    )


def _parse_floats(text: str) -> list[float]:
    return [float(x) for x in text.split(",") if x.strip()]


def _finite(x: Any) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _blf(coef: np.ndarray, mass_kg: float) -> np.ndarray:
    return np.hypot(coef[1::2], coef[2::2]) / (mass_kg * G_M_S2)


def _settings(method: str, args: argparse.Namespace) -> IdentifySettings:
    particles = {"pf": args.pf_particles, "rbpf": args.rbpf_particles}.get(method)
    return IdentifySettings.from_flat(
        method=method,
        particles=particles,
        obs_noise=args.obs_noise,
        state_noise_fraction=args.state_noise,
        seed=args.seed,
        highpass_hz=0.0,
        pieces="whole",
        time_basis="absolute",
        pacing_hz=0.5,
        force_check=False,
        force_proposal=args.force_proposal,
    )


def _checkpoint_run(
    method: str, problem: IdentificationProblem, settings: IdentifySettings
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(C, K) mean and sd and the force coefficients' mean given the problem's data."""
    if method == "exact":
        post = exact_posterior(problem)
        if post.force is None:  # pragma: no cover - only with an injected likelihood
            raise RuntimeError("exact_posterior returned no force posterior")
        return post.mean, post.sd, post.force.mean[0]
    common: dict[str, Any] = {
        "n_particles": settings.n_particles,
        "seed": settings.seed,
        "resampling": settings.flat()["resampling"],
        "ess_threshold": settings.flat()["ess_threshold"],
    }
    if method == "pf":
        out = run_pf(problem, force_proposal=settings.flat()["force_proposal"], **common)
    else:
        out = run_rbpf(problem, **common)
    return out.mean[-1], out.sd[-1], out.piece_coefficients_mean[-1]


def _summarise(
    method: str,
    result: IdentificationResult,
    truth: dict[str, Any],
    seconds: float,
) -> dict[str, Any]:
    """Numbers of one method's full-record result against the truth."""
    est, sd, ci = result.estimates, result.posterior_sd, result.interval()
    grid = result.grid_results
    exact_json = grid.to_json() if method == "exact" and grid is not None else None
    if exact_json:  # the grid posterior's own moments (no Monte Carlo error of draws)
        est = {key: float(exact_json[key]) for key, _, _ in SCALARS}
        sd = {key: float(exact_json["posterior_sd"][key]) for key, _, _ in SCALARS}
        ci = {key: tuple(exact_json["intervals_95"][key]) for key, _, _ in SCALARS}
    problem = result.problem
    coef = result.piece_coefficients_mean[0]
    coef_sd = result.piece_coefficients_sd[0]
    true_coef = np.asarray(truth["force_coefficients"], dtype=float)
    true_force = problem.basis @ true_coef
    force_err = float(
        np.sqrt(np.mean((problem.basis @ coef - true_force) ** 2) / np.mean(true_force**2))
    )
    out: dict[str, Any] = {
        "method": method,
        "seconds": round(seconds, 2),
        "estimates": {},
        "posterior_sd": {},
        "interval_95": {},
        "relative_error": {},
        "error_in_sd": {},
        "force_coefficients_mean": [float(x) for x in coef],
        "force_coefficients_sd": [float(x) for x in coef_sd],
        "force_rms_relative_error": force_err,
        "blf": [float(x) for x in _blf(coef, problem.mass_kg)],
        "identifiability": result.identifiability.get("sentence"),
        "identifiability_level": result.identifiability.get("level"),
        "warnings": result.warnings,
        "loglik": _finite(result.loglik),
    }
    for key, _, _ in SCALARS:
        true = float(truth[key])
        out["estimates"][key] = float(est[key])
        out["posterior_sd"][key] = float(sd[key])
        out["interval_95"][key] = [float(v) for v in ci[key]]
        out["relative_error"][key] = float(est[key] / true - 1.0)
        out["error_in_sd"][key] = _finite((est[key] - true) / sd[key]) if sd[key] > 0 else None
    filtered = result.filter_results
    diag: dict[str, Any] = {"n_particles": int(filtered.n_particles if filtered else 0)}
    if filtered is not None and filtered.n_particles:
        diag["min_ess_fraction"] = result.min_ess_fraction
        diag["median_ess_fraction"] = result.median_ess_fraction
        diag["final_ess_fraction"] = float(filtered.ess[-1] / filtered.n_particles)
        diag["final_distinct_ancestors"] = result.final_ancestors
        diag["frozen_parameters"] = result.frozen_parameters
        diag["degenerate"] = result.degenerate
        diag["warnings"] = result.warnings
        diag["filter_settings"] = dict(filtered.settings)
    if exact_json:
        diag.update(
            grid=exact_json["grid"],
            laplace_sd_ratio=exact_json["laplace"]["sd_ratio"],
            ck_correlation=exact_json["ck_correlation"],
            notes=exact_json["notes"],
        )
    out["diagnostics"] = diag
    return out


def _trace_json(trace: MethodTrace) -> dict[str, Any]:
    return {
        "time_s": [float(t) for t in trace.time_s],
        "mean": trace.mean.tolist(),
        "sd": trace.sd.tolist(),
        "force_coefficients": None if trace.coefficients is None else trace.coefficients.tolist(),
    }


def _percent(x: float) -> str:
    """Format a relative error as a percentage (3 significant digits when huge)."""
    return f"{100 * x:+.2f} %" if abs(x) < 10 else f"{100 * x:+.3g} %"


def _explain(method: str, row: dict[str, Any], obs_noise: float) -> str:
    """Say in one plain sentence how far the method sits from the truth and why."""
    rel = row["relative_error"]
    zs = row["error_in_sd"]
    worst = max(abs(rel["damping_ns_per_m"]), abs(rel["stiffness_n_per_m"]))
    zc, zk = zs["damping_ns_per_m"], zs["stiffness_n_per_m"]
    z_max = max((abs(z) for z in (zc, zk) if z is not None), default=math.inf)

    def fmt(z: float | None) -> str:
        return "n/a" if z is None else f"{z:+.1f}"

    where = (
        f"{method}: C {_percent(rel['damping_ns_per_m'])}, K "
        f"{_percent(rel['stiffness_n_per_m'])} from the truth "
        f"({fmt(zc)} and {fmt(zk)} posterior sd)"
    )
    diag = row["diagnostics"]
    ancestors = diag.get("final_distinct_ancestors")
    if method == "pf" and (diag.get("degenerate") or diag.get("frozen_parameters")):
        return (
            f"{where}; the seed-faithful filter degenerated (median ESS "
            f"{100 * diag.get('median_ess_fraction', 0.0):.2g} % of the particles, all "
            f"descending from {ancestors} initial particle(s)), so its spread is no "
            "uncertainty."
        )
    if method == "pf":
        fs = diag.get("filter_settings", {})
        return (
            f"{where}; the filter's spread includes the seed's random walks of C and K "
            f"({fs.get('damping_rw_sd_ns_per_m', 0):g} N s/m and "
            f"{fs.get('stiffness_rw_sd_n_per_m', 0):g} N/m per sample), so it is wider than "
            "the model's posterior."
        )
    if worst < 0.01 and z_max < 4:
        return f"{where}: recovered within 1 %, the truth inside the posterior's spread."
    state = float(row["settings"]["state_noise_fraction"])
    if z_max >= 4 and method != "pf":
        return (
            f"{where}: the data are noise-free, but the assumed noise (observation "
            f"{100 * obs_noise:g} %, process {100 * state:g} % of the RMS per sample) is part "
            "of the model and this posterior is that model's answer; the process noise lets "
            "u and u' drift away from the SMD equation, which moves the mode (compare "
            "--state-noise 0)."
        )
    return f"{where}."


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the study, print the table and write the JSON and figures; return the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--obs-noise", type=float, default=0.01)
    parser.add_argument("--methods", default=",".join(STUDIED_METHODS))
    parser.add_argument("--checkpoints", default=DEFAULT_CHECKPOINTS)
    parser.add_argument("--rbpf-trace-until", type=float, default=2.0)
    parser.add_argument(
        "--state-noise",
        type=float,
        default=None,
        help="process noise of u, u' per sample as a fraction of their RMS, for every method "
        "(default: the workbench's per-method default, 0.005 for pf and 0 otherwise)",
    )
    parser.add_argument("--pf-particles", type=int, default=PF.n_particles)
    parser.add_argument("--rbpf-particles", type=int, default=RBPF.n_particles)
    parser.add_argument("--prior", choices=["modal", "seed"], default="modal")
    parser.add_argument(
        "--force-proposal",
        choices=["regression", "prior"],
        default="regression",
        help="pf: how the force coefficients are regenerated (default regression)",
    )
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = sorted(set(methods) - set(STUDIED_METHODS))
    if unknown or not methods:
        parser.error(f"--methods takes a comma-separated subset of {','.join(STUDIED_METHODS)}")
    if not 0 < args.obs_noise < 1:
        parser.error("--obs-noise must be a fraction between 0 and 1")
    if args.state_noise is not None and not 0 <= args.state_noise < 1:
        parser.error("--state-noise must be a fraction in [0, 1)")
    prior = StiffnessDampingPrior.seed() if args.prior == "seed" else None
    args.out.mkdir(parents=True, exist_ok=True)
    json_path = args.out / "numerical_example.json"

    summary: dict[str, Any] = {"methods": {}, "traces": {}}
    traces: list[MethodTrace] = []
    results: dict[str, IdentificationResult] = {}
    truth: dict[str, Any] = {}
    base: IdentificationProblem | None = None
    for method in methods:
        settings = _settings(method, args)
        problem, truth = seed_example_problem(
            duration_s=args.duration,
            obs_fraction=args.obs_noise,
            state_fraction=settings.state_fraction,
            prior=prior,
        )
        base = base or problem
        n = problem.n_samples
        cuts = sorted(
            {round(t / problem.dt_s) for t in _parse_floats(args.checkpoints)} & set(range(2, n))
        )
        if method == "rbpf":
            cuts = [c for c in cuts if c * problem.dt_s <= args.rbpf_trace_until + 1e-9]
        print(f"[{method}] full record ({n} samples) ...", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        result = identify_problem(problem, settings)
        seconds = time.perf_counter() - t0
        results[method] = result
        row = _summarise(method, result, truth, seconds)
        row["settings"] = {
            "n_particles": settings.n_particles,
            "state_noise_fraction": settings.state_fraction,
            "seed": settings.seed,
        }
        # Traces: checkpoint runs on the data up to each cut, then the full record.
        t0 = time.perf_counter()
        ck_mean, ck_sd, coefs = [], [], []
        for cut in cuts:
            print(
                f"[{method}] data up to {cut * problem.dt_s:g} s ...", file=sys.stderr, flush=True
            )
            m, s, c = _checkpoint_run(method, head(problem, cut), settings)
            ck_mean.append(m)
            ck_sd.append(s)
            coefs.append(c)
        est, sd = row["estimates"], row["posterior_sd"]
        ck_mean.append([est["damping_ns_per_m"], est["stiffness_n_per_m"]])
        ck_sd.append([sd["damping_ns_per_m"], sd["stiffness_n_per_m"]])
        coefs.append(result.piece_coefficients_mean[0])
        # Time of the last sample each run used.
        ck_time = problem.time_s[np.array([*cuts, n], dtype=np.int64) - 1]
        row["trace_seconds"] = round(time.perf_counter() - t0, 2)
        filtered = result.filter_results
        if method == "pf" and filtered is not None:
            sd_tr = filtered.trace_sd
            trace = MethodTrace(
                method,
                filtered.trace_time_s,
                filtered.trace_mean,
                sd_tr,
                coefficients=np.asarray(coefs),
                continuous=True,
                coefficient_time_s=ck_time,
            )
            # With blind regeneration the filter is causal and a checkpoint run replays the
            # full run exactly (same seed); the regression proposal fits the force to the
            # data the run is given, so its checkpoint runs are separate Monte Carlo runs of
            # the posterior given y(0..t) and are compared in posterior sd instead.
            idx = np.array([*cuts, n], dtype=np.int64) - 1
            if args.force_proposal == "prior":
                row["checkpoint_runs_match_full_run"] = bool(
                    np.allclose(np.asarray(ck_mean)[:-1], filtered.trace_mean[idx[:-1]], rtol=1e-9)
                )
            else:
                ck_sd_arr = np.asarray(ck_sd)[:-1]
                gap = np.abs(np.asarray(ck_mean)[:-1] - filtered.trace_mean[idx[:-1]])
                row["checkpoint_runs_gap_in_sd"] = _finite(
                    np.max(gap / np.maximum(ck_sd_arr, 1e-300)) if gap.size else 0.0
                )
            trace_for_json = MethodTrace(
                method, ck_time, filtered.trace_mean[idx], sd_tr[idx], np.asarray(coefs)
            )
        else:
            trace = MethodTrace(
                method, ck_time, np.asarray(ck_mean), np.asarray(ck_sd), np.asarray(coefs)
            )
            trace_for_json = trace
        traces.append(trace)
        summary["methods"][method] = row
        summary["traces"][method] = _trace_json(trace_for_json)
        atomic_write_json(json_path, summary)  # partial results survive a later failure

    assert base is not None
    truth_json = {key: float(truth[key]) for key, _, _ in SCALARS}
    true_coef = np.asarray(truth["force_coefficients"], dtype=float)
    summary["truth"] = {
        **truth_json,
        "force_coefficients": true_coef.tolist(),
        "coefficient_names": list(base.coefficient_names),
        "blf": [float(x) for x in truth["blf"]],
        "force": truth.get("force"),
    }
    summary["problem"] = {
        "duration_s": args.duration,
        "n_samples": base.n_samples,
        "dt_s": base.dt_s,
        "mass_kg": base.mass_kg,
        "harmonics": base.harmonics,
        "pacing_hz": base.pacing_hz,
        "obs_noise_fraction": args.obs_noise,
        "state_noise_fraction": {
            m: summary["methods"][m]["settings"]["state_noise_fraction"] for m in methods
        },
        "obs_sd": base.noise.obs_sd.tolist(),
        "prior": {
            "label": base.prior.label,
            "damping_ns_per_m": list(base.prior.damping_ns_per_m),
            "stiffness_n_per_m": list(base.prior.stiffness_n_per_m),
        },
    }
    summary["sentences"] = [_explain(m, summary["methods"][m], args.obs_noise) for m in methods]

    # Figures.
    title = f"Seed numerical example, assumed observation noise {100 * args.obs_noise:g} % of RMS"
    if args.state_noise is not None:
        title += f", process noise {100 * args.state_noise:g} %"
    figures = {
        "convergence_ck.png": method_convergence_figure(
            traces, truth_json, base.prior, title=title
        ),
        "convergence_force.png": force_convergence_figure(
            traces, base.time_s, base.basis, true_coef, title=title
        ),
        "coefficients.png": coefficients_figure(
            base.coefficient_names,
            true_coef,
            {
                m: (results[m].piece_coefficients_mean[0], results[m].piece_coefficients_sd[0])
                for m in methods
            },
        ),
    }
    summary["figures"] = [str(save_figure(fig, args.out / name)) for name, fig in figures.items()]
    atomic_write_json(json_path, summary)

    # Table.
    rows = []
    for key, label, fmt in SCALARS:
        rows.append([label, "truth", fmt.format(truth_json[key]), "", "", ""])
        for m in methods:
            r = summary["methods"][m]
            z = r["error_in_sd"][key]
            rows.append(
                [
                    "",
                    m,
                    fmt.format(r["estimates"][key]),
                    fmt.format(r["posterior_sd"][key]),
                    _percent(r["relative_error"][key]),
                    "" if z is None else f"{z:+.1f}",
                ]
            )
    for m in methods:
        r = summary["methods"][m]
        rows.append(
            [
                "force RMS error",
                m,
                f"{100 * r['force_rms_relative_error']:.2f} %",
                "",
                "",
                "",
            ]
        )
    print(title)
    print(text_table(["parameter", "method", "estimate", "posterior sd", "rel. error", "z"], rows))
    print()
    for m in methods:
        r = summary["methods"][m]
        print(f"{m}: {r['seconds']:.1f} s (+ {r['trace_seconds']:.1f} s of checkpoint runs)")
    print()
    for sentence in summary["sentences"]:
        print(sentence)
    print(f"\nwrote {json_path} and {len(summary['figures'])} figures in {args.out}")
    return summary


if __name__ == "__main__":
    main()

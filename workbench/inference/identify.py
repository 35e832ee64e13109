"""Identify a record: preprocess, build the problem, set the noise, run a method, wrap results.

This is the one function the command line, the demo, the studies and batch work call. The
steps, with the decisions they take:

1. inspect the record (validation, preprocessing, steps, pacing, static balance);
2. build the :class:`~workbench.inference.problem.IdentificationProblem` with the settings'
   basis, pieces and prior (``"modal"`` scales with body mass; ``"seed"`` is the seed's box);
3. set the observation noise (``auto``: maximum marginal likelihood, the default; ``seed``:
   10 % of the RMS of u, u', u''; or a fraction);
4. run ``rbpf`` (default), ``pf`` (seed-faithful) or ``exact``;
   with ``settings.effects``, the effects' columns join the force basis as coefficients shared
   by the whole record (:mod:`workbench.inference.effect_terms`), and the result's
   ``extra["effects"]`` (``--json`` ``effects``) reports their posterior;
5. assess identifiability from the posterior: contraction against the prior, C-K correlation
   and the joint correlation of C and K with the force coefficients (for the filters this
   uses the Kalman conditional posterior of the coefficients at a subsample of particles).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.inference.identifiability import force_correlation, identifiability_report
from workbench.inference.kalman import record_loglik
from workbench.inference.noise import apply_noise_setting
from workbench.inference.outputs import ParticleFilterOutput
from workbench.inference.problem import (
    IdentificationProblem,
    StiffnessDampingPrior,
    build_problem,
)
from workbench.inference.results import IdentificationResult
from workbench.inference.settings import IdentifySettings
from workbench.records.inspection import Inspection, inspect_record
from workbench.records.record import Record

__all__ = ["identify", "identify_problem", "problem_from_inspection"]

#: Particles (a weighted subsample) used to estimate the C/K-force correlation of a filter.
CORRELATION_DRAWS = 128


@dataclass(frozen=True)
class _NoiseInfo:
    fraction: float | None
    source: str
    detail: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        label = (
            f"{self.source}: observation noise {100 * self.fraction:.3g} % of the RMS of u, u', u''"
            if self.fraction is not None
            else self.source
        )
        return {"obs_fraction": self.fraction, "source": self.source, "label": label, **self.detail}


def problem_from_inspection(insp: Inspection, settings: IdentifySettings) -> IdentificationProblem:
    """Build the identification problem of an inspected record (noise not yet set)."""
    mass = insp.record.require_mass()
    prior = StiffnessDampingPrior.seed() if settings.prior == "seed" else None
    pacing = settings.pacing_hz
    if pacing is None and settings.pieces == "whole":
        pacing = insp.pacing.pacing_hz
    problem = build_problem(
        insp.com,
        insp.steps if settings.pieces == "steps" else None,
        harmonics=settings.harmonics,
        pacing_hz=pacing,
        time_basis=settings.time_basis,  # type: ignore[arg-type]
        pieces=settings.pieces,  # type: ignore[arg-type]
        state_fraction=settings.state_fraction,
        observe=settings.observe,
        prior=prior or StiffnessDampingPrior.from_modal(mass),
    )
    return problem


def _set_noise(
    problem: IdentificationProblem, settings: IdentifySettings
) -> tuple[IdentificationProblem, _NoiseInfo]:
    problem, estimate = apply_noise_setting(problem, settings.obs_noise)
    detail: dict[str, Any] = {}
    if estimate is not None:
        detail = {"method": estimate.method, "at_bound": estimate.at_bound}
    return problem, _NoiseInfo(problem.noise.obs_fraction, problem.noise.source, detail)


def _filter_identifiability(
    problem: IdentificationProblem, out: ParticleFilterOutput, seed: int
) -> dict[str, Any]:
    w = np.exp(out.log_weights - np.max(out.log_weights))
    w /= w.sum()
    draws = out.particles
    # Weighted moments without a degrees-of-freedom correction: np.cov's would divide by
    # zero when all the weight sits on one particle (a collapsed cloud has zero spread).
    dev = draws - w @ draws
    cov = (dev * w[:, None]).T @ dev
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = float(cov[0, 1] / (sd[0] * sd[1])) if np.all(sd > 0) else float("nan")
    rng = np.random.default_rng(seed)
    idx = rng.choice(draws.shape[0], size=min(CORRELATION_DRAWS, draws.shape[0]), p=w)
    force_max = (float("nan"), float("nan"))
    if np.all(sd > 0):
        res = record_loglik(problem, draws[idx, 0], draws[idx, 1], return_pieces=True)
        if res.theta_cov is None or res.theta_mean is None:  # pragma: no cover - contract
            raise RuntimeError("record_loglik(return_pieces=True) returned no coefficients")
        var = np.diagonal(res.theta_cov, axis1=-2, axis2=-1)
        fc = force_correlation(
            draws[idx, 0],
            draws[idx, 1],
            np.ones(idx.size),
            res.theta_mean,
            var,
            problem.coefficient_names,
        )
        force_max = (fc.max_damping, fc.max_stiffness)
    report = identifiability_report(sd, problem.prior.sd, corr, force_max)
    return report.to_json()


def identify_problem(
    problem: IdentificationProblem,
    settings: IdentifySettings,
    *,
    noise_info: dict[str, Any] | None = None,
    progress: bool = False,
) -> IdentificationResult:
    """Run one method on a problem whose noise is already set and wrap the result."""
    common: dict[str, Any] = {
        "problem": problem,
        "noise": noise_info
        or {"obs_fraction": problem.noise.obs_fraction, "source": problem.noise.source},
        "settings": settings.to_json(),
    }
    if settings.method == "exact":
        from workbench.inference.exact import exact_posterior

        post = exact_posterior(problem)
        rng = np.random.default_rng(settings.seed)
        draws = post.sample(4000, rng)
        force = post.force
        if force is None:  # pragma: no cover - only with an injected likelihood
            raise RuntimeError("the exact posterior returned no force coefficients")
        report = post.identifiability
        return IdentificationResult(
            method="exact",
            draws=draws,
            weights=np.full(draws.shape[0], 1.0 / draws.shape[0]),
            piece_coefficients_mean=force.mean,
            piece_coefficients_sd=force.sd,
            loglik=float(post.log_evidence),
            identifiability=report.to_json() if report is not None else {},
            extra={"exact": post.to_json() if hasattr(post, "to_json") else {}},
            **common,
        )
    if settings.method == "rbpf":
        from workbench.inference.rbpf import run_rbpf

        out = run_rbpf(
            problem,
            n_particles=settings.n_particles,
            seed=settings.seed,
            resampling=settings.resampling,
            ess_threshold=settings.ess_threshold,
            progress=progress,
        )
    else:
        from workbench.inference.pf import run_pf

        out = run_pf(
            problem,
            n_particles=settings.n_particles,
            seed=settings.seed,
            resampling=settings.resampling,
            ess_threshold=settings.ess_threshold,
            force_proposal=settings.force_proposal,
            progress=progress,
        )
    w = np.exp(out.log_weights - np.max(out.log_weights))
    return IdentificationResult(
        method=out.method,
        draws=np.asarray(out.particles),
        weights=w / w.sum(),
        piece_coefficients_mean=out.piece_coefficients_mean,
        piece_coefficients_sd=out.piece_coefficients_sd,
        loglik=float(out.loglik),
        identifiability=_filter_identifiability(problem, out, settings.seed),
        piece_mean=out.piece_mean,
        piece_sd=out.piece_sd,
        trace_time_s=out.trace_time_s,
        trace_mean=out.mean,
        trace_sd=out.sd,
        ess=out.ess,
        distinct_ancestors=out.distinct_ancestors,
        unique_values=out.unique_values,
        n_particles=out.n_particles,
        extra={"filter_settings": out.settings},
        **common,
    )


def identify(
    record: Record | Inspection,
    settings: IdentifySettings | None = None,
    *,
    rescale: bool = False,
    progress: bool = False,
    adjust_problem: Callable[[IdentificationProblem], IdentificationProblem] | None = None,
    adjust_noise: Callable[[IdentificationProblem], IdentificationProblem] | None = None,
) -> IdentificationResult:
    """Identify the SMD model of one record.

    Parameters
    ----------
    record : Record or Inspection
        A loaded record (with body mass), or its inspection if already done.
    settings : IdentifySettings, optional
        Method, particles, harmonics, noise, prior, seed... (defaults: see
        :mod:`workbench.inference.settings`).
    rescale : bool, default False
        Apply ``--rescale-to-mass`` during inspection.
    progress : bool, default False
        Show a progress bar for the filters.
    adjust_problem : callable, optional
        Applied to the problem before its observation noise is set (a prior box or random
        walks of C and K that the settings do not name; sensitivity studies).
    adjust_noise : callable, optional
        Applied to the problem after its observation noise is set (per-channel noise scales).

    Returns
    -------
    IdentificationResult
    """
    settings = settings or IdentifySettings()
    if isinstance(record, Inspection):
        insp = record
    else:
        insp = inspect_record(record, highpass_hz=settings.highpass_hz, rescale=rescale)
    problem = problem_from_inspection(insp, settings)
    if adjust_problem is not None:
        problem = adjust_problem(problem)
    problem, info = _set_noise(problem, settings)
    if adjust_noise is not None:
        problem = adjust_noise(problem)
    base = problem
    terms = None
    if settings.effects:
        from workbench.inference.effect_terms import effect_terms, with_effects

        terms = effect_terms(
            problem,
            list(settings.effects),
            ground_acc_m_s2=_ground_on(insp, problem),
            highpass_hz=settings.highpass_hz,
        )
        problem, pilot = with_effects(problem, terms)
    result = identify_problem(problem, settings, noise_info=info.to_json(), progress=progress)
    result.extra["inspection_warnings"] = list(insp.warnings)
    if terms is not None:
        from workbench.inference.effect_terms import effect_posterior

        post = effect_posterior(base, terms, result.draws, result.weights, seed=settings.seed)
        post["pilot"] = pilot
        result.extra["effects"] = post
    if settings.force_check:
        apply_force_model_check(result, problem)
    _downgrade_untrustworthy(result)
    return result


def _ground_on(insp: Inspection, problem: IdentificationProblem) -> Any:
    """Return the record's ground acceleration on the problem's samples, or None."""
    rec = insp.record
    if rec.ground_acc_m_s2 is None:
        return None
    return np.interp(problem.time_s, rec.time_s, rec.ground_acc_m_s2)


def apply_force_model_check(result: IdentificationResult, problem: IdentificationProblem) -> None:
    """Run :func:`~workbench.inference.force_check.force_model_check` and grade by it.

    The check's JSON goes to ``identifiability["force_model_check"]``; when C or K moves
    beyond the threshold both become "not identified" with the check's sentence, whatever
    their contraction (a misfitting model is often the more confident one).
    """
    from workbench.inference.force_check import force_model_check

    check = force_model_check(problem)
    report = dict(result.identifiability)
    report["force_model_check"] = check.to_json()
    if not check.passed:
        # C and K are estimated jointly: a misfit that moves one moves the other along their
        # ridge, so neither is reported as identified (on the simulated walks of
        # analyses/coverage_study.py the check moved C by 11-12 sd on two records while K
        # stayed within 3 sd, yet K's band missed the truth there).
        jointly = "" if check.dependent.all() else "; the other is estimated jointly with it"
        report["level"] = "not identified"
        report["sentence"] = f"Not identified: {check.sentence}{jointly}."
        report["identified_damping"] = False
        report["identified_stiffness"] = False
    result.identifiability = report


def _downgrade_untrustworthy(result: IdentificationResult) -> None:
    """Mark a posterior piled at the prior's edge, or a collapsed cloud, as not identified.

    Contraction alone would call such a posterior "well identified"; say what it is instead.
    """
    bound = result.parameters_at_prior_bound
    # Few surviving *initial* ancestors is path degeneracy, normal for the rbpf (its moves
    # renew the values); it means a collapse only for the seed's pf, whose values are
    # renewed by nothing but the random walk.
    collapsed = bool(result.frozen_parameters) or (
        result.method == "pf" and result.final_ancestors is not None and result.final_ancestors <= 5
    )
    if not bound and not collapsed:
        return
    report = dict(result.identifiability)
    why = (
        f"{' and '.join(bound)} sit at the edge of the prior box"
        if bound
        else "the particle cloud collapsed"
    )
    check = report.get("force_model_check") or {}
    also = "" if check.get("passed", True) else f" Also, {check['sentence']}."
    report["level"] = "not identified"
    report["sentence"] = (
        f"Not identified: {why}, so the numbers reflect the prior range or a collapsed filter, "
        "not this record; a model that fits the record better (see the residual diagnostics) "
        f"or another noise setting is needed before C and K can be read from it.{also}"
    )
    report["identified_damping"] = False
    report["identified_stiffness"] = False
    result.identifiability = report

"""The cross-check's MCMC posterior kept: InferenceData, and identifiability graded from it.

:func:`build_inference_data` assembles the arviz InferenceData of a cross-check from
every step's kept draws, with the force coefficients completed from their Gaussian
conditional in the collapsed mode (:func:`completion`); :func:`mcmc_identifiability` and
:func:`with_mcmc_identifiability` grade a record's identifiability from the MCMC posterior
of its last converged step instead of from the filter.

Its own idea: what is made of the draws once they are there, apart from the run that
makes them (:mod:`workbench.inference.crosscheck.check`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.inference.core import IdentificationProblem, IdentificationResult
from workbench.inference.crosscheck.compare import _modal
from workbench.inference.crosscheck.mcmc_result import McmcResult
from workbench.inference.crosscheck.results import CrosscheckResult
from workbench.inference.crosscheck.step_model import StepModel
from workbench.inference.crosscheck.step_target import StepTarget

__all__ = [
    "DRAWS_PER_CHAIN",
    "build_inference_data",
    "completion",
    "mcmc_identifiability",
    "with_mcmc_identifiability",
]

FloatArray = NDArray[np.float64]

#: Kept draws per ensemble and step in the InferenceData.
DRAWS_PER_CHAIN = 100


# -- InferenceData ------------------------------------------------------------------------
def _thin_per_chain(res: McmcResult, n: int) -> tuple[FloatArray, FloatArray]:
    """``n`` evenly spaced draws per ensemble: (E, n, d) parameters and (E, n) lp."""
    if res.draws is None or res.draw_lp is None:
        raise ValueError("the MCMC run kept no draws")
    arr, lp = res.draws, res.draw_lp
    idx = np.linspace(0, arr.shape[1] - 1, n).round().astype(int)
    return arr[:, idx], lp[:, idx]


def completion(
    model: StepModel, target: StepTarget, res: McmcResult, seed: int
) -> dict[str, FloatArray]:
    """Kept draws of one step with beta completed and pointwise log-likelihoods."""
    draws, lp = _thin_per_chain(res, DRAWS_PER_CHAIN)
    n_e, n_d, d = draws.shape
    flat = draws.reshape(-1, d)
    c, k, s, beta = target.split(flat)
    hand_in = target.hand_in(c, k)
    if target.mode == "joint":
        beta = target.beta(flat)
    if target.mode == "collapsed":
        rng = np.random.default_rng(seed)
        _, mean, root = model.collapsed_loglik(c, k, s, return_posterior=True, hand_in=hand_in)
        beta = mean + np.einsum("bij,bj->bi", root, rng.standard_normal(mean.shape))
    point = model.joint_loglik(c, k, beta, s, pointwise=True, hand_in=hand_in)
    n_ch = point.shape[2]
    prior_rng = np.random.default_rng(seed + 7)
    pc, pk = target._draw_ck(prior_rng, n_e * n_d)
    return {
        "damping": c.reshape(n_e, n_d),
        "stiffness": k.reshape(n_e, n_d),
        "noise_scale": s.reshape(n_e, n_d),
        "beta": beta.reshape(n_e, n_d, -1),
        "lp": lp,
        "loglik": point.reshape(n_e, n_d, model.length * n_ch),
        "observed": model.y[:, model.observed].reshape(-1),
        "time": np.repeat(model.problem.time_s[model.start : model.end], n_ch),
        "channel": np.tile(np.flatnonzero(model.observed), model.length),
        "prior_damping": pc.reshape(1, -1),
        "prior_stiffness": pk.reshape(1, -1),
    }


def build_inference_data(
    problem: IdentificationProblem, result: CrosscheckResult, parts: Sequence[dict[str, Any]]
) -> Any:
    """Assemble the per-record arviz InferenceData of a cross-check.

    Groups: ``posterior`` (C, K, noise scale, natural frequency, damping ratio, hand-in
    state and force coefficients, dims ``chain`` = ensemble, ``draw``, ``step``),
    ``sample_stats`` (``lp``), ``log_likelihood`` (``y``: every observed value of every
    checked step, dim ``obs``, with each draw's own step parameters), ``observed_data``
    (``y`` with its time, channel and step as coordinates) and ``prior`` (each step's
    (C, K) prior). Draws are :data:`DRAWS_PER_CHAIN` evenly spaced kept draws per ensemble.
    """
    import arviz as az

    steps = [s.index for s in result.steps]

    def stack(key: str) -> FloatArray:
        return np.stack([p[key] for p in parts], axis=-1)

    damping, stiffness = stack("damping"), stack("stiffness")
    fn, zeta = _modal(damping, stiffness, problem.mass_kg)
    beta = np.stack([p["beta"] for p in parts], axis=2)  # (E, D, step, q)
    names = ["u_in_m", "v_in_m_s", *problem.coefficient_names]
    loglik = np.concatenate([p["loglik"] for p in parts], axis=2)
    obs_step = np.concatenate(
        [np.full(p["observed"].size, i) for i, p in zip(steps, parts, strict=True)]
    )
    channel_names = ("u_m", "v_m_s", "acc_m_s2")
    posterior = {
        "damping_ns_per_m": damping,
        "stiffness_n_per_m": stiffness,
        "noise_scale": stack("noise_scale"),
        "natural_frequency_hz": fn,
        "damping_ratio": zeta,
        "u_in_m": beta[..., 0],
        "v_in_m_s": beta[..., 1],
        "force_coefficients_n": beta[..., 2:],
    }
    return az.from_dict(
        posterior=posterior,
        sample_stats={"lp": stack("lp")},
        log_likelihood={"y": loglik},
        observed_data={"y": np.concatenate([p["observed"] for p in parts])},
        prior={
            "damping_ns_per_m": stack("prior_damping"),
            "stiffness_n_per_m": stack("prior_stiffness"),
        },
        constant_data={
            "obs_step": obs_step,
            "obs_time_s": np.concatenate([p["time"] for p in parts]),
            "obs_channel": np.concatenate([p["channel"] for p in parts]),
        },
        coords={
            "step": steps,
            "coefficient": names[2:],
            "obs": np.arange(loglik.shape[2]),
        },
        dims={
            "damping_ns_per_m": ["step"],
            "stiffness_n_per_m": ["step"],
            "noise_scale": ["step"],
            "natural_frequency_hz": ["step"],
            "damping_ratio": ["step"],
            "u_in_m": ["step"],
            "v_in_m_s": ["step"],
            "force_coefficients_n": ["step", "coefficient"],
            "lp": ["step"],
            "y": ["obs"],
            "obs_step": ["obs"],
            "obs_time_s": ["obs"],
            "obs_channel": ["obs"],
        },
        attrs={
            "source": problem.source,
            "method": result.method,
            "mode": result.mode,
            "prior_construction": result.prior,
            "noise_scale": result.noise_scale,
            "channels": ",".join(channel_names),
        },
    )


# -- identifiability from the MCMC --------------------------------------------------------
def mcmc_identifiability(
    problem: IdentificationProblem, result: CrosscheckResult
) -> dict[str, Any]:
    """Return the identifiability report of the MCMC posterior of the last converged step.

    With the sequential prior the last step's posterior is the whole record's (the exact
    filtering posterior, crosscheck module docstring), so its sd against the prior box's, the C-K
    correlation and the largest correlation of C and K with that step's force coefficients
    (from the kept draws with the coefficients completed) grade the record as
    :func:`~workbench.inference.core.identifiability.identifiability_report` does for the filters.
    Returns an empty dict when no step converged or the prior was the filter's own.
    """
    from workbench.inference.core import identifiability_report

    if result.prior != "sequential" or not result.compared:
        return {}
    last = result.compared[-1]
    mean, cov = last.mcmc.mean[:2], last.mcmc.cov[:2, :2]
    sd = np.sqrt(np.diag(cov))
    corr = float(cov[0, 1] / (sd[0] * sd[1]))
    force = (float("nan"), float("nan"))
    idata = result.inference_data
    if idata is not None:
        post = idata.posterior.sel(step=last.index)
        c = post["damping_ns_per_m"].values.reshape(-1)
        k = post["stiffness_n_per_m"].values.reshape(-1)
        coef = post["force_coefficients_n"].values.reshape(c.size, -1)
        mat = np.corrcoef(np.column_stack([c, k, coef]), rowvar=False)
        force = (float(np.nanmax(np.abs(mat[0, 2:]))), float(np.nanmax(np.abs(mat[1, 2:]))))
    box = problem.prior
    lo = np.array([box.damping_ns_per_m[0], box.stiffness_n_per_m[0]])
    hi = np.array([box.damping_ns_per_m[1], box.stiffness_n_per_m[1]])
    edge = (np.abs(mean - lo) < 2 * sd) | (np.abs(hi - mean) < 2 * sd)
    report = identifiability_report(
        sd, box.sd, corr, force, on_prior_edge=(bool(edge[0]), bool(edge[1]))
    ).to_json()
    report["source"] = f"MCMC posterior after step {last.index} (sequential prior)"
    return report


def with_mcmc_identifiability(
    ident: IdentificationResult, result: CrosscheckResult
) -> IdentificationResult:
    """Return the identification result graded by its cross-check's MCMC posterior.

    Where one of the cross-check's steps converged, the identifiability report is that of
    the MCMC posterior after the last such step (contraction, width and correlations from
    the MCMC draws; its ``source`` says so) and the filter's own report is kept under
    ``"filter_report"``; otherwise the result comes back unchanged.

    Parameters
    ----------
    ident : IdentificationResult
        The filter's result on a problem.
    result : CrosscheckResult
        The cross-check of that filter on the same problem.

    Returns
    -------
    IdentificationResult
        A new result (results are immutable).
    """
    report = mcmc_identifiability(ident.problem, result)
    if not report:
        return ident
    report["filter_report"] = dict(ident.identifiability)
    return ident.replace(identifiability=report)

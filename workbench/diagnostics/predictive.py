"""One-step-ahead predictive residuals of an identified model (a criticism level).

The Kalman filter of the identification problem (:mod:`workbench.inference.kalman.filter`) predicts
every sample from the samples before it, ``E[y_k | y_<k, C, K]``, with the current step's
force coefficients at their posterior given the step's earlier samples. The GRF residual
``M (u''_k - E[u''_k | y_<k])`` [N] is then an *innovation*: for a correct model it is white,
so a Ljung-Box test on it checks the whole state-space model sample by sample, and the mean
log predictive density ``log p(y_k | y_<k)`` (nats per sample; its sum is the record's
log-likelihood) scores it.

This level is weaker than the held-out steps of :mod:`workbench.diagnostics.criticism`
against effects that a step's own force coefficients can absorb (they are refitted as the
step goes on), but it sees misfit *within* a step: a transient, a nonlinearity acting faster
than the step, a wrong discretisation or noise model.

At every footfall the step's force coefficients restart from their prior (mean zero), so the
first samples of each step are predicted with almost no force and carry the largest
residuals; the one-step RMSE is therefore usually *larger* than the held-out RMSE of the
shared-shape level and the two are not to be ranked against each other. Compare one-step
scores between models identified on the same record (for example without and with an effect).

(C, K) are taken at the identification's posterior mean (a plug-in: the posterior spread of
(C, K) is not mixed into the prediction).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.diagnostics.criticism import Diagnosis, ljung_box_p
from workbench.inference.core import IdentificationProblem, IdentificationResult
from workbench.inference.kalman import initial_state, piece_filter

__all__ = [
    "ONE_STEP_LAGS",
    "OneStepResiduals",
    "attach_one_step",
    "one_step_from_result",
    "one_step_residuals",
]

FloatArray = NDArray[np.float64]

#: Lags of the Ljung-Box test of the one-step residuals.
ONE_STEP_LAGS = 20


@dataclass(frozen=True, eq=False)
class OneStepResiduals:
    """One-step-ahead predictive residuals of GRF and their scores.

    Attributes
    ----------
    time_s : ndarray, shape (N,)
        Sample times [s].
    predicted_obs : ndarray, shape (N, 3)
        ``E[(u, u', u'')_k | y_<k]``.
    residual_n : ndarray, shape (N,)
        ``M (u''_k - E[u''_k | y_<k])`` [N].
    rmse_n : float
        RMS of ``residual_n`` [N].
    ljung_box_p : float
        Ljung-Box p-value of ``residual_n`` up to :data:`ONE_STEP_LAGS` lags.
    log_score : float
        Mean one-step log predictive density of the observations [nats per sample].
    damping_ns_per_m, stiffness_n_per_m : float
        The (C, K) used.
    """

    time_s: FloatArray
    predicted_obs: FloatArray
    residual_n: FloatArray
    rmse_n: float
    ljung_box_p: float
    log_score: float
    damping_ns_per_m: float
    stiffness_n_per_m: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (no arrays)."""
        return {
            "one_step_rmse_n": self.rmse_n,
            "one_step_ljung_box_p": self.ljung_box_p,
            "one_step_log_score": self.log_score,
            "one_step_at": {
                "damping_ns_per_m": self.damping_ns_per_m,
                "stiffness_n_per_m": self.stiffness_n_per_m,
            },
        }


def one_step_residuals(
    problem: IdentificationProblem,
    damping_ns_per_m: float,
    stiffness_n_per_m: float,
    *,
    lags: int = ONE_STEP_LAGS,
) -> OneStepResiduals:
    """One-step-ahead predictive residuals of a problem at one (C, K).

    Parameters
    ----------
    problem : IdentificationProblem
        The identification problem (noise set; with effect columns if identified with them).
    damping_ns_per_m, stiffness_n_per_m : float
        C and K.
    lags : int, default 20
        Ljung-Box lags.

    Returns
    -------
    OneStepResiduals
    """
    c = np.array([float(damping_ns_per_m)])
    k = np.array([float(stiffness_n_per_m)])
    xm, xc = initial_state(problem, 1)
    pred = np.empty((problem.n_samples, 3))
    loglik = 0.0
    for j in range(problem.n_pieces):
        res = piece_filter(problem, j, c, k, xm, xc, predictive=True)
        s, e = problem.piece_starts[j], problem.piece_starts[j + 1]
        if res.predicted_obs is None:  # pragma: no cover - contract of predictive=True
            raise RuntimeError("piece_filter(predictive=True) returned no prediction")
        pred[s:e] = res.predicted_obs[0]
        loglik += float(res.loglik[0])
        xm, xc = res.x_mean_next, res.x_cov_next
    resid = problem.mass_kg * (problem.y[:, 2] - pred[:, 2])
    return OneStepResiduals(
        time_s=problem.time_s,
        predicted_obs=pred,
        residual_n=resid,
        rmse_n=float(np.sqrt(np.mean(resid**2))),
        ljung_box_p=ljung_box_p(resid, lags),
        log_score=loglik / problem.n_samples,
        damping_ns_per_m=float(c[0]),
        stiffness_n_per_m=float(k[0]),
    )


def one_step_from_result(
    result: IdentificationResult, *, lags: int = ONE_STEP_LAGS
) -> OneStepResiduals:
    """One-step-ahead residuals of an identification at its posterior mean of (C, K).

    Parameters
    ----------
    result : IdentificationResult
        Any method's result (its problem carries the data, noise and effect columns).
    lags : int, default 20
        Ljung-Box lags.

    Returns
    -------
    OneStepResiduals
    """
    est = result.estimates
    return one_step_residuals(
        result.problem, est["damping_ns_per_m"], est["stiffness_n_per_m"], lags=lags
    )


def attach_one_step(diag: Diagnosis, one_step: OneStepResiduals) -> Diagnosis:
    """Add one-step-ahead residuals to a diagnosis (its ``baseline`` gains their scores).

    Parameters
    ----------
    diag : Diagnosis
        From :func:`workbench.diagnostics.criticism.diagnose`.
    one_step : OneStepResiduals
        From :func:`one_step_from_result` on the same record.

    Returns
    -------
    Diagnosis
        A new diagnosis (results are immutable).
    """
    return diag.with_one_step(one_step)

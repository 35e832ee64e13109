"""How well a record identifies damping C and stiffness K: contraction, correlations, words.

docs/science.md 4: over steady periodic walking ``K u + C u'`` lies in the span of the Fourier
basis, so (C, K) trade off against the force coefficients and the posterior of (C, K) stays
close to the prior. The product must say so instead of printing a number that is really the
prior. This module turns posterior summaries into that statement.

Measures
--------
Contraction
    ``posterior sd / prior sd`` of C and of K (the prior is the uniform box of
    :class:`~workbench.inference.core.problem.StiffnessDampingPrior`, sd = width / sqrt(12)).
    1 means the data taught nothing; the posterior of a Gaussian likelihood much narrower
    than the box has contraction ``sd_likelihood / sd_prior``.
C-K correlation
    Posterior correlation of C and K (a ridge: the data fix a combination, e.g. the natural
    frequency, but not both).
Force correlation
    The largest ``|corr(C, theta_pj)|`` (and the same for K) over the force coefficients
    ``theta_pj`` of every piece ``p`` in the *joint* posterior ``p(C, K, theta | y)``; see
    :func:`force_correlation` for how it is computed and why it is the joint one.

Levels (per parameter, from the contraction alone; the thresholds are arguments)
    ``contraction < 0.2``: ``"well identified"`` -- the posterior is less than a fifth of the
    prior's width, so the value comes from the record.
    ``0.2 <= contraction <= 0.5``: ``"weakly identified"`` -- the record narrows the range but
    the prior still shapes the answer.
    ``contraction > 0.5``: ``"mostly prior"`` -- the posterior is more than half as wide as the
    prior box; the reported value says more about the box than about the record.
    A parameter whose posterior mode lies on a face of the prior box is ``"mostly prior"``
    whatever its contraction: the data (or the force prior) favour values outside the box,
    so the reported value is the box's bound, not an identification.
    ``identified_damping`` / ``identified_stiffness`` are True unless the level is
    ``"mostly prior"``. The overall ``level`` is the worse of the two. Correlations do not
    change the level (a narrow posterior is informative however correlated it is) but are
    named in the sentence when ``|rho| >= 0.9`` (the force correlation only for a parameter
    that is not well identified: given the data, some coefficients -- each piece's ``a0``,
    set by ``K`` times the mean displacement -- follow a well-determined ``K`` almost
    exactly, which is no reason for concern).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError

__all__ = [
    "HIGH_CORRELATION",
    "MOSTLY_PRIOR_CONTRACTION",
    "WELL_IDENTIFIED_CONTRACTION",
    "ForceCorrelation",
    "IdentifiabilityReport",
    "force_correlation",
    "identifiability_report",
]

FloatArray = NDArray[np.float64]

#: Contraction (posterior sd / prior sd) below which a parameter is "well identified".
WELL_IDENTIFIED_CONTRACTION = 0.2
#: Contraction above which a parameter is "mostly prior".
MOSTLY_PRIOR_CONTRACTION = 0.5
#: |correlation| from which the sentence names a trade-off.
HIGH_CORRELATION = 0.9

_LEVELS = ("well identified", "weakly identified", "mostly prior")
_SYMBOL = {"damping": "C", "stiffness": "K"}


def _level(contraction: float, well: float, mostly_prior: float) -> str:
    if not np.isfinite(contraction):
        return "mostly prior"  # nothing known about the width: claim nothing
    if contraction < well:
        return "well identified"
    if contraction > mostly_prior:
        return "mostly prior"
    return "weakly identified"


def _percent(x: float) -> str:
    return f"{100.0 * x:.0f} %" if x >= 0.01 else f"{100.0 * x:.1g} %"


def _clause(symbol: str, level: str, contraction: float, on_edge: bool) -> str:
    if on_edge:
        return (
            f"{symbol} is mostly prior: its posterior is piled against the edge of the prior "
            f"box (posterior sd {_percent(contraction)} of the prior's), so the data favour "
            "values outside the range and the reported value is the range's bound"
        )
    if level == "mostly prior":
        return (
            f"{symbol} is mostly prior: its posterior sd is {_percent(contraction)} of the "
            "prior's, so the reported value says more about the prior range than about this "
            "record"
        )
    return f"{symbol} is {level} (posterior sd is {_percent(contraction)} of the prior's)"


@dataclass(frozen=True)
class IdentifiabilityReport:
    """How well one record identifies C and K (see the module docstring for the measures).

    Attributes
    ----------
    contraction_damping, contraction_stiffness : float
        Posterior sd / prior sd of C and K.
    ck_correlation : float
        Posterior correlation of C and K (NaN if unknown).
    max_force_correlation_damping, max_force_correlation_stiffness : float
        Largest |joint posterior correlation| of C (K) with any force coefficient of any
        piece (NaN if unknown).
    level_damping, level_stiffness : str
        ``"well identified"``, ``"weakly identified"`` or ``"mostly prior"``.
    identified_damping, identified_stiffness : bool
        False when the parameter is ``"mostly prior"``.
    on_prior_edge : (bool, bool)
        Whether the posterior mode of C / K lies on a face of the prior box.
    level : str
        The worse of the two levels.
    sentence : str
        Plain-words summary for reports and the command line.
    thresholds : dict
        The contraction and correlation thresholds used.
    """

    contraction_damping: float
    contraction_stiffness: float
    ck_correlation: float
    max_force_correlation_damping: float
    max_force_correlation_stiffness: float
    level_damping: str
    level_stiffness: str
    identified_damping: bool
    identified_stiffness: bool
    level: str
    sentence: str
    thresholds: dict[str, float] = field(default_factory=dict)
    on_prior_edge: tuple[bool, bool] = (False, False)

    def to_json(self) -> dict[str, Any]:
        """Return a JSON-able dict (NaN becomes None)."""

        def num(x: float) -> float | None:
            return round(float(x), 6) if np.isfinite(x) else None

        return {
            "level": self.level,
            "sentence": self.sentence,
            "identified_damping": bool(self.identified_damping),
            "identified_stiffness": bool(self.identified_stiffness),
            "level_damping": self.level_damping,
            "level_stiffness": self.level_stiffness,
            "contraction_damping": num(self.contraction_damping),
            "contraction_stiffness": num(self.contraction_stiffness),
            "ck_correlation": num(self.ck_correlation),
            "max_force_correlation_damping": num(self.max_force_correlation_damping),
            "max_force_correlation_stiffness": num(self.max_force_correlation_stiffness),
            "thresholds": {k: float(v) for k, v in self.thresholds.items()},
            "on_prior_edge": {
                "damping": bool(self.on_prior_edge[0]),
                "stiffness": bool(self.on_prior_edge[1]),
            },
        }


def _pair(value: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.shape != (2,):
        raise UsageError(
            f"identifiability_report: {name} must be two numbers (C, K), got {value!r}"
        )
    return arr


def identifiability_report(
    posterior_sd: ArrayLike,
    prior_sd: ArrayLike,
    ck_correlation: float = float("nan"),
    max_force_correlation: ArrayLike = (float("nan"), float("nan")),
    *,
    well_identified: float = WELL_IDENTIFIED_CONTRACTION,
    mostly_prior: float = MOSTLY_PRIOR_CONTRACTION,
    high_correlation: float = HIGH_CORRELATION,
    on_prior_edge: tuple[bool, bool] = (False, False),
) -> IdentifiabilityReport:
    """Grade how well C and K are identified and say it in plain words.

    Parameters
    ----------
    posterior_sd : (float, float)
        Posterior standard deviation of (C [N s/m], K [N/m]).
    prior_sd : (float, float)
        Prior standard deviation of (C, K) (``StiffnessDampingPrior.sd``).
    ck_correlation : float, optional
        Posterior correlation of C and K.
    max_force_correlation : (float, float), optional
        Largest |joint posterior correlation| of C and of K with the force coefficients
        (:func:`force_correlation`).
    well_identified, mostly_prior : float, optional
        Contraction thresholds (module docstring); ``0 < well_identified <= mostly_prior``.
    high_correlation : float, optional
        |correlation| from which the sentence names a trade-off.
    on_prior_edge : (bool, bool), optional
        Whether the posterior mode of C / K lies on a face of the prior box (then that
        parameter is ``"mostly prior"``).

    Returns
    -------
    IdentifiabilityReport

    Examples
    --------
    >>> r = identifiability_report((40.0, 300.0), (57.0, 7500.0))
    >>> r.level_stiffness, r.level_damping, r.level
    ('well identified', 'mostly prior', 'mostly prior')
    """
    post = _pair(posterior_sd, "posterior_sd")
    prior = _pair(prior_sd, "prior_sd")
    force = _pair(max_force_correlation, "max_force_correlation")
    if not (0 < well_identified <= mostly_prior):
        raise UsageError(
            "identifiability_report: thresholds must satisfy 0 < well_identified <= "
            f"mostly_prior, got {well_identified} and {mostly_prior}"
        )
    if np.any(~(prior > 0)):
        raise UsageError(f"identifiability_report: prior_sd must be positive, got {prior_sd!r}")
    contraction = post / prior
    edge = [bool(e) for e in on_prior_edge]
    if len(edge) != 2:
        raise UsageError("identifiability_report: on_prior_edge must be two booleans (C, K)")
    levels = [
        "mostly prior" if e else _level(float(c), well_identified, mostly_prior)
        for c, e in zip(contraction, edge, strict=True)
    ]
    level = max(levels, key=_LEVELS.index)
    # K first: it is the better identified of the two on almost every record, and the
    # sentence reads best from the firm statement to the weak one.
    clauses = [
        _clause("K", levels[1], float(contraction[1]), edge[1]),
        _clause("C", levels[0], float(contraction[0]), edge[0]),
    ]
    rho = float(ck_correlation)
    if np.isfinite(rho) and abs(rho) >= high_correlation:
        clauses.append(
            f"C and K are strongly correlated (rho = {rho:.2f}): the record fixes a "
            "combination of them better than each"
        )
    # A well-identified parameter's conditional coefficients follow it closely (a0 of
    # every piece is fixed by K times the mean displacement, say), so a high force
    # correlation is news only for a parameter the record does not pin down.
    traded = [
        f"{sym} (max |rho| = {abs(r):.2f})"
        for sym, r, lev in (("C", force[0], levels[0]), ("K", force[1], levels[1]))
        if np.isfinite(r) and abs(r) >= high_correlation and lev != "well identified"
    ]
    if traded:
        clauses.append(
            " and ".join(traded)
            + (" trade" if len(traded) > 1 else " trades")
            + " off against the force coefficients"
        )
    sentence = "; ".join(clauses) + "."
    return IdentifiabilityReport(
        contraction_damping=float(contraction[0]),
        contraction_stiffness=float(contraction[1]),
        ck_correlation=rho,
        max_force_correlation_damping=float(force[0]),
        max_force_correlation_stiffness=float(force[1]),
        level_damping=levels[0],
        level_stiffness=levels[1],
        identified_damping=levels[0] != "mostly prior",
        identified_stiffness=levels[1] != "mostly prior",
        level=level,
        sentence=sentence[0].upper() + sentence[1:],
        thresholds={
            "well_identified_contraction": float(well_identified),
            "mostly_prior_contraction": float(mostly_prior),
            "high_correlation": float(high_correlation),
        },
        on_prior_edge=(edge[0], edge[1]),
    )


@dataclass(frozen=True)
class ForceCorrelation:
    """Posterior correlation of C and K with every force coefficient of every piece.

    Attributes
    ----------
    damping, stiffness : ndarray, shape (P, m)
        Joint-posterior correlation ``corr(C, theta_pj)`` and ``corr(K, theta_pj)``.
    damping_between, stiffness_between : ndarray, shape (P, m)
        Correlation with the conditional means ``E[theta_pj | C, K, y]`` only (what
        correlating draws of (C, K) with their conditional means gives); always at least
        as large in magnitude as the joint one.
    max_damping, max_stiffness : float
        Largest |joint correlation| (NaN if nothing varies).
    argmax_damping, argmax_stiffness : (int, str)
        Piece and coefficient name where the maximum occurs.
    """

    damping: FloatArray
    stiffness: FloatArray
    damping_between: FloatArray
    stiffness_between: FloatArray
    max_damping: float
    max_stiffness: float
    argmax_damping: tuple[int, str]
    argmax_stiffness: tuple[int, str]


def _safe_max(corr: FloatArray, names: tuple[str, ...]) -> tuple[float, tuple[int, str]]:
    mag = np.abs(corr)
    if not np.any(np.isfinite(mag)):
        return float("nan"), (-1, "")
    idx = np.unravel_index(int(np.nanargmax(mag)), mag.shape)
    return float(mag[idx]), (int(idx[0]), names[int(idx[1])])


def force_correlation(
    damping: ArrayLike,
    stiffness: ArrayLike,
    weights: ArrayLike,
    theta_mean: ArrayLike,
    theta_var: ArrayLike,
    coefficient_names: tuple[str, ...] | None = None,
) -> ForceCorrelation:
    """Joint posterior correlation of (C, K) with the force coefficients.

    The joint posterior factorises as ``p(C, K | y) p(theta | C, K, y)``, with the second
    factor Gaussian (the Kalman filter's) with mean ``mu(C, K)`` and variance
    ``s2(C, K)``. By the laws of total covariance and variance,

        Cov(C, theta) = Cov(C, mu(C, K))            (the within-(C, K) part is zero)
        Var(theta)    = E[s2(C, K)] + Var(mu(C, K))

    so ``corr(C, theta) = Cov(C, mu) / (sd(C) sqrt(E[s2] + Var(mu)))``. That is the
    correlation in the joint posterior, the one a sampler over (C, K, theta) would report,
    and the one used for identifiability. Correlating draws of (C, K) with the conditional
    means alone (``corr(C, mu)``, returned as ``*_between``) leaves out the within-draw
    variance ``E[s2]`` and overstates the dependence when the coefficients are uncertain
    for a reason that has nothing to do with (C, K).

    The expectations are weighted sums over the given (C, K) points, which may be the nodes
    of a grid posterior with their weights (exact quadrature, deterministic) or equally
    weighted draws.

    Parameters
    ----------
    damping, stiffness : array_like, shape (B,)
        (C, K) points [N s/m, N/m].
    weights : array_like, shape (B,)
        Their posterior weights (normalised here).
    theta_mean : array_like, shape (B, P, m)
        Conditional posterior mean of the coefficients of every piece at every point.
    theta_var : array_like, shape (B, P, m)
        Conditional posterior variances (diagonal of the covariance).
    coefficient_names : tuple of str, optional
        Names of the m coefficients (for :attr:`ForceCorrelation.argmax_damping`).

    Returns
    -------
    ForceCorrelation
    """
    c = np.asarray(damping, dtype=np.float64).reshape(-1)
    k = np.asarray(stiffness, dtype=np.float64).reshape(-1)
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    mu = np.asarray(theta_mean, dtype=np.float64)
    var = np.asarray(theta_var, dtype=np.float64)
    if mu.ndim != 3 or var.shape != mu.shape or not (c.size == k.size == w.size == mu.shape[0]):
        raise UsageError(
            "force_correlation: damping, stiffness and weights need shape (B,) and theta_mean, "
            "theta_var shape (B, P, m) with the same B"
        )
    if not (np.all(w >= 0) and w.sum() > 0):
        raise UsageError("force_correlation: weights must be non-negative and not all zero")
    w = w / w.sum()
    names = coefficient_names or tuple(f"theta{j}" for j in range(mu.shape[2]))
    mu_bar = np.einsum("b,bpm->pm", w, mu)
    dmu = mu - mu_bar
    var_between = np.einsum("b,bpm->pm", w, dmu**2)
    var_total = var_between + np.einsum("b,bpm->pm", w, var)

    def corr_with(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        dx = x - np.dot(w, x)
        sd_x = math.sqrt(float(np.dot(w, dx**2)))
        cov = np.einsum("b,b,bpm->pm", w, dx, dmu)
        with np.errstate(invalid="ignore", divide="ignore"):
            joint = cov / (sd_x * np.sqrt(var_total))
            between = cov / (sd_x * np.sqrt(var_between))
        # No spread in the parameter or the coefficient: the correlation is undefined.
        joint = np.where(np.isfinite(joint), joint, np.nan)
        between = np.where(np.isfinite(between), between, np.nan)
        return joint, between

    jc, bc = corr_with(c)
    jk, bk = corr_with(k)
    max_c, arg_c = _safe_max(jc, names)
    max_k, arg_k = _safe_max(jk, names)
    return ForceCorrelation(jc, jk, bc, bk, max_c, max_k, arg_c, arg_k)

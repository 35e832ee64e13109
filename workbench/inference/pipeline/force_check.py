"""Is (C, K) set by the record or by the force model? A Hausman-type check.

docs/science.md 4: damping C and stiffness K are identified only by what the per-piece Fourier
force cannot absorb, so any force the basis misses lands on (C, K) instead. The posterior
width does not show this: it measures the noise, not the misfit, and a misfitting model is
often *more* confident. Measured on the simulated walks of ``tests/test_exact.py`` (step
durations, amplitudes and phases varying from step to step, force coefficients splined
through the steps, footfall pieces boundary to boundary): the marginal likelihood put (C, K) in
a corner of the prior box some 30-1000 posterior sd from the truth, and merely allowing each
harmonic to drift linearly across each step moved the mode by 10-30 sd the other way
(``analyses/coverage_study.py``). A user must be told.

The check
    Refit with a *richer* force: every harmonic ``i <= modulated_harmonics`` gets two more
    columns, its cosine and sine times the piece's local time ``s in [-1/2, 1/2)`` (the
    coefficient may change linearly across the piece: amplitude and phase drift within a
    step, a step whose length the footfall cut got slightly wrong). The richer model nests
    the reference one, so if the reference force model is right both locate the same
    (C, K) up to noise, and the difference of the two modes has variance close to
    ``var_rich - var_reference`` (Hausman 1978). The check reports, per parameter,

        z = |mode_rich - mode_reference| / sqrt(max(var_rich - var_ref, var_rich / 4))

    (the floor keeps z finite when the two widths coincide) and calls the parameter
    *force-model dependent* when ``z > threshold`` (default 3). The modes and curvatures are
    the Laplace approximations from :func:`~workbench.inference.methods.exact.find_mode` after a
    coarse grid over the prior box, on the problem's own noise model.

What it does not do: a record whose force the reference basis already describes (the seed's
numerical example) passes, and so may a misfit the linear drift does not resemble. Passing
is necessary, not sufficient; failing is a clear sign.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference.core import ForcePrior, IdentificationProblem
from workbench.inference.methods import LogLikelihood, find_mode, kalman_loglik

__all__ = [
    "DEFAULT_MODULATED_HARMONICS",
    "DEFAULT_THRESHOLD",
    "ForceModelCheck",
    "force_model_check",
    "with_step_drift",
]

FloatArray = NDArray[np.float64]

#: Harmonics whose coefficients may drift across a piece in the richer model (walking
#: forces carry most of their energy in the first few; each adds two columns per piece).
DEFAULT_MODULATED_HARMONICS = 5
#: z above which a parameter is called force-model dependent.
DEFAULT_THRESHOLD = 3.0
_RESTARTS = 4


def with_step_drift(
    problem: IdentificationProblem, modulated_harmonics: int = DEFAULT_MODULATED_HARMONICS
) -> IdentificationProblem:
    """Return the problem with each harmonic allowed to drift linearly across each piece.

    Parameters
    ----------
    problem : IdentificationProblem
        The reference problem.
    modulated_harmonics : int, default 5
        Harmonics ``1..min(n, modulated_harmonics)`` get a cosine and a sine column times the
        piece's local time ``s`` (from -1/2 at the piece's first sample to just under 1/2).

    Returns
    -------
    IdentificationProblem
        Same data, noise and prior; ``basis`` and ``force_prior`` extended (the drift
        coefficients have the prior sd of their harmonic). Only for likelihood evaluations:
        the extra coefficients have no names in reports.
    """
    n_mod = min(int(problem.harmonics), int(modulated_harmonics))
    if n_mod < 1:
        raise UsageError(f"modulated_harmonics must be at least 1, got {modulated_harmonics!r}")
    starts = problem.piece_starts
    piece = problem.piece_index
    length = np.diff(starts)[piece]
    local = (np.arange(problem.n_samples) - starts[:-1][piece]) / length - 0.5
    cols = slice(1, 1 + 2 * n_mod)
    basis = np.column_stack([problem.basis, problem.basis[:, cols] * local[:, None]])
    fp = problem.force_prior
    prior = ForcePrior(
        np.concatenate([fp.mean_n, np.zeros(2 * n_mod)]),
        np.concatenate([fp.sd_n, fp.sd_n[cols]]),
    )
    return dataclasses.replace(problem, basis=np.ascontiguousarray(basis), force_prior=prior)


@dataclass(frozen=True)
class _Mode:
    x: FloatArray
    cov: FloatArray | None
    at_bound: NDArray[np.bool_]
    converged: bool


def _locate(
    problem: IdentificationProblem,
    loglik: LogLikelihood,
    start: FloatArray | None,
    coarse_points: int,
) -> _Mode:
    lo = np.array([problem.prior.damping_ns_per_m[0], problem.prior.stiffness_n_per_m[0]])
    hi = np.array([problem.prior.damping_ns_per_m[1], problem.prior.stiffness_n_per_m[1]])

    def f(points: FloatArray) -> FloatArray:
        pts = np.atleast_2d(points)
        out = np.asarray(loglik(problem, pts[:, 0].copy(), pts[:, 1].copy()), dtype=np.float64)
        return np.where(np.isfinite(out), out, -np.inf)

    n = coarse_points
    centres = lo + (hi - lo) * (np.arange(n) + 0.5)[:, None] / n
    cc, kk = np.meshgrid(centres[:, 0], centres[:, 1], indexing="ij")
    nodes = np.column_stack([cc.ravel(), kk.ravel()])
    if start is not None:
        nodes = np.vstack([nodes, np.clip(start, lo, hi)[None]])
    values = f(nodes)
    best = int(np.argmax(values))
    x, value, scale = nodes[best], float(values[best]), np.diag((hi - lo) / n)
    # A narrow, curved ridge can stall the trust-region search before it converges; restart
    # from where it stopped with the curvature it found (a stalled search would hand both
    # models the same point and hide any shift).
    for _ in range(_RESTARTS):
        mode = find_mode(f, x, scale, lo, hi, value0=value, max_iter=30, tol=1e-2)
        if mode.converged:
            break
        x, value = mode.x, mode.value
        if mode.cov is not None:
            scale = np.linalg.cholesky(mode.cov + 1e-12 * np.diag(np.diag(mode.cov)))
    return _Mode(mode.x, mode.cov, mode.at_bound, mode.converged)


@dataclass(frozen=True)
class ForceModelCheck:
    """Result of :func:`force_model_check`.

    Attributes
    ----------
    reference_mode, rich_mode : ndarray, shape (2,)
        (C, K) modes of the reference and of the richer force model.
    reference_sd, rich_sd : ndarray, shape (2,)
        Their Laplace standard deviations (NaN where the log-likelihood is not concave).
    z : ndarray, shape (2,)
        The Hausman-type statistic of C and K (NaN when a curvature is missing).
    dependent : ndarray of bool, shape (2,)
        ``z > threshold`` for C, K.
    threshold : float
        The threshold used.
    modulated_harmonics : int
        Harmonics that could drift in the richer model.
    sentence : str
        Plain-words result.
    converged : bool
        Whether both mode searches converged (if not, the check is inconclusive and says so).
    """

    reference_mode: FloatArray
    rich_mode: FloatArray
    reference_sd: FloatArray
    rich_sd: FloatArray
    z: FloatArray
    dependent: NDArray[np.bool_]
    threshold: float
    modulated_harmonics: int
    sentence: str
    converged: bool = True

    @property
    def passed(self) -> bool:
        """True when neither C nor K moved beyond the threshold."""
        return not bool(np.any(self.dependent))

    def to_json(self) -> dict[str, Any]:
        """JSON-able dict (NaN becomes None)."""

        def nums(a: FloatArray) -> list[float | None]:
            return [round(float(v), 6) if math.isfinite(v) else None for v in a]

        return {
            "passed": self.passed,
            "sentence": self.sentence,
            "converged": self.converged,
            "threshold": self.threshold,
            "modulated_harmonics": self.modulated_harmonics,
            "reference_mode": nums(self.reference_mode),
            "rich_mode": nums(self.rich_mode),
            "reference_sd": nums(self.reference_sd),
            "rich_sd": nums(self.rich_sd),
            "z": nums(self.z),
            "dependent": {"damping": bool(self.dependent[0]), "stiffness": bool(self.dependent[1])},
        }


def _sd(cov: FloatArray | None) -> FloatArray:
    if cov is None:
        return np.full(2, np.nan)
    return np.sqrt(np.maximum(np.diag(cov), 0.0))


def force_model_check(
    problem: IdentificationProblem,
    *,
    modulated_harmonics: int = DEFAULT_MODULATED_HARMONICS,
    threshold: float = DEFAULT_THRESHOLD,
    coarse_points: int = 9,
    loglik: LogLikelihood | None = None,
    discretisation: str = "foh",
) -> ForceModelCheck:
    """Compare the (C, K) mode of the problem with that of a richer force model.

    Parameters
    ----------
    problem : IdentificationProblem
        The problem with its noise model already set.
    modulated_harmonics : int, default 5
        See :func:`with_step_drift`.
    threshold : float, default 3
        z above which a parameter is force-model dependent.
    coarse_points : int, default 9
        Nodes per axis of the coarse grid over the prior box that starts each mode search.
    loglik : callable, optional
        ``loglik(problem, damping, stiffness) -> (B,)``; default the Kalman filter's.
    discretisation : str, default "foh"
        Kalman discretisation for the default likelihood.

    Returns
    -------
    ForceModelCheck
    """
    if not (math.isfinite(threshold) and threshold > 0):
        raise UsageError(f"the force-model check threshold must be positive, got {threshold!r}")
    loglik = loglik or kalman_loglik(discretisation)
    rich_problem = with_step_drift(problem, modulated_harmonics)
    ref = _locate(problem, loglik, None, coarse_points)
    rich = _locate(rich_problem, loglik, ref.x, coarse_points)
    sd_ref, sd_rich = _sd(ref.cov), _sd(rich.cov)
    with np.errstate(invalid="ignore"):
        var = np.maximum(sd_rich**2 - sd_ref**2, 0.25 * sd_rich**2)
        z = np.abs(rich.x - ref.x) / np.sqrt(var)
    # A missing curvature (not concave, or a mode on the box face) leaves z undefined; a
    # move across more than a tenth of the prior box is then itself the sign.
    width = np.array(
        [np.diff(problem.prior.damping_ns_per_m)[0], np.diff(problem.prior.stiffness_n_per_m)[0]]
    )
    big_move = np.abs(rich.x - ref.x) > 0.1 * width
    dependent = np.where(np.isfinite(z), z > threshold, big_move)
    n_mod = min(int(problem.harmonics), int(modulated_harmonics))
    names = ("C", "K")
    moved = [names[j] for j in range(2) if dependent[j]]
    if moved:
        detail = ", ".join(
            f"{names[j]} from {ref.x[j]:.4g} to {rich.x[j]:.4g}"
            + (f" ({z[j]:.0f} sd)" if np.isfinite(z[j]) else "")
            for j in range(2)
            if dependent[j]
        )
        sentence = (
            f"{' and '.join(moved)} {'depend' if len(moved) > 1 else 'depends'} on the force "
            f"model: letting harmonics 1-{n_mod} "
            f"drift linearly across each step moves {detail}, so the record's misfit, not its "
            "information, sets the value and the band is too narrow"
        )
    else:
        sentence = (
            f"C and K do not move beyond {threshold:g} sd when harmonics 1-{n_mod} may drift "
            "across each step"
        )
    converged = ref.converged and rich.converged
    if not converged:
        sentence += " (a mode search did not converge: the check is inconclusive)"
    return ForceModelCheck(
        converged=converged,
        reference_mode=ref.x,
        rich_mode=rich.x,
        reference_sd=sd_ref,
        rich_sd=sd_rich,
        z=z,
        dependent=np.asarray(dependent, dtype=bool),
        threshold=float(threshold),
        modulated_harmonics=n_mod,
        sentence=sentence,
    )

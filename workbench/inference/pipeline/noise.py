"""Observation noise from the data: the ``auto`` setting of ``--obs-noise`` (the default).

The seed fixes the observation noise of (u, u', u'') at 10 % of their RMS (section 5.2). That
number is part of the model: it sets how much the filter trusts the data, hence how narrow the
posterior of (C, K) is and, on real records, where its mode lies. ``auto`` lets the record
choose: with ``obs_sd = s * RMS(u, u', u'')`` it maximises the marginal likelihood over the
scale ``s`` with (C, K) profiled out,

    s_hat = argmax_s  max_{C, K}  log p(y | C, K, s),

an empirical-Bayes (type-II maximum likelihood) estimate. Everything else in the noise model
(process noise, initial state, random walks of C and K) is kept as it is.

How it is found (each likelihood call is one batched Kalman run, whose cost hardly depends on
the number of (C, K) pairs, so every call evaluates a small (C, K) grid):

1. At a start fraction (the problem's own, if inside ``bounds``), locate the (C, K) mode
   with a coarse grid over the prior box and the batched Newton search of
   :func:`workbench.inference.methods.exact.find_mode`.
2. The profile ``max_{C,K} log p`` at any other ``s`` comes from one call on a 5 x 5 grid at
   +-2 sd around the mode of the nearest ``s`` already evaluated (its covariance rescaled by
   ``(s / s_near)^2``), a least-squares quadratic fit and the fit's maximum; when that
   maximum falls outside the fitted patch or the fit is poor, a 3 x 3 check around it follows.
3. In ``log s``: steps of a factor 3 from the start until the profile falls (a bracket), then
   Brent's parabolic search to ``xtol`` (about 10 % in ``s``). A maximum at a bound of
   ``bounds`` is reported as such (:attr:`NoiseEstimate.at_bound`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference.core import SEED_OBS_FRACTION, IdentificationProblem, NoiseModel
from workbench.inference.methods import LogLikelihood, find_mode, kalman_loglik

__all__ = [
    "NoiseEstimate",
    "apply_noise_setting",
    "estimate_obs_fraction",
    "noise_with_fraction",
    "parse_noise_setting",
]

FloatArray = NDArray[np.float64]

_PATCH = np.array(
    [(i, j) for i in (-2.0, -1.0, 0.0, 1.0, 2.0) for j in (-2.0, -1.0, 0.0, 1.0, 2.0)]
)
_CHECK = np.array([(i, j) for i in (-1.0, 0.0, 1.0) for j in (-1.0, 0.0, 1.0)])


@dataclass(frozen=True)
class NoiseEstimate:
    """The observation-noise fraction chosen from the data, and how it was found.

    Attributes
    ----------
    obs_fraction : float
        Chosen ``s``: ``obs_sd = s * RMS(u, u', u'')``.
    noise : NoiseModel
        The problem's noise model with that observation noise (``source="auto"``).
    profile_fraction : ndarray
        Fractions evaluated, increasing.
    profile_loglik : ndarray
        ``max_{C,K} log p(y | C, K, s)`` at each.
    damping_ns_per_m, stiffness_n_per_m : float
        The (C, K) maximising the likelihood at the chosen fraction.
    cov : ndarray, shape (2, 2) or None
        Inverse negative Hessian of the log-likelihood there (None if not concave); with
        the mode it is a good start for :func:`~workbench.inference.methods.exact.exact_posterior`
        (:attr:`mode`).
    at_bound : str or None
        ``"lower"`` or ``"upper"`` when the maximum is at a bound of the search range.
    bounds : (float, float)
        The search range.
    n_calls : int
        Number of batched likelihood calls.
    method : str
        One sentence on how the fraction was found.
    """

    obs_fraction: float
    noise: NoiseModel
    profile_fraction: FloatArray
    profile_loglik: FloatArray
    damping_ns_per_m: float
    stiffness_n_per_m: float
    cov: FloatArray | None
    at_bound: str | None
    bounds: tuple[float, float]
    n_calls: int
    method: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def mode(self) -> tuple[FloatArray, FloatArray | None]:
        """``((C, K), cov)`` at the chosen fraction, for ``exact_posterior(start=...)``."""
        return np.array([self.damping_ns_per_m, self.stiffness_n_per_m]), self.cov

    def to_json(self) -> dict[str, Any]:
        """Return a JSON-able dict."""
        return {
            "obs_fraction": float(self.obs_fraction),
            "source": "auto",
            "at_bound": self.at_bound,
            "bounds": [float(b) for b in self.bounds],
            "damping_ns_per_m": float(self.damping_ns_per_m),
            "stiffness_n_per_m": float(self.stiffness_n_per_m),
            "profile": {
                "obs_fraction": [float(v) for v in self.profile_fraction],
                "loglik": [float(v) for v in self.profile_loglik],
            },
            "likelihood_calls": int(self.n_calls),
            "method": self.method,
            "notes": list(self.notes),
        }


def noise_with_fraction(problem: IdentificationProblem, fraction: float, source: str) -> NoiseModel:
    """Return the problem's noise model with ``obs_sd = fraction * RMS(u, u', u'')``.

    Unlike :meth:`IdentificationProblem.noise_from_fractions` this keeps the process noise,
    initial-state noise and random walks exactly as they are.

    Parameters
    ----------
    problem : IdentificationProblem
        The problem.
    fraction : float
        Positive fraction.
    source : str
        ``"seed"``, ``"fixed"`` or ``"auto"``.

    Returns
    -------
    NoiseModel
    """
    f = float(fraction)
    if not (np.isfinite(f) and f > 0):
        raise UsageError(
            f"the observation noise fraction must be a positive number, got {fraction!r}"
        )
    return dataclasses.replace(
        problem.noise,
        obs_sd=problem.obs_sd_for(f),
        obs_fraction=f,
        source=source,
    )


def _fit_quadratic(z: FloatArray, f: FloatArray) -> tuple[float, FloatArray, FloatArray, float]:
    """Least-squares ``f ~ f0 + g.z + z.H.z / 2``; returns (f0, g, H, RMS residual)."""
    x, y = z[:, 0], z[:, 1]
    design = np.column_stack([np.ones_like(x), x, y, 0.5 * x * x, x * y, 0.5 * y * y])
    coef, *_ = np.linalg.lstsq(design, f, rcond=None)
    resid = f - design @ coef
    h = np.array([[coef[3], coef[4]], [coef[4], coef[5]]], dtype=np.float64)
    return (
        float(coef[0]),
        np.asarray(coef[1:3], dtype=np.float64),
        h,
        float(np.sqrt(np.mean(resid**2))),
    )


class _Profile:
    """Profile log-likelihood over (C, K) at given fractions, warm-started and cached."""

    def __init__(
        self, problem: IdentificationProblem, loglik: LogLikelihood, lo: FloatArray, hi: FloatArray
    ):
        self.problem = problem
        self.loglik = loglik
        self.lo, self.hi = lo, hi
        self.n_calls = 0
        #: ln s -> (profile value, mode (2,), cov (2, 2))
        self.cache: dict[float, tuple[float, FloatArray, FloatArray]] = {}

    def call(self, fraction: float, points: FloatArray) -> FloatArray:
        prob = self.problem.with_noise(noise_with_fraction(self.problem, fraction, "auto"))
        pts = np.atleast_2d(points)
        self.n_calls += 1
        out = np.asarray(self.loglik(prob, pts[:, 0].copy(), pts[:, 1].copy()), dtype=np.float64)
        return np.where(np.isfinite(out), out, -np.inf)

    def locate(self, fraction: float, coarse_points: int) -> None:
        """Stage 1: coarse grid over the box plus Newton search at one fraction."""
        n = coarse_points
        centres = [self.lo + (self.hi - self.lo) * (np.arange(n) + 0.5)[:, None] / n]
        cc, kk = np.meshgrid(centres[0][:, 0], centres[0][:, 1], indexing="ij")
        nodes = np.column_stack([cc.ravel(), kk.ravel()])
        values = self.call(fraction, nodes)
        best = int(np.argmax(values))
        mode = find_mode(
            lambda p: self.call(fraction, p),
            nodes[best],
            np.diag((self.hi - self.lo) / n),
            self.lo,
            self.hi,
            value0=float(values[best]),
            max_iter=15,
            tol=1e-2,
        )
        cov = mode.cov if mode.cov is not None else np.diag(((self.hi - self.lo) / n) ** 2)
        self.cache[math.log(fraction)] = (mode.value, mode.x, cov)

    def __call__(self, log_fraction: float) -> float:
        key = float(log_fraction)
        if key in self.cache:
            return self.cache[key][0]
        near = min(self.cache, key=lambda t: abs(t - key))
        _, centre, cov = self.cache[near]
        fraction = math.exp(key)
        guess = cov * math.exp(2.0 * (key - near))
        value, x, new_cov = self._patch(fraction, centre, guess)
        self.cache[key] = (value, x, new_cov)
        return value

    def _patch(
        self, fraction: float, centre: FloatArray, cov: FloatArray
    ) -> tuple[float, FloatArray, FloatArray]:
        s = _sqrt_cov(cov)
        z = _PATCH
        pts = self._keep_positive(centre, s, z)
        f = self.call(fraction, pts)
        ok = np.isfinite(f)
        zz = np.asarray(np.linalg.solve(s, (pts - centre).T).T, dtype=np.float64)
        best = int(np.argmax(np.where(ok, f, -np.inf)))
        f0, g, h, resid = (
            _fit_quadratic(zz[ok], f[ok])
            if ok.sum() >= 8
            else (0.0, np.zeros(2), np.eye(2), np.inf)
        )
        concave = bool(np.all(np.linalg.eigvalsh(h) < 0))
        if concave:
            z_star = -np.linalg.solve(h, g)
            x_star = np.clip(centre + s @ z_star, self.lo, self.hi)
            z_star = np.linalg.solve(s, x_star - centre)
            predicted = float(f0 + g @ z_star + 0.5 * z_star @ h @ z_star)
            new_cov = s @ np.linalg.inv(-h) @ s.T
            spread = float(np.max(np.abs(f[ok]))) if np.any(ok) else 1.0
            trusted = float(np.max(np.abs(z_star))) <= 1.5 and resid <= max(0.05, 1e-3 * spread)
            if trusted:
                return max(predicted, float(f[best])), x_star, 0.5 * (new_cov + new_cov.T)
            # Check around the fitted maximum with the fitted curvature.
            s2 = _sqrt_cov(new_cov)
            pts2 = self._keep_positive(x_star, s2, _CHECK)
            f2 = self.call(fraction, pts2)
            z2 = np.asarray(np.linalg.solve(s2, (pts2 - x_star).T).T, dtype=np.float64)
            ok2 = np.isfinite(f2)
            f0b, gb, hb, _ = (
                _fit_quadratic(z2[ok2], f2[ok2])
                if ok2.sum() >= 6
                else (0.0, np.zeros(2), np.eye(2), np.inf)
            )
            i2 = int(np.argmax(np.where(ok2, f2, -np.inf)))
            if np.all(np.linalg.eigvalsh(hb) < 0):
                zb = -np.linalg.solve(hb, gb)
                if float(np.max(np.abs(zb))) <= 1.5:
                    xb = np.clip(x_star + s2 @ zb, self.lo, self.hi)
                    zb = np.linalg.solve(s2, xb - x_star)
                    pred_b = float(f0b + gb @ zb + 0.5 * zb @ hb @ zb)
                    cov_b = s2 @ np.linalg.inv(-hb) @ s2.T
                    return max(pred_b, float(f2[i2])), xb, 0.5 * (cov_b + cov_b.T)
            return float(f2[i2]), pts2[i2], new_cov
        return float(f[best]), pts[best], cov

    def _keep_positive(self, centre: FloatArray, s: FloatArray, z: FloatArray) -> FloatArray:
        step = 1.0
        while True:
            pts = centre + step * (z @ s.T)
            if np.all(pts > 0) or step < 1e-6:
                return pts
            step *= 0.5


def _sqrt_cov(cov: FloatArray) -> FloatArray:
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    return (v * np.sqrt(np.maximum(w, 1e-300))) @ v.T


def estimate_obs_fraction(
    problem: IdentificationProblem,
    *,
    bounds: tuple[float, float] = (1e-4, 0.5),
    start: float | None = None,
    discretisation: str = "foh",
    loglik: LogLikelihood | None = None,
    coarse_points: int = 9,
    xtol: float = 0.1,
    max_calls: int = 40,
) -> NoiseEstimate:
    """Choose the observation-noise fraction by maximising the profile marginal likelihood.

    Parameters
    ----------
    problem : IdentificationProblem
        The problem; its noise model supplies everything except the observation noise.
    bounds : (float, float), default (1e-4, 0.5)
        Search range of the fraction ``s``.
    start : float, optional
        First fraction tried; default the problem's own if inside ``bounds``, else the
        geometric mean of the bounds.
    discretisation : str, default "foh"
        Kalman discretisation.
    loglik : callable, optional
        ``loglik(problem, damping, stiffness) -> (B,)`` (the problem carries the noise);
        default the Kalman filter's.
    coarse_points : int, default 9
        Nodes per axis of the first (C, K) grid over the prior box.
    xtol : float, default 0.1
        Tolerance of the search in ``ln s`` (10 % in ``s``: the posterior of (C, K) changes
        little over such a step, and every step costs a filter pass).
    max_calls : int, default 40
        Budget of batched likelihood calls; the best fraction so far is returned if it runs
        out (with a note).

    Returns
    -------
    NoiseEstimate
    """
    lo_s, hi_s = (float(b) for b in bounds)
    if not (np.isfinite(lo_s) and np.isfinite(hi_s) and 0 < lo_s < hi_s):
        raise UsageError(f"noise bounds must be two numbers 0 < low < high, got {bounds!r}")
    if start is None:
        own = problem.noise.obs_fraction
        start = own if own is not None and lo_s <= own <= hi_s else math.sqrt(lo_s * hi_s)
    if not lo_s <= float(start) <= hi_s:
        raise UsageError(f"the start fraction {start!r} lies outside the bounds {bounds!r}")
    loglik = loglik or kalman_loglik(discretisation)
    prior = problem.prior
    lo = np.array([prior.damping_ns_per_m[0], prior.stiffness_n_per_m[0]])
    hi = np.array([prior.damping_ns_per_m[1], prior.stiffness_n_per_m[1]])
    prof = _Profile(problem, loglik, lo, hi)
    notes: list[str] = []
    t_lo, t_hi = math.log(lo_s), math.log(hi_s)
    t0 = math.log(float(start))
    prof.locate(float(start), coarse_points)

    def neg(t: float) -> float:
        return -prof(t)

    # Bracket: factor-3 steps in ln s, uphill from the start, until the profile falls.
    step = math.log(3.0)
    around = sorted({max(t_lo, t0 - step), t0, min(t_hi, t0 + step)})
    t_b = max(around, key=prof)
    at_bound: str | None = None
    if t_b != t0:
        direction = 1.0 if t_b > t0 else -1.0
        while prof.n_calls < max_calls:
            t_next = float(np.clip(t_b + direction * step, t_lo, t_hi))
            if t_next == t_b or prof(t_next) <= prof(t_b):
                break
            t_b = t_next
        else:
            notes.append("the call budget ran out while bracketing the noise fraction")
    if t_b <= t_lo:
        at_bound = "lower"
    elif t_b >= t_hi:
        at_bound = "upper"
    t_best = t_b
    if at_bound is None and prof.n_calls < max_calls:
        a = max(t_lo, t_b - step)
        c = min(t_hi, t_b + step)
        for t in (a, c):
            prof(t)  # cached if already evaluated
        try:
            res = scipy.optimize.minimize_scalar(
                neg,
                bracket=(a, t_b, c),
                method="brent",
                options={"xtol": xtol / max(abs(t_b), 1.0), "maxiter": 8},
            )
            t_cand = float(np.clip(res.x, t_lo, t_hi))
            prof(t_cand)
        except ValueError:
            pass  # the bracket was not strict (a flat profile): keep the best evaluated
        t_best = max(prof.cache, key=lambda t: prof.cache[t][0])
        if t_best <= t_lo + 1e-12:
            at_bound = "lower"
        elif t_best >= t_hi - 1e-12:
            at_bound = "upper"
    fractions = np.exp(np.array(sorted(prof.cache)))
    values = np.array([prof.cache[t][0] for t in sorted(prof.cache)])
    _, x, cov = prof.cache[t_best]
    fraction = math.exp(t_best)
    if at_bound is not None:
        notes.append(
            f"the likelihood is largest at the {at_bound} bound of the search range "
            f"({fraction:.3g} of the RMS); the record is "
            + ("nearly noise-free for this model" if at_bound == "lower" else "far from the model")
        )
    concave_cov = cov if np.all(np.linalg.eigvalsh(0.5 * (cov + cov.T)) > 0) else None
    return NoiseEstimate(
        obs_fraction=fraction,
        noise=noise_with_fraction(problem, fraction, "auto"),
        profile_fraction=fractions,
        profile_loglik=values,
        damping_ns_per_m=float(x[0]),
        stiffness_n_per_m=float(x[1]),
        cov=concave_cov,
        at_bound=at_bound,
        bounds=(lo_s, hi_s),
        n_calls=prof.n_calls,
        method=(
            "maximum of the marginal likelihood over the observation-noise fraction, with "
            f"(C, K) profiled out ({prof.n_calls} batched Kalman runs)"
        ),
        notes=notes,
    )


_SETTING_HELP = (
    "a positive fraction of the RMS of u, u', u'' such as 0.05 (or 5%), 'seed' for the seed "
    "study's 0.10, or 'auto' to estimate it from the record"
)


def parse_noise_setting(setting: Any) -> float | str:
    """Validate an observation-noise setting: a fraction in (0, 1], ``"seed"`` or ``"auto"``.

    Parameters
    ----------
    setting : float, int or str
        ``0.05``, ``"0.05"``, ``"5%"``, ``"seed"``, ``"auto"`` (case and spaces ignored).

    Returns
    -------
    float or str
        The fraction, or ``"seed"`` / ``"auto"``.

    Raises
    ------
    UsageError
        One sentence naming the bad value and what is accepted.
    """
    bad = UsageError(f"'obs_noise' must be {_SETTING_HELP}; got {setting!r}", parameter="obs_noise")
    if isinstance(setting, bool) or setting is None:
        raise bad
    if isinstance(setting, str):
        text = setting.strip().lower()
        if text in ("seed", "auto"):
            return text
        scale = 1.0
        if text.endswith("%"):
            text, scale = text[:-1].strip(), 0.01
        try:
            value = float(text) * scale
        except ValueError:
            raise bad from None
    elif isinstance(setting, int | float | np.integer | np.floating):
        value = float(setting)
    else:
        raise bad
    if not (np.isfinite(value) and 0 < value <= 1):
        raise bad
    return value


def apply_noise_setting(
    problem: IdentificationProblem, setting: Any = "auto", **estimate_kwargs: Any
) -> tuple[IdentificationProblem, NoiseEstimate | None]:
    """Return the problem with the observation noise an ``--obs-noise`` setting asks for.

    Parameters
    ----------
    problem : IdentificationProblem
        The problem.
    setting : float or str, default "auto"
        A fraction (``0.05``, ``"5%"``), ``"seed"`` (0.10) or ``"auto"``
        (:func:`estimate_obs_fraction`).
    **estimate_kwargs
        Passed to :func:`estimate_obs_fraction` for ``"auto"``.

    Returns
    -------
    (IdentificationProblem, NoiseEstimate or None)
        The estimate only for ``"auto"``.
    """
    value = parse_noise_setting(setting)
    if value == "auto":
        estimate = estimate_obs_fraction(problem, **estimate_kwargs)
        return problem.with_noise(estimate.noise), estimate
    if value == "seed":
        return problem.with_noise(noise_with_fraction(problem, SEED_OBS_FRACTION, "seed")), None
    assert isinstance(value, float)
    return problem.with_noise(noise_with_fraction(problem, value, "fixed")), None

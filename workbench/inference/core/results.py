"""The identification results object (statsmodels-like).

Whatever the method, the posterior over (C, K) is held as weighted draws (particles of a
filter, or draws from the exact grid posterior); force coefficients per piece as means and
standard deviations. From these the result derives the quantities engineers report -- natural
frequency, damping ratio, BLFs -- with posterior standard deviations and 95 % intervals, and
it carries its own diagnostics: residuals, a Ljung-Box test of their serial correlation,
particle degeneracy and frozen-parameter flags, and the identifiability report.

A quantity the identifiability report grades not identified (C, K, and what rests on them)
is withheld from every view -- ``params``, ``conf_int()``, ``summary()``, the JSON -- and its
numbers are kept, named as the posterior given the prior box, for diagnosis.

Plotting lives in :mod:`workbench.reporting`; this module only computes.

All the views (statsmodels-like accessors, summary, JSON, netCDF, arviz) live in this one
class because they read the same grades: split across modules, one view could print what
another withholds. The parts only some runs produce are typed objects of
:mod:`workbench.inference.core.result_parts`.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from workbench.fileutil import atomic_path
from workbench.inference.core.load_factors import LoadFactorPosterior, coefficient_load_factors
from workbench.inference.core.node_posterior import NodePosterior
from workbench.inference.core.problem import IdentificationProblem
from workbench.inference.core.result_parts import (
    EffectPosterior,
    FilterResults,
    GridResults,
    Route,
    SurfaceReport,
)
from workbench.inference.core.weighted import _moments, weighted_quantile
from workbench.models.smd import SMDModel
from workbench.records.record import G_M_S2
from workbench.wording import count, p_value, parameters_in_words, verb

if TYPE_CHECKING:
    import arviz
    from matplotlib.figure import Figure

__all__ = ["IdentificationResult", "weighted_quantile"]

FloatArray = NDArray[np.float64]

#: Keys of the scalar estimates, in report order (docs/contracts.md names).
SCALAR_KEYS = ("stiffness_n_per_m", "damping_ns_per_m", "natural_frequency_hz", "damping_ratio")

#: What each scalar is computed from: it is identified only when all of these are. The BLFs
#: and the effects' parameters are the force given C and K, so they rest on both.
RESTS_ON = {
    "stiffness_n_per_m": ("stiffness",),
    "damping_ns_per_m": ("damping",),
    "natural_frequency_hz": ("stiffness",),
    "damping_ratio": ("damping", "stiffness"),
}
FORCE_RESTS_ON = ("damping", "stiffness")

#: The JSON key (and Python method) under which the numbers of quantities graded not
#: identified are kept: they are the posterior given the prior box, not estimates.
CONDITIONAL_KEY = "conditional_on_prior_box"

#: A filter whose median ESS fraction falls below this is reported as degenerate: its
#: weights stayed collapsed for most of the record. A single dip (the first informative
#: sample, a piece end's importance correction) that the filter recovers from is not.
DEGENERATE_ESS_FRACTION = 0.01
#: A parameter with at most this many distinct particle values at the end is "frozen".
FROZEN_UNIQUE_VALUES = 5
#: Fraction of the prior width within which a 95 % interval counts as touching the box edge.
BOUND_TOLERANCE = 0.01
#: A filter whose particles all descend from at most this many initial particles has lost
#: the diversity of its (C, K) cloud; reported with the frozen parameters.
FROZEN_ANCESTORS = 5


@dataclass(frozen=True, eq=False)
class IdentificationResult:
    """Estimates, uncertainty and diagnostics of one identification.

    Results are immutable: :meth:`replace` returns a derived copy. The statsmodels-like
    views are :attr:`params` and :attr:`bse` (pandas Series), :meth:`conf_int` (a
    DataFrame), :meth:`summary`, :meth:`to_json`, :meth:`to_inference_data` (arviz) and
    :meth:`plot_diagnostics`; :attr:`fitted_model` is the pedestrian model with the
    estimates filled in.

    Attributes
    ----------
    method : str
        ``"rbpf"``, ``"pf"`` or ``"exact"``.
    problem : IdentificationProblem
        The problem that was solved (data, basis, noise, priors).
    draws : ndarray, shape (S, 2)
        Posterior draws of (C [N s/m], K [N/m]).
    weights : ndarray, shape (S,)
        Their normalised weights.
    piece_coefficients_mean, piece_coefficients_sd : ndarray, shape (P, 2 n + 1)
        Posterior mean and std of each piece's force coefficients [N].
    loglik : float
        (Estimated) log marginal likelihood of the data under the model.
    identifiability : dict
        The identifiability report (JSON-able), see :mod:`workbench.inference.core.identifiability`.
    noise : dict
        The noise setting used and how it was chosen.
    settings : dict
        The run's settings.
    model : SMDModel or None
        The pedestrian model that was identified (mass, force description, effects).
    route : Route or None
        Which method ran, where C and K came from and why (set by ``identify``; None for a
        result a method returned on a problem directly).
    filter_results : FilterResults or None
        Traces, per-piece values and diagnostics of a particle filter (None for the exact
        grid).
    grid_results : GridResults or None
        The exact grid posterior's summary (None for the filters).
    surface : SurfaceReport or None
        What the walking surface contributed (set by ``identify``).
    effects : EffectPosterior or None
        The effects' posterior (a model with effects).
    inspection_warnings : tuple of str
        What inspecting the record found (static balance, body weight, footfalls).
    split : dict or None
        The footfall split's consistency check (``inspect --json``'s ``split``; set by
        ``identify`` on a record cut into steps).
    load_factors : LoadFactorPosterior or None
        The walk's load factors mixed over the (C, K) posterior (every built-in method sets
        it; without it the BLFs are those of the mean coefficients and their sd is the
        step-to-step standard error, which leaves out C and K).
    node_posterior : NodePosterior or None
        The (C, K) posterior on the nodes holding nearly all its mass, with each node's load
        factors, for fits over many records (:mod:`workbench.inference.core.node_posterior`;
        the exact grid and the deck route set it, the particle filters do not).
    """

    method: str
    problem: IdentificationProblem
    draws: FloatArray
    weights: FloatArray
    piece_coefficients_mean: FloatArray
    piece_coefficients_sd: FloatArray
    loglik: float
    identifiability: dict[str, Any]
    noise: dict[str, Any]
    settings: dict[str, Any]
    model: SMDModel | None = None
    route: Route | None = None
    filter_results: FilterResults | None = None
    grid_results: GridResults | None = None
    surface: SurfaceReport | None = None
    effects: EffectPosterior | None = None
    inspection_warnings: tuple[str, ...] = ()
    split: dict[str, Any] | None = None
    load_factors: LoadFactorPosterior | None = None
    node_posterior: NodePosterior | None = None

    def replace(self, **changes: Any) -> IdentificationResult:
        """Return a copy with some fields changed (results are immutable)."""
        return dataclasses.replace(self, **changes)

    @property
    def mass_kg(self) -> float:
        """Body mass [kg]."""
        return self.problem.mass_kg

    def _derived_draws(self) -> dict[str, FloatArray]:
        c, k = self.draws[:, 0], self.draws[:, 1]
        m = self.mass_kg
        return {
            "stiffness_n_per_m": k,
            "damping_ns_per_m": c,
            "natural_frequency_hz": np.sqrt(np.maximum(k, 0.0) / m) / (2 * np.pi),
            "damping_ratio": c / (2 * np.sqrt(np.maximum(k, 1e-12) * m)),
        }

    @property
    def estimates(self) -> dict[str, float]:
        """Posterior means of K, C, natural frequency and damping ratio."""
        w = self.weights
        return {k: _moments(v, w)[0] for k, v in self._derived_draws().items()}

    @property
    def posterior_sd(self) -> dict[str, float]:
        """Posterior standard deviations of K, C, natural frequency and damping ratio."""
        w = self.weights
        return {k: _moments(v, w)[1] for k, v in self._derived_draws().items()}

    def interval(self, level: float = 0.95) -> dict[str, tuple[float, float]]:
        """Equal-tailed posterior intervals of the scalar parameters."""
        q = np.array([(1 - level) / 2, (1 + level) / 2])
        out: dict[str, tuple[float, float]] = {}
        for k, v in self._derived_draws().items():
            lo, hi = weighted_quantile(v, self.weights, q)
            out[k] = (float(lo), float(hi))
        return out

    def _identified(self, what: str) -> bool:
        # A result without an identifiability report was not graded: nothing is withheld.
        return bool(self.identifiability.get(f"identified_{what}", True))

    def grade(self, key: str) -> str:
        """How well the record identifies ``key`` (a name of :attr:`params`).

        ``"not identified"`` when C or K that it rests on is graded not identified (K for K
        and the natural frequency, C for C, both for the damping ratio, the BLFs and the
        effects' parameters, which are the force given C and K); otherwise the worse level of
        those it rests on (``"well identified"``, ``"weakly identified"``) or
        ``"not assessed"``.
        """
        rests = RESTS_ON.get(key, FORCE_RESTS_ON)
        if not all(self._identified(w) for w in rests):
            return "not identified"
        levels = [self.identifiability.get(f"level_{w}") for w in rests]
        if any(lv is None for lv in levels):
            return "not assessed"
        return "weakly identified" if "weakly identified" in levels else "well identified"

    @property
    def force_identified(self) -> bool:
        """Whether C and K are both identified, so the BLFs and effects are estimates."""
        return all(self._identified(w) for w in FORCE_RESTS_ON)

    @property
    def not_identified(self) -> list[str]:
        """Names of :attr:`params` graded not identified (their numbers are no estimates)."""
        return [k for k in self._all_params().index if self.grade(k) == "not identified"]

    def prior_range(self, key: str) -> tuple[float, float]:
        """Range the prior box allows for K, C, the natural frequency or the damping ratio."""
        (c_lo, c_hi), (k_lo, k_hi) = (
            self.problem.prior.damping_ns_per_m,
            self.problem.prior.stiffness_n_per_m,
        )
        m = self.mass_kg
        ranges = {
            "stiffness_n_per_m": (k_lo, k_hi),
            "damping_ns_per_m": (c_lo, c_hi),
            "natural_frequency_hz": (
                float(np.sqrt(k_lo / m) / (2 * np.pi)),
                float(np.sqrt(k_hi / m) / (2 * np.pi)),
            ),
            # The box's corners: least damping on the stiffest walker and the reverse.
            "damping_ratio": (
                float(c_lo / (2 * np.sqrt(k_hi * m))),
                float(c_hi / (2 * np.sqrt(max(k_lo, 1e-12) * m))),
            ),
        }
        return ranges[key]

    def _all_params(self) -> pd.Series:
        values = dict(self.estimates)
        values.update({f"blf{i}": float(b) for i, b in enumerate(self.blf, start=1)})
        for name, post in self._effect_posterior().items():
            values[name] = post["mean"]
        return pd.Series(values, name="estimate", dtype=float)

    def _all_bse(self) -> pd.Series:
        values = dict(self.posterior_sd)
        values.update({f"blf{i}": float(b) for i, b in enumerate(self.blf_sd, start=1)})
        for name, post in self._effect_posterior().items():
            values[name] = post["sd"]
        return pd.Series(values, name="sd", dtype=float)

    def _all_conf_int(self, alpha: float) -> pd.DataFrame:
        if not (0 < alpha < 1):
            from workbench.errors import UsageError

            raise UsageError(f"conf_int: alpha must be in (0, 1), got {alpha!r}")
        from scipy.stats import norm

        rows = {k: list(v) for k, v in self.interval(1.0 - alpha).items()}
        z = float(norm.ppf(1.0 - alpha / 2.0))
        params, bse = self._all_params(), self._all_bse()
        for key in params.index:
            if key not in rows:
                rows[key] = [params[key] - z * bse[key], params[key] + z * bse[key]]
        frame = pd.DataFrame.from_dict(rows, orient="index", columns=["lower", "upper"])
        return frame.loc[params.index]

    @property
    def params(self) -> pd.Series:
        """Posterior means: K, C, f_n, zeta, BLF1..n and the effects' parameters.

        Effect parameters are named ``"effect.parameter"`` (``"gait_asymmetry.a_half_n"``).
        A quantity graded not identified (:meth:`grade`) is NaN: its number is the posterior
        given the prior box, not an estimate, and is in :meth:`conditional_on_prior_box`.
        """
        out = self._all_params()
        out[self.not_identified] = np.nan
        return out

    @property
    def bse(self) -> pd.Series:
        """Posterior standard deviations, indexed like :attr:`params` (NaN where it is).

        For the BLFs it is the standard error of the mean over steps.
        """
        out = self._all_bse()
        out[self.not_identified] = np.nan
        return out

    def conf_int(self, alpha: float = 0.05) -> pd.DataFrame:
        """Posterior intervals at level ``1 - alpha``, indexed like :attr:`params`.

        Equal-tailed quantiles of the posterior draws for K, C, f_n and zeta; mean plus or
        minus the normal quantile times the standard error for the BLFs and the effects.
        Rows graded not identified are NaN (see :meth:`conditional_on_prior_box`).

        Parameters
        ----------
        alpha : float, default 0.05
            One minus the level.

        Returns
        -------
        pandas.DataFrame
            Columns ``lower`` and ``upper``.
        """
        out = self._all_conf_int(alpha)
        out.loc[self.not_identified] = np.nan
        return out

    def conditional_on_prior_box(self, alpha: float = 0.05) -> pd.DataFrame:
        """Return the numbers withheld from :attr:`params`: the posterior given the prior box.

        For each quantity graded not identified, its posterior mean, sd and interval at level
        ``1 - alpha``. They describe the prior box as much as the record (a posterior piled
        at the box's edge, or one a misfitting force model moves by many sd), so they are no
        estimates; they are kept to diagnose the fit. Empty when everything is identified.

        Returns
        -------
        pandas.DataFrame
            Columns ``estimate``, ``sd``, ``lower``, ``upper``.
        """
        keys = self.not_identified
        ci = self._all_conf_int(alpha).loc[keys]
        return pd.DataFrame(
            {
                "estimate": self._all_params()[keys],
                "sd": self._all_bse()[keys],
                "lower": ci["lower"],
                "upper": ci["upper"],
            },
            index=pd.Index(keys),
        )

    def _effect_posterior(self) -> dict[str, dict[str, float]]:
        return {} if self.effects is None else self.effects.means()

    @property
    def fitted_model(self) -> SMDModel:
        """The identified pedestrian model: posterior-mean K and C, effects at their means.

        Its force is the pacing of the problem and the mean over pieces of the posterior-mean
        Fourier coefficients (on the problem's time basis), so the model can walk on a
        simulated record or a footbridge.
        """
        base = self.model if self.model is not None else SMDModel(harmonics=self.problem.harmonics)
        est = self.estimates
        effects = base.effects
        if effects:
            post = self._effect_posterior()
            effects = type(effects)(
                e.with_values(
                    **{
                        p: post[f"{e.name}.{p}"]["mean"]
                        for p in e.parameter_names
                        if f"{e.name}.{p}" in post
                    }
                )
                for e in effects
            )
        n_force = 2 * self.problem.harmonics + 1
        return base.replace(
            mass_kg=self.mass_kg,
            stiffness_n_per_m=est["stiffness_n_per_m"],
            damping_ns_per_m=est["damping_ns_per_m"],
            effects=effects,
            harmonics=self.problem.harmonics,
            pacing_hz=float(self.problem.pacing_hz),
            force_coefficients_n=tuple(self.piece_coefficients_mean[:, :n_force].mean(axis=0)),
        )

    @property
    def piece_blf(self) -> FloatArray:
        """BLF_i of every piece, shape (P, n): mixed over (C, K) where the result has them."""
        if self.load_factors is not None:
            return self.load_factors.piece
        return coefficient_load_factors(
            self.piece_coefficients_mean, self.mass_kg, self.problem.harmonics
        )

    @property
    def blf(self) -> FloatArray:
        """BLF_1..n: posterior mean of the walk's mean load factors over its steps."""
        if self.load_factors is not None:
            return self.load_factors.mean
        return self.piece_blf.mean(axis=0)

    @property
    def blf_sd(self) -> FloatArray:
        """Posterior sd of :attr:`blf`, C and K's uncertainty included.

        A result without :attr:`load_factors` (a method that does not mix them) falls back
        to the step-to-step sd over the square root of the count, given C and K.
        """
        if self.load_factors is not None:
            return self.load_factors.sd
        pb = self.piece_blf
        if pb.shape[0] < 2:
            return np.full(pb.shape[1], np.nan)
        return pb.std(axis=0, ddof=1) / np.sqrt(pb.shape[0])

    @property
    def blf_step_sd(self) -> FloatArray:
        """Step-to-step standard deviation of the BLFs (variability, not uncertainty).

        NaN for a one-piece identification: a single step shows no spread.
        """
        if self.load_factors is not None:
            return self.load_factors.step_sd
        pb = self.piece_blf
        return pb.std(axis=0, ddof=1) if pb.shape[0] > 1 else np.full(pb.shape[1], np.nan)

    def biomechanical_force_n(self) -> FloatArray:
        """Reconstructed biomechanical force at every sample (seed fig. 9) [N]."""
        p = self.problem
        return np.einsum("km,km->k", p.basis, self.piece_coefficients_mean[p.piece_index])

    def fourier_amplitudes_n(self) -> FloatArray:
        """Mean amplitude of each harmonic over the steps (seed fig. 10) [N], shape (n,)."""
        return self.piece_blf.mean(axis=0) * self.mass_kg * G_M_S2

    def fitted_acceleration(self) -> FloatArray:
        """Predict the absolute u'' (the GRF's) from the model and u, u' [m/s^2] (``y``)."""
        p = self.problem
        est = self.estimates
        u, v = p.y[:, 0], p.y[:, 1]
        k, c = est["stiffness_n_per_m"], est["damping_ns_per_m"]
        return (-k * u - c * v + self.biomechanical_force_n()) / p.mass_kg

    @property
    def resid_grf_n(self) -> FloatArray:
        """GRF residual ``M (u''_measured - u''_fitted)`` [N]."""
        return self.mass_kg * (self.problem.absolute_y[:, 2] - self.fitted_acceleration())

    def test_serial_correlation(self, lags: int | list[int] | None = None) -> pd.DataFrame:
        """Ljung-Box test of the GRF residuals (statsmodels ``acorr_ljungbox``).

        Parameters
        ----------
        lags : int or list of int, optional
            Default: one step and two steps worth of samples.

        Returns
        -------
        DataFrame
            ``lb_stat`` and ``lb_pvalue`` per lag.
        """
        from statsmodels.stats.diagnostic import acorr_ljungbox

        if lags is None:
            step = max(1, round(1.0 / (self.problem.pacing_hz * self.problem.dt_s)))
            lags = [step, 2 * step]
        return acorr_ljungbox(self.resid_grf_n, lags=lags)

    @property
    def min_ess_fraction(self) -> float | None:
        """Smallest ESS along the run as a fraction of the particle count (filters only)."""
        f = self.filter_results
        if f is None or not f.n_particles:
            return None
        return float(np.min(f.ess) / f.n_particles)

    @property
    def median_ess_fraction(self) -> float | None:
        """Median ESS along the run as a fraction of the particle count (filters only)."""
        f = self.filter_results
        if f is None or not f.n_particles:
            return None
        return float(np.median(f.ess) / f.n_particles)

    @property
    def static_parameters(self) -> bool:
        """Whether C and K had no artificial random walk in the filter (pf only)."""
        fs = self.filter_results.settings if self.filter_results is not None else {}
        return (
            float(fs.get("damping_rw_sd_ns_per_m", 0.0)) == 0.0
            and float(fs.get("stiffness_rw_sd_n_per_m", 0.0)) == 0.0
        )

    @property
    def frozen_parameters(self) -> list[str]:
        """Parameters whose particles collapsed to a handful of distinct values at the end."""
        if self.filter_results is None:
            return []
        # A random walk makes every value distinct after each move, so look at the fewest
        # distinct values over the last tenth of the run (resampling points show the truth).
        uv = np.asarray(self.filter_results.unique_values)
        tail = uv[-max(1, uv.shape[0] // 10) :]
        fewest = tail.min(axis=0)
        names = ("damping_ns_per_m", "stiffness_n_per_m")
        return [n for n, u in zip(names, fewest, strict=True) if u <= FROZEN_UNIQUE_VALUES]

    @property
    def parameters_at_prior_bound(self) -> list[str]:
        """Parameters whose 95 % interval reaches the edge of the prior box.

        A posterior piled against the box edge is the prior's range speaking, not the data:
        the data pull the value beyond what the prior allows (often a sign that the model
        does not fit the record), so the number is no estimate.
        """
        ci = self.interval()
        prior = self.problem.prior
        out = []
        for key, (lo, hi) in (
            ("damping_ns_per_m", prior.damping_ns_per_m),
            ("stiffness_n_per_m", prior.stiffness_n_per_m),
        ):
            tol = BOUND_TOLERANCE * (hi - lo)
            if ci[key][0] <= lo + tol or ci[key][1] >= hi - tol:
                out.append(key)
        return out

    @property
    def final_ancestors(self) -> int | None:
        """Distinct initial particles with descendants at the end (filters only)."""
        f = self.filter_results
        if f is None or len(f.distinct_ancestors) == 0:
            return None
        return int(np.asarray(f.distinct_ancestors)[-1])

    @property
    def collapsed(self) -> bool:
        """Whether the particle cloud collapsed (a frozen parameter, or few ancestors).

        Few ancestors: all particles descend from at most :data:`FROZEN_ANCESTORS` initial
        ones, for a filter where that means a collapse
        (:attr:`~workbench.inference.core.result_parts.FilterResults.collapse_on_few_ancestors`).
        """
        f, anc = self.filter_results, self.final_ancestors
        few = f is not None and f.collapse_on_few_ancestors and anc is not None
        return bool(self.frozen_parameters) or (few and anc is not None and anc <= FROZEN_ANCESTORS)

    @property
    def degenerate(self) -> bool:
        """Whether the filter's weights stayed collapsed (median ESS below 1 % of P)."""
        frac = self.median_ess_fraction
        return frac is not None and frac < DEGENERATE_ESS_FRACTION

    @property
    def trustworthy(self) -> bool:
        """False when a frozen, degenerate or prior-bound posterior makes the sd meaningless."""
        return not (self.frozen_parameters or self.parameters_at_prior_bound)

    @property
    def warnings(self) -> list[str]:
        """Plain sentences about anything that makes the estimates less trustworthy."""
        out = []
        if self.frozen_parameters:
            out.append(
                f"{parameters_in_words(self.frozen_parameters)} froze: the particles hold at most "
                f"{FROZEN_UNIQUE_VALUES} distinct values at the end, so the reported sd is not "
                "a posterior sd; use more particles, jitter, or method rbpf/exact."
            )
        anc = self.final_ancestors
        # With the seed's random walks of C and K every value is renewed at each sample, so
        # a single surviving lineage over a long record is expected and says nothing about
        # the cloud's spread (the frozen check does); for static C and K it does.
        f = self.filter_results
        if (
            f is not None
            and f.collapse_on_few_ancestors
            and anc is not None
            and anc <= FROZEN_ANCESTORS
            and self.static_parameters
        ):
            out.append(
                f"all particles descend from {count(anc, 'initial particle')}: the filter lost its "
                "diversity, so the reported spread understates the uncertainty."
            )
        if self.degenerate:
            out.append(
                f"the particle weights degenerated (median ESS {self.median_ess_fraction:.2%} of "
                "the particles); the estimates rest on very few particles."
            )
        bound = self.parameters_at_prior_bound
        if bound:
            out.append(
                f"{parameters_in_words(bound)} {verb(len(bound), 'reaches', 'reach')} the edge of "
                "the prior box: the data push the value outside the range the prior allows, so it "
                "is no estimate and its sd no uncertainty (check the model fit and noise setting)."
            )
        sentence = self.identifiability.get("sentence")
        level = self.identifiability.get("level")
        if sentence and level and level != "well identified":
            out.append(sentence)
        return out

    def to_json(self) -> dict[str, Any]:
        """Return the JSON object of ``workbench identify --json`` (docs/contracts.md)."""
        est, sd, ci = self.estimates, self.posterior_sd, self.interval()
        out: dict[str, Any] = {
            "mass_kg": self.mass_kg,
            "pacing_hz": round(self.problem.pacing_hz, 5),
            "method": self.method,
        }
        # What is graded not identified is null where estimates go; its numbers are kept
        # under CONDITIONAL_KEY, named for what they are (the posterior given the prior box).
        hidden = set(self.not_identified)
        force_hidden = not self.force_identified
        conditional: dict[str, Any] = {}
        out.update({k: None if k in hidden else float(est[k]) for k in SCALAR_KEYS})
        blf = [float(x) for x in self.blf]
        # NaN (one piece, no spread to measure) is null: strict JSON lacks NaN.
        blf_sd = [float(x) if np.isfinite(x) else None for x in self.blf_sd]
        out["blf"] = None if force_hidden else blf
        out["posterior_sd"] = {k: None if k in hidden else float(sd[k]) for k in SCALAR_KEYS}
        out["posterior_sd"]["blf"] = None if force_hidden else blf_sd
        # The walk's variability, not an uncertainty (docs/science.md section 4).
        blf_step_sd = [float(x) if np.isfinite(x) else None for x in self.blf_step_sd]
        out["blf_step_sd"] = None if force_hidden else blf_step_sd
        out["interval_95"] = {k: None if k in hidden else list(ci[k]) for k in SCALAR_KEYS}
        for k in SCALAR_KEYS:
            if k in hidden:
                conditional[k] = {
                    "estimate": float(est[k]),
                    "posterior_sd": float(sd[k]),
                    "interval_95": list(ci[k]),
                    "prior_range": list(self.prior_range(k)),
                }
        if force_hidden:
            conditional["blf"] = {
                "estimate": blf,
                "posterior_sd": blf_sd,
                "step_sd": blf_step_sd,
            }
        out["identifiability"] = self.identifiability
        out["steps"] = int(self.problem.n_pieces)
        if self.split is not None:
            out["split"] = self.split
        out["harmonics"] = int(self.problem.harmonics)
        out["time_basis"] = self.problem.time_basis
        out["noise"] = self.noise
        out["loglik"] = float(self.loglik)
        out["diagnostics"] = {
            "n_particles": int(self.filter_results.n_particles if self.filter_results else 0),
            "min_ess_fraction": self.min_ess_fraction,
            "median_ess_fraction": self.median_ess_fraction,
            "frozen_parameters": self.frozen_parameters,
            "degenerate": self.degenerate,
            "final_ancestors": self.final_ancestors,
            "at_prior_bound": self.parameters_at_prior_bound,
            "trustworthy": self.trustworthy,
        }
        out["warnings"] = self.warnings
        out["settings"] = self.settings
        if self.surface is not None:
            out["surface"] = self._surface_json(hidden)
        if self.effects is not None:
            effects = self.effects.to_json()
            out["effects"] = None if force_hidden else effects
            if force_hidden:
                conditional["effects"] = effects
        out[CONDITIONAL_KEY] = conditional
        return out

    def _surface_json(self, hidden: set[str]) -> dict[str, Any]:
        """Return the surface report without its copy of numbers that are not identified.

        When C and K came from the deck's transmissibility, its ``transmissibility`` block
        is that same posterior; graded not identified, its numbers go the way of the
        result's (null, kept under ``conditional_on_prior_box``).
        """
        assert self.surface is not None
        surface = self.surface.to_json()
        frf = surface.get("transmissibility")
        if not hidden or surface.get("c_and_k_from") != "transmissibility" or not frf:
            return surface
        frf = dict(frf)
        for block in ("estimates", "posterior_sd", "interval_95"):
            if isinstance(frf.get(block), dict):
                frf[block] = {k: None if k in hidden else v for k, v in frf[block].items()}
        bound = frf.get("information_bound")
        if isinstance(bound, dict) and isinstance(bound.get("efficiency"), dict):
            # The efficiency carries the posterior sd withheld above.
            efficiency = {k: None if k in hidden else v for k, v in bound["efficiency"].items()}
            frf["information_bound"] = {**bound, "efficiency": efficiency}
        surface["transmissibility"] = frf
        return surface

    def summary(self) -> str:
        """Return a text table of the estimates with posterior sd and 95 % intervals.

        A quantity graded not identified shows no number: the row says so and gives the range
        the prior box allows, named as such. Weakly identified ones keep their numbers with
        the grade after them.
        """
        est, sd, ci = self.estimates, self.posterior_sd, self.interval()
        p = self.problem
        lines = [
            f"SMD identification ({self.method}) of {p.source}",
            f"mass {self.mass_kg:.1f} kg, pacing {p.pacing_hz:.3f} Hz, {count(p.n_pieces, 'piece')}"
            f" ({p.time_basis} basis, n = {p.harmonics}), noise {self.noise.get('label', '')}",
            "",
            f"{'parameter':<24}{'estimate':>12}{'sd':>12}{'95 % interval':>26}",
        ]
        fmt = {
            "stiffness_n_per_m": ("K [N/m]", "{:.0f}"),
            "damping_ns_per_m": ("C [N s/m]", "{:.1f}"),
            "natural_frequency_hz": ("natural frequency [Hz]", "{:.3f}"),
            "damping_ratio": ("damping ratio", "{:.3f}"),
        }
        for key in SCALAR_KEYS:
            label, f = fmt[key]
            grade = self.grade(key)
            if grade == "not identified":
                lo, hi = self.prior_range(key)
                lines.append(
                    f"{label:<24}{'not identified':>24}   prior range {f.format(lo)} to "
                    f"{f.format(hi)}"
                )
                continue
            lo, hi = ci[key]
            lines.append(
                f"{label:<24}{f.format(est[key]):>12}{f.format(sd[key]):>12}"
                f"{'[' + f.format(lo) + ', ' + f.format(hi) + ']':>26}"
                + ("   weakly identified" if grade == "weakly identified" else "")
            )
        if not self.force_identified:
            lines.append(
                f"{'BLFs':<24}{'not identified':>24}   the force given C and K, so conditional "
                "on them"
            )
        else:
            z95 = 1.959963984540054
            rows = zip(self.blf[:5], self.blf_sd[:5], self.blf_step_sd[:5], strict=True)
            for i, (b, s, step) in enumerate(rows, start=1):
                band = f"[{b - z95 * s:.3f}, {b + z95 * s:.3f}]" if np.isfinite(s) else ""
                spread = f"   step-to-step sd {step:.3f}" if np.isfinite(step) else ""
                lines.append(f"{'BLF' + str(i):<24}{b:>12.3f}{s:>12.3f}{band:>26}{spread}")
        lb = self.test_serial_correlation()
        sentence = self.identifiability.get("sentence", "not assessed")  # not again as a warning
        lines += [
            "",
            f"identifiability: {sentence}",
            *([f"surface: {self.surface.sentence}"] if self.surface is not None else []),
            f"log-likelihood {self.loglik:.2f}; Ljung-Box p of GRF residuals "
            f"{p_value(float(lb['lb_pvalue'].iloc[0]))} at lag {int(lb.index[0])}",
        ]
        if self.not_identified:
            lines.append(
                "Quantities not identified show no number: theirs are the posterior given the "
                "prior box, not estimates, and are kept for diagnosis under "
                f"{CONDITIONAL_KEY} (JSON and Python)."
            )
        lines += [f"warning: {w}" for w in self.warnings if w != sentence]
        return "\n".join(lines)

    def to_inference_data(self, n_draws: int | None = None) -> arviz.InferenceData:
        """Return the posterior as arviz InferenceData (one chain of equal-weight draws).

        Weighted draws (particles) are resampled systematically with the run's seed, so the
        draws carry the posterior without weights (the weights' effective sample size is an
        attribute). Observations are the preprocessed (u, u', u'').

        Parameters
        ----------
        n_draws : int, optional
            Draws to keep (default: as many as the result holds).

        Returns
        -------
        arviz.InferenceData
            Groups ``posterior`` (K, C, f_n, zeta), ``observed_data`` and
            ``constant_data`` (mass, pacing).
        """
        import arviz as az

        from workbench.inference.core.resampling import resample

        n = self.draws.shape[0] if n_draws is None else int(n_draws)
        rng = np.random.default_rng(int(self.settings.get("seed", 0)))
        log_w = np.log(np.maximum(self.weights, 1e-300))
        idx = resample(log_w, rng, "systematic", n)
        posterior = {k: v[idx][None, :] for k, v in self._derived_draws().items()}
        p = self.problem
        w = self.weights / self.weights.sum()
        y = p.absolute_y  # what was measured, whatever frame the model used
        return az.from_dict(
            posterior=posterior,
            observed_data={"u_m": y[:, 0], "u_dot_m_s": y[:, 1], "u_ddot_m_s2": y[:, 2]},
            constant_data={"mass_kg": np.array([p.mass_kg]), "pacing_hz": np.array([p.pacing_hz])},
            dims={"u_m": ["time"], "u_dot_m_s": ["time"], "u_ddot_m_s2": ["time"]},
            coords={"time": p.time_s},
            attrs={
                "method": self.method,
                "source": p.source,
                "identifiability": str(self.identifiability.get("level", "")),
                "weights_ess": float(1.0 / np.sum(w**2)),
            },
        )

    def plot_diagnostics(self) -> Figure:
        """Draw the convergence, force and residual diagnostics (one matplotlib figure).

        Plotting lives in :mod:`workbench.reporting`; this calls
        :func:`workbench.reporting.identification.plot_diagnostics`.
        """
        from workbench.reporting.identification import plot_diagnostics

        return plot_diagnostics(self)

    def to_netcdf(self, path: str | Path) -> Path:
        """Save estimates, draws, traces and per-step coefficients to a netCDF file."""
        import xarray as xr

        p = self.problem
        data: dict[str, Any] = {
            "draws": (("draw", "parameter"), self.draws),
            "weights": (("draw",), self.weights),
            "piece_coefficients_mean": (("piece", "coefficient"), self.piece_coefficients_mean),
            "piece_coefficients_sd": (("piece", "coefficient"), self.piece_coefficients_sd),
            "biomechanical_force_n": (("time",), self.biomechanical_force_n()),
            "observations": (("time", "response"), p.absolute_y),
            # Per step, mixed over the (C, K) posterior like the reported BLFs.
            "piece_load_factors": (("piece", "harmonic"), self.piece_blf),
        }
        coords: dict[str, Any] = {
            "parameter": ["damping_ns_per_m", "stiffness_n_per_m"],
            "coefficient": list(p.coefficient_names),
            "piece": np.arange(p.n_pieces),
            "time": p.time_s,
            "response": ["u_m", "u_dot_m_s", "u_ddot_m_s2"],
            "harmonic": np.arange(1, p.harmonics + 1),
        }
        f = self.filter_results
        if f is not None:
            coords["trace_time"] = f.trace_time_s
            data["trace_mean"] = (("trace_time", "parameter"), f.trace_mean)
            data["trace_sd"] = (("trace_time", "parameter"), f.trace_sd)
            data["ess"] = (("trace_time",), f.ess)
        ds = xr.Dataset(data, coords=coords)
        ds.attrs["workbench_result_json"] = json.dumps(self.to_json(), default=float)
        path = Path(path)
        with atomic_path(path) as tmp:
            ds.to_netcdf(tmp, engine="scipy")
        return path

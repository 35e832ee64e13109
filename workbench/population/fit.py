"""Population laws from batch results: OLS mean laws, residual normality, lognormal BLF2/3.

``fit_population(results)`` takes the batch table (``results.csv`` of
:mod:`workbench.population.batch`) and fits, as the seed's section 5.3 does:

- ``y = slope * f_p + intercept`` for the natural frequency, the damping ratio and BLF1 by
  ordinary least squares (statsmodels), with 95 % intervals of slope and intercept and the
  confidence band of the mean law and the prediction band of a new record on a grid of
  pacing frequencies;
- the model errors (residuals): fitted normal (mean, sd), Shapiro-Wilk and Anderson-Darling
  tests (statsmodels' ``normal_ad``, which gives a p-value), and the quantiles for a QQ plot;
- BLF2 and BLF3: lognormal by maximum likelihood (``mu``, ``sigma`` of log BLF, with a t
  interval for ``mu`` and a chi-square interval for ``sigma``), goodness of fit by
  Kolmogorov-Smirnov against the fitted lognormal (its p-value is conservative because the
  parameters come from the same data) and Shapiro-Wilk on the logs, beside the generalised
  extreme value (GEV) distribution Zhang et al. used, compared by AIC.

Records whose identifiability report says C or K is not identified are *excluded* from every
fit (their C and K, hence f_n and zeta, reflect the prior or a misfit, and their force
coefficients are estimated jointly with them); the output says how many and which. Records
with non-finite values in a fitted column, or values no walking record gives
(:data:`PLAUSIBLE_RANGES`, for tables edited by hand), are excluded too, with that reason.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from workbench.errors import UsageError
from workbench.records.validation import PACING_RANGE_HZ

__all__ = ["LAW_COLUMNS", "LOGNORMAL_COLUMNS", "PopulationFit", "fit_population", "identified_mask"]

LAW_COLUMNS = ("natural_frequency_hz", "damping_ratio", "blf1")
LOGNORMAL_COLUMNS = ("blf2", "blf3")
#: Pacing range over which the report quotes the laws' ranges (the seed's text: 1.5-2.5 Hz).
RANGE_PACING_HZ = (1.5, 2.5)
#: Fewest records a fit needs (below this, intervals are meaningless).
MIN_RECORDS = 5
#: Ranges outside which a value cannot come from identifying a walking record (the pacing
#: range of the record checks, generous bounds on the rest); a record outside is excluded.
PLAUSIBLE_RANGES: dict[str, tuple[float, float]] = {
    "pacing_hz": PACING_RANGE_HZ,
    "natural_frequency_hz": (0.0, 50.0),
    "damping_ratio": (0.0, 10.0),
    "blf1": (0.0, 5.0),
    "blf2": (0.0, 5.0),
    "blf3": (0.0, 5.0),
}
#: Smallest spread of the records' pacing [Hz] a law against pacing is fitted over (below
#: it the slope is numerically undetermined; results.csv keeps 10 significant digits).
PACING_SPREAD_HZ = 1e-6


@dataclass(frozen=True, eq=False)
class PopulationFit:
    """The fitted laws, their tests, the bands and the records used.

    Attributes
    ----------
    population_json : dict
        The ``workbench population --json`` object (docs/contracts.md keys and more);
        :meth:`to_json` returns it.
    bands : pandas.DataFrame
        Per law and pacing on a grid: mean, confidence and prediction bands.
    used : pandas.DataFrame
        The records used, with the residual of each law (``<law>_residual``).
    excluded : pandas.DataFrame
        ``path, reason`` of the records left out.
    """

    population_json: dict[str, Any]
    bands: pd.DataFrame
    used: pd.DataFrame
    excluded: pd.DataFrame

    def to_json(self) -> dict[str, Any]:
        """Return the ``workbench population --json`` object."""
        return dict(self.population_json)

    def summary(self) -> str:
        """Return the laws as text: each law with its 95 % intervals, residual sd and tests."""
        s = self.population_json
        lines = [
            f"records used {s['records_used']} ({s.get('records_through_surface', 0)} with C "
            f"and K from a deck's transmissibility), excluded {s['records_excluded']} "
            f"({s['exclusion_rule']})"
        ]
        for key, law in s["laws"].items():
            lo, hi = law["slope_ci"]
            ilo, ihi = law["intercept_ci"]
            r = law["residuals"]
            lines.append(
                f"{key:22s} = {law['slope']:.4f} f_p {'-' if law['intercept'] < 0 else '+'} "
                f"{abs(law['intercept']):.4f}  slope 95 % "
                f"[{lo:.4f}, {hi:.4f}], intercept [{ilo:.4f}, {ihi:.4f}], residual sd "
                f"{law['residual_sd']:.4g} (Shapiro p {r['shapiro_p']:.3g}, AD p "
                f"{r['anderson_darling_p']:.3g})"
            )
        for key, ln in s["lognormal"].items():
            gev = ln["aic_gev"]
            lines.append(
                f"{key:22s} lognormal mu {ln['mu']:.4f} "
                f"[{ln['mu_ci'][0]:.4f}, {ln['mu_ci'][1]:.4f}], "
                f"sigma {ln['sigma']:.4f} [{ln['sigma_ci'][0]:.4f}, {ln['sigma_ci'][1]:.4f}]; "
                f"KS p {ln['ks_p']:.3g}; AIC lognormal {ln['aic_lognormal']:.1f} vs GEV "
                f"{gev if gev is None else round(gev, 1)}"
            )
        return "\n".join(lines)


def _flag(value: Any) -> bool:
    if isinstance(value, str):
        return value.strip().lower() in ("true", "1", "yes")
    return bool(value) if not (isinstance(value, float) and math.isnan(value)) else False


def identified_mask(results: pd.DataFrame) -> pd.Series:
    """Mark the rows of a results table whose C and K are both identified.

    The flags are read as the fit reads them (text such as ``"False"`` is false, a missing
    value is false); a table without the columns (an earlier version's) counts as identified.
    """
    mask = pd.Series(True, index=results.index)
    for column in ("identified_damping", "identified_stiffness"):
        if column in results.columns:
            mask &= results[column].map(_flag).astype(bool)
    return mask


def _through_surface(used: pd.DataFrame) -> int:
    """How many of the records used had C and K from a deck's transmissibility."""
    if "c_and_k_from" not in used.columns:  # results of an earlier version
        return 0
    return int((used["c_and_k_from"].astype(str) == "deck transmissibility").sum())


def _select(results: pd.DataFrame, keep_not_identified: bool) -> tuple[pd.DataFrame, pd.DataFrame]:
    reasons: list[str | None] = []
    identified = identified_mask(results).to_numpy()
    for ok, (_, row) in zip(identified, results.iterrows(), strict=True):
        why = None
        if not keep_not_identified and not ok:
            why = f"C or K not identified ({row.get('identifiability', 'no report')})"
        else:
            bad = [
                c
                for c in ("pacing_hz", *LAW_COLUMNS, *LOGNORMAL_COLUMNS)
                if not np.isfinite(float(row[c])) or (c in LOGNORMAL_COLUMNS and float(row[c]) <= 0)
            ]
            if bad:
                why = f"no finite positive value of {', '.join(bad)}"
            else:
                # An edited or foreign table: one absurd point would swamp the regression.
                absurd = [
                    f"{c} {float(row[c]):g} outside {lo:g}-{hi:g}"
                    for c, (lo, hi) in PLAUSIBLE_RANGES.items()
                    if not lo <= float(row[c]) <= hi
                ]
                if absurd:
                    why = f"not a walking pedestrian's value: {'; '.join(absurd)}"
        reasons.append(why)
    mask = np.array([r is None for r in reasons])
    excluded = pd.DataFrame(
        {
            "path": results.loc[~mask, "path"].astype(str).to_numpy(),
            "reason": [r for r in reasons if r is not None],
        }
    )
    return results.loc[mask].reset_index(drop=True), excluded


def _ols(x: np.ndarray, y: np.ndarray, grid: np.ndarray) -> tuple[dict[str, Any], Any, Any]:
    import statsmodels.api as sm
    from statsmodels.stats.diagnostic import normal_ad

    fit = sm.OLS(y, sm.add_constant(x)).fit()
    ci = fit.conf_int(alpha=0.05)
    resid = np.asarray(fit.resid)
    sd = float(np.sqrt(fit.scale))
    shapiro = stats.shapiro(resid)
    ad_stat, ad_p = normal_ad(resid)
    law = {
        "slope": float(fit.params[1]),
        "intercept": float(fit.params[0]),
        "slope_ci": [float(ci[1, 0]), float(ci[1, 1])],
        "intercept_ci": [float(ci[0, 0]), float(ci[0, 1])],
        "slope_se": float(fit.bse[1]),
        "intercept_se": float(fit.bse[0]),
        "residual_sd": sd,
        "r_squared": float(fit.rsquared),
        "p_value_slope": float(fit.pvalues[1]),
        "n": int(x.size),
        "residuals": {
            "normal_mean": float(resid.mean()),
            "normal_sd": float(resid.std(ddof=1)),
            "shapiro_w": float(shapiro.statistic),
            "shapiro_p": float(shapiro.pvalue),
            "anderson_darling": float(ad_stat),
            "anderson_darling_p": float(ad_p),
            "normal_at_5pct": bool(shapiro.pvalue > 0.05 and ad_p > 0.05),
        },
    }
    frame = fit.get_prediction(sm.add_constant(grid, has_constant="add")).summary_frame(alpha=0.05)
    return law, frame, resid


def _lognormal(x: np.ndarray) -> dict[str, Any]:
    logs = np.log(x)
    n = logs.size
    mu = float(logs.mean())
    s = float(logs.std(ddof=1))
    t = stats.t.ppf(0.975, n - 1)
    chi_lo, chi_hi = stats.chi2.ppf([0.975, 0.025], n - 1)
    sigma_mle = float(logs.std(ddof=0))
    ll_logn = float(np.sum(stats.lognorm.logpdf(x, sigma_mle, scale=math.exp(mu))))
    ks = stats.kstest(x, stats.lognorm(s, scale=math.exp(mu)).cdf)
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        # The GEV optimiser may probe shapes where the density is zero; that is its business.
        warnings.simplefilter("ignore", RuntimeWarning)
        # scipy's default start often stalls far from the optimum; start from a few shapes
        # at moment-based location and scale and keep the best likelihood.
        best: tuple[float, tuple[float, float, float]] = (-math.inf, (0.0, 0.0, 1.0))
        for c0 in (-0.3, 0.0, 0.3):
            par = stats.genextreme.fit(x, c0, loc=float(np.mean(x)), scale=float(np.std(x)))
            ll = float(np.sum(stats.genextreme.logpdf(x, *par)))
            if np.isfinite(ll) and ll > best[0]:
                best = (ll, (float(par[0]), float(par[1]), float(par[2])))
        ll_gev, (c, loc, scale) = best
    aic_logn = 2 * 2 - 2 * ll_logn
    aic_gev = 2 * 3 - 2 * ll_gev if np.isfinite(ll_gev) else math.inf
    return {
        "mu": mu,
        "sigma": s,
        "mu_ci": [float(mu - t * s / math.sqrt(n)), float(mu + t * s / math.sqrt(n))],
        "sigma_ci": [
            float(s * math.sqrt((n - 1) / chi_lo)),
            float(s * math.sqrt((n - 1) / chi_hi)),
        ],
        "median": math.exp(mu),
        "mean": math.exp(mu + s**2 / 2),
        "n": int(n),
        "ks_statistic": float(ks.statistic),
        "ks_p": float(ks.pvalue),
        "shapiro_log_p": float(stats.shapiro(logs).pvalue),
        "aic_lognormal": aic_logn,
        "aic_gev": aic_gev if math.isfinite(aic_gev) else None,
        "gev": {"shape_c": float(c), "loc": float(loc), "scale": float(scale)},
        "preferred_by_aic": "lognormal" if aic_logn <= aic_gev else "gev",
    }


def fit_population(
    results: pd.DataFrame, *, keep_not_identified: bool = False, source: str = "results"
) -> PopulationFit:
    """Fit the population laws to a batch results table.

    Parameters
    ----------
    results : pandas.DataFrame
        Batch results (columns as :data:`workbench.result_rows.RESULT_COLUMNS`).
    keep_not_identified : bool, default False
        Keep records whose C or K is flagged not identified (default: exclude them).
    source : str
        Where the table came from, for the messages.

    Returns
    -------
    PopulationFit
    """
    need = {"path", "pacing_hz", *LAW_COLUMNS, *LOGNORMAL_COLUMNS}
    missing = sorted(need - set(results.columns))
    if missing:
        raise UsageError(
            f"{source}: the results table lacks the column(s) {', '.join(missing)}; give the "
            "results.csv that 'workbench batch' writes"
        )
    used, excluded = _select(results, keep_not_identified)
    if len(used) < MIN_RECORDS:
        not_identified = sum(str(r).startswith("C or K not identified") for r in excluded["reason"])
        if not_identified:
            raise UsageError(
                f"{source}: only {len(used)} of {len(results)} records can be used "
                f"({not_identified} excluded because C or K is not identified, "
                f"{len(excluded) - not_identified} for other reasons), fewer than the "
                f"{MIN_RECORDS} a population fit needs; identify more records, or pass "
                "'keep_not_identified' to fit them too (their C and K may reflect the prior)",
                parameter="keep_not_identified",
            )
        raise UsageError(
            f"{source}: only {len(used)} of {len(results)} records can be used "
            f"({len(excluded)} excluded), fewer than the {MIN_RECORDS} a population fit needs; "
            "identify more records"
        )
    fp = used["pacing_hz"].to_numpy(float)
    # The laws are regressions on pacing: with one pacing there is no slope to fit (and
    # statsmodels would drop the constant column and fail deep inside).
    if float(np.ptp(fp)) < PACING_SPREAD_HZ:
        raise UsageError(
            f"{source}: all {len(used)} usable records share one pacing ({fp[0]:.4g} Hz) in "
            "the column pacing_hz, so no law against pacing can be fitted; add records walked "
            "at other pacings"
        )
    lo_hz = min(float(fp.min()), RANGE_PACING_HZ[0])
    hi_hz = max(float(fp.max()), RANGE_PACING_HZ[1])
    grid = np.linspace(lo_hz, hi_hz, 61)
    laws: dict[str, Any] = {}
    band_frames = []
    used = used.copy()
    for col in LAW_COLUMNS:
        law, frame, resid = _ols(fp, used[col].to_numpy(float), grid)
        laws[col] = law
        used[f"{col}_residual"] = resid
        band_frames.append(
            pd.DataFrame(
                {
                    "law": col,
                    "pacing_hz": grid,
                    "mean": frame["mean"].to_numpy(),
                    "ci_low": frame["mean_ci_lower"].to_numpy(),
                    "ci_high": frame["mean_ci_upper"].to_numpy(),
                    "pi_low": frame["obs_ci_lower"].to_numpy(),
                    "pi_high": frame["obs_ci_upper"].to_numpy(),
                }
            )
        )
    lognormal = {c: _lognormal(used[c].to_numpy(float)) for c in LOGNORMAL_COLUMNS}
    ranges = {
        col: [laws[col]["slope"] * f + laws[col]["intercept"] for f in RANGE_PACING_HZ]
        for col in ("natural_frequency_hz", "damping_ratio")
    }
    summary: dict[str, Any] = {
        "laws": laws,
        "lognormal": lognormal,
        "records_used": len(used),
        "records_excluded": len(excluded),
        "excluded": excluded.to_dict(orient="records"),
        "exclusion_rule": "excluded"
        + (
            " only records without finite values"
            if keep_not_identified
            else " records whose C or K is flagged not identified, and records without finite "
            "values"
        ),
        "records_through_surface": _through_surface(used),
        "pacing_range_hz": [float(fp.min()), float(fp.max())],
        "ranges_at_pacing_hz": {"pacing_hz": list(RANGE_PACING_HZ), **ranges},
    }
    return PopulationFit(summary, pd.concat(band_frames, ignore_index=True), used, excluded)

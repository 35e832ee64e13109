"""Can the population pipeline recover a law at all? Simulation-based calibration of it.

``run_recovery(out_dir, design, settings)`` simulates a population of realistic walks whose
SMD parameters follow a *known* law against pacing, identifies every record with the same
settings a batch would use (:func:`~workbench.population.batch.run_batch`), fits the
population laws as ``workbench population`` does
(:func:`~workbench.population.fit.fit_population`) and compares the recovered laws with the
truth, parameter by parameter.

Truth laws (:data:`TRUTH_LAWS`, or any laws JSON :func:`~workbench.population.laws.read_laws`
reads): ``seed`` (the seed study's laws, f_n = 0.3049 f_p + 1.3670, zeta = -0.2116 f_p +
0.8737), ``constant`` (f_n 2.85 Hz and zeta 0.29 whatever the pacing: the frequency-response
tests of occupied structures) and ``zhang`` (f_n = 1.1043 f_p, zeta 0.30). The residual sds
and the load-factor laws are the documented defaults of
:class:`~workbench.population.laws.PopulationLaws`.

Records (:func:`recovery_plan`): the seed's eight metronome rates in turn, a walker's mass
from the mass distribution, f_n, zeta and BLF1 from the truth's mean laws plus their
residuals, BLF2-3 lognormal, and the step-to-step variability, GRF noise and record length of
a realistic walk (:data:`RECORD_RANGES`), started in steady walking. On a ``deck`` the
surface moves as a sine or a narrow-band deck of 0.3-1 m/s^2 RMS between the pacing
harmonics (:data:`DECK_RATIOS`), and the record measures it (``ground_acc``); on a
``rigid`` floor it does not move.

Verdict of each law parameter, from the 95 % interval of the fit: the slope and intercept
of the linear laws of f_n, zeta and BLF1 (the OLS intervals), and ``mu`` and ``sigma`` of
the lognormal laws of BLF2 and BLF3 (the t interval of the mean of log BLF and the
chi-square interval of its sd, :func:`~workbench.population.fit.fit_population`):

- ``recovered``: the interval holds the true value;
- ``manufactured``: a slope whose truth is zero and whose interval excludes zero -- the
  method makes a dependence on pacing that the walkers do not have;
- ``biased``: any other interval that excludes the truth;
- ``not fitted``: too few records are usable for a fit.

Every law is judged on the records the fit uses, so a load factor's verdict is that of the
walks whose C and K are identified too (the load factors are estimated with them).

Two fits are reported: the pipeline's (records whose C or K is flagged "not identified" are
excluded, as ``workbench population`` does) and, beside it, the fit of every record with the
flags ignored -- what a pipeline without identifiability checks, such as the seed's, would
have printed. The records' own truths give a third line (``sample``): the law a perfect
identification of each record's parameters would fit to these very records, against the
pacing the pipeline identified for each, which separates the error in the parameters from
the population's sampling scatter and from an error in the pacing (a law whose records'
truths come back biased too is biased by the pacing the laws are regressed on).

Beside the two-stage fits, the hierarchical laws
(:func:`~workbench.population.batch_hierarchy.hierarchical_laws`, docs/science.md 8) are
fitted to every usable record's stored posterior in the batch and judged the same way on
their 95 % posterior intervals (:func:`hierarchical_verdicts`), with each linear law's
residual sd judged too: the recovery's records are each a walker of their own, so the
fit's residual sd is the truth's.

Files in ``out_dir``: ``plan.csv`` (the truth of every record), ``records/`` (CSV and JSON
sidecar each) and ``manifest.csv``, ``batch/`` (the batch's files), ``recovery.json`` (with
its ``hierarchical`` part). Every file is written atomically; ``resume`` keeps the records
already simulated and the batch's finished records. The seed fixes every record and every
identification, whatever the number of workers.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from workbench.errors import InputError, UsageError
from workbench.executor import run_tasks
from workbench.fileutil import atomic_path, atomic_write_json, strict_json
from workbench.inference.pipeline import IdentifySettings
from workbench.population.laws import PopulationLaws
from workbench.population.recovery_design import (
    FLOORS,
    RECORD_RANGES,
    TRUTH_LAWS,
    RecoveryDesign,
    _RecordTask,
    _write_record,
    recovery_plan,
    simulate_recovery_record,
    truth_laws,
)
from workbench.population.recovery_text import recovery_text

__all__ = [
    "FLOORS",
    "JUDGED",
    "LINEAR_LAWS",
    "LOGNORMAL_LAWS",
    "RECORD_RANGES",
    "TRUTH_LAWS",
    "RecoveryDesign",
    "RecoveryResult",
    "hierarchical_verdicts",
    "law_verdicts",
    "recovery_plan",
    "run_recovery",
    "simulate_recovery_record",
    "truth_laws",
]

#: The linear laws against pacing a recovery judges (their slope and intercept).
LINEAR_LAWS = ("natural_frequency_hz", "damping_ratio", "blf1")
#: The lognormal laws a recovery judges (``mu`` and ``sigma`` of log BLF).
LOGNORMAL_LAWS = ("blf2", "blf3")
#: The law parameters a recovery judges: (law, parameter).
JUDGED = tuple((law, par) for law in LINEAR_LAWS for par in ("slope", "intercept")) + tuple(
    (law, par) for law in LOGNORMAL_LAWS for par in ("mu", "sigma")
)


def law_verdicts(
    truth: PopulationLaws,
    fitted: dict[str, Any] | None,
    lognormal: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Judge each law parameter of a fit against the truth (module docstring).

    Parameters
    ----------
    truth : PopulationLaws
        The true laws.
    fitted : dict or None
        The ``laws`` object of a population fit (the linear laws, each with ``slope_ci`` and
        ``intercept_ci``); None when no fit was possible.
    lognormal : dict, optional
        The ``lognormal`` object of the same fit (BLF2 and BLF3, each with ``mu_ci`` and
        ``sigma_ci``).

    Returns
    -------
    dict
        ``{law: {parameter: verdict}}`` for every parameter of :data:`JUDGED`; a law the fit
        does not hold is ``not fitted``.
    """
    out: dict[str, dict[str, str]] = {}
    for law, par in JUDGED:
        true = float(getattr(getattr(truth, law), par))
        fit = (fitted if law in LINEAR_LAWS else lognormal) or {}
        if law not in fit:
            verdict = "not fitted"
        else:
            lo, hi = fit[law][f"{par}_ci"]
            if lo <= true <= hi:
                verdict = "recovered"
            elif par == "slope" and true == 0.0:
                verdict = "manufactured"
            else:
                verdict = "biased"
        out.setdefault(law, {})[par] = verdict
    return out


def hierarchical_verdicts(truth: PopulationLaws, recovered: dict[str, Any]) -> dict[str, Any]:
    """Judge the hierarchical fit's law parameters against the truth (module docstring).

    As :func:`law_verdicts`, on the fit's 95 % posterior intervals, and also each linear
    law's residual sd: against the truth's residual sd when the fit has no walker effects (a
    recovery's records are each a walker of their own, so the residual sd is the whole
    spread about the law), ``not judged`` when it has them (the truth has no walker sd).

    Parameters
    ----------
    truth : PopulationLaws
        The true laws.
    recovered : dict
        The ``recovered`` object of the recovery's hierarchical part (``laws`` and
        ``lognormal`` as a two-stage fit's, each linear law also with ``residual_sd_ci``),
        or ``{"error": reason}``.

    Returns
    -------
    dict
        ``{law: {parameter: verdict}}``: :func:`law_verdicts`' parameters, and
        ``residual_sd`` for the linear laws.
    """
    out = law_verdicts(truth, recovered.get("laws"), recovered.get("lognormal"))
    laws = recovered.get("laws") or {}
    for law in LINEAR_LAWS:
        if law not in laws:
            verdict = "not fitted"
        elif recovered.get("walker_effects"):
            verdict = "not judged"
        else:
            lo, hi = laws[law]["residual_sd_ci"]
            verdict = "recovered" if lo <= getattr(truth, law).residual_sd <= hi else "biased"
        out[law]["residual_sd"] = verdict
    return out


def _hierarchical_recovered(fit: Any) -> dict[str, Any]:
    """Return a hierarchical fit's laws shaped as a two-stage fit's (posterior means, 95 %)."""
    s = fit.to_json()["laws"]

    def pair(entry: dict[str, Any]) -> tuple[float, list[float]]:
        return float(entry["mean"]), [float(v) for v in entry["ci95"]]

    laws: dict[str, Any] = {}
    for law in LINEAR_LAWS:
        entry: dict[str, Any] = {"n": int(fit.records_used)}
        for par in ("slope", "intercept", "residual_sd", "walker_sd"):
            if s[law].get(par) is not None:
                entry[par], entry[f"{par}_ci"] = pair(s[law][par])
        laws[law] = entry
    lognormal: dict[str, Any] = {}
    for law in LOGNORMAL_LAWS:
        mu, mu_ci = pair(s[law]["mu"])
        sigma, sigma_ci = pair(s[law]["residual_sd"])
        lognormal[law] = {
            "mu": mu,
            "sigma": sigma,
            "mu_ci": mu_ci,
            "sigma_ci": sigma_ci,
            "n": int(fit.records_used),
        }
        if s[law].get("walker_sd") is not None:
            lognormal[law]["walker_sd"], lognormal[law]["walker_sd_ci"] = pair(s[law]["walker_sd"])
    return {
        "laws": laws,
        "lognormal": lognormal,
        "records_used": int(fit.records_used),
        "walkers": int(fit.walkers),
        "walker_effects": bool(fit.walker_effects),
    }


def _hierarchical_part(batch_dir: Path, truth: PopulationLaws, seed: int) -> dict[str, Any]:
    """Fit the hierarchical laws to the batch's stored posteriors and judge them.

    Returns the ``hierarchical`` part of ``recovery.json``: ``recovered`` (as
    :func:`_hierarchical_recovered`, or ``{"error": reason}``), ``verdict``
    (:func:`hierarchical_verdicts`), ``records_left_out`` with ``left_out_reasons`` (counts)
    and ``left_out`` (path and reason of each), and ``convergence`` (R-hat max, ESS min,
    the parameters flagged).
    """
    from workbench.population.batch_hierarchy import hierarchical_laws

    try:
        laws = hierarchical_laws(batch_dir, seed=seed)
    except InputError as err:
        recovered: dict[str, Any] = {"error": f"no record to fit ({err})"}
        return {
            "recovered": recovered,
            "verdict": hierarchical_verdicts(truth, recovered),
            "records_left_out": 0,
            "left_out_reasons": {},
            "left_out": [],
            "convergence": None,
        }
    fit = laws.fit
    recovered = {"error": laws.no_fit or "no fit"} if fit is None else _hierarchical_recovered(fit)
    convergence = None
    if fit is not None:
        diag = fit.to_json()["diagnostics"]
        convergence = {k: diag[k] for k in ("rhat_max", "ess_bulk_min", "ess_tail_min", "flagged")}
    summary = laws.to_json()
    return {
        "recovered": recovered,
        "verdict": hierarchical_verdicts(truth, recovered),
        "records_left_out": summary["records_left_out"],
        "left_out_reasons": summary["left_out_reasons"],
        "left_out": [
            {"path": str(r["path"]), "reason": str(r["reason"])}
            for r in laws.left_out.to_dict(orient="records")
        ],
        "convergence": convergence,
    }


def _law_json(law: dict[str, Any]) -> dict[str, Any]:
    keep = ("slope", "intercept", "slope_ci", "intercept_ci", "residual_sd", "n")
    return {k: law[k] for k in keep}


def _lognormal_json(law: dict[str, Any]) -> dict[str, Any]:
    return {k: law[k] for k in ("mu", "sigma", "mu_ci", "sigma_ci", "n")}


def _fit(results: pd.DataFrame, keep: bool, source: str) -> tuple[dict[str, Any], str | None]:
    """Fit the laws as ``workbench population`` does; the reason when it cannot."""
    from workbench.population.fit import fit_population

    try:
        fit = fit_population(results, keep_not_identified=keep, source=source)
    except UsageError as err:
        return {}, str(err)
    s = fit.to_json()
    return {
        "laws": {k: _law_json(s["laws"][k]) for k in LINEAR_LAWS},
        "lognormal": {k: _lognormal_json(s["lognormal"][k]) for k in LOGNORMAL_LAWS},
        "records_used": int(s["records_used"]),
        "records_excluded": int(s["records_excluded"]),
    }, None


def _sample_law(plan: pd.DataFrame, results: pd.DataFrame) -> dict[str, Any]:
    """Fit the laws a perfect identification of the parameters would fit.

    The records' true parameters, regressed on the pacing the pipeline identified for each.

    Returns ``{"laws": ..., "lognormal": ...}`` as a pipeline fit has them.
    """
    from workbench.population.fit import _lognormal, _ols

    merged = results[["path", "pacing_hz"]].merge(
        plan.drop(columns="pacing_hz"), on="path", how="inner"
    )
    fp = merged["pacing_hz"].to_numpy(float)
    grid = np.array([1.5, 2.25])
    return {
        "laws": {
            law: _law_json(_ols(fp, merged[law].to_numpy(float), grid)[0]) for law in LINEAR_LAWS
        },
        "lognormal": {
            law: _lognormal_json(_lognormal(merged[law].to_numpy(float))) for law in LOGNORMAL_LAWS
        },
    }


#: Relative error of a record's identified pacing beyond which it is counted as mistaken (the
#: metronome rates are 0.05-0.15 Hz apart, about 3-8 %).
PACING_ERROR_SHARE = 0.05


def _identified(results: pd.DataFrame) -> pd.Series:
    """Mark the records whose C and K are both identified (the fit's reading of the flags)."""
    # Imported here: the fit module's scipy.stats takes most of a second to import.
    from workbench.population.fit import identified_mask

    return identified_mask(results)


def _record_errors(plan: pd.DataFrame, results: pd.DataFrame) -> dict[str, Any]:
    """Per-record errors of the identified records against their truth.

    f_n and zeta: median error and how often the band holds; the load factors: median error;
    the pacing every law is regressed on: how many records have it wrong.
    """
    cols = ["path", "pacing_hz", *LINEAR_LAWS, *LOGNORMAL_LAWS]
    merged = results.merge(plan[cols], on="path", suffixes=("", "_true"))
    out: dict[str, Any] = {}
    ok = _identified(merged).to_numpy()
    for law in (*LINEAR_LAWS, *LOGNORMAL_LAWS):
        est, true = merged[law].to_numpy(float), merged[f"{law}_true"].to_numpy(float)
        out[law] = {
            "median_error": float(np.median(est - true)) if est.size else math.nan,
            "median_error_identified": float(np.median((est - true)[ok])) if ok.any() else None,
        }
        if law in ("natural_frequency_hz", "damping_ratio"):
            # The load factors' truth is the walk's drawn mean, not the force's realised one
            # (steps vary about it), so only f_n and zeta's bands are checked against it.
            held = np.abs(est - true) <= 1.96 * merged[f"{law}_sd"].to_numpy(float)
            out[law]["band_holds_truth_identified"] = f"{int(held[ok].sum())}/{int(ok.sum())}"
    est, true = merged["pacing_hz"].to_numpy(float), merged["pacing_hz_true"].to_numpy(float)
    wrong = np.abs(est - true) > PACING_ERROR_SHARE * true
    out["pacing_hz"] = {
        "median_error": float(np.median(est - true)) if est.size else math.nan,
        "off_by_over_5pct": f"{int(wrong.sum())}/{wrong.size}",
        "off_by_over_5pct_identified": f"{int(wrong[ok].sum())}/{int(ok.sum())}",
    }
    return out


@dataclass(frozen=True, eq=False)
class RecoveryResult:
    """Truth, recovered laws and verdicts of one recovery run.

    Attributes
    ----------
    truth : PopulationLaws
        The simulated truth.
    design : RecoveryDesign
        What was simulated.
    settings : IdentifySettings
        How every record was identified.
    recovered : dict
        ``pipeline`` (the fit ``workbench population`` makes), ``flags_ignored`` (every
        record, as a pipeline without identifiability checks) and ``sample`` (the records'
        true parameters, the best any identification could fit), each ``{"laws": ...,
        "lognormal": ...}`` (the linear laws of f_n, zeta and BLF1; the lognormal BLF2 and
        BLF3) or ``{"error": reason}``.
    verdict : dict
        ``pipeline``, ``flags_ignored`` and ``sample``: :func:`law_verdicts` of each.
    records : dict
        Counts (``simulated``, ``processed`` -- identified without error, flagged or not --,
        ``failed``, ``not_identified``) and per-record errors (``errors``: of every judged
        law's parameter, its median error; of f_n and zeta, how often the band, the estimate
        +- 1.96 posterior sd, holds the truth; of the pacing, how many records are more than
        5 % off).
    out_dir : Path
        Where the files are.
    sensitivity : list of dict
        One entry per sensitivity design point (empty without factors): ``point``,
        ``changed``, ``recovered`` and ``verdict`` of its pipeline fit, and ``slope_change``:
        the change of each law's slope from the baseline, paired over the records both
        identify, with its 95 % interval and whether the setting ``moves`` it.
    hierarchical : dict or None
        The hierarchical laws fitted to every usable record's stored posterior, judged the
        same way (:func:`_hierarchical_part`): ``recovered``, ``verdict``, the records left
        out with their reasons and the convergence diagnostics; None when not run.
    """

    truth: PopulationLaws
    design: RecoveryDesign
    settings: IdentifySettings
    recovered: dict[str, Any]
    verdict: dict[str, Any]
    records: dict[str, Any]
    out_dir: Path
    sensitivity: list[dict[str, Any]] = field(default_factory=list)
    hierarchical: dict[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        """Return the ``workbench recovery --json`` object (docs/contracts.md)."""
        t = self.truth
        return {
            "truth": {
                "source": t.source,
                "floor": self.design.floor,
                "laws": {
                    law: {
                        "slope": getattr(t, law).slope,
                        "intercept": getattr(t, law).intercept,
                        "residual_sd": getattr(t, law).residual_sd,
                    }
                    for law in LINEAR_LAWS
                },
                "lognormal": {
                    law: {"mu": getattr(t, law).mu, "sigma": getattr(t, law).sigma}
                    for law in LOGNORMAL_LAWS
                },
            },
            "recovered": self.recovered,
            "verdict": self.verdict,
            "records": self.records,
            "sensitivity": self.sensitivity,
            **({} if self.hierarchical is None else {"hierarchical": self.hierarchical}),
            "settings": self.settings.to_json(),
            "design": self.design.to_json(),
            "out": str(self.out_dir),
        }

    def summary(self) -> str:
        """Return truth, recovered laws and verdicts as text."""
        return recovery_text(self.to_json())


def run_recovery(
    out_dir: str | os.PathLike[str],
    design: RecoveryDesign,
    settings: IdentifySettings | None = None,
    *,
    seed: int = 0,
    workers: int = 1,
    scheduler: str | None = None,
    resume: bool = False,
    progress: bool = False,
    on_record: Callable[[dict[str, Any]], None] | None = None,
    factors: list[str] | None = None,
    levels: dict[str, Any] | None = None,
) -> RecoveryResult:
    """Simulate the population, identify it in batch, fit the laws and judge them.

    Parameters
    ----------
    out_dir : path-like
        Output folder (module docstring); must be empty unless ``resume``.
    design : RecoveryDesign
        Truth, floor and records.
    settings : IdentifySettings, optional
        Identification settings, exactly as ``workbench batch`` takes them.
    seed : int
        Seed of the population and of the hierarchical fit's sampler (the batch's seed is
        ``settings.seed``).
    workers, scheduler : int, str
        As for :func:`~workbench.population.batch.run_batch`.
    resume : bool
        Continue a recovery in ``out_dir``.
    progress : bool
        Show progress bars on stderr.
    on_record : callable, optional
        Called with each identified record's outcome.
    factors : list of str, optional
        Sensitivity of the recovered laws: settings factors of
        :mod:`workbench.sensitivity.design` varied one at a time around ``settings``; every
        design point identifies the same records again (``OUT/sensitivity/<point>/``).
    levels : dict, optional
        Levels of those factors (:func:`~workbench.sensitivity.design.parse_levels`); the
        factors' default levels otherwise.

    Returns
    -------
    RecoveryResult
    """
    from tqdm import tqdm

    from workbench.population.batch import run_batch
    from workbench.population.files import read_results

    settings = settings or IdentifySettings()
    out = Path(out_dir)
    meta_path = out / "recovery_design.json"
    meta = json.loads(json.dumps({"design": design.to_json(), "seed": int(seed)}))
    if meta_path.exists():
        if not resume:
            raise UsageError(
                f"the output folder {out} already holds a recovery; pass 'resume' to continue "
                "it, or choose an empty folder",
                parameter="resume",
            )
        try:
            old = json.loads(meta_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            old = None
        if old != meta:
            raise UsageError(
                f"'resume': the recovery in {out} was run with another truth, floor, seed or "
                "population; use the same ones, or a new output folder",
                parameter="resume",
            )
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(meta_path, meta)
    plan = recovery_plan(design, seed=seed)
    with atomic_path(out / "plan.csv") as tmp:
        plan.to_csv(tmp, index=False, float_format="%.10g", lineterminator="\n")
    todo = [
        _RecordTask(row, str(out / row["path"]), float(design.sample_rate_hz))
        for row in plan.to_dict(orient="records")
        if not (resume and (out / row["path"]).exists())
    ]
    (out / "records").mkdir(exist_ok=True)
    bar = tqdm(total=len(todo), desc="simulate", unit="record", disable=not progress)
    try:
        for _ in run_tasks(
            _write_record,
            todo,
            workers=min(int(workers), max(len(todo), 1)),
            scheduler=scheduler,
            keys=[f"workbench-recovery-{Path(t.file).stem}" for t in todo],
        ):
            bar.update(1)
    finally:
        bar.close()
    manifest = out / "manifest.csv"
    with atomic_path(manifest) as tmp:
        plan[["path", "mass_kg"]].to_csv(tmp, index=False, float_format="%.10g")
    summary = run_batch(
        manifest,
        out / "batch",
        settings=settings,
        workers=workers,
        scheduler=scheduler,
        resume=resume,
        progress=progress,
        on_record=on_record,
    )
    try:
        results = read_results(out / "batch")
    except InputError:
        results = pd.DataFrame()
    recovered: dict[str, Any] = {}
    verdict: dict[str, Any] = {}
    source = "recovery batch"
    for which, keep in (("pipeline", False), ("flags_ignored", True)):
        fit, error = _fit(results, keep, source) if len(results) else ({}, "no record identified")
        recovered[which] = fit if error is None else {"error": error}
        verdict[which] = law_verdicts(design.truth, fit.get("laws"), fit.get("lognormal"))
    if len(results) >= 3:
        sample = _sample_law(plan, results)
        recovered["sample"] = sample
        verdict["sample"] = law_verdicts(design.truth, sample["laws"], sample["lognormal"])
    else:
        recovered["sample"] = {"error": "fewer than 3 records identified"}
    not_identified = 0
    if len(results):
        not_identified = int((~_identified(results)).sum())
    records = {
        "simulated": len(plan),
        "processed": len(results),
        "failed": int(summary.failed),
        "not_identified": not_identified,
        "errors": _record_errors(plan, results) if len(results) else {},
    }
    sensitivity: list[dict[str, Any]] = []
    if factors:
        run = {"workers": workers, "scheduler": scheduler, "resume": resume, "progress": progress}
        sensitivity = _sensitivity(out, manifest, design, settings, results, factors, levels, run)
    hierarchical = _hierarchical_part(out / "batch", design.truth, int(seed))
    result = RecoveryResult(
        design.truth,
        design,
        settings,
        recovered,
        verdict,
        records,
        out.resolve(),
        sensitivity,
        hierarchical,
    )
    atomic_write_json(out / "recovery.json", strict_json(result.to_json()))
    return result


#: Fewest records a paired slope change is computed over.
MIN_PAIRED = 5


def _paired_slope_change(base: pd.DataFrame, point: pd.DataFrame) -> dict[str, Any]:
    """Change of each law's slope between two identifications of the same records.

    Paired: the per-record differences of the estimate regressed on the baseline's pacing,
    over the records both identify with C and K (the records' own scatter about the law
    cancels, so a setting's effect is measured far more tightly than two separate fits).
    """
    from workbench.population.fit import _ols

    merged = base[_identified(base)].merge(
        point[_identified(point)], on="path", suffixes=("", "_point")
    )
    over = "identified in both"
    if len(merged) < MIN_PAIRED:
        # Nothing to pair among the identified (a rigid floor): the slopes as fitted with the
        # flags ignored, so the study still says which settings move them.
        merged = base.merge(point, on="path", suffixes=("", "_point"))
        over = "all records (too few identified in both)"
    out: dict[str, Any] = {"records": len(merged), "over": over}
    if len(merged) < MIN_PAIRED:
        return out
    fp = merged["pacing_hz"].to_numpy(float)
    for law in ("natural_frequency_hz", "damping_ratio"):
        diff = merged[f"{law}_point"].to_numpy(float) - merged[law].to_numpy(float)
        if np.ptp(diff) == 0.0:
            # Every record moved by the same amount (on a deck, C and K come from the
            # transmissibility and most settings move nothing): no slope change, exactly.
            out[law] = {"change": 0.0, "change_ci": [0.0, 0.0], "moves": False}
            continue
        fit = _ols(fp, diff, np.array([1.5, 2.25]))[0]
        lo, hi = fit["slope_ci"]
        out[law] = {"change": fit["slope"], "change_ci": [lo, hi], "moves": not lo <= 0.0 <= hi}
    return out


def _slug(key: str) -> str:
    return "".join(c if c.isalnum() or c in "-_.=" else "_" for c in key.replace("; ", "+"))


def _sensitivity(
    out: Path,
    manifest: Path,
    design: RecoveryDesign,
    settings: IdentifySettings,
    baseline: pd.DataFrame,
    factors: list[str],
    levels: dict[str, Any] | None,
    run: dict[str, Any],
) -> list[dict[str, Any]]:
    """Identify the records again at every one-at-a-time design point and refit the laws."""
    from workbench.population.batch import run_batch
    from workbench.population.files import read_results
    from workbench.sensitivity.design import build_design, default_levels

    chosen = {name: (levels or {}).get(name) or default_levels(name, settings) for name in factors}
    _, points = build_design("oat", chosen)
    rows = []
    for point in points[1:]:
        point_settings, overrides = point.configure(settings)
        folder = out / "sensitivity" / _slug(point.key)
        run_batch(manifest, folder, settings=point_settings, overrides=overrides, **run)
        try:
            results = read_results(folder)
        except InputError:
            results = pd.DataFrame()
        fit, error = _fit(results, False, str(folder)) if len(results) else ({}, "none identified")
        rows.append(
            {
                "point": point.key,
                "changed": point.changed,
                "recovered": fit if error is None else {"error": error},
                "verdict": law_verdicts(design.truth, fit.get("laws"), fit.get("lognormal")),
                "slope_change": _paired_slope_change(baseline, results)
                if len(results) and len(baseline)
                else {"records": 0},
            }
        )
    return rows

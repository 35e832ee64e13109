"""What a population pipeline recovers: text, report section and conclusions of recovery runs.

A recovery run (:func:`workbench.population.recovery.run_recovery`, ``workbench recovery``)
simulates walkers with a known law and fits the laws back. This module words its results:
:func:`recovery_text` for the terminal (it lives with the result, in
:mod:`workbench.population.recovery_text`, and is re-exported here), :func:`recovery_section`
for a report (the truth, each fit with its 95 % intervals and verdicts, the records used
and not identified, the sensitivity of the slopes to the settings) and
:func:`recovery_conclusions`, the sentences with which the Table-2 report states what its
own laws can and cannot be read as.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from workbench.errors import InputError
from workbench.population.recovery_text import (
    LAW_NAMES,
    LOAD_FACTOR_NAMES,
    LOGNORMAL_NAMES,
    NOT_RUN,
    fit_entries,
    hierarchical_text,
    interval_text,
    recovery_text,
    settings_text,
)
from workbench.reporting.document import Section, Table

__all__ = ["read_recovery", "recovery_conclusions", "recovery_section", "recovery_text"]


def read_recovery(path: str | Path) -> dict[str, Any]:
    """Read ``recovery.json`` from a recovery's output folder (or the file itself).

    Raises
    ------
    InputError
        If there is no such file or it is not a recovery's JSON.
    """
    p = Path(path)
    file = p / "recovery.json" if p.is_dir() else p
    try:
        # A recovery writes null for a number that does not exist; a bare NaN or Infinity
        # (Python's json would read it) comes from an edit and makes every verdict moot.
        obj = json.loads(file.read_text(encoding="utf-8"), parse_constant=_refuse_constant)
    except FileNotFoundError:
        raise InputError(
            file,
            "whole file",
            "there is no recovery result here",
            "give the --out folder of 'workbench recovery' (it holds recovery.json)",
        ) from None
    except (OSError, ValueError) as err:
        raise InputError(
            file, "whole file", f"cannot be read as JSON ({err})", "run the recovery again"
        ) from None
    if not isinstance(obj, dict) or not {"truth", "recovered", "verdict"} <= set(obj):
        raise InputError(
            file,
            "whole file",
            "is not the result of 'workbench recovery' (no truth, recovered and verdict)",
            "give the recovery.json a recovery wrote",
        )
    _check_truth(obj, file)
    return obj


def _refuse_constant(token: str) -> Any:
    raise ValueError(f"{token} is not a number JSON allows")


def _check_truth(obj: dict[str, Any], file: Path) -> None:
    """Refuse a truth law without finite parameters: its verdicts judge nothing.

    The f_n and zeta laws must be there; the load-factor laws are checked when present (a
    recovery written before they were judged has none).
    """
    import math

    truth = obj["truth"] if isinstance(obj["truth"], dict) else {}
    checks = [("laws", law, par, True) for law in LAW_NAMES for par in ("slope", "intercept")]
    checks += [
        ("laws", law, par, False) for law in LOAD_FACTOR_NAMES for par in ("slope", "intercept")
    ]
    checks += [("lognormal", law, par, False) for law in LOGNORMAL_NAMES for par in ("mu", "sigma")]
    for group, law, par, required in checks:
        laws = truth.get(group)
        if not required and not (isinstance(laws, dict) and law in laws):
            continue
        value = laws.get(law, {}).get(par) if isinstance(laws, dict) else None
        number = isinstance(value, int | float) and not isinstance(value, bool)
        if not (number and math.isfinite(float(value or 0))):
            raise InputError(
                file,
                f"key truth.{group}.{law}.{par}",
                f"the true value {value!r} is not a finite number, so no fit can be "
                "judged against it",
                "run the recovery again (it writes the truth it simulated)",
            )


def recovery_section(runs: list[dict[str, Any]]) -> Section:
    """Return the report section "What this pipeline recovers" for one or more runs."""
    sec = Section("What this pipeline recovers")
    sec.paragraph(
        "Each run below simulated a population of realistic walks whose natural frequency, "
        "damping ratio and first load factor follow a known law against pacing (BLF2 and BLF3 "
        "lognormal), identified every record with the settings named, and fitted the laws as "
        "this report does. A law parameter is 'recovered' when its 95 % interval holds the "
        "truth, 'manufactured' when the truth has no slope and the interval excludes zero, "
        "'biased' otherwise. 'flags ignored' is the fit of every record, as a pipeline "
        "without identifiability checks would make it; 'records' truth' is the law a perfect "
        "identification of the parameters would fit to the same records, against the pacing "
        "the pipeline identified for each (biased too when the pacing is). 'hierarchical' is "
        "the fit of every usable record's stored posterior (docs/science.md 8), judged the "
        "same way on its 95 % posterior intervals; a recovery written before it was added "
        "says 'not run'."
    )
    rows = []
    for obj in runs:
        truth, rec = obj["truth"], obj["records"]
        for which, label, fit, verdicts in fit_entries(obj):
            # The records' truth is not a pipeline fit: its law's own count stands for it.
            law_n = fit.get("laws", {}).get("natural_frequency_hz", {}).get("n", 0)
            used_n = fit.get("records_used", law_n)
            if which == "hierarchical":
                left = obj.get("hierarchical", {}).get("records_left_out", 0)
                used = f"{used_n} / {rec['simulated']} ({left} left out)"
            else:
                used = f"{used_n} / {rec['simulated']} ({rec['not_identified']} not identified)"
            cells = [
                f"{truth['source'].split(' (')[0]}, {truth['floor']}",
                settings_text(obj),
                label,
                "not run" if fit.get("error") == NOT_RUN else used,
            ]
            for law in LAW_NAMES:
                tl = truth["laws"][law]
                if "laws" not in fit:
                    state = "not run" if fit.get("error") == NOT_RUN else "not fitted"
                    cells.append(f"truth {tl['slope']:.4g}; {state}")
                    continue
                v = verdicts.get(law, {})
                slope = interval_text(fit, law, "slope")
                cells.append(f"truth {tl['slope']:.4g}; {slope} {v.get('slope', '')}")
            rows.append(cells)
    sec.table(
        Table(
            ["truth, floor", "settings", "fit", "records used", "f_n slope", "zeta slope"],
            rows,
            "Recovered slopes with 95 % intervals and verdicts, the two-stage fits and the "
            "hierarchical one side by side (intercepts in recovery.json).",
        )
    )
    sec.paragraph(
        " ".join(
            f"Run '{obj['truth']['source'].split(' (')[0]}', {obj['truth']['floor']}: "
            f"{hierarchical_text(obj)}."
            for obj in runs
        )
    )
    load_rows = [row for obj in runs for row in _load_factor_rows(obj)]
    if load_rows:
        sec.table(
            Table(
                ["truth, floor", "settings", "fit", "BLF1 slope", "BLF2 mu", "BLF3 mu"],
                load_rows,
                "Recovered load-factor laws with 95 % intervals and verdicts: BLF1's slope "
                "against pacing, the mean of log BLF2 and log BLF3 (intercept and sigma in "
                "recovery.json).",
            )
        )
    sens = [
        [f"{obj['truth']['source'].split(' (')[0]}, {obj['truth']['floor']}", row["point"]]
        + [_change_text(row["slope_change"].get(law)) for law in LAW_NAMES]
        for obj in runs
        for row in obj.get("sensitivity", [])
    ]
    if sens:
        sec.table(
            Table(
                ["truth, floor", "settings changed", "change of f_n slope", "change of zeta slope"],
                sens,
                "Sensitivity: the change of each recovered slope from the run's settings, "
                "paired over the records both identify, with its 95 % interval.",
            )
        )
    return sec


def _load_factor_rows(obj: dict[str, Any]) -> list[list[str]]:
    """Rows of the load-factor table for one run (none for a run that did not judge them)."""
    truth = obj["truth"]
    judged = [("blf1", "slope", truth["laws"].get("blf1", {}).get("slope"))] + [
        (law, "mu", truth.get("lognormal", {}).get(law, {}).get("mu")) for law in LOGNORMAL_NAMES
    ]
    if any(true is None for _, _, true in judged):
        return []
    rows = []
    for _, label, fit, verdicts in fit_entries(obj):
        cells = [f"{truth['source'].split(' (')[0]}, {truth['floor']}", settings_text(obj), label]
        for law, par, true in judged:
            if "laws" not in fit:
                state = "not run" if fit.get("error") == NOT_RUN else "not fitted"
                cells.append(f"truth {true:.4g}; {state}")
                continue
            v = verdicts.get(law, {}).get(par, "")
            cells.append(f"truth {true:.4g}; {interval_text(fit, law, par)} {v}".rstrip())
        rows.append(cells)
    return rows


def _change_text(change: dict[str, Any] | None) -> str:
    if not change:
        return "too few records"
    lo, hi = change["change_ci"]
    return f"{change['change']:+.3g} [{lo:.3g}, {hi:.3g}]" + (" moves" if change["moves"] else "")


#: How a verdict is said of a fit's slope ("the hierarchical fit recovers it").
_VERBS = {
    "recovered": "recovers",
    "manufactured": "manufactures",
    "biased": "biases",
    "not fitted": "could not fit",
}


def _both_fits_sentence(
    obj: dict[str, Any], law: str, short: str, where: str, own: str
) -> str | None:
    """Say which fit's slope of a law can be read as a finding (None without the part)."""
    part = obj.get("hierarchical")
    if part is None:
        return None
    fits = {
        "hierarchical": (part.get("recovered", {}), part.get("verdict", {})),
        "two-stage": (obj["recovered"].get("pipeline", {}), obj["verdict"].get("pipeline", {})),
    }
    clauses, findings = [], []
    for label, (fit, verdicts) in fits.items():
        verdict = verdicts.get(law, {}).get("slope", "not fitted") if "laws" in fit else ""
        verdict = verdict or "not fitted"
        got = f" ({interval_text(fit, law, 'slope')})" if "laws" in fit else ""
        clauses.append(f"the {label} fit {_VERBS.get(verdict, verdict)} it{got}")
        if verdict == "recovered":
            findings.append(label)
    if len(findings) == 2:
        reading = f"either fit's {short} slope can be read as a finding within its interval"
    elif findings:
        other = next(label for label in fits if label != findings[0])
        reading = f"read the {findings[0]} fit's {short} slope as the finding, not the {other} one"
    else:
        # Named by floor: the report's own records may come from another floor (a deck).
        reading = (
            f"neither fit's {short} slope from records {where.split(' with ')[0]} is a finding"
        )
    true_slope = obj["truth"]["laws"][law]["slope"]
    return (
        f"Of the two fits {where}, with a true {short} slope of {true_slope:.4g}: "
        f"{clauses[0]}, {clauses[1]}; {reading}{own}."
    )


def recovery_conclusions(
    runs: list[dict[str, Any]],
    fitted_laws: dict[str, Any],
    hierarchical_laws: dict[str, Any] | None = None,
) -> list[str]:
    """Sentences that say what the report's laws can be read as, given the recovery runs.

    A slope the pipeline manufactures (or biases) on a floor is not presented as a finding:
    the sentence names the run, the truth and what came back.

    Parameters
    ----------
    runs : list of dict
        ``recovery.json`` objects.
    fitted_laws : dict
        The report's own ``laws`` (from the population fit).
    hierarchical_laws : dict, optional
        The report's own hierarchical laws (``HierarchicalFit.to_json()["laws"]``), named
        beside the two-stage slope.

    A run with the hierarchical part (``workbench recovery`` fits both) gets instead, per
    law, one sentence saying what each fit does with the true slope and which fit's slope
    can be read as a finding, from the two verdicts.
    """
    hier = hierarchical_laws or {}
    out = []
    for obj in runs:
        truth = obj["truth"]
        where = f"on {truth['floor']} floors with {settings_text(obj)}"
        name = truth["source"].split(" (")[0]
        fit = obj["recovered"].get("pipeline", {})
        for law, short in {**LAW_NAMES, **LOAD_FACTOR_NAMES}.items():
            if law not in truth["laws"]:  # a recovery written before BLF1 was judged
                continue
            mine = fitted_laws.get(law)
            own = f" (this report: slope {mine['slope']:.4g})" if mine else ""
            slope = (hier.get(law) or {}).get("slope")
            both_own = own
            if slope:
                both_own = f" (this report: hierarchical slope {slope['mean']:.4g}" + (
                    f", two-stage slope {mine['slope']:.4g})" if mine else ")"
                )
            both = _both_fits_sentence(obj, law, short, where, both_own)
            if both is not None:  # a run of both fits: one sentence says which to read
                out.append(both)
                continue
            true_slope = truth["laws"][law]["slope"]
            verdict = obj["verdict"]["pipeline"][law]["slope"] if "laws" in fit else ""
            got = interval_text(fit, law, "slope") if "laws" in fit else ""
            if "laws" not in fit:
                rec = obj["records"]
                out.append(
                    f"{short} law {where}: the pipeline could not fit the '{name}' truth at "
                    f"all ({rec['not_identified']} of {rec['simulated']} records not "
                    f"identified), so a law fitted {where.split(' with ')[0]} rests on the "
                    "records that happened to pass; read it with that in mind" + own + "."
                )
            elif verdict == "manufactured":
                out.append(
                    f"The pacing dependence of {short} is not a finding {where}: walkers whose "
                    f"{short} does not depend on pacing came back with a slope of {got}"
                    f"{own}."
                )
            elif verdict == "biased":
                out.append(
                    f"The {short} slope is biased {where}: the '{name}' truth's slope "
                    f"{true_slope:.4g} came back as {got}{own}."
                )
            else:
                out.append(
                    f"The {short} slope is recovered {where}: the '{name}' truth's slope "
                    f"{true_slope:.4g} came back as {got}, so a slope of this size here is a "
                    f"property of the walkers within its interval{own}."
                )
    return out

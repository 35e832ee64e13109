"""A recovery run as text: what ``RecoveryResult.summary()`` and ``workbench recovery`` print.

The words live with the result (as an identification's ``summary()`` does), below the
reporting layer, which builds its report section (:mod:`workbench.reporting.recovery`) from
the same names and numbers.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "FIT_LABELS",
    "LAW_NAMES",
    "LOAD_FACTOR_NAMES",
    "LOGNORMAL_NAMES",
    "NOT_RUN",
    "fit_entries",
    "hierarchical_text",
    "interval_text",
    "recovery_text",
    "settings_text",
]

#: Short names of the judged laws of the SMD parameters (their slope against pacing is what
#: a report's conclusions turn on).
LAW_NAMES = {"natural_frequency_hz": "f_n", "damping_ratio": "zeta"}
#: Short names of the judged linear load-factor law (slope and intercept against pacing).
LOAD_FACTOR_NAMES = {"blf1": "BLF1"}
#: Short names of the judged lognormal load-factor laws (``mu`` and ``sigma`` of log BLF).
LOGNORMAL_NAMES = {"blf2": "BLF2", "blf3": "BLF3"}
#: Labels of the three fits of a recovery.
FIT_LABELS = {"pipeline": "pipeline", "flags_ignored": "flags ignored", "sample": "records' truth"}


#: Label of the hierarchical fit of a recovery (the ``hierarchical`` part of recovery.json).
HIERARCHICAL_LABEL = "hierarchical"
#: What a recovery written before the hierarchical fit was added says of it.
NOT_RUN = "not run (a recovery written before the hierarchical fit was added)"


def fit_entries(obj: dict[str, Any]) -> list[tuple[str, str, dict[str, Any], dict[str, Any]]]:
    """Every fit of a recovery: ``(key, label, fit, verdicts)``.

    The three two-stage fits of :data:`FIT_LABELS`, then the hierarchical one (its
    ``recovered`` and ``verdict``; ``{"error": NOT_RUN}`` for a recovery without the part).
    """
    out = [
        (which, label, obj["recovered"].get(which, {}), obj["verdict"].get(which, {}))
        for which, label in FIT_LABELS.items()
    ]
    part = obj.get("hierarchical")
    if part is None:
        out.append(("hierarchical", HIERARCHICAL_LABEL, {"error": NOT_RUN}, {}))
    else:
        out.append(
            ("hierarchical", HIERARCHICAL_LABEL, part.get("recovered", {}), part.get("verdict", {}))
        )
    return out


def hierarchical_text(obj: dict[str, Any]) -> str:
    """One sentence on a recovery's hierarchical fit: records used and left out, convergence."""
    part = obj.get("hierarchical")
    if part is None:
        return f"hierarchical fit: {NOT_RUN}"
    fit = part.get("recovered", {})
    reasons = "; ".join(f"{n} {why}" for why, n in part.get("left_out_reasons", {}).items())
    left = f"{part.get('records_left_out', 0)} left out" + (f" ({reasons})" if reasons else "")
    if "laws" not in fit:
        return f"hierarchical fit: not fitted ({fit.get('error', '')}); {left}"
    effects = "with walker effects" if fit.get("walker_effects") else "no walker effects"
    conv = part.get("convergence") or {}
    if conv.get("flagged"):
        mixing = f"convergence: check {', '.join(conv['flagged'])} (R-hat or ESS)"
    elif conv:
        mixing = (
            f"converged (R-hat max {conv['rhat_max']:.3f}, ESS min "
            f"{min(conv['ess_bulk_min'], conv['ess_tail_min']):.0f})"
        )
    else:
        mixing = "convergence not recorded"
    return (
        f"hierarchical fit: {fit['records_used']} records of {fit['walkers']} walkers used "
        f"({effects}), {left}; {mixing}"
    )


def settings_text(obj: dict[str, Any]) -> str:
    """Name a recovery's method and observation noise (from its ``settings``)."""
    s = obj.get("settings", {})
    return f"method {s.get('method', '?')}, observation noise {s.get('obs_noise', '?')}"


def interval_text(fit: dict[str, Any], law: str, par: str) -> str:
    """Write a fitted law parameter with its 95 % interval: ``value [low, high]``.

    ``law`` is a linear law of ``fit["laws"]`` or a lognormal one of ``fit["lognormal"]``.
    """
    fl = fit["laws"][law] if law in fit["laws"] else fit["lognormal"][law]
    lo, hi = fl[f"{par}_ci"]
    return f"{fl[par]:.4g} [{lo:.4g}, {hi:.4g}]"


def _fit_lines(obj: dict[str, Any], law: str, pars: tuple[str, ...], group: str) -> list[str]:
    """One line per fit of a law (two-stage and hierarchical): parameters, intervals, verdicts."""
    lines = []
    for _, label, fit, all_verdicts in fit_entries(obj):
        if fit.get("error") == NOT_RUN:
            lines.append(f"  {label:15s} {NOT_RUN}")
            continue
        if "laws" not in fit:
            lines.append(f"  {label:15s} not fitted: {fit.get('error', '')}")
            continue
        if law not in fit.get(group, {}):  # a recovery written before the law was judged
            lines.append(f"  {label:15s} not judged in this recovery")
            continue
        verdicts = all_verdicts.get(law, {})
        # The hierarchical fit also judges a linear law's residual sd (on its interval).
        shown = (*pars, "residual_sd") if "residual_sd_ci" in fit[group][law] else pars
        parts = [
            f"{par.replace('_', ' ')} {interval_text(fit, law, par)} "
            f"{verdicts.get(par, '')}".rstrip()
            for par in shown
        ]
        lines.append(f"  {label:15s} n={fit[group][law]['n']:<4d} " + "; ".join(parts))
    return lines


def recovery_text(obj: dict[str, Any]) -> str:
    """Format a ``recovery.json`` object as text (truth, each fit, verdicts, sensitivity).

    Each law's lines give the two-stage fits and the hierarchical one (``not run`` for a
    recovery written before it was fitted), each with its 95 % intervals and verdicts.
    """
    truth, rec = obj["truth"], obj["records"]
    lines = [
        f"recovery of {truth['source']} on a {truth['floor']} floor; {settings_text(obj)}",
        f"records: {rec['simulated']} simulated, {rec['processed']} identified without error "
        f"({rec['not_identified']} of them flagged C or K not identified), {rec['failed']} "
        "failed",
    ]
    pacing = rec.get("errors", {}).get("pacing_hz")
    if pacing:  # every law is regressed on it, so a record with the wrong pacing misleads all
        lines.append(
            f"pacing: {pacing['off_by_over_5pct']} records identified more than 5 % off their "
            f"true pacing ({pacing['off_by_over_5pct_identified']} of those with C and K "
            "identified)"
        )
    for law, name in {**LAW_NAMES, **LOAD_FACTOR_NAMES}.items():
        tl = truth["laws"].get(law)
        if tl is None:  # a recovery written before the load factors were judged
            continue
        lines.append(f"{name}: truth slope {tl['slope']:.4g}, intercept {tl['intercept']:.4g}")
        lines += _fit_lines(obj, law, ("slope", "intercept"), "laws")
    for law, name in LOGNORMAL_NAMES.items():
        tl = truth.get("lognormal", {}).get(law)
        if tl is None:
            continue
        lines.append(f"{name} lognormal: truth mu {tl['mu']:.4g}, sigma {tl['sigma']:.4g}")
        lines += _fit_lines(obj, law, ("mu", "sigma"), "lognormal")
    lines.append(hierarchical_text(obj))
    for row in obj.get("sensitivity", []):
        change = row["slope_change"]
        parts = []
        for law, name in LAW_NAMES.items():
            if law in change:
                c = change[law]
                lo, hi = c["change_ci"]
                moves = "moves it" if c["moves"] else "does not move it"
                parts.append(f"{name} slope {c['change']:+.3g} [{lo:.3g}, {hi:.3g}] ({moves})")
        lines.append(
            f"sensitivity {row['point']}: "
            + ("; ".join(parts) or f"{change['records']} records in common, too few")
            + (f", over {change['records']} {change['over']}" if parts else "")
        )
    return "\n".join(lines)

"""The two embedded real records cut into passes of one walker, criticised together.

Usage::

    python analyses/walker_real_passes.py [--pass-steps 25] [--markdown FILE]

Model criticism over a walker's walks (:mod:`workbench.diagnostics.walker`) is meant for
several passes of one person over a track. Neither embedded real record holds passes: both
are continuous walks. This script cuts each into passes of about ``--pass-steps`` whole
steps and asks what the pooled criticism makes of them, against the single-record
criticism of one pass alone and of the whole record (docs/validation/criticism.md, "The
real records"). Deterministic: no random numbers are drawn.

The records
    Loaded as ``python analyses/hidden_effect.py --real`` loads them: the treadmill trial as
    it is, the insole record with its calibration rescaled so that its mean force over whole
    steps is M g (:func:`~workbench.records.steps.rescale_to_mass`, all force channels).

Steps and slow pacing
    The whole record is prepared for criticism (:func:`~workbench.diagnostics.criticism.
    prepare`); its step boundaries (``footfall_times_s``, one per footfall of the split)
    are the steps counted below. A step's *slow pacing* is the mean step rate over the
    :data:`~workbench.diagnostics.criticism_data.SLOW_STEPS` (8) steps centred on it:
    ``8 / (t[j + 4] - t[j - 4])`` for step ``j`` starting at footfall ``t[j]``, the window
    shortened at the record's ends -- the same averaging length as the criticism's slow
    pacing change.

Steady stretches (the treadmill)
    The treadmill's belt speed changes, so only its steady stretches are cut: repeatedly,
    the longest run of consecutive steps not yet taken whose slow pacing stays within 2 %
    of the run's own median (the earliest when runs tie) is taken, until no run of at least
    ``--pass-steps`` + 8 steps is left; each run then loses 4 steps (half the averaging
    window) at either end, so that no kept step's window reaches into a change of pace.

Passes
    A steady stretch of ``M`` steps (for the insole record: the whole walk, all its steps)
    is divided into ``n = max(1, round(M / N))`` consecutive passes of ``M / n`` steps,
    rounded to whole steps (``N = --pass-steps``): passes of about ``N`` steps, every step
    used. Each pass is cut from the record itself (:meth:`Record.slice
    <workbench.records.record.Record.slice>`: the same mass, metadata and foot channels)
    from half a step before its first footfall to half a step after its last, so that
    preparing the pass alone finds the same whole steps (cut at the footfalls themselves,
    the first and last steps are lost to the split's edges). Neighbouring passes share those
    half steps of margin, never a kept step.

Printed per record
    The steady stretches, the passes (number, steps and duration per pass), the pooled
    diagnosis (:func:`~workbench.diagnostics.walker.diagnose_walker`, the default surface:
    the records have no ground motion) with its left/right labelling and each pass's foot
    agreement, every candidate's score +- se, one-sided p and whole-pass-held-out score, the
    scoreboard (:func:`~workbench.diagnostics.walker.compare_walker` with the effects called,
    in the order called: step-held-out and whole-passes-held-out RMSE and their drops) and
    each added effect's force at the walker level; then what the single-record criticism
    calls on the first pass alone, how often it calls each effect on every pass alone, and
    what it calls on the whole record. On the treadmill the passes of each steady stretch
    (one belt speed) are also pooled on their own. ``--markdown FILE`` writes the same with
    the candidates and the scoreboard as Markdown tables.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.datasets import EMBEDDED, load
from workbench.diagnostics.criticism import diagnose, prepare
from workbench.diagnostics.criticism_data import SLOW_STEPS, CriticismData
from workbench.diagnostics.criticism_results import Candidate, Diagnosis
from workbench.diagnostics.walker import compare_walker, diagnose_walker
from workbench.diagnostics.walker_results import WalkerComparison, WalkerDiagnosis
from workbench.records.preprocess import preprocess
from workbench.records.record import Record
from workbench.records.steps import rescale_to_mass, segment_steps
from workbench.wording import p_value

FloatArray = NDArray[np.float64]

#: Largest departure of a step's slow pacing from its stretch's median (treadmill).
STEADY_TOLERANCE = 0.02
#: Steps dropped at either end of a steady stretch: half the slow pacing's window.
STRETCH_TRIM = SLOW_STEPS // 2
#: Margin cut before a pass's first footfall and after its last [steps].
MARGIN_STEPS = 0.5

RECORDS = ("treadmill", "insole")


def load_real(key: str) -> Record:
    """Load an embedded real record as ``analyses/hidden_effect.py --real`` does."""
    rec = load(key, mass_kg=EMBEDDED[key].mass_kg)
    if key == "insole":
        # The insole calibration is 33 % high (docs/science.md 2): rescale to M g first.
        rec = rescale_to_mass(rec, segment_steps(preprocess(rec)))
    return rec


def slow_pacing(footfalls_s: FloatArray) -> FloatArray:
    """Each step's mean step rate over the SLOW_STEPS steps centred on it [Hz]."""
    n = footfalls_s.size - 1
    half = SLOW_STEPS // 2
    out = np.empty(n)
    for j in range(n):
        a, b = max(j - half, 0), min(j + half, n)
        out[j] = (b - a) / (footfalls_s[b] - footfalls_s[a])
    return out


def _steady(values: FloatArray) -> bool:
    med = float(np.median(values))
    return bool(np.all(np.abs(values - med) <= STEADY_TOLERANCE * med))


def steady_stretches(rate_hz: FloatArray, min_steps: int) -> list[tuple[int, int]]:
    """Steady stretches of steps ``[first, stop)`` (module docstring), in time order."""
    free = np.ones(rate_hz.size, dtype=bool)
    runs: list[tuple[int, int]] = []
    while True:
        best: tuple[int, int] | None = None
        for a in range(rate_hz.size):
            if not free[a]:
                continue
            b = a + 1
            longest = a + 1
            while b <= rate_hz.size and free[b - 1]:
                if _steady(rate_hz[a:b]):
                    longest = b
                b += 1
            if best is None or longest - a > best[1] - best[0]:
                best = (a, longest)
        if best is None or best[1] - best[0] < min_steps + 2 * STRETCH_TRIM:
            break  # every run left would be dropped below
        free[best[0] : best[1]] = False
        runs.append(best)
    kept = []
    for a, b in sorted(runs):
        a, b = a + STRETCH_TRIM, b - STRETCH_TRIM
        if b - a >= min_steps:
            kept.append((a, b))
    return kept


def pass_spans(first: int, stop: int, pass_steps: int) -> list[tuple[int, int]]:
    """Divide steps ``[first, stop)`` into consecutive passes of about ``pass_steps``."""
    m = stop - first
    n = max(1, round(m / pass_steps))
    edges = [first + round(i * m / n) for i in range(n + 1)]
    return list(itertools.pairwise(edges))


def cut_pass(record: Record, footfalls_s: FloatArray, first: int, stop: int) -> Record:
    """Cut the record from half a step before footfall ``first`` to half a step after ``stop``."""
    durations = np.diff(footfalls_s)
    t0 = footfalls_s[first] - MARGIN_STEPS * durations[first]
    t1 = footfalls_s[stop] + MARGIN_STEPS * durations[stop - 1]
    part = record.slice(max(t0, float(record.time_s[0])), t1)
    return part.replace(source=f"{record.source} steps {first}-{stop - 1}")


@dataclass
class RecordResult:
    """What the script measured on one record."""

    key: str
    description: str
    whole_steps: int
    pacing_hz: float
    stretches: list[tuple[int, int, float, float, float]]  # first, stop, t0, t1, median Hz
    spans: list[tuple[int, int]]
    walks: WalkerDiagnosis
    called: list[str]
    board: WalkerComparison | None
    per_pass: list[Diagnosis]
    whole: Diagnosis
    per_stretch: list[WalkerDiagnosis]


def _called(candidates: tuple[Candidate, ...]) -> list[str]:
    return [c.effect for c in candidates if c.significant]


def run_record(key: str, pass_steps: int) -> RecordResult:
    """Cut one record into passes and criticise them (module docstring)."""
    rec = load_real(key)
    data: CriticismData = prepare(rec)
    ff = data.footfall_times_s
    rate = slow_pacing(ff)
    if key == "treadmill":
        stretches = steady_stretches(rate, pass_steps)
    else:
        stretches = [(0, data.n_steps)]
    spans = [s for a, b in stretches for s in pass_spans(a, b, pass_steps)]
    if not spans:
        raise SystemExit(
            f"{key}: no steady stretch of {pass_steps} steps or more; give a smaller --pass-steps"
        )
    passes = [cut_pass(rec, ff, a, b) for a, b in spans]
    walks = diagnose_walker(passes)
    called = _called(walks.candidates)
    board = compare_walker(walks.walks, called) if called else None
    per_stretch = []
    if len(stretches) > 1:
        at = 0
        for a, b in stretches:
            k = len(pass_spans(a, b, pass_steps))
            per_stretch.append(diagnose_walker(walks.walks[at : at + k]))
            at += k
    return RecordResult(
        key=key,
        description=EMBEDDED[key].description,
        whole_steps=data.n_steps,
        pacing_hz=data.pacing_hz,
        stretches=[
            (a, b, float(ff[a]), float(ff[b]), float(np.median(rate[a:b]))) for a, b in stretches
        ],
        spans=spans,
        walks=walks,
        called=called,
        board=board,
        # One pass alone is criticised as a single record: all its steps.
        per_pass=[diagnose(prepare(p)) for p in passes],
        whole=diagnose(data),
        per_stretch=per_stretch,
    )


def _pm(value: float, se: float) -> str:
    return f"{100 * value:+.1f} % +- {100 * se:.1f} %"


def _drop(value: float | None, se: float | None) -> str:
    if value is None or se is None:
        return "-"
    return _pm(value, se)


def _candidate_rows(walks: WalkerDiagnosis) -> list[list[str]]:
    rows = []
    for c in walks.candidates:
        if not c.testable:
            rows.append([c.effect, "untestable", "-", "-", "-", ""])
            continue
        ws = walks.walk_scores.get(c.effect)
        twins = f" (indistinguishable from {', '.join(c.indistinguishable_from)})"
        rows.append(
            [
                c.effect,
                _pm(c.score, c.score_se),
                p_value(c.p_value, 2),
                "-" if ws is None else _pm(*ws),
                "called" if c.significant else "",
                twins if c.indistinguishable_from else "",
            ]
        )
    return rows


def _single_lines(label: str, diag: Diagnosis) -> list[str]:
    b = diag.baseline
    called = [c for c in diag.candidates if c.significant]
    head = (
        f"{label}: {b['steps']} steps, baseline held-out RMSE {b['heldout_rmse_n']:.1f} N, "
        f"fit {b['fit_percent']:.1f} %; "
    )
    if not called:
        top = next((c for c in diag.candidates if c.testable), None)
        tail = "nothing called"
        if top is not None:
            tail += (
                f" (largest: {top.effect} {_pm(top.score, top.score_se)}, p "
                f"{p_value(top.p_value, 2)}; callable only from "
                f"{100 * top.detectable_score:.1f} %)"
            )
        return [head + tail]
    return [head + "called:"] + [
        f"    {c.effect} {_pm(c.score, c.score_se)}, p {p_value(c.p_value, 2)}" for c in called
    ]


def text_report(r: RecordResult, pass_steps: int) -> list[str]:
    """Return the plain-text lines printed for one record."""
    w = r.walks
    b = w.baseline
    per = b["per_walk"]
    steps = [p["steps"] for p in per]
    dur = [p["duration_s"] for p in per]
    pac = [p["pacing_hz"] for p in per]
    out = [f"== {r.key}: {r.description}"]
    out.append(
        f"whole record: {r.whole_steps} steps at {r.pacing_hz:.2f} Hz; passes of about "
        f"{pass_steps} steps"
    )
    if r.key == "treadmill":
        out.append(
            f"steady stretches (slow pacing within {100 * STEADY_TOLERANCE:.0f} % of the "
            f"stretch's median, {STRETCH_TRIM} steps trimmed at either end):"
        )
        for a, s, t0, t1, med in r.stretches:
            out.append(
                f"    steps {a}-{s - 1} ({s - a} steps, {t0:.1f}-{t1:.1f} s), slow pacing "
                f"{med:.2f} Hz"
            )
    out.append(
        f"{len(per)} passes: {min(steps)}-{max(steps)} steps each ({sum(steps)} in all), "
        f"{min(dur):.1f}-{max(dur):.1f} s, pacing {min(pac):.2f}-{max(pac):.2f} Hz"
    )
    if any(p["steps"] != s1 - s0 for p, (s0, s1) in zip(per, r.spans, strict=True)):
        out.append(
            "    (steps of each pass criticised when pooled, its first and last three left "
            "out, against the steps cut: "
            + ", ".join(
                f"{s1 - s0}->{p['steps']}" for p, (s0, s1) in zip(per, r.spans, strict=True)
            )
            + ")"
        )
    feet = ", ".join(
        f"{p['first_foot'] or '?'} {100 * p['foot_agreement']:.0f} %"
        if p["foot_agreement"] is not None
        else "no channels"
        for p in per
    )
    out.append(f"left/right labelling: {b['asymmetry_labelling']}")
    out.append(f"    first foot and foot channels' agreement per pass: {feet}")
    walk_rmse = b["walk_heldout_rmse_n"]
    out.append(
        f"pooled baseline: held-out RMSE {b['heldout_rmse_n']:.1f} N"
        + ("" if walk_rmse is None else f" (whole passes held out {walk_rmse:.1f} N)")
        + f", fit {b['fit_percent']:.1f} %, {b['steps']} steps, {b['folds']} folds"
    )
    out.append(
        "candidates (score: share of the baseline's held-out squared error removed, p "
        "one-sided; the calls are made stage by stage):"
    )
    header = ["effect", "score", "p", "whole-pass score", "", ""]
    out += ["    " + line for line in _text_table(header, _candidate_rows(w))]
    out.append(f"verdict: {w.verdict}")
    if r.board is None:
        out.append("scoreboard: nothing called, so no effect to add")
    else:
        out.append("scoreboard (effects in the order called):")
        rows = [
            [
                row.model,
                f"{row.heldout_rmse_n:.1f}",
                "-" if i == 0 else _drop(row.rmse_drop_fraction, row.rmse_drop_se),
                "-" if row.walk_heldout_rmse_n is None else f"{row.walk_heldout_rmse_n:.1f}",
                _drop(row.walk_rmse_drop_fraction, row.walk_rmse_drop_se),
                f"{row.fit_percent:.1f}",
            ]
            for i, row in enumerate(r.board.rows)
        ]
        header = ["model", "RMSE [N]", "drop", "passes held out [N]", "drop", "fit %"]
        out += ["    " + line for line in _text_table(header, rows)]
        for c in r.board.coefficients:
            out.append(
                f"    {c.effect} ({c.sharing}): force {c.force_rms_n:.2f} +- "
                f"{c.force_rms_se_n:.2f} N RMS at the walker level"
            )
    if r.per_stretch:
        out.append("pooled within each steady stretch (the passes at one belt speed):")
        for (a, s, *_), d in zip(r.stretches, r.per_stretch, strict=True):
            called = [c for c in d.candidates if c.significant]
            out.append(
                f"    steps {a}-{s - 1}, {d.baseline['walks']} passes: baseline "
                f"{d.baseline['heldout_rmse_n']:.1f} N; called "
                + (
                    ", ".join(f"{c.effect} {_pm(c.score, c.score_se)}" for c in called)
                    if called
                    else "nothing"
                )
            )
    out += _single_lines("one pass alone (the first)", r.per_pass[0])
    out.append(
        f"each pass alone ({len(r.per_pass)} passes): " + _per_pass_summary(r.per_pass, r.called)
    )
    out += _single_lines("whole record", r.whole)
    return out


def _per_pass_summary(diags: list[Diagnosis], pooled: list[str]) -> str:
    """How often each effect is called on a pass alone, with its scores there.

    Every effect called on some pass or by the pooled diagnosis (``pooled``) is listed.
    """
    parts = []
    names = [c.effect for c in diags[0].candidates]
    for name in names:
        scores = [c.score for d in diags for c in d.candidates if c.effect == name]
        hits = sum(c.significant for d in diags for c in d.candidates if c.effect == name)
        if hits or name in pooled:
            parts.append(
                f"{name} called in {hits}/{len(diags)} (score {100 * min(scores):+.1f} to "
                f"{100 * max(scores):+.1f} % over the passes)"
            )
    silent = sum(not any(c.significant for c in d.candidates) for d in diags)
    if silent:
        parts.append(f"nothing called in {silent}/{len(diags)}")
    return "; ".join(parts) if parts else "nothing called on any pass"


def _text_table(header: list[str], rows: list[list[str]]) -> list[str]:
    widths = [max(len(x[i]) for x in [header, *rows]) for i in range(len(header))]
    return [
        "  ".join(cell.ljust(wd) for cell, wd in zip(row, widths, strict=True)).rstrip()
        for row in [header, *rows]
    ]


def _md_table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell.replace("+-", "±") for cell in row) + " |" for row in rows]
    return lines


def markdown_report(results: list[RecordResult], pass_steps: int) -> str:
    """Return the same measurements with Markdown tables."""
    lines = [
        "# The real records cut into passes",
        "",
        f"`python analyses/walker_real_passes.py --pass-steps {pass_steps}`",
        "",
    ]
    for r in results:
        text = text_report(r, pass_steps)
        lines += [f"## {r.key}", "", "```text", *text, "```", ""]
        lines += ["Candidates over the passes:", ""]
        lines += _md_table(
            ["effect", "score", "p", "whole-pass score", "called", "note"],
            _candidate_rows(r.walks),
        )
        lines.append("")
        if r.board is not None:
            lines += ["Scoreboard:", ""]
            lines += _md_table(
                ["model", "RMSE [N]", "drop", "passes held out [N]", "drop", "fit %"],
                [
                    [
                        row.model,
                        f"{row.heldout_rmse_n:.1f}",
                        "-" if i == 0 else _drop(row.rmse_drop_fraction, row.rmse_drop_se),
                        "-"
                        if row.walk_heldout_rmse_n is None
                        else f"{row.walk_heldout_rmse_n:.1f}",
                        _drop(row.walk_rmse_drop_fraction, row.walk_rmse_drop_se),
                        f"{row.fit_percent:.1f}",
                    ]
                    for i, row in enumerate(r.board.rows)
                ],
            )
            lines.append("")
    return "\n".join(lines) + "\n"


def _finite(results: list[RecordResult]) -> list[str]:
    """Return the non-finite numbers among the results (there should be none)."""
    bad = []
    for r in results:
        numbers: list[tuple[str, Any]] = [
            ("baseline heldout_rmse_n", r.walks.baseline["heldout_rmse_n"]),
            ("baseline walk_heldout_rmse_n", r.walks.baseline["walk_heldout_rmse_n"]),
        ]
        for c in r.walks.candidates:
            numbers += [(f"{c.effect} score", c.score), (f"{c.effect} se", c.score_se)]
        for name, (s, se) in r.walks.walk_scores.items():
            numbers += [(f"{name} walk score", s), (f"{name} walk se", se)]
        if r.board is not None:
            for row in r.board.rows:
                numbers += [
                    (f"{row.model} RMSE", row.heldout_rmse_n),
                    (f"{row.model} walk RMSE", row.walk_heldout_rmse_n),
                ]
            for coef in r.board.coefficients:
                numbers += [
                    (f"{coef.effect} force", coef.force_rms_n),
                    (f"{coef.effect} force se", coef.force_rms_se_n),
                ]
        bad += [
            f"{r.key}: {name} = {v}"
            for name, v in numbers
            if v is not None and not math.isfinite(float(v))
        ]
    return bad


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument(
        "--pass-steps", type=int, default=25, metavar="N", help="steps per pass, about (25)"
    )
    ap.add_argument("--markdown", type=Path, metavar="FILE", help="also write Markdown here")
    args = ap.parse_args(argv)
    if args.pass_steps < 6:
        ap.error("--pass-steps must be at least 6 (the fewest steps a record is criticised on)")
    results = []
    for key in RECORDS:
        r = run_record(key, args.pass_steps)
        results.append(r)
        print("\n".join(text_report(r, args.pass_steps)))
        print()
    for line in _finite(results):
        print("non-finite:", line)
    if args.markdown is not None:
        args.markdown.write_text(markdown_report(results, args.pass_steps), encoding="utf-8")
        print("markdown:", args.markdown)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Model criticism as a story: a record with a hidden effect, found, added, re-scored.

Usage::

    python analyses/hidden_effect.py [--seed 3] [--out DIR]      # the story
    python analyses/hidden_effect.py --sweep 10 [--raw-error]     # what is found, per effect
    python analyses/hidden_effect.py --sweep 10 --no-modulation   # without the nuisance block
    python analyses/hidden_effect.py --real [--out DIR] [--no-pace]  # the embedded records
    python analyses/hidden_effect.py --pairs 10                   # two effects hidden at once
    python analyses/hidden_effect.py --baseline-stiffness 6       # the baseline's own K, C

The story (default)
    A pedestrian is simulated walking on the spot with realistic step-to-step variability
    (durations, amplitudes and phases of the force vary from step to step) and a hidden
    left/right asymmetry. We pretend not to know it and follow the loop of docs/science.md 5:

    1. *Compare*: predict every block of three steps from a model fitted to the other
       steps (a force shape shared by all steps plus ``K u + C u'``, each step allowed its
       own size and timing of that shape) and measure the held-out error.
    2. *Locate*: where does the error live? By gait phase, by step (odd against even), by
       frequency (at multiples of ``f_p`` or at odd multiples of ``f_p / 2``?).
    3. *Explain*: rank the catalogue of effects by the held-out error each removes, with a
       significance decision that respects the autocorrelation of the error.
    4. *Extend*: add the winner to the model (``SMDModel(...) + GaitAsymmetry()``).
    5. *Re-score*: the scoreboard (held-out RMSE, fit %, Ljung-Box p, predictive score),
       with a wrong effect for contrast.

``--sweep N [--raw-error] [--no-modulation]``
    For every catalogued effect and for records without any effect, N seeded records
    (``workbench.synth.hidden_effect_walk``: 20-120 s, 100-1000 Hz, 55-95 kg, pacing
    1.6-2.3 Hz, varied variability and noise; the effect's three sizes of
    ``HIDDEN_EFFECT_LEVELS`` in turn; ``--only NAME,...`` for some rows): how often the
    hidden effect is ranked first and significant (or significant and named
    indistinguishable from the first), how often ``compare`` with it cuts the held-out RMSE
    by more than its uncertainty, how often a wrong effect does, and how often a record
    without an effect raises an alarm. ``--raw-error`` scores the raw error instead of the
    error beyond each step's own size and timing.

``--pairs N``
    Every pair of the force-acting catalogued effects (and stiffness drift) hidden together,
    N seeded records each: how often both are in the top three, and both called.

``--real``
    Diagnose the two embedded real records (the treadmill trial, the insole record).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np
from scipy import signal

from workbench.datasets import EMBEDDED, embedded_path
from workbench.diagnostics.criticism import (
    CATALOGUE,
    baseline_columns,
    compare,
    diagnose,
    error_by_gait_phase,
    error_by_step,
    prepare,
    residual_spectrum,
    slow_pacing_change,
)
from workbench.models import (
    GaitAsymmetry,
    SMDModel,
)
from workbench.records.io import load_record
from workbench.records.preprocess import highpass, preprocess
from workbench.synth import hidden_effect_walk, varied_walk


def _odd_even_contrast(data: Any, residual: np.ndarray, bins: int = 20) -> float:
    b = np.minimum((data.step_fraction * bins).astype(int), bins - 1)
    odd = data.step % 2 == 1
    half = [
        0.5 * (residual[(b == k) & odd].mean() - residual[(b == k) & ~odd].mean())
        for k in range(bins)
    ]
    return float(np.sqrt(np.mean(np.square(half))))


def story(seed: int, out: Path | None, response_modulation: bool = True) -> None:
    """Print the loop on one record with a hidden asymmetry; write a report under ``out``."""
    hidden = GaitAsymmetry(a_half_n=60.0, b_half_n=30.0)
    rec = varied_walk(seed, [hidden], duration_s=(20.0, 40.0)).record
    print(f"A {rec.duration_s:.0f} s record at {rec.sample_rate_hz:.0f} Hz, {rec.mass_kg:.0f} kg.")
    print("(Hidden from the analysis: left and right steps differ.)\n")

    data = prepare(rec)
    diag = diagnose(data, response_modulation=response_modulation)
    base = diag.baseline
    print(
        "1. Compare: each block of 3 steps predicted from the other steps (beyond each step's\n"
        "   own size and timing of the shared force shape)"
    )
    print(
        f"   held-out RMSE {base['heldout_rmse_n']:.1f} N on a GRF of {base['grf_rms_n']:.0f} N "
        f"RMS; fit {base['fit_percent']:.1f} %; Ljung-Box p {base['ljung_box_p']:.2g}"
    )
    print("\n2. Locate: where does the error live?")
    phase = error_by_gait_phase(data, diag.residual_n, 10)
    print("   by gait phase (10 % bins from footfall):", " ".join(f"{x:.0f}" for x in phase), "N")
    per_step = error_by_step(data, diag.residual_n)
    print(
        f"   by step: RMS error per step {per_step.min():.0f}-{per_step.max():.0f} N; mean error "
        "profile of odd steps minus that of even steps, halved: "
        f"{_odd_even_contrast(data, diag.residual_n):.1f} N RMS"
    )
    f, p = residual_spectrum(data, diag.residual_n)

    def power_near(freqs: np.ndarray) -> float:
        return float(sum(p[np.argmin(np.abs(f - x))] for x in freqs))

    fp = data.pacing_hz
    half = power_near(np.array([0.5, 1.5, 2.5]) * fp)
    whole = power_near(np.array([1.0, 2.0, 3.0]) * fp)
    print(
        f"   by frequency: error power at f_p/2, 3f_p/2, 5f_p/2 is {half / whole:.1f} times "
        "that at f_p, 2f_p, 3f_p"
    )
    print("\n3. Explain: candidate effects, best first (* = significant)")
    for c in diag.candidates:
        mark = "*" if c.significant else " "
        print(
            f"   {mark} {c.effect:<18} removes {100 * c.score:5.1f} % +- {100 * c.score_se:.1f} % "
            "of the held-out squared error"
        )
    print(f"   verdict: {diag.verdict}")
    top = diag.candidates[0].effect
    print("\n4. Extend:", SMDModel(mass_kg=float(rec.mass_kg or 70.0)) + GaitAsymmetry())
    print("\n5. Re-score: the scoreboard (and a wrong effect for contrast)")
    rows = compare(data, [top], response_modulation=response_modulation)
    wrong = compare(data, ["cubic_stiffness"], response_modulation=response_modulation)[1]
    for r in [*rows, wrong]:
        drop = (
            ""
            if r.model == "baseline"
            else f"  RMSE drop {100 * r.rmse_drop_fraction:+.1f} % +- {100 * r.rmse_drop_se:.1f} %"
        )
        print(
            f"   {r.model:<30} RMSE {r.heldout_rmse_n:6.1f} N  fit {r.fit_percent:5.1f} %  "
            f"LB p {r.ljung_box_p:.2g}  score {r.score:.3f}{drop}"
        )
    if out is not None:
        from workbench.reporting.criticism import write_criticism_report

        print("\nreport:", write_criticism_report(diag, out))


def sweep(
    n: int,
    step_variation: bool = True,
    only: list[str] | None = None,
    response_modulation: bool = True,
) -> None:
    """Print, per hidden effect, what diagnose and compare make of N varied records."""
    print(
        "N seeded records per row (hidden_effect_walk): 20-120 s, 100-1000 Hz, 55-95 kg, pacing\n"
        "1.6-2.3 Hz, the three sizes of HIDDEN_EFFECT_LEVELS in turn. first+sig: ranked first\n"
        "and significant; found: that, or\n"
        "significant and named indistinguishable from the first; cut: compare with the hidden\n"
        "effect cuts the held-out RMSE by more than its fold-to-fold uncertainty; wrong: pairs\n"
        "(record, other effect not named indistinguishable) where the other effect does that;\n"
        "after: where the other effect does that added after the hidden one.\n"
    )
    # The rigid-floor model: on the base_motion rows the surface is the effect it leaves out.
    opts: dict[str, Any] = {
        "step_variation": step_variation,
        "response_modulation": response_modulation,
        "surface": "rigid",
    }
    head = (
        f"{'hidden effect':<32} {'first+sig':>9} {'found':>6} {'cut':>6} {'wrong':>7} {'after':>7}"
    )
    print(head + "  notes")
    rows: list[tuple[str, str, dict[str, Any]]] = [("none (alarms)", "none", {})]
    rows += [(name, name, {}) for name in CATALOGUE]
    # State-acting effects show only through step-to-step variation, and large variation
    # is where a linear model's misfit of the response raised false alarms: the same with
    # the force amplitudes varying 15 % from step to step instead of 2-6 %, and records
    # without an effect whose step durations or phases vary far more than drawn.
    amplitudes: dict[str, Any] = {"amplitude_sd": 0.15}
    rows += [
        (f"{n} (steps 15 %)", n, amplitudes)
        for n in ("none", "cubic_stiffness", "quadratic_damping")
    ]
    rows += [
        ("none (durations 5 %)", "none", {"step_duration_sd": 0.05}),
        ("none (phases 0.15 rad)", "none", {"phase_sd_rad": 0.15}),
    ]
    if only:
        rows = [r for r in rows if r[1] in only]
    for label, name, variation in rows:
        first = found = cut = wrong = wrong_after = pairs = inseparable = big = big_cut = 0
        max_t = -np.inf
        instead: dict[str, int] = {}
        wrong_names: dict[str, int] = {}
        for seed in range(n):
            rec = hidden_effect_walk(name, seed, **variation).record
            data = prepare(rec)
            diag = diagnose(data, **opts)
            cands = {c.effect: c for c in diag.candidates}
            if name == "none":
                found += any(c.significant for c in diag.candidates)
                max_t = max([max_t, *(c.t_ratio for c in diag.candidates)])
                for c in diag.candidates:
                    if c.significant:
                        instead[c.effect] = instead.get(c.effect, 0) + 1
                continue
            top = diag.candidates[0]
            mine = cands[name]
            first += top.effect == name and top.significant
            found += bool(
                (top.effect == name and top.significant)
                or (mine.significant and top.effect in mine.indistinguishable_from)
            )
            inseparable += "cannot be separated" in mine.evidence
            if top.effect != name and top.significant:
                instead[top.effect] = instead.get(top.effect, 0) + 1
            row = compare(data, [name], **opts)[1]
            cut += row.rmse_drop_fraction > row.rmse_drop_se
            if mine.score >= 0.5:
                big += 1
                big_cut += row.rmse_drop_fraction >= 0.2
            for other, cand in cands.items():
                if other == name or other in mine.indistinguishable_from or not cand.testable:
                    continue
                pairs += 1
                w = compare(data, [other], **opts)[1]
                if w.rmse_drop_fraction > w.rmse_drop_se:
                    wrong += 1
                    wrong_names[other] = wrong_names.get(other, 0) + 1
                after = compare(data, [name, other], **opts)[2]
                wrong_after += after.rmse_drop_fraction > after.rmse_drop_se
        if name == "none":
            print(
                f"{label:<32} {'-':>9} {found:>3}/{n:<2}{'-':>6} {'-':>7} "
                f"{'-':>7}  largest t ratio of any candidate {max_t:.1f} (Holm's test over "
                "the candidates decides)"
                + "".join(f"; {k} significant {v}" for k, v in instead.items())
            )
            continue
        notes = []
        if instead:
            notes.append("first instead: " + ", ".join(f"{k} {v}" for k, v in instead.items()))
        if inseparable:
            notes.append(f"called inseparable {inseparable}/{n}")
        if wrong_names:
            notes.append("wrong: " + ", ".join(f"{k} {v}" for k, v in wrong_names.items()))
        if big:
            notes.append(f"carries >= half the error in {big}: RMSE cut >= 20 % in {big_cut}")
        print(
            f"{label:<32} {first:>5}/{n:<3} {found:>3}/{n:<2} {cut:>3}/{n:<2} {wrong:>3}/{pairs:<3}"
            f" {wrong_after:>3}/{pairs:<3}  {'; '.join(notes)}"
        )


def _called(cands: dict[str, Any], name: str) -> bool:
    """Significant, or named indistinguishable from a significant candidate."""
    c = cands[name]
    return bool(c.significant or any(cands[o].significant for o in c.indistinguishable_from))


def pairs(n: int) -> None:
    """Print, for every pair of catalogued effects hidden together, how often both are found.

    Both are in the top three of the ranking; both are significant (or named
    indistinguishable from a significant one); N seeded records per pair at the sizes of
    ``HIDDEN_EFFECT_LEVELS`` in turn. Cubic stiffness and quadratic damping are left out:
    on steady walking the record cannot separate them (the sweep).
    """
    names = [c for c in CATALOGUE if c not in ("cubic_stiffness", "quadratic_damping")]
    print(f"{'hidden effects':<36} {'both in top 3':>13} {'both significant':>17}")
    total = both_top = both_sig = 0
    for i, first in enumerate(names):
        for second in names[i + 1 :]:
            top3 = sig = 0
            for seed in range(n):
                diag = diagnose(hidden_effect_walk([first, second], seed).record, surface="rigid")
                cands = {c.effect: c for c in diag.candidates}
                top = [c.effect for c in diag.candidates[:3]]
                top3 += first in top and second in top
                sig += _called(cands, first) and _called(cands, second)
            total += n
            both_top += top3
            both_sig += sig
            label = f"{first} + {second}"
            print(f"{label:<36} {top3:>9}/{n:<3} {sig:>13}/{n:<3}")
    print(f"{'all pairs':<36} {both_top:>9}/{total:<3} {both_sig:>13}/{total:<3}")


def baseline_stiffness(n: int) -> None:
    """Print the baseline regression's own K and C against the walker's, on N records.

    The baseline's ``K u + C u'`` lies mostly in the span of the shared force shape, so its
    fitted K and C are not estimates of the walker's; this shows by how much, and measures
    one of the two reasons: the preprocessed ``u`` (double integral of the measured GRF)
    carries the integrated GRF noise, almost all of it below ``f_p / 2`` where the true
    ``u`` has next to nothing (an error in the regressor, which pulls K towards zero). The
    last column refits with ``u`` and ``u'`` high-passed again at 0.3 ``f_p``. The other
    reason is that ``u`` responds to the step-to-step variation of the force, which stays
    in the error.
    """
    print(
        f"{'seed':>4} {'K true':>8} {'K fit':>8} {'ratio':>6} {'C true':>7} {'C fit':>7} "
        f"{'u err %':>8} {'< fp/2':>7} {'ratio, u hp 0.3 fp':>19}"
    )
    for seed in range(n):
        sim = hidden_effect_walk("none", seed)
        truth = sim.record.metadata["truth"]
        data = prepare(sim.record)
        x = baseline_columns(data)
        coef, *_ = np.linalg.lstsq(x, data.target_n, rcond=None)
        k_fit, c_fit = -coef[-2], -coef[-1]
        k, c = truth["stiffness_n_per_m"], truth["damping_ns_per_m"]
        # The preprocessed u against the simulator's, over the middle 80 % of the record.
        com = preprocess(sim.record)
        fs = sim.record.sample_rate_hz
        mid = slice(sim.time_s.size // 10, -(sim.time_s.size // 10))
        err = (com.disp_m - sim.disp_m)[mid]
        freq, power = signal.welch(err, fs, nperseg=min(err.size, int(16 * fs)))
        below = float(power[freq < 0.5 * data.pacing_hz].sum() / power.sum())
        u_err = float(np.std(err) / np.std(sim.disp_m[mid]))
        cut = 0.3 * data.pacing_hz
        clean = dataclasses.replace(
            data,
            disp_m=highpass(data.disp_m, fs, cut),
            vel_m_s=highpass(data.vel_m_s, fs, cut),
        )
        coef_hp, *_ = np.linalg.lstsq(baseline_columns(clean), data.target_n, rcond=None)
        print(
            f"{seed:>4} {k:>8.0f} {k_fit:>8.0f} {k_fit / k:>6.2f} {c:>7.0f} {c_fit:>7.0f} "
            f"{100 * u_err:>8.1f} {100 * below:>6.0f}% {-coef_hp[-2] / k:>19.2f}"
        )


def real(
    out: Path | None,
    step_variation: bool = True,
    response_modulation: bool = True,
    follow_pace: bool = True,
) -> None:
    """Diagnose the embedded real records and print the ranking and scoreboard."""
    opts: dict[str, Any] = {
        "step_variation": step_variation,
        "response_modulation": response_modulation,
        "follow_pace": follow_pace,
    }
    for key in ("treadmill", "insole"):
        meta = EMBEDDED[key]
        rec = load_record(embedded_path(key), mass_kg=meta.mass_kg)
        if key == "insole":
            from workbench.records.preprocess import preprocess
            from workbench.records.steps import rescale_to_mass, segment_steps

            # The insole calibration is 33 % high (docs/science.md 2): rescale to M g first.
            rec = rescale_to_mass(rec, segment_steps(preprocess(rec)))
        data = prepare(rec)
        diag = diagnose(data, **opts)
        print(f"== {key}: {meta.description}")
        b = diag.baseline
        rate = slow_pacing_change(data)
        slow = 0.0 if rate is None else float(np.std(rate)) / data.pacing_hz
        print(
            f"   {b['steps']} steps at {b['pacing_hz']:.2f} Hz (slow pacing varies by "
            f"{100 * slow:.1f} % sd); baseline held-out RMSE {b['heldout_rmse_n']:.1f} N, "
            f"fit {b['fit_percent']:.1f} %"
        )
        if rec.grf_left_n is not None and rec.grf_right_n is not None:
            # An independent look at a left/right difference: the feet's own channels.
            left, right = float(np.mean(rec.grf_left_n)), float(np.mean(rec.grf_right_n))
            print(
                f"   feet's channels: mean force left {left:.0f} N, right {right:.0f} N "
                f"(left {100 * (left / right - 1):+.1f} % against right)"
            )
        for c in diag.candidates:
            mark = "*" if c.significant else " "
            print(f"   {mark} {c.effect:<18} {100 * c.score:+5.1f} % +- {100 * c.score_se:.1f} %")
        print(f"   verdict: {diag.verdict}")
        sig = [c.effect for c in diag.candidates if c.significant]
        if sig:
            for r in compare(data, sig, **opts):
                print(f"   {r.model:<55} RMSE {r.heldout_rmse_n:6.1f} N fit {r.fit_percent:5.1f} %")
        if out is not None:
            from workbench.reporting.criticism import write_criticism_report

            print("   report:", write_criticism_report(diag, out / key))


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--seed", type=int, default=3, help="seed of the story's record (3)")
    ap.add_argument("--sweep", type=int, metavar="N", help="N records per effect instead")
    ap.add_argument("--real", action="store_true", help="diagnose the embedded real records")
    ap.add_argument(
        "--pairs", type=int, metavar="N", help="N records per pair of effects hidden together"
    )
    ap.add_argument("--only", help="sweep: only these rows (comma-separated effect names, or none)")
    ap.add_argument(
        "--raw-error",
        action="store_true",
        help="sweep and --real: score the raw error (step_variation=False) instead",
    )
    ap.add_argument(
        "--no-modulation",
        action="store_true",
        help="story, sweep and --real: leave out the response-modulation block "
        "(response_modulation=False)",
    )
    ap.add_argument(
        "--no-pace",
        action="store_true",
        help="--real: leave out the baseline's force following the pace (follow_pace=False)",
    )
    ap.add_argument(
        "--baseline-stiffness",
        type=int,
        metavar="N",
        help="print the baseline's fitted K, C against the truth on N records without effects",
    )
    ap.add_argument("--out", type=Path, help="write an HTML/Markdown report here")
    args = ap.parse_args(argv)
    if args.baseline_stiffness:
        baseline_stiffness(args.baseline_stiffness)
        return 0
    if args.pairs:
        pairs(args.pairs)
        return 0
    if args.sweep:
        only = args.only.split(",") if args.only else None
        sweep(
            args.sweep,
            step_variation=not args.raw_error,
            only=only,
            response_modulation=not args.no_modulation,
        )
    elif args.real:
        real(
            args.out,
            step_variation=not args.raw_error,
            response_modulation=not args.no_modulation,
            follow_pace=not args.no_pace,
        )
    else:
        story(args.seed, args.out, response_modulation=not args.no_modulation)
    return 0


if __name__ == "__main__":
    sys.exit(main())

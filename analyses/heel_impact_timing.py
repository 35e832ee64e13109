"""Where the criticism's step phase puts the heel strikes, and what it does to heel impact.

Usage::

    python analyses/heel_impact_timing.py [--kind overground] [--size-factor 2]
                                          [--seeds 100-109] [--markdown FILE]

Every record is ``hidden_effect_walk("heel_impact", seed, kind=KIND,
size_factor=SIZE_FACTOR)``; the simulator knows each step's true start
(``Simulation.step_start_s``), where the heel-impact pulse begins. For each record, with
``diagnose``'s preparation (``prepare``):

- ``lag``: the mean step phase at the true starts, in steps (its circular mean; positive
  when the boundaries come before the true starts);
- ``jitter``: the sd of the phase at the true starts about that mean [ms], of the smooth
  step phase (``phase_rad``) and of the phase re-timed to each step's force
  (``force_timed_phase``), with the largest error at the first and last two steps;
- ``p`` and ``found``: the heel-impact candidate's p-value, and whether ``diagnose`` finds
  it (ranked first and significant, or significant and indistinguishable from the first,
  as the detection table counts), with its columns on either phase.

The smooth phase's columns are what the criticism used before ``force_timed_phase``; they
are built here by a ``CriticismData`` whose re-timed phase is the smooth one.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from workbench.diagnostics.criticism import diagnose, prepare
from workbench.diagnostics.criticism_data import CriticismData
from workbench.synth import hidden_effect_walk


class _SmoothPhase(CriticismData):
    """The record with the heel-impact columns on the smooth step phase."""

    def force_timed_phase(self) -> np.ndarray:
        return self.phase_rad


def _errors_ms(
    data: CriticismData, phase: np.ndarray, starts: np.ndarray
) -> tuple[np.ndarray, float]:
    """Phase at the true starts inside the kept steps, about its circular mean [ms]."""
    inside = starts[(starts >= data.time_s[0]) & (starts <= data.time_s[-1])]
    at = np.interp(inside, data.time_s, phase)
    mean = float(np.angle(np.mean(np.exp(1j * at))))
    err = np.angle(np.exp(1j * (at - mean))) / (2.0 * np.pi)
    return np.asarray(1000.0 * err / data.pacing_hz, dtype=np.float64), mean / (2.0 * np.pi)


def _found(data: CriticismData) -> tuple[float, bool]:
    diag = diagnose(data, surface="rigid")
    top = diag.candidates[0]
    mine = next(c for c in diag.candidates if c.effect == "heel_impact")
    found = (top.effect == "heel_impact" and top.significant) or (
        mine.significant and top.effect in mine.indistinguishable_from
    )
    return float(mine.p_value), bool(found)


def measure(kind: str, size_factor: float, seed: int) -> dict[str, Any]:
    """Return one record's row (module docstring)."""
    sim = hidden_effect_walk("heel_impact", seed, kind=kind, size_factor=size_factor)
    data = prepare(sim.record)
    starts = np.asarray(sim.step_start_s, dtype=np.float64)
    smooth, lag = _errors_ms(data, data.phase_rad, starts)
    timed, _ = _errors_ms(data, data.force_timed_phase(), starts)
    old = _SmoothPhase(**{f.name: getattr(data, f.name) for f in dataclasses.fields(data)})
    p_old, found_old = _found(old)
    p_new, found_new = _found(data)
    ends = np.concatenate([smooth[:2], smooth[-2:]])
    ends_timed = np.concatenate([timed[:2], timed[-2:]])
    return {
        "seed": seed,
        "lag": lag,
        "jitter_smooth": float(np.std(smooth)),
        "ends_smooth": float(np.max(np.abs(ends))),
        "jitter_timed": float(np.std(timed)),
        "ends_timed": float(np.max(np.abs(ends_timed))),
        "p_smooth": p_old,
        "found_smooth": found_old,
        "p_timed": p_new,
        "found_timed": found_new,
    }


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--kind", default="overground")
    ap.add_argument("--size-factor", type=float, default=2.0)
    ap.add_argument("--seeds", default="100-109")
    ap.add_argument("--markdown", type=Path, help="also write the table to this file")
    args = ap.parse_args(argv)
    rows = [measure(args.kind, args.size_factor, s) for s in _seeds(args.seeds)]
    lines = [
        f"heel_impact, {args.kind} walks, size factor {args.size_factor:g}, seeds {args.seeds}.",
        "",
        "| seed | lag [step] | jitter smooth [ms] | first/last 2 smooth [ms] | jitter re-timed "
        "[ms] | first/last 2 re-timed [ms] | p smooth | p re-timed |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['seed']} | {r['lag']:+.3f} | {r['jitter_smooth']:.1f} | "
            f"{r['ends_smooth']:.0f} | {r['jitter_timed']:.1f} | {r['ends_timed']:.0f} | "
            f"{r['p_smooth']:.2g}{' (found)' if r['found_smooth'] else ''} | "
            f"{r['p_timed']:.2g}{' (found)' if r['found_timed'] else ''} |"
        )
    n = len(rows)
    lines += [
        "",
        f"Found on the smooth phase: {sum(r['found_smooth'] for r in rows)}/{n}; on the "
        f"re-timed phase: {sum(r['found_timed'] for r in rows)}/{n}. Median jitter "
        f"{np.median([r['jitter_smooth'] for r in rows]):.1f} ms smooth, "
        f"{np.median([r['jitter_timed'] for r in rows]):.1f} ms re-timed.",
    ]
    print("\n".join(lines))
    if args.markdown:
        args.markdown.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

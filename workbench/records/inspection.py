"""Inspect a record: validate, preprocess, segment steps, estimate pacing, check static balance.

This is the first thing a user runs on a new record (``workbench inspect``) and the front half
of every later job. It collects the derived objects in one :class:`Inspection` so that
reports and identification reuse them instead of recomputing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from workbench.errors import InputError
from workbench.records.pacing import FAST_WALKING_HZ
from workbench.records.preprocess import DEFAULT_HIGHPASS_HZ, COMResponse, preprocess
from workbench.records.record import G_M_S2, Record
from workbench.records.steps import (
    PacingEstimate,
    SplitCheck,
    Steps,
    check_split,
    estimate_pacing,
    rescale_to_mass,
    segment_steps,
    static_balance,
    static_balance_warning,
)

__all__ = ["Inspection", "check_walking", "inspect_record"]

#: Relative disagreement between a stated and an estimated pacing frequency that earns a warning.
PACING_MISMATCH_TOLERANCE = 0.05
#: Standard deviation of the GRF over whole steps, as a fraction of body weight, below which a
#: record holds no walking (walking varies by about 10-40 %; a standing person by 1 %).
MIN_WALKING_VARIATION = 0.04
#: Pacing frequencies that can be walking [Hz] (docs/science.md 7: 1.5-2.25 Hz in the seed study;
#: slow shuffling and fast walking widen it).
WALKING_PACING_HZ = (0.8, 3.5)
#: Without the high-pass, a static balance further than this from 1 makes the integrals drift.
DRIFT_BALANCE_TOLERANCE = 0.002


@dataclass(frozen=True)
class Inspection:
    """Everything ``workbench inspect`` derives from one record.

    Attributes
    ----------
    record : Record
        The record as analysed (after ``--rescale-to-mass`` when that was asked for).
    com : COMResponse
        COM acceleration, velocity and displacement after preprocessing.
    steps : Steps
        Footfall steps, each from one peak of the walker's pacing component to the next
        (docs/science.md 2).
    pacing : PacingEstimate
        Global and instantaneous pacing frequency.
    static_balance : float
        Mean GRF over whole steps divided by M g, of the record as analysed.
    static_balance_raw : float
        The same ratio before any rescaling (equal to ``static_balance`` without rescaling).
    warnings : list of str
        Plain sentences about anything suspicious.
    split : SplitCheck or None
        Whether the steps keep the walker's rhythm (:func:`~workbench.records.steps.check_split`).
    """

    record: Record
    com: COMResponse
    steps: Steps
    pacing: PacingEstimate
    static_balance: float
    static_balance_raw: float
    warnings: list[str] = field(default_factory=list)
    split: SplitCheck | None = None

    @property
    def mean_grf_n(self) -> float:
        """Mean GRF over whole steps [N]."""
        return self.static_balance * self.record.require_mass() * G_M_S2

    def to_json(self) -> dict[str, Any]:
        """Return the ``workbench inspect --json`` object (docs/contracts.md) and details."""
        rec = self.record
        inst = np.asarray(self.pacing.instantaneous_hz, dtype=float)
        return {
            "source": rec.source,
            "format": rec.metadata.get("format"),
            "duration_s": round(rec.duration_s, 4),
            "sample_rate_hz": round(rec.sample_rate_hz, 4),
            "mass_kg": rec.mass_kg,
            "pacing_hz": round(float(self.pacing.pacing_hz), 4),
            "steps": int(self.steps.n_steps),
            "mean_grf_n": round(self.mean_grf_n, 2),
            "static_balance": round(float(self.static_balance), 4),
            "warnings": list(self.warnings),
            "pacing": {
                "method": self.pacing.method,
                "spectral_hz": _round_or_none(self.pacing.spectral_pacing_hz),
                "footfall_hz": _round_or_none(self.pacing.footfall_pacing_hz),
                "varies": bool(self.pacing.varies),
                "instantaneous_p10_hz": _round_or_none(np.percentile(inst, 10)),
                "instantaneous_p90_hz": _round_or_none(np.percentile(inst, 90)),
                "times_s": [round(float(x), 4) for x in self.pacing.times_s],
                "instantaneous_hz": [round(float(x), 4) for x in inst],
            },
            "split": None if self.split is None else self.split.to_json(self.steps),
            "static_balance_raw": round(float(self.static_balance_raw), 4),
            "grf_scale_factor": rec.metadata.get("grf_scale_factor"),
            "highpass_hz": self.com.highpass_hz,
        }


def _round_or_none(value: float | None, digits: int = 4) -> float | None:
    if value is None or not np.isfinite(value):
        return None
    return round(float(value), digits)


def check_walking(record: Record, steps: Steps, pacing: PacingEstimate) -> None:
    """Refuse a record in which the step detector found periodicity but nobody walks.

    The one check of every command that identifies or compares: a person standing still or
    a machine's sine has "steps" to the detector, and a model fitted to them is a number
    about nothing.

    Parameters
    ----------
    record : Record
        The record, with its body mass.
    steps : Steps
        Its steps as found by :func:`~workbench.records.steps.segment_steps`.
    pacing : PacingEstimate
        Their pacing (:func:`~workbench.records.steps.estimate_pacing`).

    Raises
    ------
    InputError
        Naming the record: the force varies too little, or repeats outside walking's pacing.
    """
    lo, hi = int(steps.boundaries[0]), int(steps.boundaries[-1])
    variation = float(np.std(record.grf_n[lo:hi]) / record.weight_n)
    if variation < MIN_WALKING_VARIATION:
        raise InputError(
            record.source,
            "whole record",
            f"the force varies by only {100 * variation:.2g} % of body weight (standard "
            f"deviation), far less than walking does (about 10-40 %), so there are no steps "
            "to analyse",
            "check that the file holds a walking trial and that the force column is the "
            "total vertical force",
        )
    lo_hz, hi_hz = WALKING_PACING_HZ
    if not (lo_hz <= pacing.pacing_hz <= hi_hz):
        raise InputError(
            record.source,
            "whole record",
            f"the force repeats at {pacing.pacing_hz:.3g} Hz, outside the {lo_hz:g}-{hi_hz:g} "
            "Hz of walking, so these are not footfalls",
            "check that the record is walking; if the pacing is known, pass pacing_hz=... "
            "(--pacing HZ on the command line)",
        )


def inspect_record(
    record: Record,
    *,
    highpass_hz: float = DEFAULT_HIGHPASS_HZ,
    rescale: bool = False,
    balance_tolerance: float = 0.05,
) -> Inspection:
    """Preprocess and segment a record and collect warnings about it.

    Parameters
    ----------
    record : Record
        A validated record with its body mass.
    highpass_hz : float, default 0.15
        Cut-off of the zero-phase high-pass filter (0 switches it off).
    rescale : bool, default False
        Apply :func:`~workbench.records.steps.rescale_to_mass` when the static balance is off
        (the ``--rescale-to-mass`` flag); the returned record carries the scale factor.
    balance_tolerance : float, default 0.05
        Relative deviation of the static balance from 1 that earns a warning.

    Returns
    -------
    Inspection

    Raises
    ------
    InputError
        If the record has no mass or holds fewer than three whole steps.
    """
    record.require_mass()
    warnings = [str(w) for w in record.metadata.get("warnings", [])]
    com = preprocess(record, highpass_hz=highpass_hz)
    steps = segment_steps(com, pacing_hz=record.pacing_hz, surface_acc_m_s2=record.ground_acc_m_s2)
    balance_raw = static_balance(record, steps)
    balance = balance_raw
    message = static_balance_warning(balance_raw, record.name, tolerance=balance_tolerance)
    if rescale and message is not None:
        record = rescale_to_mass(record, steps)
        com = preprocess(record, highpass_hz=highpass_hz)
        steps = segment_steps(
            com, pacing_hz=record.pacing_hz, surface_acc_m_s2=record.ground_acc_m_s2
        )
        balance = static_balance(record, steps)
        warnings.append(
            f"{record.name}: GRF was rescaled by {1.0 / balance_raw:.4f} so that its mean over "
            f"whole steps equals M g (static balance was {balance_raw:.3f}); this assumes a pure "
            "gain error of the sensor and a correct body mass."
        )
    elif message is not None:
        warnings.append(message)
    pacing = estimate_pacing(com, steps, surface_acc_m_s2=record.ground_acc_m_s2)
    check_walking(record, steps, pacing)
    if steps.lone_line_hz is not None:
        warnings.append(
            f"{record.name}: a strong line at {steps.lone_line_hz:.3f} Hz has no step shape "
            "behind it (the steps cut at its period average to a pure sinusoid), so it was "
            "left out of the footfalls and the pacing; a vibrating floor whose acceleration "
            "is not in the record, or a machine, makes such a line. If the floor moved, give "
            "its acceleration (a ground_acc column) so that its response is taken out "
            "exactly."
        )
    if record.pacing_hz is None and pacing.pacing_hz > FAST_WALKING_HZ:
        half = pacing.pacing_hz / 2.0
        warnings.append(
            f"{record.name}: the pacing found, {pacing.pacing_hz:.2f} Hz, is fast for walking; "
            "when the GRF's second harmonic outweighs the first (a walker whose natural "
            "frequency is near twice the pacing), the pacing is found an octave high. If the "
            f"walker paced at about {half:.2f} Hz, state it (--pacing {half:.2f}, or pacing_hz "
            "in the record's JSON sidecar)."
        )
    if steps.unremoved_line_hz is not None:
        warnings.append(
            f"{record.name}: the footfalls follow a strong line at "
            f"{steps.unremoved_line_hz:.3f} Hz with no step shape behind it, and it could not "
            "be taken out (without it no walk is left, or its notch would reach half the "
            "sample rate), so the steps and the pacing may be the line's, not the walk's; "
            "check that the record holds walking, and if the floor moved, give its "
            "acceleration (a ground_acc column)."
        )
    split = check_split(steps)
    off_rhythm = split.warning(steps, record.name)
    if off_rhythm is not None:
        warnings.append(off_rhythm)
    if not highpass_hz and abs(balance - 1.0) > DRIFT_BALANCE_TOLERANCE:
        warnings.append(
            f"{record.name}: with the high-pass off, the static offset of "
            f"{100 * (balance - 1):+.1f} % of body weight integrates into a displacement that "
            "drifts quadratically; switch the filter on (--highpass-hz 0.15) unless the "
            "record starts at rest and is exactly balanced."
        )
    if record.pacing_hz is not None:
        rel = abs(pacing.pacing_hz - record.pacing_hz) / record.pacing_hz
        if rel > PACING_MISMATCH_TOLERANCE:
            warnings.append(
                f"{record.name}: the stated pacing {record.pacing_hz:.3f} Hz differs from the "
                f"{pacing.pacing_hz:.3f} Hz measured from footfalls by {100 * rel:.0f} %; check "
                "the metadata or drop the stated pacing (pacing_hz, --pacing on the command "
                "line) to use the measured value."
            )
    if pacing.varies:
        inst = np.asarray(pacing.instantaneous_hz, dtype=float)
        warnings.append(
            f"{record.name}: the pacing frequency changes along the record "
            f"(10th-90th percentile {np.percentile(inst, 10):.2f}-"
            f"{np.percentile(inst, 90):.2f} Hz); "
            "a single fixed pacing frequency will not describe the whole record, so identify "
            "per step or per steady segment."
        )
    return Inspection(
        record=record,
        com=com,
        steps=steps,
        pacing=pacing,
        static_balance=float(balance),
        static_balance_raw=float(balance_raw),
        warnings=warnings,
        split=split,
    )

"""Results of model criticism over a walker's walks: the diagnosis and the scoreboard.

Immutable, like the single record's (:mod:`workbench.diagnostics.criticism_results`);
``to_json()`` gives the JSON objects of ``workbench diagnose`` and ``workbench compare``
given several walks (docs/contracts.md), ``summary()`` a plain-text table.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, overload

import numpy as np
from numpy.typing import NDArray

from workbench.diagnostics.criticism_results import Candidate, ScoreRow, _table
from workbench.wording import p_value, signed

__all__ = ["EffectCoefficients", "WalkScoreRow", "WalkerComparison", "WalkerDiagnosis"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class WalkScoreRow(ScoreRow):
    """A scoreboard row over a walker's walks: the step-held-out scores and whole walks'.

    Attributes
    ----------
    walk_heldout_rmse_n : float or None
        RMSE with whole walks held out [N] (the shared coefficients from the other walks);
        None with one walk.
    walk_rmse_drop_fraction, walk_rmse_drop_se : float or None
        Its relative drop from the row before and the drop's standard error (walks as
        clusters: every step of a held-out walk shares the error of the coefficients
        learned on the others); None on the first row or with one walk.
    """

    walk_heldout_rmse_n: float | None = None
    walk_rmse_drop_fraction: float | None = None
    walk_rmse_drop_se: float | None = None

    @classmethod
    def from_row(
        cls,
        row: ScoreRow,
        walk_heldout_rmse_n: float | None,
        walk_gain: tuple[float, float] | None,
    ) -> WalkScoreRow:
        """Add the whole-walk scores to a step-held-out row.

        ``walk_gain`` is the fraction of the previous row's whole-walk held-out squared
        error removed and its standard error (walks as clusters), carried here to the RMSE.
        """
        drop = se = None
        if walk_gain is not None:
            gain, gain_se = walk_gain
            drop = 1.0 - math.sqrt(max(1.0 - gain, 0.0))
            # d(1 - sqrt(1 - g)) / dg = 1 / (2 sqrt(1 - g)).
            se = gain_se / (2.0 * math.sqrt(max(1.0 - gain, 1e-12)))
        return cls(**dataclasses.asdict(row), walk_heldout_rmse_n=walk_heldout_rmse_n,
                   walk_rmse_drop_fraction=drop, walk_rmse_drop_se=se)  # fmt: skip


@dataclass(frozen=True)
class EffectCoefficients:
    """An effect's coefficients at the walker level, fitted on all the walks.

    Attributes
    ----------
    effect : str
    sharing : str
        "shared" (one set for the walks), "aligned by the foot channels" (one set, each
        walk's left/right labelling turned to a common one) or "per walk" (each walk its
        own set, in walk order).
    coefficients, standard_errors : tuple of float
        The coefficients of the effect's criticism columns
        (:meth:`~workbench.models.effect_base.Effect.criticism_columns`; units those of
        ``N`` over the column's) with cluster-robust standard errors (blocks of steps as
        clusters). Per walk: no standard errors (NaN; null in JSON): a walk's few blocks
        are too few clusters.
    force_rms_n, force_rms_se_n : float
        The effect's force over the walks it was fitted on [N RMS] and its standard error:
        the delta method for shared coefficients; per walk, the jackknife over the walks
        (NaN with fewer than three), and the force then includes the fit's own noise, so
        it is biased up when the effect is small.
    walk_of_coefficient : tuple of int or None
        Per walk: the walk (its index in the walks given) each coefficient belongs to;
        None for shared coefficients.
    """

    effect: str
    sharing: str
    coefficients: tuple[float, ...]
    standard_errors: tuple[float, ...]
    force_rms_n: float
    force_rms_se_n: float
    walk_of_coefficient: tuple[int | None, ...] = ()

    def to_json(self) -> dict[str, Any]:
        """JSON-able dictionary (NaN as null)."""

        def number(v: float) -> float | None:
            return None if not math.isfinite(v) else v

        out = dataclasses.asdict(self)
        out["coefficients"] = list(self.coefficients)
        out["standard_errors"] = [number(v) for v in self.standard_errors]
        out["force_rms_se_n"] = number(self.force_rms_se_n)
        out["walk_of_coefficient"] = list(self.walk_of_coefficient)
        return out

    to_dict = to_json


@dataclass(frozen=True, eq=False)
class WalkerDiagnosis:
    """Result of :func:`~workbench.diagnostics.walker.diagnose_walker`.

    Attributes
    ----------
    baseline : dict
        The pooled baseline's scores and settings, with a ``per_walk`` list (JSON-able).
    candidates : tuple of Candidate
        Ranked as by :func:`~workbench.diagnostics.criticism.diagnose`.
    verdict : str
    walks : tuple of Walk
        The walks, in the frame of the surface model used.
    residual_n : ndarray
        The baseline's held-out error on the walks' samples, laid end to end [N].
    sharing : dict of str to str
        How each effect's coefficients are shared by the walks
        (:class:`EffectCoefficients`).
    walk_scores : dict of str to (float, float)
        Each testable candidate's score with whole walks held out, and its standard error
        (none with one walk).
    current_effects : tuple of str
    """

    baseline: dict[str, Any]
    candidates: tuple[Candidate, ...]
    verdict: str
    walks: tuple[Any, ...]
    residual_n: FloatArray
    sharing: dict[str, str]
    walk_scores: dict[str, tuple[float, float]]
    current_effects: tuple[str, ...] = ()

    @property
    def candidates_by_score(self) -> tuple[Candidate, ...]:
        """The candidates, highest score first, those the walks cannot test last."""
        return tuple(sorted(self.candidates, key=lambda c: (not c.testable, -c.score)))

    def to_json(self) -> dict[str, Any]:
        """Return the JSON object of ``workbench diagnose`` given several walks."""
        cands = []
        for c in self.candidates:
            item = c.to_json()
            item["sharing"] = self.sharing.get(c.effect, "shared")
            score = self.walk_scores.get(c.effect)
            item["walk_heldout_score"] = None if score is None else score[0]
            item["walk_heldout_score_se"] = None if score is None else score[1]
            cands.append(item)
        return {"baseline": self.baseline, "candidates": cands, "verdict": self.verdict}

    to_dict = to_json

    def summary(self) -> str:
        """Return a plain-text table: the pooled baseline, the candidates, the verdict."""
        b = self.baseline
        walk = b["walk_heldout_rmse_n"]
        lines = [
            f"Model criticism over {b['walks']} walks of one walker: {b['model']}",
            f"baseline held-out RMSE {b['heldout_rmse_n']:.3g} N"
            + ("" if walk is None else f" (whole walks held out {walk:.3g} N)")
            + f", fit {b['fit_percent']:.1f} %, Ljung-Box p {p_value(b['ljung_box_p'])} "
            f"({b['folds']} folds, {b['steps']} steps, left/right: {b['asymmetry_labelling']})",
            "",
        ]
        rows = []
        for c in self.candidates_by_score:
            score = self.walk_scores.get(c.effect)
            rows.append(
                [
                    c.effect,
                    signed(c.score),
                    f"{c.score_se:.3f}",
                    "-" if score is None else signed(score[0]),
                    ("yes" if c.significant else "no") if c.testable else "untestable",
                    self.sharing.get(c.effect, "shared"),
                    c.headline,
                ]
            )
        header = ["effect", "score", "se", "walk score", "significant", "sharing", "reason"]
        lines += _table(header, rows) if rows else ["(no candidates)"]
        lines += ["", f"verdict: {self.verdict}"]
        return "\n".join(lines)


@dataclass(frozen=True, eq=False)
class WalkerComparison:
    """Result of :func:`~workbench.diagnostics.walker.compare_walker`: the scoreboard.

    A sequence of :class:`WalkScoreRow`, the baseline first.

    Attributes
    ----------
    rows : tuple of WalkScoreRow
    sources : tuple of str
        The walks' records.
    coefficients : tuple of EffectCoefficients
        Each added effect's walker-level coefficients, in the rows' order (fitted with the
        effects before it in the model).
    sharing : dict of str to str
    """

    rows: tuple[WalkScoreRow, ...]
    sources: tuple[str, ...]
    coefficients: tuple[EffectCoefficients, ...]
    sharing: dict[str, str]

    @overload
    def __getitem__(self, index: int) -> WalkScoreRow: ...

    @overload
    def __getitem__(self, index: slice) -> tuple[WalkScoreRow, ...]: ...

    def __getitem__(self, index: int | slice) -> WalkScoreRow | tuple[WalkScoreRow, ...]:
        return self.rows[index]

    def __len__(self) -> int:
        return len(self.rows)

    def __iter__(self) -> Iterator[WalkScoreRow]:
        return iter(self.rows)

    def to_json(self) -> dict[str, Any]:
        """Return the JSON object of ``workbench compare`` given several walks."""
        return {
            "walks": list(self.sources),
            "rows": [r.to_json() for r in self.rows],
            "effects": {c.effect: c.to_json() for c in self.coefficients},
        }

    to_dict = to_json

    def summary(self) -> str:
        """Return a plain-text table of the rows and the effects' sizes."""

        def drop(value: float | None, se: float | None) -> str:
            if value is None or se is None:
                return ""
            return f"{100 * value:+.1f} +- {100 * se:.1f}"

        rows = [
            [
                r.model,
                f"{r.heldout_rmse_n:.3f}",
                "-" if r.walk_heldout_rmse_n is None else f"{r.walk_heldout_rmse_n:.3f}",
                f"{r.fit_percent:.1f}",
                p_value(r.ljung_box_p),
                "" if i == 0 else drop(r.rmse_drop_fraction, r.rmse_drop_se),
                drop(r.walk_rmse_drop_fraction, r.walk_rmse_drop_se),
            ]
            for i, r in enumerate(self.rows)
        ]
        header = [
            "model",
            "RMSE [N]",
            "walks held out [N]",
            "fit %",
            "LB p",
            "drop %",
            "walks drop %",
        ]
        lines = [f"Scoreboard over {len(self.sources)} walks of one walker", *_table(header, rows)]
        lines.append("")
        for c in self.coefficients:
            se = "" if not math.isfinite(c.force_rms_se_n) else f" +- {c.force_rms_se_n:.2g}"
            lines.append(
                f"{c.effect} ({c.sharing}): force {c.force_rms_n:.3g}{se} N RMS over the walks"
            )
        return "\n".join(lines)

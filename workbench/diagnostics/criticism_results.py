"""Results of model criticism: candidates, scoreboard rows, the diagnosis and the comparison.

All are immutable. ``to_json()`` gives the JSON objects of ``workbench diagnose`` and
``workbench compare`` (docs/contracts.md; ``to_dict()`` is the same), ``summary()`` a
plain-text table.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, overload

import numpy as np
from numpy.typing import NDArray

from workbench.diagnostics.criticism_data import CriticismData
from workbench.wording import p_value, signed

__all__ = ["Candidate", "Comparison", "Diagnosis", "ScoreRow"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Candidate:
    """One candidate effect's result (the JSON contract of docs/contracts.md, plus details).

    Attributes
    ----------
    effect : str
        Effect name.
    score : float
        Fraction of the baseline's held-out squared error that adding the effect removes.
    significant : bool
        Whether the record supports the effect (module docstring of
        :mod:`workbench.diagnostics.criticism`).
    evidence : str
        Plain words: the reason or why not, the revealing statistic, the gain.
    expected_error_drop : float
        Expected relative drop of the held-out RMSE.
    indistinguishable_from : tuple of str
        Candidates that explain the same held-out error on this record.
    score_se, t_ratio : float
        Block-to-block standard error of the score and the score over it.
    statistic : float
        Value of the effect's revealing statistic (0 when it has none).
    testable : bool
        False when the record cannot test the effect (e.g. no ground motion).
    separable_fraction : float
        Share of the effect's columns' variation outside the baseline's span.
    p_value : float
        One-sided p-value of the score from the step-paired t ratio (before Holm's
        adjustment over the candidates).
    detectable_score : float
        For a testable candidate not called: the smallest score the record could have
        called at its standard error (Holm's first step; at least the 1 % floor). 0 when
        called or not testable.
    """

    effect: str
    score: float
    significant: bool
    evidence: str
    expected_error_drop: float
    indistinguishable_from: tuple[str, ...] = ()
    score_se: float = 0.0
    t_ratio: float = 0.0
    statistic: float = 0.0
    testable: bool = True
    separable_fraction: float = 1.0
    p_value: float = 1.0
    detectable_score: float = 0.0

    @property
    def headline(self) -> str:
        """The first clause of the evidence: the reason when significant, else why not."""
        return self.evidence.split("; ", 1)[0]

    def to_json(self) -> dict[str, Any]:
        """JSON-able dictionary."""
        out = dataclasses.asdict(self)
        out["indistinguishable_from"] = list(self.indistinguishable_from)
        return out

    to_dict = to_json


@dataclass(frozen=True)
class ScoreRow:
    """One scoreboard row: a model's held-out errors."""

    model: str
    heldout_rmse_n: float
    fit_percent: float
    ljung_box_p: float
    score: float
    rmse_drop_fraction: float = 0.0
    rmse_drop_se: float = 0.0

    def to_json(self) -> dict[str, Any]:
        """JSON-able dictionary."""
        return dataclasses.asdict(self)

    to_dict = to_json


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    """Left-aligned plain-text columns; the last column is not padded."""
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header) - 1)]

    def line(cells: Sequence[str]) -> str:
        padded = [c.ljust(w) for c, w in zip(cells, widths, strict=False)]
        return "  ".join([*padded, cells[-1]]).rstrip()

    return [line(header), *(line(r) for r in rows)]


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of :func:`~workbench.diagnostics.criticism.diagnose`.

    Attributes
    ----------
    baseline : dict
        The baseline's scores and settings (JSON-able).
    candidates : tuple of Candidate
        Ranked: the effects kept by the stepwise selection first.
    verdict : str
        What to do next, in plain words.
    data : CriticismData
        The prepared record.
    residual_n, prediction_n : ndarray
        The baseline's held-out error and prediction of ``GRF - M g`` [N].
    current_effects : tuple of str
        Effects already in the model (their columns joined the baseline).
    one_step : OneStepResiduals or None
        One-step-ahead residuals of an identified model (:meth:`with_one_step`).

    Notes
    -----
    Frozen: :meth:`with_one_step` returns a copy with one-step-ahead residuals.
    """

    baseline: dict[str, Any]
    candidates: tuple[Candidate, ...]
    verdict: str
    data: CriticismData
    residual_n: FloatArray
    prediction_n: FloatArray
    current_effects: tuple[str, ...] = ()
    one_step: Any = None

    def with_one_step(self, one_step: Any) -> Diagnosis:
        """Return the diagnosis with one-step-ahead residuals (``baseline`` gains their scores).

        Parameters
        ----------
        one_step : OneStepResiduals
            From :func:`workbench.diagnostics.predictive.one_step_from_result`.

        Returns
        -------
        Diagnosis
        """
        baseline = {**self.baseline, **one_step.to_dict()}
        return dataclasses.replace(self, baseline=baseline, one_step=one_step)

    @property
    def candidates_by_score(self) -> tuple[Candidate, ...]:
        """The candidates for reading: highest score first, those the record cannot test last."""
        return tuple(sorted(self.candidates, key=lambda c: (not c.testable, -c.score)))

    def to_json(self) -> dict[str, Any]:
        """Return the JSON object of ``workbench diagnose``."""
        return {
            "baseline": self.baseline,
            "candidates": [c.to_json() for c in self.candidates],
            "verdict": self.verdict,
        }

    to_dict = to_json

    def summary(self) -> str:
        """Return a plain-text table: the baseline's error, the candidates, the verdict."""
        b = self.baseline
        lines = [
            f"Model criticism of {self.data.source}: {b['model']}",
            f"baseline held-out RMSE {b['heldout_rmse_n']:.3g} N, fit {b['fit_percent']:.1f} %, "
            f"Ljung-Box p {p_value(b['ljung_box_p'])} ({b['folds']} folds, {b['steps']} steps, "
            f"{b['harmonics']} harmonics)",
            "",
        ]
        rows = [
            [
                c.effect,
                signed(c.score),
                f"{c.score_se:.3f}",
                ("yes" if c.significant else "no") if c.testable else "untestable",
                f"{100 * c.separable_fraction:.1f} %",
                c.headline,
            ]
            for c in self.candidates_by_score
        ]
        header = ["effect", "score", "se", "significant", "separable", "reason"]
        lines += _table(header, rows) if rows else ["(no candidates)"]
        lines += ["", f"verdict: {self.verdict}"]
        return "\n".join(lines)


@dataclass(frozen=True, eq=False)
class Comparison(Sequence[ScoreRow]):
    """Result of :func:`~workbench.diagnostics.criticism.compare`: the scoreboard.

    A sequence of :class:`ScoreRow`, the baseline first, then the baseline with each effect
    added in turn (``comparison[1]`` is the first effect's row).

    Attributes
    ----------
    rows : tuple of ScoreRow
    source : str
        Where the record came from.
    """

    rows: tuple[ScoreRow, ...]
    source: str = "<memory>"

    @overload
    def __getitem__(self, index: int) -> ScoreRow: ...

    @overload
    def __getitem__(self, index: slice) -> tuple[ScoreRow, ...]: ...

    def __getitem__(self, index: int | slice) -> ScoreRow | tuple[ScoreRow, ...]:
        return self.rows[index]

    def __len__(self) -> int:
        return len(self.rows)

    def __iter__(self) -> Iterator[ScoreRow]:
        return iter(self.rows)

    def to_json(self) -> dict[str, Any]:
        """Return the JSON object of ``workbench compare``: ``{"rows": [...]}``."""
        return {"rows": [r.to_json() for r in self.rows]}

    to_dict = to_json

    def summary(self) -> str:
        """Return a plain-text table of the rows."""
        rows = [
            [
                r.model,
                f"{r.heldout_rmse_n:.3f}",
                f"{r.fit_percent:.1f}",
                p_value(r.ljung_box_p),
                f"{r.score:.3f}",
                ""
                if i == 0
                else f"{100 * r.rmse_drop_fraction:+.1f} +- {100 * r.rmse_drop_se:.1f}",
            ]
            for i, r in enumerate(self.rows)
        ]
        header = ["model", "RMSE [N]", "fit %", "LB p", "score", "RMSE drop % (+- se)"]
        return "\n".join([f"Scoreboard of {self.source}", *_table(header, rows)])

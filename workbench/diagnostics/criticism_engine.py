"""The held-out engine of model criticism: step variation, cross-validation and scores.

:class:`StepVariation` takes each step's own size and timing of the shared force shape out
of a signal; :class:`_CV` holds per-fold Gram matrices of the baseline's and the candidates'
columns, so any subset is scored by step-blocked cross-validation cheaply. See the module
docstring of :mod:`workbench.diagnostics.criticism` for the method.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from workbench.diagnostics.criticism_data import (
    DEFAULT_HARMONICS,
    SLOW_STEPS,
    CriticismData,
    _harmonics,
    _max_order,
    _moving_average,
    _shape_slope,
    _without_stride_lines,
    baseline_columns,
)
from workbench.diagnostics.criticism_results import ScoreRow
from workbench.models.effects import PACING_CHANGE_MIN, Effect

__all__ = [
    "BLOCK_STEPS",
    "DEFAULT_FOLDS",
    "RESPONSE_MODULATION_ORDERS",
    "StepVariation",
    "ljung_box_p",
]

FloatArray = NDArray[np.float64]
ArrayLikeFloat = FloatArray | Sequence[float]

#: Folds of the step-blocked cross-validation (fewer on short records, at least 3 steps each).
DEFAULT_FOLDS = 10
#: Steps per block; blocks are dealt to the folds in turn (block b goes to fold b mod K).
BLOCK_STEPS = 3
#: Ridge added to the normal equations of standardised features (numerical safety only).
_RIDGE = 1e-8


#: Orders of the step-phase harmonics that modulate ``u`` and ``u'`` in the baseline's
#: nuisance block (module docstring, "Response modulation"). Orders 1 and 2 hold the
#: first-order part of ``u^3`` and ``|u'| u'``: with a response led by its first harmonic,
#: ``U^2`` and ``|U'|`` have most of their power at orders 0 and 2, and the product of the
#: first and second harmonics puts some at order 1. ``response_modulation=False`` in
#: :func:`diagnose` and :func:`compare` leaves the block out.
RESPONSE_MODULATION_ORDERS: tuple[int, ...] = (1, 2)


def _modulation_columns(data: CriticismData) -> FloatArray:
    """``u`` and ``u'`` times the step-phase harmonics of :data:`RESPONSE_MODULATION_ORDERS`."""
    u, v = _without_stride_lines(data)
    h = _harmonics(data.phase_rad, RESPONSE_MODULATION_ORDERS)
    return np.column_stack([u[:, None] * h, v[:, None] * h])


def _shape_columns(data: CriticismData, baseline: FloatArray) -> FloatArray:
    """Return the shared force shape ``S(phi)`` fitted to all steps and its phase slope."""
    coef, *_ = np.linalg.lstsq(baseline, data.target_n, rcond=None)
    n = (baseline.shape[1] - 3) // 2
    shape = baseline[:, 1 : 1 + 2 * n] @ coef[1 : 1 + 2 * n]
    return np.column_stack([shape, _shape_slope(data)])


def _pace_columns(data: CriticismData, harmonics: int) -> FloatArray | None:
    """Return the force's harmonics and timing following the pace, when the walk changes pace.

    A walker who walks faster pushes harder (the population's BLF laws grow with the
    pacing), and at another pacing every harmonic of the GRF passes through the body's
    frequency response at another frequency, which the baseline's ``K u + C u'`` follows
    only as far as its K and C are right (they are not: module docstring of
    :mod:`workbench.diagnostics.criticism`). So on a record whose slow pacing varies by more
    than :data:`~workbench.models.effects.PACING_CHANGE_MIN` each harmonic of the shared
    shape, and its timing, follow the slow pacing: ``(f - f_mean) / f_mean`` times the
    step-phase harmonics and ``S'(phi)``. That is the walker's ordinary gait at a changing
    pace, part of the baseline, not a missing effect: without it nearly every simulated
    speed-change record without an effect raised ``pacing_drift``
    (``analyses/criticism_detection.py --calibration --no-pace``). ``pacing_drift`` is then
    judged on a drift in time beyond the pace. None on a walk at a steady pace.
    """
    rate = data.slow_pacing_change()
    if rate is None or np.std(rate) <= PACING_CHANGE_MIN * data.pacing_hz:
        return None
    n = int(min(harmonics, math.floor(_max_order(data))))
    cols = np.column_stack([_harmonics(data.phase_rad, range(1, n + 1)), _shape_slope(data)])
    return np.asarray((rate / data.pacing_hz)[:, None] * cols, dtype=np.float64)


# -- step-to-step variation of the force's size and timing -------------------------------
class StepVariation:
    """The linear map that takes each step's own size and timing jitter out of a signal.

    For step ``j`` with samples ``s`` and nuisance columns ``N_s = [S(phi_s), S'(phi_s)]``
    (the baseline's shared force shape fitted to all steps, and its phase slope), a signal
    ``a`` has per-step coefficients ``c_j = argmin |a_s - N_s c|``. Their moving average over
    :data:`SLOW_STEPS` steps is the slow part ``c_slow``; the map returns
    ``a_s - N_s (c_j - c_slow,j)`` (module docstring). The map is linear in ``a``, so
    regressing the mapped target on the mapped columns is the regression with each step's
    size and timing jitter as nuisance parameters.

    Parameters
    ----------
    data : CriticismData
    harmonics : int, optional
        Harmonics of the shared shape.
    baseline : ndarray, optional
        :func:`baseline_columns` of ``data`` with those harmonics, when already built.
    """

    def __init__(
        self,
        data: CriticismData,
        harmonics: int = DEFAULT_HARMONICS,
        baseline: FloatArray | None = None,
    ) -> None:
        x = baseline_columns(data, harmonics) if baseline is None else baseline
        self.columns = _shape_columns(data, x)
        self.step = data.step
        self.n_steps = data.n_steps
        # Per-step least-squares operators (2 x n_j), built once for every signal mapped.
        self._pinv = [np.linalg.pinv(self.columns[data.step == j]) for j in range(data.n_steps)]

    def __call__(self, values: FloatArray) -> FloatArray:
        """Map a signal (n_samples,) or columns (n_samples, k) (class docstring)."""
        a = np.asarray(values, dtype=np.float64)
        flat = a.reshape(a.shape[0], -1)
        coefs = np.stack([p @ flat[self.step == j] for j, p in enumerate(self._pinv)])
        width = max(min(SLOW_STEPS, self.n_steps), 1)
        series = coefs.reshape(self.n_steps, -1)
        slow = np.column_stack(
            [_moving_average(series[:, i], width) for i in range(series.shape[1])]
        )
        jitter = coefs - slow.reshape(coefs.shape)
        out = flat - np.einsum("sa,sak->sk", self.columns, jitter[self.step])
        return np.asarray(out.reshape(a.shape), dtype=np.float64)


# -- cross-validation engine --------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Piece:
    """The samples of one walk and the columns that are not zero on them.

    A pooled criticism over a walker's walks (:mod:`workbench.diagnostics.walker`) has a
    baseline of its own for every walk: its columns are zero outside the walk, so each walk
    keeps only its own and the shared ones (``columns``, global indices; ``x`` holds them
    on the walk's samples, already through the step-variation map). One record is one piece
    holding every column.
    """

    rows: slice
    columns: NDArray[np.intp]
    x: FloatArray


def step_blocks(step: NDArray[np.int64], n_steps: int) -> tuple[NDArray[np.int64], int]:
    """Return the block of :data:`BLOCK_STEPS` steps of each sample (the last takes the rest)."""
    n_blocks = max(n_steps // BLOCK_STEPS, 1)
    return np.minimum(step // BLOCK_STEPS, n_blocks - 1), n_blocks


class _CV:
    """Per-fold Gram matrices of all columns, so any column subset is scored cheaply.

    Parameters
    ----------
    layout : object
        What the scores are counted over: ``step`` (each sample's step), ``n_steps`` and
        ``step_fraction`` (a :class:`CriticismData`, or a walker's walks laid end to end).
    widths : dict of str to int
        Width of every block of columns, in the order of the global columns ("baseline"
        first).
    pieces : list of _Piece
        Samples and their non-zero columns (mapped, not yet scaled).
    y : ndarray
        The mapped target on all samples.
    block : ndarray of int
        Each sample's block of steps (held out together); ``n_blocks`` of them.
    folds : int
    """

    def __init__(
        self,
        layout: Any,
        widths: dict[str, int],
        pieces: Sequence[_Piece],
        y: FloatArray,
        block: NDArray[np.int64],
        n_blocks: int,
        folds: int,
    ) -> None:
        self.data = layout
        self.names = list(widths)
        self.slices: dict[str, NDArray[np.intp]] = {}
        start = 0
        for k, w in widths.items():
            self.slices[k] = np.arange(start, start + w)
            start += w
        n_cols = start
        self.y = np.asarray(y, dtype=np.float64)
        n = self.y.size
        # RMS, not sd: after the step-variation map the constant column varies a little,
        # and dividing it by that small sd would make the normal equations ill-conditioned.
        sumsq = np.zeros(n_cols)
        for p in pieces:
            np.add.at(sumsq, p.columns, np.sum(p.x**2, axis=0))
        scale = np.sqrt(sumsq / n)
        scale[scale == 0] = 1.0
        self.scale = scale
        self.pieces = [_Piece(p.rows, p.columns, p.x / scale[p.columns]) for p in pieces]
        n_folds = int(max(3, min(folds, n_blocks)))
        self.fold_of = block % n_folds
        self.block_of = block
        self.n_blocks = n_blocks
        #: Degrees of freedom of the t ratio of :meth:`gain` (one per step, less the mean).
        self.dof = max(layout.n_steps - 1, 1)
        self._step_cache: dict[tuple[str, ...], FloatArray] = {}
        self.n_folds = n_folds
        self.n_columns = n_cols
        self.gram = np.zeros((n_folds, n_cols, n_cols))
        self.xty = np.zeros((n_folds, n_cols))
        self.yty = np.zeros(n_folds)
        self.count = np.zeros(n_folds)
        #: Each piece's Gram matrix and ``x' y`` over all its samples, on its own columns
        #: (a pooled criticism refits without one piece at a time).
        self.piece_gram: list[FloatArray] = []
        self.piece_xty: list[FloatArray] = []
        for p in self.pieces:
            fold = self.fold_of[p.rows]
            yp = self.y[p.rows]
            cols = np.ix_(p.columns, p.columns)
            g_piece = np.zeros((p.columns.size, p.columns.size))
            b_piece = np.zeros(p.columns.size)
            for f in range(n_folds):
                sel = fold == f
                xf, yf = p.x[sel], yp[sel]
                g_fold, b_fold = xf.T @ xf, xf.T @ yf
                self.gram[f][cols] += g_fold
                self.xty[f][p.columns] += b_fold
                g_piece += g_fold
                b_piece += b_fold
                self.yty[f] += yf @ yf
                self.count[f] += sel.sum()
            self.piece_gram.append(g_piece)
            self.piece_xty.append(b_piece)
        self.gram_all = self.gram.sum(axis=0)
        self.xty_all = self.xty.sum(axis=0)

    @property
    def x(self) -> FloatArray:
        """All columns on all samples (scaled), zero where a piece lacks a column."""
        out = np.zeros((self.y.size, self.n_columns))
        for p in self.pieces:
            out[p.rows, p.columns] = p.x  # rows is a slice: a view is written
        return out

    def predict(self, beta: FloatArray) -> FloatArray:
        """``x @ beta`` on all samples, ``beta`` over all columns (scaled)."""
        out = np.zeros(self.y.size)
        for p in self.pieces:
            out[p.rows] = p.x @ beta[p.columns]
        return out

    def columns(self, groups: Sequence[str]) -> NDArray[np.intp]:
        return np.concatenate([self.slices[g] for g in ("baseline", *groups)])

    def _solve(self, g: FloatArray, b: FloatArray) -> FloatArray:
        ridge = _RIDGE * np.trace(g) / g.shape[0]
        return np.asarray(np.linalg.solve(g + ridge * np.eye(g.shape[0]), b), dtype=np.float64)

    def fold_sse(self, groups: Sequence[str]) -> tuple[FloatArray, FloatArray]:
        """Held-out SSE per fold and training residual variance per fold."""
        idx = self.columns(groups)
        sse = np.empty(self.n_folds)
        train_var = np.empty(self.n_folds)
        g_all = self.gram_all[np.ix_(idx, idx)]
        b_all = self.xty_all[idx]
        yty_all = float(self.yty.sum())
        for f in range(self.n_folds):
            g_f = self.gram[f][np.ix_(idx, idx)]
            b_f = self.xty[f][idx]
            beta = self._solve(g_all - g_f, b_all - b_f)
            sse[f] = max(self.yty[f] - 2.0 * beta @ b_f + beta @ g_f @ beta, 0.0)
            train_sse = (yty_all - self.yty[f]) - 2.0 * beta @ (b_all - b_f)
            train_sse += beta @ (g_all - g_f) @ beta
            n_train = self.count.sum() - self.count[f]
            train_var[f] = max(train_sse, 1e-300) / max(n_train - idx.size, 1.0)
        return sse, train_var

    def heldout_prediction(self, groups: Sequence[str]) -> FloatArray:
        idx = self.columns(groups)
        pred = np.empty_like(self.y)
        g_all = self.gram_all[np.ix_(idx, idx)]
        b_all = self.xty_all[idx]
        beta = np.zeros(self.n_columns)
        for f in range(self.n_folds):
            beta[idx] = self._solve(
                g_all - self.gram[f][np.ix_(idx, idx)], b_all - self.xty[f][idx]
            )
            for p in self.pieces:
                sel = self.fold_of[p.rows] == f
                pred[p.rows][sel] = p.x[sel] @ beta[p.columns]
        return pred

    def separable_fraction(self, group: str, base: Sequence[str]) -> float:
        """Share of a group's variation the baseline (plus ``base``) cannot represent.

        ``1 - R^2`` of the group's columns regressed on the model's columns over the whole
        record, pooled over the columns (their variances add). A candidate whose columns
        lie almost wholly in the model's span cannot show its error however large it is.
        """
        idx_m = self.columns(base)
        idx_g = self.slices[group]
        g = self.gram_all
        g_mm = g[np.ix_(idx_m, idx_m)]
        g_mg = g[np.ix_(idx_m, idx_g)]
        coef = self._solve(g_mm, g_mg)
        total = np.diag(g[np.ix_(idx_g, idx_g)]).copy()
        n = self.count.sum()
        sums = np.zeros(self.n_columns)
        for p in self.pieces:
            np.add.at(sums, p.columns, p.x.sum(axis=0))
        mean = sums[idx_g] / n
        total_c = total - n * mean**2
        resid = total - np.einsum("ij,ij->j", g_mg, coef)
        keep = total_c > 0
        if not np.any(keep):
            return 0.0
        return float(np.clip(np.sum(resid[keep]) / np.sum(total_c[keep]), 0.0, 1.0))

    def step_sse(self, groups: Sequence[str]) -> FloatArray:
        """Held-out SSE per step (each step predicted by its block's fold's fit)."""
        key = tuple(groups)
        if key not in self._step_cache:
            resid = self.y - self.heldout_prediction(groups)
            n = self.data.n_steps
            sse = np.bincount(self.data.step, weights=resid**2, minlength=n)
            self._step_cache[key] = np.asarray(sse, dtype=np.float64)
        return self._step_cache[key]

    def gain(self, base: Sequence[str], extended: Sequence[str]) -> tuple[float, float, float]:
        """Pooled fraction of held-out SSE removed, its standard error, and the t ratio.

        The pooled fraction is the mean over steps of ``(SSE_base,j - SSE_ext,j)`` divided
        by the mean baseline SSE per step. Its standard error allows for the correlation of
        neighbouring steps (the steps of a block are predicted by one fit, and the error
        of a shared shape carries over from step to step): a Bartlett-weighted
        (Newey-West) long-run variance of the paired differences with :data:`BLOCK_STEPS`
        lags. Its t ratio has :attr:`dof` degrees of freedom. Whole blocks as units would
        leave an overground walk only a third as many units as it has steps; the measured
        false-alarm rate of this test is in docs/validation/criticism.md ("Family-wise
        control").
        """
        return paired_gain(self.step_sse(base), self.step_sse(extended))


def paired_gain(sse_base: FloatArray, sse_extended: FloatArray) -> tuple[float, float, float]:
    """Fraction of held-out SSE removed, its long-run standard error and the t ratio.

    ``sse_base`` and ``sse_extended`` are the held-out squared errors of each step under the
    two models (see :meth:`_CV.gain`).
    """
    scale = max(float(sse_base.mean()), 1e-300)
    diff = (sse_base - sse_extended) / scale
    pooled = float(diff.mean())
    dev = diff - pooled
    n = dev.size
    var = float(dev @ dev) / n
    for lag in range(1, min(BLOCK_STEPS, n - 1) + 1):
        var += 2.0 * (1.0 - lag / (BLOCK_STEPS + 1.0)) * float(dev[lag:] @ dev[:-lag]) / n
    se = float(np.sqrt(max(var, 0.0) / n))
    t = pooled / se if se > 0 else (np.inf if pooled > 0 else 0.0)
    return pooled, se, float(t)


def ljung_box_p(residual: ArrayLikeFloat, lags: int) -> float:
    """Ljung-Box p-value that a series is white up to ``lags``.

    Parameters
    ----------
    residual : array_like
    lags : int

    Returns
    -------
    float
    """
    x = np.asarray(residual, dtype=np.float64)
    x = x - x.mean()
    n = x.size
    lags = int(min(lags, n - 2))
    denom = float(x @ x)
    if lags < 1 or denom == 0:
        return 1.0
    q = 0.0
    for k in range(1, lags + 1):
        rho = float(x[k:] @ x[:-k]) / denom
        q += rho * rho / (n - k)
    q *= n * (n + 2)
    return float(stats.chi2.sf(q, lags))


def _step_binned(data: CriticismData, resid: FloatArray, per_step: int = 10) -> FloatArray:
    """Average the residual in ``per_step`` equal phase bins of every step.

    The whiteness of that series is about step-to-step structure, not the smoothness of
    the error within a step.
    """
    bins = np.minimum((data.step_fraction * per_step).astype(int), per_step - 1)
    key = data.step * per_step + bins
    sums = np.bincount(key, weights=resid, minlength=data.n_steps * per_step)
    counts = np.bincount(key, minlength=data.n_steps * per_step)
    ok = counts > 0
    return np.asarray(sums[ok] / counts[ok], dtype=np.float64)


def _row(cv: _CV, groups: Sequence[str], label: str, base_sse: FloatArray | None) -> ScoreRow:
    sse, train_var = cv.fold_sse(groups)
    n = cv.count.sum()
    rmse = float(np.sqrt(sse.sum() / n))
    pred = cv.heldout_prediction(groups)
    resid = cv.y - pred
    y = cv.y
    fit = 100.0 * (1.0 - float(np.linalg.norm(resid) / np.linalg.norm(y - y.mean())))
    series = _step_binned(cv.data, resid)
    lb = ljung_box_p(series, 20)
    # Gaussian log predictive density per sample with each fold's training variance.
    lpd = -0.5 * np.sum(cv.count * np.log(2 * np.pi * train_var) + sse / train_var) / n
    drop = se = 0.0
    if base_sse is not None:
        drop = 1.0 - rmse / float(np.sqrt(base_sse.sum() / n))
        per_fold = 1.0 - np.sqrt(sse / np.maximum(base_sse, 1e-300))
        se = float(np.std(per_fold, ddof=1) / np.sqrt(cv.n_folds))
    return ScoreRow(label, rmse, fit, lb, float(lpd), drop, se)


def record_blocks(
    data: CriticismData,
    effects: Iterable[str | Effect],
    harmonics: int,
    step_variation: bool = True,
    response_modulation: bool = True,
    follow_pace: bool = True,
) -> tuple[dict[str, FloatArray], StepVariation | None, list[str]]:
    """Return the baseline's and the effects' criticism columns on one record, before the map.

    Parameters
    ----------
    data : CriticismData
    effects : iterable of Effect or str
        Effects (specs are read by :meth:`Effect.from_spec`); their names key the blocks.
    harmonics : int
    step_variation, response_modulation, follow_pace : bool, optional

    Returns
    -------
    (dict, StepVariation or None, list of str)
        The blocks ("baseline" first), the record's step-variation map (None when not
        used) and the names of the effects the record cannot test.
    """
    base = baseline_columns(data, harmonics)
    # The step-variation map needs the plain baseline (its shared shape); the modulation
    # columns are nuisance columns of the baseline block itself.
    jitter = StepVariation(data, harmonics, base) if step_variation else None
    pace = _pace_columns(data, harmonics) if follow_pace else None
    if pace is not None:
        base = np.column_stack([base, pace])
    if response_modulation and RESPONSE_MODULATION_ORDERS:
        base = np.column_stack([base, _modulation_columns(data)])
    blocks: dict[str, FloatArray] = {"baseline": base}
    untestable = []
    for item in effects:
        effect = item if isinstance(item, Effect) else Effect.from_spec(item)
        cols = effect.criticism_columns(data)
        if cols is None:
            untestable.append(effect.name)
        else:
            blocks[effect.name] = np.asarray(cols, dtype=np.float64).reshape(data.time_s.size, -1)
    return blocks, jitter, untestable


def _build_cv(
    data: CriticismData,
    effects: Iterable[str | Effect],
    harmonics: int,
    folds: int,
    step_variation: bool = True,
    response_modulation: bool = True,
    follow_pace: bool = True,
) -> tuple[_CV, list[str]]:
    """Build the engine on the baseline and the effects' criticism columns.

    Parameters
    ----------
    data : CriticismData
    effects : iterable of Effect or str
        Effects (specs are read by :meth:`Effect.from_spec`); their names key the blocks.
    harmonics, folds : int
    step_variation, response_modulation, follow_pace : bool, optional

    Returns
    -------
    (_CV, list of str)
        The engine and the names of the effects the record cannot test.
    """
    blocks, jitter, untestable = record_blocks(
        data, effects, harmonics, step_variation, response_modulation, follow_pace
    )
    x = np.column_stack([*blocks.values(), data.target_n])
    if jitter is not None:
        # One pass over the steps for the columns and the target together.
        x = jitter(x)
    widths = {k: v.shape[1] for k, v in blocks.items()}
    piece = _Piece(slice(0, x.shape[0]), np.arange(x.shape[1] - 1), x[:, :-1])
    block, n_blocks = step_blocks(data.step, data.n_steps)
    return _CV(data, widths, [piece], x[:, -1], block, n_blocks, folds), untestable

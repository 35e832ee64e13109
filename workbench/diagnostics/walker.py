"""Model criticism over a walker's walks: one diagnosis pooled over several passes.

Why pool
--------
One pass of the seed study's 40 m track holds 17-33 whole steps, too few for the drifts and
for the smaller effects (docs/validation/criticism.md). A walker walks the track many times;
what is the walker's -- a heel impact, a left/right difference, a nonlinear spring -- is in
every pass, while what is the pass's -- its force shape's size and timing, its pacing, its
start and stop, its noise -- is not. So the pooled baseline is each walk's own
(:func:`~workbench.diagnostics.criticism_engine.record_blocks`: the shared force shape of
that walk, its ``K u + C u'`` with the response modulation, its pace block; each step's own
size and timing taken out by that walk's step-variation map), and a candidate effect adds
one set of coefficients shared by the walks.

How each effect is shared
-------------------------
- Effects whose columns mean the same on every walk share one coefficient set: heel
  impact (step-phase harmonics on each walk's re-timed phase), base motion, the state
  effects (``u^3``, ``|u'| u'``).
- Drifts (pacing, stiffness) are walk-specific in time: their columns use each walk's own
  centred time (-1/2 at its first kept sample, +1/2 at its last), so the shared
  coefficient is the same total change over a pass, whatever the pass's length. A walker
  whose gait changes the same way through every pass (speeding up through the track,
  settling after the start) shows it; a drift that changes sign from pass to pass cancels
  and is not looked for.
- Left/right asymmetry (:attr:`Effect.swaps_with_feet
  <workbench.models.effect_base.Effect.swaps_with_feet>`): its columns change sign with the
  foot that takes a walk's first kept step, which a GRF record of both feet together does
  not say. Where every walk has foot channels (``grf_left_n`` and ``grf_right_n``), each
  walk's first step is labelled from them (:func:`first_foot`) and the columns are turned
  to a common labelling: one coefficient set, the walker's asymmetry with its sign. Without
  them the test is sign-free: each walk has its own coefficients (its columns are zero on
  the other walks), and the pooled test asks whether the walks together show a stride
  line, whatever foot came first. The diagnosis says which (``asymmetry_labelling``).

Starts and stops
----------------
A pass of the seed's protocol starts and stops standing, and gait initiation is not
termination played backwards: the force grows over the first steps and falls over the last,
and the body's response lags it, building up at the start and ringing down after the stop.
The error of a baseline made for steady steps is then different at the two ends of a pass,
and alike in every pass. Pooled over a walker's passes, that shared pattern is what a
drift's columns (odd in the pass's time) pick up: on simulated walkers *without any
effect*, six overground passes raised the pacing drift in 4 of 10 and the stiffness drift in
3, and none once the first and last three steps of each pass were left out
(docs/validation/criticism.md). A walk's ends are therefore its own: the pooled criticism
leaves out the first and last :data:`START_STOP_STEPS` steps of every walk
(:func:`start_stop_steps`; ``start_stop=False`` keeps them) and judges the candidates on
the steps between. The rule is the same for every walk rather than detected: the force of
a walk's first kept steps did not tell a start from standing reliably (the split may keep
the first step of gait initiation or not; on a deck, or in a walk that changes pace, the
steps' sizes vary for other reasons), and a pass cut from a longer record loses little.

Surfaces
--------
On a vibrating deck, with the surface coupled, the spring and damper act on the motion
relative to the surface; but a baseline's ``K`` and ``C`` are not the walker's
(docs/validation/criticism.md), so part of the deck-driven force stays in its error, at
the deck's frequency, in every pass. Alone, a pass shows too little of it to matter; pooled,
the sign-free asymmetry (each pass its own stride-line coefficients, a deck near 1.5 times
the pacing a few frequency bins away in a 10 s pass) took it up: on walkers without any
effect over a deck, six passes called an asymmetry on 5 of 10 and twelve on 9 of 10. So
each pass's baseline also carries the measured surface motion (displacement, velocity,
acceleration) with free coefficients: for a deck moving at one frequency that is exactly
the pass's own response to it, whatever ``K`` and ``C`` (``surface_response=False`` leaves
them out, kept to measure what they change).

Scores
------
The test is the single record's (:mod:`workbench.diagnostics.criticism`), over all the
walks' steps: blocks of :data:`~workbench.diagnostics.criticism_engine.BLOCK_STEPS` steps
inside each walk, dealt to the folds in turn; the paired step-by-step differences of
held-out squared error with their long-run standard error; Holm's step-down test over the
candidates at the family-wise level, stage by stage. A second score holds out *whole
walks*: the shared coefficients are fitted on the other walks and predict the held-out
walk, whose own baseline (and any coefficients of its own) comes from the step-blocked
folds inside it. That is the error on a new pass of the same walker, and the scoreboard
(:func:`compare_walker`) reports it beside the step-held-out error; its standard error
takes the walks as clusters (:func:`walk_clustered_gain`), since every step of a held-out
walk shares the error of the coefficients learned on the others. The coefficients of the
effects added are reported at the walker level with cluster-robust standard errors (the
blocks of steps as clusters), and each effect's force over the walks [N RMS] with its
standard error by the delta method; coefficients fitted walk by walk get none (a walk's
few blocks are too few clusters) and their force's error is the jackknife over the walks.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.diagnostics.criticism import (
    DEFAULT_FOLDS,
    EffectsLike,
    _rank,
    _resolve,
    _surface_frame,
    _surface_name,
    candidate_effects,
    compared_effects,
    prepare,
)
from workbench.diagnostics.criticism_data import CriticismData, _max_order
from workbench.diagnostics.criticism_engine import (
    _CV,
    _Piece,
    _row,
    record_blocks,
    step_blocks,
)
from workbench.diagnostics.walker_results import (
    EffectCoefficients,
    WalkerComparison,
    WalkerDiagnosis,
    WalkScoreRow,
)
from workbench.errors import UsageError
from workbench.models.effects import Effect
from workbench.models.smd import SMDModel
from workbench.records.record import Record

__all__ = [
    "FOOT_AGREEMENT_MIN",
    "START_STOP_STEPS",
    "Walk",
    "compare_walker",
    "diagnose_walker",
    "first_foot",
    "prepare_walks",
    "start_stop_steps",
    "walk_clustered_gain",
]

FloatArray = NDArray[np.float64]

#: Share of a walk's steps whose stance foot (from the foot channels) must alternate from
#: the first step's for the walk's feet to count as known.
FOOT_AGREEMENT_MIN = 0.8
#: Steps left out at each end of a walk in a pooled criticism (module docstring, "Starts
#: and stops"): gait initiation and termination take about three steps.
START_STOP_STEPS = 3
#: Steps a walk keeps at least when its start and stop are left out.
MIN_STEADY_STEPS = 6
#: Fewest whole steps of a walk in a pooled criticism (two blocks of steps).
MIN_WALK_STEPS = 6


@dataclass(frozen=True, eq=False)
class Walk:
    """One walk of a walker, prepared for criticism.

    Attributes
    ----------
    data : CriticismData
        The prepared record (:func:`~workbench.diagnostics.criticism.prepare`).
    first_foot : {"left", "right"} or None
        The foot of the walk's first kept step, from the record's foot channels; None when
        the record has none or they do not alternate clearly.
    foot_agreement : float or None
        Share of the steps whose stance foot, by the foot channels, alternates from
        ``first_foot`` (None without foot channels).
    start_stop : (int, int)
        Steps of the walk's start and of its stop left out of the pooled criticism
        (:func:`start_stop_steps`); ``data`` then holds the steps between.
    """

    data: CriticismData
    first_foot: str | None = None
    foot_agreement: float | None = None
    start_stop: tuple[int, int] = (0, 0)

    @property
    def source(self) -> str:
        """Where the walk's record came from."""
        return self.data.source


def first_foot(record: Record, data: CriticismData) -> tuple[str | None, float | None]:
    """Label a walk's first kept step left or right from the record's foot channels.

    In each step of the criticism's split the foot that carries more of the step's force
    (the integral of ``grf_left_n - grf_right_n`` over the step) is its stance foot; the
    first step's foot is the one that makes the steps alternate best.

    Parameters
    ----------
    record : Record
        The walk's record, with ``grf_left_n`` and ``grf_right_n`` when the feet are known.
    data : CriticismData
        The record prepared for criticism.

    Returns
    -------
    (str or None, float or None)
        ``"left"`` or ``"right"`` and the share of the steps that agree with alternating
        from it; ``(None, None)`` without foot channels, and ``(None, share)`` when fewer
        than :data:`FOOT_AGREEMENT_MIN` of the steps agree.
    """
    if record.grf_left_n is None or record.grf_right_n is None:
        return None, None
    diff = np.interp(data.time_s, record.time_s, np.asarray(record.grf_left_n - record.grf_right_n))
    per_step = np.bincount(data.step, weights=diff, minlength=data.n_steps)
    left = per_step > 0
    even_is_left = left == (np.arange(data.n_steps) % 2 == 0)
    share_left = float(np.mean(even_is_left))
    foot, share = ("left", share_left) if share_left >= 0.5 else ("right", 1.0 - share_left)
    return (foot if share >= FOOT_AGREEMENT_MIN else None), share


def start_stop_steps(data: CriticismData) -> tuple[int, int]:
    """Return the steps of a walk's start and of its stop, left out when pooled.

    :data:`START_STOP_STEPS` at each end (module docstring, "Starts and stops"), unless
    fewer than :data:`MIN_STEADY_STEPS` would be left.

    Returns
    -------
    (int, int)
        Steps to leave out at the start and at the stop.
    """
    if data.n_steps < 2 * START_STOP_STEPS + MIN_STEADY_STEPS:
        return 0, 0
    return START_STOP_STEPS, START_STOP_STEPS


def _steady(walks: Sequence[Walk], start_stop: bool) -> tuple[Walk, ...]:
    """Leave each walk's start and stop out (:func:`start_stop_steps`)."""
    if not start_stop:
        return tuple(walks)
    out = []
    for w in walks:
        a, b = (0, 0) if w.start_stop != (0, 0) else start_stop_steps(w.data)
        if a or b:
            foot = w.first_foot
            if foot is not None and a % 2 == 1:
                # The new first step is the other foot's.
                foot = "right" if foot == "left" else "left"
            w = dataclasses.replace(
                w,
                data=w.data.step_range(a, w.data.n_steps - b),
                first_foot=foot,
                start_stop=(a, b),
            )
        out.append(w)
    return tuple(out)


def prepare_walks(
    records: Sequence[Record | CriticismData | Walk],
    *,
    highpass_hz: float | None = None,
    pacing_hz: float | None = None,
) -> tuple[Walk, ...]:
    """Prepare a walker's records for a pooled criticism.

    Parameters
    ----------
    records : sequence of Record, CriticismData or Walk
        The walks (records are prepared with :func:`~workbench.diagnostics.criticism.prepare`
        and their feet labelled with :func:`first_foot`).
    highpass_hz, pacing_hz : float, optional
        As in :func:`~workbench.diagnostics.criticism.prepare`.

    Returns
    -------
    tuple of Walk
    """
    if isinstance(records, Record | CriticismData | Walk):
        records = [records]
    if isinstance(records, str | bytes) or not hasattr(records, "__iter__"):
        raise UsageError(
            "a walker's walks must be a list of records, prepared records or Walk objects; "
            f"got {type(records).__name__}"
        )
    out = []
    for item in records:
        if isinstance(item, Walk):
            out.append(item)
        elif isinstance(item, CriticismData):
            out.append(Walk(item))
        elif isinstance(item, Record):
            kwargs: dict[str, Any] = {"pacing_hz": pacing_hz}
            if highpass_hz is not None:
                kwargs["highpass_hz"] = highpass_hz
            data = prepare(item, **kwargs)
            foot, share = first_foot(item, data)
            out.append(Walk(data, foot, share))
        else:
            raise UsageError(
                "a walker's walks must be records, prepared records or Walk objects; got "
                f"{type(item).__name__}"
            )
    if not out:
        raise UsageError("a walker's criticism needs at least one walk; give one or more records")
    for i, w in enumerate(out):
        if w.data.n_steps < MIN_WALK_STEPS:
            raise UsageError(
                f"walk {i + 1} ({w.source}) keeps {w.data.n_steps} whole steps; a walk needs "
                f"at least {MIN_WALK_STEPS} to be criticised: leave it out"
            )
    return tuple(out)


@dataclass(frozen=True, eq=False)
class _Layout:
    """The walks' samples laid end to end: what the scores count over."""

    step: NDArray[np.int64]
    n_steps: int
    step_fraction: FloatArray
    walk_of_step: NDArray[np.int64]


@dataclass(eq=False)
class _Pool:
    """The engine over the walks, and what the walk-held-out score and coefficients need."""

    cv: _CV
    layout: _Layout
    untestable: list[str]
    #: Global column indices that belong to one walk only (its baseline, per-walk effects).
    own: list[NDArray[np.intp]]
    #: Sharing of each effect: "shared", "aligned by the foot channels" or "per walk".
    sharing: dict[str, str]
    #: The effects' columns before the step-variation map and their global indices, per walk
    #: (for their force).
    raw: list[dict[str, tuple[FloatArray, NDArray[np.intp]]]]


def _pool(
    walks: Sequence[Walk],
    effects: Sequence[Effect],
    harmonics: int,
    folds: int,
    step_variation: bool,
    response_modulation: bool,
    follow_pace: bool,
    surface_response: bool = True,
) -> _Pool:
    built = [
        record_blocks(w.data, effects, harmonics, step_variation, response_modulation, follow_pace)
        for w in walks
    ]
    for walk, (b, _, _) in zip(walks, built, strict=True):
        if surface_response and walk.data.surface_coupled and walk.data.ground is not None:
            # The walk's own response to the surface (module docstring, "Surfaces").
            b["baseline"] = np.column_stack([b["baseline"], *walk.data.ground])
    feet_known = all(w.first_foot is not None for w in walks)
    sharing: dict[str, str] = {}
    for e in effects:
        if not e.swaps_with_feet:
            sharing[e.name] = "shared"
        elif feet_known:
            sharing[e.name] = "aligned by the foot channels"
        else:
            sharing[e.name] = "per walk"
    names = [e.name for e in effects]
    untestable = [n for n in names if not any(n in b for b, _, _ in built)]
    # Global column layout: every walk's baseline, then each testable effect's columns
    # (shared: the widest walk's; per walk: every walk's in turn).
    widths: dict[str, int] = {"baseline": sum(b["baseline"].shape[1] for b, _, _ in built)}
    for n in names:
        if n in untestable:
            continue
        counts = [b[n].shape[1] for b, _, _ in built if n in b]
        widths[n] = sum(counts) if sharing[n] == "per walk" else max(counts)
    starts: dict[str, int] = {}
    at = 0
    for k, w in widths.items():
        starts[k] = at
        at += w
    pieces: list[_Piece] = []
    own: list[NDArray[np.intp]] = []
    raw: list[dict[str, tuple[FloatArray, NDArray[np.intp]]]] = []
    targets, steps, fractions, blocks, walk_of_step = [], [], [], [], []
    row = step0 = block0 = 0
    offset = {k: starts[k] for k in widths}  # next free column of per-walk blocks
    for i, (walk, (b, jitter, _)) in enumerate(zip(walks, built, strict=True)):
        data = walk.data
        sign = -1.0 if (feet_known and walk.first_foot == "right") else 1.0
        local = [b["baseline"]]
        columns = [np.arange(offset["baseline"], offset["baseline"] + b["baseline"].shape[1])]
        offset["baseline"] += b["baseline"].shape[1]
        mine = [columns[0]]
        raw.append({})
        for n in widths:
            if n == "baseline" or n not in b:
                continue
            cols = b[n]
            if sharing[n] == "aligned by the foot channels":
                cols = sign * cols
            if sharing[n] == "per walk":
                idx = np.arange(offset[n], offset[n] + cols.shape[1])
                offset[n] += cols.shape[1]
                mine.append(idx)
            else:
                idx = np.arange(starts[n], starts[n] + cols.shape[1])
            raw[i][n] = (cols, idx)
            local.append(cols)
            columns.append(idx)
        x = np.column_stack([*local, data.target_n])
        if jitter is not None:
            x = jitter(x)
        n_rows = x.shape[0]
        pieces.append(_Piece(slice(row, row + n_rows), np.concatenate(columns), x[:, :-1]))
        own.append(np.concatenate(mine))
        targets.append(x[:, -1])
        steps.append(data.step + step0)
        fractions.append(data.step_fraction)
        blk, n_blk = step_blocks(data.step, data.n_steps)
        blocks.append(blk + block0)
        walk_of_step.append(np.full(data.n_steps, i))
        row += n_rows
        step0 += data.n_steps
        block0 += n_blk
    layout = _Layout(
        np.concatenate(steps),
        step0,
        np.concatenate(fractions),
        np.concatenate(walk_of_step),
    )
    cv = _CV(layout, widths, pieces, np.concatenate(targets), np.concatenate(blocks), block0, folds)
    return _Pool(cv, layout, untestable, own, sharing, raw)


def _walk_heldout_step_sse(pool: _Pool, groups: Sequence[str]) -> FloatArray | None:
    """Held-out squared error per step with whole walks held out (module docstring).

    For each walk the shared coefficients come from a fit to the other walks; the walk's
    own columns are fitted in the step-blocked folds inside it. None with one walk.
    """
    cv = pool.cv
    if len(cv.pieces) < 2:
        return None
    idx = cv.columns(groups)
    in_model = np.zeros(cv.n_columns, dtype=bool)
    in_model[idx] = True
    sse = np.zeros(cv.data.n_steps)
    for i, p in enumerate(cv.pieces):
        mine = np.zeros(cv.n_columns, dtype=bool)
        mine[pool.own[i]] = True
        other = np.flatnonzero(in_model & ~mine)
        g = cv.gram_all.copy()
        b = cv.xty_all.copy()
        g[np.ix_(p.columns, p.columns)] -= cv.piece_gram[i]
        b[p.columns] -= cv.piece_xty[i]
        beta = np.zeros(cv.n_columns)
        beta[other] = cv._solve(g[np.ix_(other, other)], b[other])
        y = cv.y[p.rows] - p.x @ beta[p.columns]
        keep = in_model[p.columns] & mine[p.columns]
        xo = p.x[:, keep]
        fold = cv.fold_of[p.rows]
        resid = np.empty_like(y)
        for f in np.unique(fold):
            test = fold == f
            gt = xo[~test].T @ xo[~test]
            coef = cv._solve(gt, xo[~test].T @ y[~test])
            resid[test] = y[test] - xo[test] @ coef
        step = cv.data.step[p.rows]
        sse += np.bincount(step, weights=resid**2, minlength=cv.data.n_steps)
    return sse


def walk_clustered_gain(
    sse_base: FloatArray, sse_extended: FloatArray, walk_of_step: NDArray[np.int64]
) -> tuple[float, float]:
    """Fraction of whole-walk held-out squared error removed, with walks as clusters.

    With whole walks held out, every step of a walk shares the error of the coefficients
    fitted on the other walks, so the unit of evidence is the walk: the ratio
    ``sum(base - extended) / sum(base)`` with the cluster-robust (linearised) standard error
    over the walks, ``W / (W - 1)`` small-sample factor.
    """
    diff = np.bincount(walk_of_step, weights=sse_base - sse_extended)
    base = np.bincount(walk_of_step, weights=sse_base)
    total = max(float(base.sum()), 1e-300)
    gain = float(diff.sum()) / total
    n = diff.size
    resid = diff - gain * base
    var = n / max(n - 1, 1) * float(resid @ resid) / total**2
    return gain, float(np.sqrt(var))


def _coefficients(pool: _Pool, groups: Sequence[str], name: str) -> EffectCoefficients:
    """Return an added effect's walker-level coefficients and force, cluster-robust errors."""
    cv = pool.cv
    idx = cv.columns(groups)
    g = cv.gram_all[np.ix_(idx, idx)]
    ridge = 1e-8 * np.trace(g) / g.shape[0]
    bread = np.linalg.inv(g + ridge * np.eye(g.shape[0]))
    beta = np.zeros(cv.n_columns)
    beta[idx] = bread @ cv.xty_all[idx]
    resid = cv.y - cv.predict(beta)
    pos = np.full(cv.n_columns, -1)
    pos[idx] = np.arange(idx.size)
    # Scores summed over each block of steps (the clusters).
    meat_rows = np.zeros((cv.n_blocks, idx.size))
    for p in cv.pieces:
        sel = pos[p.columns] >= 0
        contrib = p.x[:, sel] * resid[p.rows, None]
        blk = cv.block_of[p.rows]
        by_block = np.zeros((cv.n_blocks, int(sel.sum())))
        np.add.at(by_block, blk, contrib)
        meat_rows[:, pos[p.columns[sel]]] += by_block
    n_b = cv.n_blocks
    meat = meat_rows.T @ meat_rows * (n_b / max(n_b - 1, 1))
    cov = bread @ meat @ bread
    cov = 0.5 * (cov + cov.T)
    mine = cv.slices[name]
    at = pos[mine]
    coef_all = beta / cv.scale
    cov_e = cov[np.ix_(at, at)] / np.outer(cv.scale[mine], cv.scale[mine])
    # The effect's force on the walks, before the step-variation map [N RMS].
    per_walk = pool.sharing[name] == "per walk"
    walk_of_coefficient: list[int | None] = [None] * mine.size
    sums: list[float] = []
    counts: list[int] = []
    grads = np.zeros(mine.size)
    for i, cols in enumerate(pool.raw):
        if name not in cols:
            continue
        c, where = cols[name]
        f = c @ coef_all[where]
        sums.append(float(f @ f))
        counts.append(f.size)
        grads[where - mine[0]] += c.T @ f
        if per_walk:
            for k in where - mine[0]:
                walk_of_coefficient[int(k)] = i
    total, n = float(np.sum(sums)), max(int(np.sum(counts)), 1)
    rms = float(np.sqrt(total / n))
    ses = np.sqrt(np.clip(np.diag(cov_e), 0.0, None))
    if per_walk:
        # A walk's own coefficients are fitted on its few blocks of steps beside its own
        # baseline: too few clusters for a cluster-robust error, which then comes out too
        # small. The force's error is the jackknife over the walks instead, and the
        # coefficients get none.
        ses = np.full(mine.size, np.nan)
        rms_se = _jackknife_rms(np.asarray(sums), np.asarray(counts, dtype=np.float64))
    else:
        grad = grads / max(n * rms, 1e-300)
        rms_se = float(np.sqrt(max(grad @ cov_e @ grad, 0.0)))
    return EffectCoefficients(
        effect=name,
        sharing=pool.sharing[name],
        coefficients=tuple(float(v) for v in coef_all[mine]),
        standard_errors=tuple(float(v) for v in ses),
        force_rms_n=rms,
        force_rms_se_n=rms_se,
        walk_of_coefficient=tuple(walk_of_coefficient),
    )


def _jackknife_rms(sums: FloatArray, counts: FloatArray) -> float:
    """Jackknife standard error over walks of ``sqrt(sum(sums) / sum(counts))`` (NaN below 3)."""
    w = sums.size
    if w < 3:
        return float("nan")
    leave = np.sqrt((sums.sum() - sums) / (counts.sum() - counts))
    return float(np.sqrt((w - 1) / w * np.sum((leave - leave.mean()) ** 2)))


def _check_settings(harmonics: int | None, folds: int, where: str) -> None:
    """Refuse harmonics and folds the engine cannot use, in one sentence."""
    if harmonics is not None and (
        isinstance(harmonics, bool) or not isinstance(harmonics, int | np.integer) or harmonics < 1
    ):
        raise UsageError(
            f"{where}: harmonics must be a whole number of at least 1, got {harmonics!r}",
            parameter="harmonics",
        )
    if isinstance(folds, bool) or not isinstance(folds, int | np.integer) or folds < 3:
        raise UsageError(
            f"{where}: folds must be a whole number of at least 3, got {folds!r}",
            parameter="folds",
        )


def _walks_in_frame(
    walks: Sequence[Walk], model: SMDModel | None, surface: str | None, where: str
) -> tuple[Walk, ...]:
    return tuple(
        dataclasses.replace(w, data=_surface_frame(w.data, model, surface, where)) for w in walks
    )


def _candidates(
    walks: Sequence[Walk], candidates: EffectsLike, current: Sequence[str], where: str
) -> list[Effect]:
    chosen = [e for e in candidate_effects(candidates) if e.name not in current]
    coupled = any(w.data.surface_coupled for w in walks)
    if coupled and "base_motion" in [*current, *(e.name for e in chosen)]:
        if candidates is not None or "base_motion" in current:
            raise UsageError(
                f"{where}: the model already lets the surface act through K and C, so "
                "'base_motion' would count it twice; leave base_motion out, or criticise the "
                "rigid-floor model (surface='rigid', --rigid-floor) to test the surface as the "
                "missing effect",
                parameter="effects",
            )
        chosen = [e for e in chosen if e.name != "base_motion"]
    return chosen


def _on_walks(text: str) -> str:
    """Say "the walker's walks" where the single record's wording says "this record"."""
    for single, pooled in (
        ("on this record", "on these walks"),
        ("On this record", "On these walks"),
        ("this record could", "these walks could"),
        ("the record cannot show", "the walks cannot show"),
        ("what the record shows", "what the walks show"),
    ):
        text = text.replace(single, pooled)
    return text


def diagnose_walker(
    walks: Sequence[Record | CriticismData | Walk],
    model: SMDModel | None = None,
    *,
    effects: EffectsLike = None,
    candidates: EffectsLike = None,
    harmonics: int | None = None,
    folds: int = DEFAULT_FOLDS,
    step_variation: bool = True,
    response_modulation: bool = True,
    surface: str | None = None,
    follow_pace: bool = True,
    start_stop: bool = True,
    surface_response: bool = True,
) -> WalkerDiagnosis:
    """Rank candidate effects by the held-out error they remove over a walker's walks.

    Each walk keeps its own baseline; a candidate adds coefficients shared by the walks
    (module docstring). The test, the stepwise selection and the verdict are those of
    :func:`~workbench.diagnostics.criticism.diagnose`, over all the walks' steps.

    Parameters
    ----------
    walks : sequence of Record, CriticismData or Walk
        The walker's walks (:func:`prepare_walks`).
    model, effects, candidates, harmonics, folds, step_variation, response_modulation, \
surface, follow_pace
        As in :func:`~workbench.diagnostics.criticism.diagnose`.
    start_stop : bool, default True
        Leave the first and last steps of each walk out (:func:`start_stop_steps`; module
        docstring, "Starts and stops"); False keeps every step.
    surface_response : bool, default True
        With the surface coupled, give each walk's baseline the measured surface motion
        (module docstring, "Surfaces"); False leaves it out, kept to measure what it
        changes.

    Returns
    -------
    WalkerDiagnosis
    """
    _check_settings(harmonics, folds, "diagnose")
    walks = _walks_in_frame(_steady(prepare_walks(walks), start_stop), model, surface, "diagnose")
    current_effects, harmonics = _resolve(model, effects, harmonics, "diagnose")
    current = [e.name for e in current_effects]
    cand_effects = _candidates(walks, candidates, current, "diagnose")
    pool = _pool(
        walks,
        [*current_effects, *cand_effects],
        harmonics,
        folds,
        step_variation,
        response_modulation,
        follow_pace,
        surface_response,
    )
    cv = pool.cv
    base_row = _row(cv, current, "baseline", None)
    resid = cv.y - cv.heldout_prediction(current)
    per_walk_resid = [resid[p.rows] for p in cv.pieces]

    def statistic(effect: Effect) -> tuple[float, str] | None:
        values = []
        for w, r, cols in zip(walks, per_walk_resid, pool.raw, strict=True):
            if effect.name not in cols:
                continue  # the walk cannot test it
            stat = effect.statistic(w.data, r)
            if stat is not None:
                values.append(stat)
        if not values:
            return None
        values.sort(key=lambda v: v[0])
        value, text = values[len(values) // 2]
        return value, f"in the median walk, {text}"

    results, verdict = _rank(
        cv,
        current,
        cand_effects,
        pool.untestable,
        statistic,
        f"over {cv.data.n_steps} steps of {len(walks)} walks",
        base_row,
    )
    walk_base = _walk_heldout_step_sse(pool, current)
    walk_scores: dict[str, tuple[float, float]] = {}
    for c in results:
        c.evidence = _on_walks(c.evidence)
        if walk_base is not None and c.testable:
            ext = _walk_heldout_step_sse(pool, [*current, c.effect])
            assert ext is not None
            walk_scores[c.effect] = walk_clustered_gain(walk_base, ext, pool.layout.walk_of_step)
    feet_known = all(w.first_foot is not None for w in walks)
    baseline: dict[str, Any] = {
        "model": "baseline per walk" + "".join(f" + {e}" for e in current),
        "effects": current,
        "walks": len(walks),
        "heldout_rmse_n": base_row.heldout_rmse_n,
        "fit_percent": base_row.fit_percent,
        "ljung_box_p": base_row.ljung_box_p,
        "score": base_row.score,
        "harmonics": int(min(harmonics, min(math.floor(_max_order(w.data)) for w in walks))),
        "folds": cv.n_folds,
        "steps": cv.data.n_steps,
        "walk_heldout_rmse_n": None
        if walk_base is None
        else float(np.sqrt(walk_base.sum() / cv.y.size)),
        "asymmetry_labelling": "foot channels" if feet_known else "sign-free (per walk)",
        "step_variation": bool(step_variation),
        "response_modulation": bool(response_modulation),
        "follow_pace": bool(follow_pace),
        "start_stop": bool(start_stop),
        "surface_response": bool(surface_response),
        "per_walk": [
            {
                "source": w.source,
                "steps": w.data.n_steps,
                "pacing_hz": w.data.pacing_hz,
                "duration_s": float(w.data.time_s[-1] - w.data.time_s[0]),
                "heldout_rmse_n": float(np.sqrt(np.mean(r**2))),
                "first_foot": w.first_foot,
                "start_stop_steps_left_out": list(w.start_stop),
                "foot_agreement": w.foot_agreement,
                "surface": _surface_name(w.data),
            }
            for w, r in zip(walks, per_walk_resid, strict=True)
        ],
    }
    return WalkerDiagnosis(
        baseline,
        tuple(c.freeze() for c in results),
        _on_walks(verdict),
        walks,
        resid,
        dict(pool.sharing),
        walk_scores,
        tuple(current),
    )


def compare_walker(
    walks: Sequence[Record | CriticismData | Walk],
    effects: EffectsLike | SMDModel = None,
    *,
    model: SMDModel | None = None,
    harmonics: int | None = None,
    folds: int = DEFAULT_FOLDS,
    step_variation: bool = True,
    response_modulation: bool = True,
    surface: str | None = None,
    follow_pace: bool = True,
    start_stop: bool = True,
    surface_response: bool = True,
) -> WalkerComparison:
    """Scoreboard over a walker's walks: the baseline, then each effect added in turn.

    Each row has the step-held-out error over all the walks' steps and the error on whole
    walks held out (module docstring); each effect added has its walker-level coefficients
    and force with their standard errors.

    Parameters
    ----------
    walks : sequence of Record, CriticismData or Walk
    effects, model, harmonics, folds, step_variation, response_modulation, surface, \
follow_pace
        As in :func:`~workbench.diagnostics.criticism.compare`.
    start_stop, surface_response : bool, default True
        As in :func:`diagnose_walker`.

    Returns
    -------
    WalkerComparison
    """
    _check_settings(harmonics, folds, "compare")
    walks = _steady(prepare_walks(walks), start_stop)
    model, effect_list, harmonics = compared_effects(effects, model, harmonics)
    walks = _walks_in_frame(walks, model, surface, "compare")
    added = list(effect_list)
    names = [e.name for e in added]
    _candidates(walks, names, [], "compare")
    pool = _pool(
        walks,
        added,
        harmonics,
        folds,
        step_variation,
        response_modulation,
        follow_pace,
        surface_response,
    )
    if pool.untestable:
        raise UsageError(
            f"compare: effect '{pool.untestable[0]}' cannot be tested on any of the walks (for "
            "base_motion the records need a ground_acc column); drop it from 'effects'",
            parameter="effects",
        )
    cv = pool.cv
    rows: list[WalkScoreRow] = []
    prev_walk = _walk_heldout_step_sse(pool, [])
    first_row = _row(cv, [], "baseline per walk", None)

    def walk_rmse(sse: FloatArray | None) -> float | None:
        return None if sse is None else float(np.sqrt(sse.sum() / cv.y.size))

    rows.append(WalkScoreRow.from_row(first_row, walk_rmse(prev_walk), None))
    coefficients = []
    for i in range(len(names)):
        prev, _ = cv.fold_sse(names[:i])
        label = "baseline per walk + " + " + ".join(names[: i + 1])
        walk_sse = _walk_heldout_step_sse(pool, names[: i + 1])
        gain = (
            None
            if walk_sse is None or prev_walk is None
            else walk_clustered_gain(prev_walk, walk_sse, pool.layout.walk_of_step)
        )
        rows.append(
            WalkScoreRow.from_row(_row(cv, names[: i + 1], label, prev), walk_rmse(walk_sse), gain)
        )
        prev_walk = walk_sse
        coefficients.append(_coefficients(pool, names[: i + 1], names[i]))
    return WalkerComparison(
        tuple(rows), tuple(w.source for w in walks), tuple(coefficients), dict(pool.sharing)
    )

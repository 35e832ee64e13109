"""Model criticism: held-out prediction of GRF, effect ranking and the scoreboard.

Why this level
--------------
Force coefficients redrawn for every step fit almost anything inside one step, so a misfit
has to be judged where they cannot absorb it. Here the *baseline* predicts the measured GRF
from one force shape shared by all steps (a Fourier series in the step phase, ``n``
harmonics) plus the spring and damper acting on the COM response::

    GRF - M g = a0 + sum_i (a_i cos(i phi) + b_i sin(i phi)) - K u - C u'

which is linear in ``(a, b, K, C)``; ``u`` and ``u'`` come from the preprocessed record
(docs/science.md 2), with their steady lines at odd multiples of ``f_p / 2`` removed (see
:func:`~workbench.diagnostics.criticism_data._without_stride_lines`). The step phase is that
of the pacing component of the COM acceleration
(:func:`~workbench.diagnostics.criticism_data._fundamental_phase`). A candidate effect adds
its *criticism columns* (:meth:`Effect.criticism_columns
<workbench.models.effects.Effect.criticism_columns>`: the columns its term is made of, e.g.
``u^3`` for cubic stiffness). The candidates are the registered effects
(:func:`~workbench.models.effects.register_effect`): the catalogue first, in the order of
:data:`CATALOGUE`, then any other that is linear or gives its criticism columns. A
user-written effect needs no other registration.

Step-to-step variation of the force
-----------------------------------
Real and simulated steps differ a little in size and timing. Each step's own size and timing
of the shared shape (two numbers per step: the coefficients of ``S(phi)`` and ``S'(phi)``,
with ``S`` the baseline's shared force shape) are fitted on that step and taken out of the
target and of every column before scoring (:class:`StepVariation`); their slow part (a
moving average over :data:`SLOW_STEPS` steps) is kept, because a slow change of the force's
size or timing is what the drift candidates look for. Left in the error, the step-to-step
variation masks the small non-periodic signature of the effects that act through ``u`` and
``u'``, and it drives the response, so that ``u^3`` and the drift columns pick up some of it
on records without any effect. The held-out error is then the error beyond each step's own
size and timing: like ``u`` and ``u'``, those two numbers come from the step's own record;
the shape, ``K``, ``C`` and the candidates' coefficients come from the other folds.
``step_variation=False`` in :func:`diagnose` and :func:`compare` scores the raw error
instead. What it changes is measured by ``analyses/hidden_effect.py --sweep 10`` with and
without ``--raw-error`` (README, "Model criticism").

Response modulation (a nuisance block of the baseline)
------------------------------------------------------
The step-to-step variation of a walker's force is not only a change of its size and timing:
every harmonic varies on its own. The response to that variation passes through the body's
frequency response, which one ``K`` and one ``C`` fit only on average, so the baseline leaves
a misfit that follows ``u`` and ``u'`` with a gain that changes over the step. To first order
in the variation, ``u^3 = U^3 + 3 U^2 du + ...`` (``U`` the periodic response, ``du`` the
step's deviation) is exactly such a gain, ``3 U^2(phi)``, and so is ``|u'| u'``. Without
further columns ``u^3`` was called significant on 5 of 10 simulated records *without any
effect* whose force amplitudes varied 15 % from step to step (2-6 %: 0 of 10), and on 4 of
10 whose step durations varied 5 % (``analyses/hidden_effect.py --sweep 10
--no-modulation``). The baseline therefore also carries ``u`` and ``u'`` times the
step-phase harmonics of orders :data:`RESPONSE_MODULATION_ORDERS` (a stiffness and damping
that vary with the gait phase), and candidates are judged beyond them (with them: 0 of 10
in each case). A nonlinear spring or damper then shows only through its second-order part
(``3 U du^2 + du^3``), which needs large changes of amplitude (gait initiation, a change of
intensity); on steady walking the diagnosis says it cannot be separated
(``separable_fraction``).

Scoring and significance
------------------------
Every model is scored by step-blocked cross-validation: the steps are cut into blocks of
:data:`BLOCK_STEPS`, the blocks are dealt to :data:`DEFAULT_FOLDS` folds in turn, each
fold is predicted from a fit to the others. A candidate's *score* is the fraction of the
baseline's held-out squared error it removes. Residuals of a shared force shape are
correlated within and across neighbouring steps, so samples are not independent evidence;
the unit of evidence is the step, and the score's standard error is a long-run
(Bartlett-weighted) one of the paired step-by-step differences of held-out squared error
(:meth:`_CV.gain`), which gives each candidate a one-sided p-value. One diagnosis tests
the whole catalogue, so significance controls the *family-wise* false-alarm rate:
Holm's step-down test over the candidates at :data:`FAMILY_ALPHA` (:func:`_holm`), and a
candidate it calls must also remove :data:`SIGNIFICANCE_MIN_DROP` of the error. The
level was calibrated on simulated records without an effect of every kind (steady,
overground, speed change, deck; docs/validation/criticism.md, "Family-wise control").
A testable candidate that is not called carries the smallest score the record could have
called (``detectable_score``): not found is not absent.

A walk that changes pace
------------------------
When the slow pacing varies by more than
:data:`~workbench.models.effects.PACING_CHANGE_MIN`, every harmonic of the shared shape,
and its timing, may follow it: these columns join the baseline
(:func:`~workbench.diagnostics.criticism_engine._pace_columns`). A walker who walks
faster pushes harder, and each harmonic then passes through the body at another
frequency; that is ordinary gait, not a missing effect.

Candidates are then selected stepwise (:func:`_forward_selection`): at each stage Holm's
test runs over the candidates still outside the model, and the one with the largest gain
among those it calls joins it, so a second effect
masked by a dominant one is still found. A candidate significant on its own that adds
nothing to the selected ones is *explained by* them. Two that explain the same error --
neither adds to a model with the other, or one's columns lie, on this record, within the
other's (:func:`_nested`: a stiffness drift's ``t u`` inside a pacing drift's ``t`` times
the force harmonics) -- both stay significant and name each other in
``indistinguishable_from``. Each candidate also reports the share of its columns' variation
that lies outside the baseline's span (``separable_fraction``); below
:data:`SEPARABLE_MIN` the record cannot show the effect at all, and the diagnosis says so
instead of calling it absent (effects acting through ``u`` or ``u'`` on nearly periodic
walking).

Modules
-------
This module holds the ranking (:func:`diagnose`, :func:`compare`) and re-exports the rest:
:mod:`~workbench.diagnostics.criticism_data` (:func:`prepare`, :class:`CriticismData`, the
baseline's columns), :mod:`~workbench.diagnostics.criticism_engine` (the step variation map
and the cross-validation engine) and :mod:`~workbench.diagnostics.criticism_results`
(:class:`Diagnosis`, :class:`Comparison`, :class:`Candidate`, :class:`ScoreRow`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from workbench.diagnostics.criticism_data import (
    DEFAULT_HARMONICS,
    SLOW_STEPS,
    CriticismData,
    _centred_time,
    _max_order,
    baseline_columns,
    prepare,
    slow_pacing_change,
)
from workbench.diagnostics.criticism_data import (
    _moving_average as _moving_average,
)
from workbench.diagnostics.criticism_engine import (
    _CV,
    BLOCK_STEPS,
    DEFAULT_FOLDS,
    RESPONSE_MODULATION_ORDERS,
    StepVariation,
    _build_cv,
    _row,
    ljung_box_p,
)
from workbench.diagnostics.criticism_engine import (
    _RIDGE as _RIDGE,
)
from workbench.diagnostics.criticism_results import Candidate, Comparison, Diagnosis, ScoreRow
from workbench.errors import UsageError
from workbench.models.effects import (
    CATALOGUE,
    PACING_CHANGE_MIN,
    Effect,
    Effects,
    available_effects,
    effect_class,
    split_effect_specs,
)
from workbench.models.smd import SURFACE_MODELS, SMDModel
from workbench.records.record import Record
from workbench.wording import p_value as p_text

__all__ = [
    "BLOCK_STEPS",
    "CATALOGUE",
    "DEFAULT_FOLDS",
    "DEFAULT_HARMONICS",
    "FAMILY_ALPHA",
    "PACING_CHANGE_MIN",
    "RESPONSE_MODULATION_ORDERS",
    "SIGNIFICANCE_MIN_DROP",
    "SLOW_STEPS",
    "Candidate",
    "Comparison",
    "CriticismData",
    "Diagnosis",
    "ScoreRow",
    "StepVariation",
    "baseline_columns",
    "candidate_effects",
    "compare",
    "diagnose",
    "error_by_gait_phase",
    "error_by_step",
    "ljung_box_p",
    "prepare",
    "residual_spectrum",
    "slow_pacing_change",
    "state_features",
]

FloatArray = NDArray[np.float64]

#: Family-wise false-alarm rate of one diagnosis: Holm's step-down test over the candidates
#: (module docstring, "Scoring and significance"; the rate it gives is measured in
#: docs/validation/criticism.md).
FAMILY_ALPHA = 0.05
#: A candidate Holm's test calls must also remove this fraction of the baseline's held-out
#: squared error.
SIGNIFICANCE_MIN_DROP = 0.01
#: Below this share of variation outside the baseline's span, a candidate that is not
#: significant is reported as "cannot be separated on this record" rather than absent.
SEPARABLE_MIN = 0.05

#: What names, specs, effects or a model holding them may be given as.
EffectsLike = str | Effect | Effects | SMDModel | Iterable[str | Effect] | None


def candidate_effects(specs: EffectsLike = None) -> tuple[Effect, ...]:
    """Effects model criticism can test, from specs, effects or a model; default all.

    Parameters
    ----------
    specs : str, Effect, Effects, SMDModel, iterable of str or Effect, or None
        Effect specs (``"NAME[:P=V...],..."``, read by
        :meth:`~workbench.models.effects.Effect.from_spec`), effects, or a model whose
        effects are taken. None gives every registered effect that criticism can test: the
        catalogue in the order of :data:`CATALOGUE`, then the others by name.

    Returns
    -------
    tuple of Effect
        In order, each name once (a repeated name is dropped).
    """
    if specs is None:
        names = [*CATALOGUE, *(n for n in available_effects() if n not in CATALOGUE)]
        classes = [effect_class(n) for n in names if n in available_effects()]
        return tuple(c() for c in classes if c.is_criticism_candidate())
    if isinstance(specs, SMDModel):
        specs = specs.effects
    items: list[str | Effect] = []
    for item in [specs] if isinstance(specs, str | Effect) else specs:
        if isinstance(item, str):
            items += split_effect_specs(item)
        else:
            items.append(item)
    out: dict[str, Effect] = {}
    for item in items:
        effect = item if isinstance(item, Effect) else Effect.from_spec(item)
        if not effect.is_criticism_candidate():
            raise UsageError(
                f"effect '{effect.name}' cannot be criticised: it is nonlinear in its "
                "parameters and gives no criticism columns; override criticism_columns(data) "
                "in its class or leave it out"
            )
        out.setdefault(effect.name, effect)
    return tuple(out.values())


def _resolve(
    model: SMDModel | None, effects: EffectsLike, harmonics: int | None, where: str
) -> tuple[tuple[Effect, ...], int]:
    """Return the current effects and the baseline's harmonics from a model or arguments."""
    if model is None:
        default = DEFAULT_HARMONICS if harmonics is None else harmonics
        return candidate_effects(effects or ()), default
    if not isinstance(model, SMDModel):
        raise UsageError(
            f"{where}: model must be an SMDModel, got {type(model).__name__}; pass effects as "
            "effects=[...]"
        )
    if effects:
        raise UsageError(
            f"{where}: the current effects are given twice (in the model and as effects); add "
            "them to the model or pass effects alone"
        )
    return candidate_effects(model), model.harmonics if harmonics is None else harmonics


def _surface_frame(
    data: CriticismData, model: SMDModel | None, surface: str | None, where: str
) -> CriticismData:
    """Return the record in the frame of the model's surface (docs/science.md 6).

    The surface model is ``surface``, else the model's, else the default ``"coupled"`` (as
    in :func:`~workbench.inference.pipeline.identification.identify`). Coupled or joint, with
    measured ground
    motion, the spring and damper act on the motion relative to the surface; ``"rigid"``
    keeps the absolute motion, and ``base_motion`` is then the candidate that stands for the
    surface the model left out.
    """
    chosen = surface if surface is not None else (model.surface if model else "coupled")
    if chosen not in SURFACE_MODELS:
        raise UsageError(
            f"{where}: surface must be one of {', '.join(SURFACE_MODELS)}, got {chosen!r}",
            parameter="surface",
        )
    if model is not None and surface is not None and surface != model.surface:
        raise UsageError(
            f"{where}: surface={surface!r} contradicts the model's surface "
            f"{model.surface!r}; give it in one place",
            parameter="surface",
        )
    return data if chosen == "rigid" else data.coupled_to_surface()


def _surface_name(data: CriticismData) -> str:
    """How the baseline saw the surface: coupled, rigid (ignored) or none measured."""
    if data.ground is None:
        return "none measured"
    return "coupled" if data.surface_coupled else "ignored (rigid floor)"


def _refuse_base_motion_on_a_coupled_surface(
    data: CriticismData, names: Iterable[str], where: str
) -> None:
    if data.surface_coupled and "base_motion" in names:
        raise UsageError(
            f"{where}: the model already lets the surface act through K and C, so "
            "'base_motion' would count it twice; leave base_motion out, or criticise the "
            "rigid-floor model (surface='rigid', --rigid-floor) to test the surface as the "
            "missing effect",
            parameter="effects",
        )


@dataclass
class _Draft:
    """A candidate's result while the stepwise selection settles it (then frozen)."""

    effect: str
    score: float
    significant: bool
    evidence: str
    expected_error_drop: float
    indistinguishable_from: list[str] = field(default_factory=list)
    score_se: float = 0.0
    t_ratio: float = 0.0
    statistic: float = 0.0
    testable: bool = True
    separable_fraction: float = 1.0
    p_value: float = 1.0
    detectable_score: float = 0.0

    def freeze(self) -> Candidate:
        fields = dataclasses.asdict(self)
        fields["indistinguishable_from"] = tuple(self.indistinguishable_from)
        return Candidate(**fields)


def diagnose(
    data: CriticismData | Record,
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
) -> Diagnosis:
    """Rank candidate effects by the held-out GRF error they remove.

    Parameters
    ----------
    data : CriticismData or Record
        The record (prepared with :func:`prepare` when a ``Record`` is given).
    model : SMDModel, optional
        The current model: its effects join the baseline and its ``harmonics`` are those of
        the shared force shape (unless ``harmonics`` is given). Give it or ``effects``.
    effects : str, Effect, Effects or iterable of str or Effect, optional
        Effects already in the current model (their columns join the baseline); names or
        specs as in :func:`candidate_effects`.
    candidates : str, Effect, Effects or iterable of str or Effect, optional
        Effects to test; default every registered effect criticism can test
        (:func:`candidate_effects`) that is not in the current model.
    harmonics : int, optional
        Harmonics of the shared force shape; default the model's, else
        :data:`DEFAULT_HARMONICS`.
    folds : int, optional
        Folds of the step-blocked cross-validation.
    step_variation : bool, default True
        Take each step's own size and timing jitter out of the error before scoring
        (:class:`StepVariation`, module docstring); False scores the raw error.
    response_modulation : bool, default True
        Judge candidates beyond a ``K`` and ``C`` that may vary with the gait phase (module
        docstring, "Response modulation"); False is the plain ``K u + C u'``, kept to
        measure what the block changes.
    surface : {"coupled", "joint", "rigid"}, optional
        How a measured surface motion enters the baseline; default the model's, else
        ``"coupled"``. Coupled (or joint), ``K`` and ``C`` act on the motion relative to the
        surface and ``base_motion`` is not a candidate (it is in the model); ``"rigid"``
        ignores the surface, and ``base_motion`` is the candidate that finds it.
    follow_pace : bool, default True
        On a walk that changes pace, let each harmonic of the shared shape follow the slow
        pacing in the baseline (module docstring, "A walk that changes pace"); False leaves
        that block out, kept to measure what it changes.

    Returns
    -------
    Diagnosis
        ``residual_n`` is the held-out error (beyond each step's own size and timing when
        ``step_variation``), ``prediction_n`` the measured ``GRF - M g`` minus it.
    """
    if isinstance(data, Record):
        data = prepare(data)
    current_effects, harmonics = _resolve(model, effects, harmonics, "diagnose")
    data = _surface_frame(data, model, surface, "diagnose")
    current = [e.name for e in current_effects]
    _refuse_base_motion_on_a_coupled_surface(data, current, "diagnose")
    cand_effects = [e for e in candidate_effects(candidates) if e.name not in current]
    if data.surface_coupled:
        if candidates is not None:
            _refuse_base_motion_on_a_coupled_surface(
                data, [e.name for e in cand_effects], "diagnose"
            )
        cand_effects = [e for e in cand_effects if e.name != "base_motion"]
    cv, untestable = _build_cv(
        data,
        [*current_effects, *cand_effects],
        harmonics,
        folds,
        step_variation,
        response_modulation,
        follow_pace,
    )
    base_row = _row(cv, current, "baseline", None)
    resid = cv.y - cv.heldout_prediction(current)
    base_pred = data.target_n - resid

    results, verdict = _rank(
        cv,
        current,
        cand_effects,
        untestable,
        lambda effect: effect.statistic(data, resid),
        f"over {data.n_steps} steps",
        base_row,
    )
    baseline = {
        "model": "baseline" + "".join(f" + {e}" for e in current),
        "effects": current,
        "heldout_rmse_n": base_row.heldout_rmse_n,
        "fit_percent": base_row.fit_percent,
        "ljung_box_p": base_row.ljung_box_p,
        "score": base_row.score,
        "harmonics": int(min(harmonics, math.floor(_max_order(data)))),
        "folds": cv.n_folds,
        "steps": data.n_steps,
        "pacing_hz": data.pacing_hz,
        "split": data.split,
        "grf_rms_n": float(np.std(data.target_n)),
        "step_variation": bool(step_variation),
        "response_modulation": bool(response_modulation),
        "follow_pace": bool(follow_pace),
        "surface": _surface_name(data),
    }
    candidates_out = tuple(c.freeze() for c in results)
    return Diagnosis(baseline, candidates_out, verdict, data, resid, base_pred, tuple(current))


def _rank(
    cv: _CV,
    current: Sequence[str],
    cand_effects: Sequence[Effect],
    untestable: Sequence[str],
    statistic: Callable[[Effect], tuple[float, str] | None],
    where: str,
    base_row: ScoreRow,
) -> tuple[list[_Draft], str]:
    """Test the candidates, select them stepwise and give the verdict (module docstring).

    Parameters
    ----------
    cv : _CV
        The engine on the baseline, the current effects and the candidates.
    current : sequence of str
        Effects already in the model.
    cand_effects : sequence of Effect
        The candidates, in the catalogue's order.
    untestable : sequence of str
        Candidates the record (or walks) cannot test.
    statistic : callable
        An effect's revealing statistic on the baseline's held-out error, as
        :meth:`Effect.statistic`.
    where : str
        What the evidence is counted over, e.g. "over 25 steps".
    base_row : ScoreRow
        The baseline's scores.

    Returns
    -------
    (list of _Draft, str)
        The candidates in their reading order and the verdict.
    """
    by_name = {e.name: e for e in cand_effects}
    cands = [e.name for e in cand_effects]
    results: list[_Draft] = []
    gains: dict[str, tuple[float, float, float]] = {}
    for name in cands:
        if name not in untestable:
            gains[name] = cv.gain(current, [*current, name])
    called = _holm(gains, cv.dof)
    for name in cands:
        effect = by_name[name]
        stat = statistic(effect)
        stat_value, stat_text = (0.0, "") if stat is None else stat
        if name in untestable:
            results.append(
                _Draft(
                    name,
                    0.0,
                    False,
                    f"not testable on this record: {stat_text or 'it lacks what the columns need'}",
                    0.0,
                    testable=False,
                    p_value=1.0,
                )
            )
            continue
        pooled, se, t = gains[name]
        significant = name in called
        drop = 1.0 - math.sqrt(max(1.0 - pooled, 0.0))
        separable = cv.separable_fraction(name, current)
        if significant:
            head = effect.reason
        elif separable < SEPARABLE_MIN:
            head = (
                f"cannot be separated on this record: only {100 * separable:.1f} % of its "
                "variation lies outside what the shared force shape and a K u + C u' whose "
                "K and C may vary with the gait phase represent, so its error would be "
                "absorbed by them"
            )
        else:
            head = "no significant held-out gain"
        stat_part = f"; {stat_text}" if stat is not None else ""
        p_value = _p_value(t, cv.dof)
        evidence = (
            f"{head}{stat_part}; adding it removes {100 * pooled:.1f} % "
            f"(+- {100 * se:.1f} %) of the held-out squared error (one-sided p "
            f"{p_text(p_value, 2)} {where})"
        )
        results.append(
            _Draft(
                name,
                pooled,
                significant,
                evidence,
                drop,
                [],
                se,
                t,
                stat_value,
                True,
                separable,
                p_value,
            )
        )

    results.sort(key=lambda c: (c.testable, c.score), reverse=True)
    reasons = {name: by_name[name].reason for name in cands}
    _forward_selection(cv, current, results, reasons)
    # Not found is not absent: say how large a gain this record could have called.
    t_needed = float(stats.t.isf(FAMILY_ALPHA / max(len(gains), 1), cv.dof))
    for c in results:
        if c.testable and not c.significant:
            c.detectable_score = max(t_needed * c.score_se, SIGNIFICANCE_MIN_DROP)
            c.evidence += (
                f"; this record could call it only if it removed {100 * c.detectable_score:.1f} "
                "% or more"
            )

    return results, _verdict(results, base_row, reasons)


def _p_value(t: float, dof: int) -> float:
    """One-sided p-value of a paired t ratio (Student t with ``dof`` degrees of freedom)."""
    if not math.isfinite(t):
        return 0.0 if t > 0 else 1.0
    return float(stats.t.sf(t, max(dof, 1)))


def _holm(gains: Mapping[str, tuple[float, float, float]], dof: int) -> set[str]:
    """Candidates Holm's step-down test calls significant at :data:`FAMILY_ALPHA`.

    ``gains`` maps each candidate of the family to its (score, standard error, t ratio)
    from :meth:`_CV.gain`. The smallest p-value is compared with ``alpha / m``, the next
    with ``alpha / (m - 1)`` and so on until one fails; those before it are called when
    they also remove :data:`SIGNIFICANCE_MIN_DROP` of the error.
    """
    order = sorted(gains, key=lambda name: _p_value(gains[name][2], dof))
    called: set[str] = set()
    for i, name in enumerate(order):
        if _p_value(gains[name][2], dof) > FAMILY_ALPHA / (len(order) - i):
            break
        if gains[name][0] > SIGNIFICANCE_MIN_DROP:
            called.add(name)
    return called


def _adds(cv: _CV, base: Sequence[str], extra: str, family: int) -> tuple[bool, float, float]:
    """Whether ``extra`` adds significantly to ``base``, tested as one of ``family``."""
    pooled, se, t = cv.gain(base, [*base, extra])
    level = FAMILY_ALPHA / max(family, 1)
    significant = _p_value(t, cv.dof) <= level and pooled > SIGNIFICANCE_MIN_DROP
    return significant, pooled, se


def _forward_selection(
    cv: _CV, current: Sequence[str], results: list[_Draft], reasons: Mapping[str, str]
) -> None:
    """Stepwise selection of the effects the record supports, and who is explained by whom.

    At each stage every remaining candidate's held-out gain beyond the model so far (the
    baseline, the current effects and the candidates kept) is scored; the best is kept when
    that gain is significant. So a second effect masked by a dominant one is still found
    once the dominant one is in the model. A candidate significant on its own but not kept
    is *explained by* the kept ones -- unless it and a kept one explain the same error
    (neither adds significantly to a model with the other) or one is nested in the other on
    this record (:func:`_nested`: whatever the inner one explains, the outer one does too):
    then the record cannot say which is acting, both are significant and they name each
    other in ``indistinguishable_from``. The list is reordered: kept candidates in the
    order selected, each followed by those it cannot be told apart from, then the others
    by their gain beyond the kept ones.
    """
    testable = [c for c in results if c.testable]
    kept: list[_Draft] = []
    deferred: list[_Draft] = []
    beyond: dict[str, tuple[float, float, float]] = {}
    remaining = list(testable)
    while remaining:
        base = [*current, *(k.effect for k in kept)]
        beyond = {c.effect: cv.gain(base, [*base, c.effect]) for c in remaining}
        # Each stage is a family of its own: the candidates still outside the model.
        stage = _holm(beyond, cv.dof)
        passing = [c for c in remaining if c.effect in stage]
        if not passing:
            break
        best = max(passing, key=lambda c: beyond[c.effect][0])
        pooled, se, _ = beyond[best.effect]
        nest = [
            k
            for k in kept
            if _nested(cv, current, best.effect, k.effect)
            or _nested(cv, current, k.effect, best.effect)
        ]
        if nest:
            # Its gain beyond the kept ones is the side effect a nested pair leaves (module
            # docstring of _nested): not a second effect. It is settled with the twins below.
            remaining.remove(best)
            deferred.append(best)
            continue
        if kept and not best.significant:
            # Masked on its own by the effects kept before it.
            names = ", ".join(k.effect for k in kept)
            _, tail = best.evidence.split("; ", 1)
            best.evidence = (
                f"{reasons[best.effect]} (masked by {names}: beyond them it "
                f"removes {100 * pooled:.1f} % (+- {100 * se:.1f} %) of the held-out squared "
                f"error); {tail}"
            )
        best.significant = True
        kept.append(best)
        remaining.remove(best)

    twins_of: dict[str, list[_Draft]] = {k.effect: [] for k in kept}
    for cand in deferred + remaining:
        if not cand.significant:
            continue
        twins = []
        for k in kept:
            others = [*current, *(x.effect for x in kept if x is not k), cand.effect]
            if (
                _nested(cv, current, cand.effect, k.effect)
                or _nested(cv, current, k.effect, cand.effect)
                or not _adds(cv, others, k.effect, len(testable))[0]
            ):
                twins.append(k)
        if twins:
            for k in twins:
                k.indistinguishable_from.append(cand.effect)
                cand.indistinguishable_from.append(k.effect)
            twins_of[twins[0].effect].append(cand)
            continue
        cand.significant = False
        pooled, se, _ = beyond.get(cand.effect, (0.0, 0.0, 0.0))
        names = ", ".join(k.effect for k in kept)
        cand.evidence = cand.evidence.replace(
            reasons[cand.effect],
            f"explained by {names}: beyond it, it removes only {100 * pooled:.1f} % "
            f"(+- {100 * se:.1f} %) of the held-out squared error",
            1,
        )
    for cand in testable:
        if cand.indistinguishable_from:
            cand.evidence += (
                "; on this record it explains the same held-out error as "
                + ", ".join(cand.indistinguishable_from)
                + " (neither adds significantly to a model with the other, or what the record "
                "shows of the one lies within the other's columns)"
            )
    ordered: list[_Draft] = []
    for k in kept:
        ordered += [k, *twins_of[k.effect]]
    rest = [c for c in testable if c not in ordered]
    rest.sort(key=lambda c: beyond.get(c.effect, (c.score,))[0], reverse=True)
    results[:] = ordered + rest + [c for c in results if not c.testable]


#: A candidate is nested in another on a record when less than this share of its variation
#: outside the baseline's span is also outside the other's (see :func:`_nested`).
NESTED_MAX = 0.1


def _nested(cv: _CV, current: Sequence[str], inner: str, outer: str) -> bool:
    """Whether what the record shows of ``inner`` lies within ``outer``'s columns.

    When ``inner``'s columns' variation outside the baseline's span lies almost wholly
    inside ``outer``'s (less than :data:`NESTED_MAX` of it left), ``outer`` explains whatever
    ``inner`` would, and the extra columns of ``outer`` may be fitting a side effect of
    ``inner`` on the baseline. The record cannot then say which of the two is acting. This
    is the case of a stiffness drift, whose ``t u`` is nearly ``t`` times the response's
    harmonics, inside the pacing drift's ``t`` times the force's harmonics.
    """
    alone = cv.separable_fraction(inner, current)
    return alone > 0 and cv.separable_fraction(inner, [*current, outer]) < NESTED_MAX * alone


def _verdict(results: Sequence[_Draft], base: ScoreRow, reasons: Mapping[str, str]) -> str:
    sig = [c for c in results if c.significant]
    hidden = [c for c in results if c.testable and c.separable_fraction < SEPARABLE_MIN]
    caveat = ""
    if hidden:
        caveat = (
            " "
            + ", ".join(c.effect for c in hidden)
            + " cannot"
            + " be separated from the force shape on this record ("
            + ", ".join(f"{100 * c.separable_fraction:.1f} %" for c in hidden)
            + " of the variation outside it), so the record cannot show whether "
            + ("they are" if len(hidden) > 1 else "it is")
            + " present."
        )
    if not sig:
        seen = [c for c in results if c.testable and c.separable_fraction >= SEPARABLE_MIN]
        reach = ""
        if seen:
            least = min(seen, key=lambda c: c.detectable_score)
            reach = (
                f" On this record an effect had to remove at least "
                f"{100 * least.detectable_score:.1f} % of that error to be called "
                f"({least.effect}; up to {100 * max(c.detectable_score for c in seen):.0f} % "
                "for the others), so a smaller one may be present."
            )
        return (
            f"No candidate effect removes a significant share of the held-out error "
            f"(baseline held-out RMSE {base.heldout_rmse_n:.3g} N, fit {base.fit_percent:.0f} %); "
            "what is left is not structured the way any tested effect would make it "
            "(step-to-step variability of the force, noise)." + reach + caveat
        )
    top = sig[0]
    alike = (
        f" (on this record it cannot be told apart from {', '.join(top.indistinguishable_from)})"
        if top.indistinguishable_from
        else ""
    )
    return (
        f"Add {top.effect}: {reasons[top.effect]}; it is expected to cut the held-out RMSE by "
        f"{100 * top.expected_error_drop:.0f} %{alike}." + caveat
    )


def compared_effects(
    effects: EffectsLike | SMDModel, model: SMDModel | None, harmonics: int | None
) -> tuple[SMDModel | None, tuple[Effect, ...], int]:
    """Return the model, the effects :func:`compare` adds in turn and the harmonics.

    ``effects`` may be the model itself; a model's effects come first, then ``effects``.
    """
    if isinstance(effects, SMDModel):
        if model is not None:
            raise UsageError(
                "compare: two models are given (as effects and as model); pass one model"
            )
        model, effects = effects, None
    if model is not None:
        first, harmonics = _resolve(model, None, harmonics, "compare")
    else:
        first, harmonics = (), DEFAULT_HARMONICS if harmonics is None else harmonics
    added = candidate_effects([*first, *candidate_effects(effects or ())])
    if not added:
        raise UsageError(
            "compare: give at least one effect in 'effects', e.g. gait_asymmetry",
            parameter="effects",
        )
    return model, added, harmonics


def compare(
    data: CriticismData | Record,
    effects: EffectsLike | SMDModel = None,
    *,
    model: SMDModel | None = None,
    harmonics: int | None = None,
    folds: int = DEFAULT_FOLDS,
    step_variation: bool = True,
    response_modulation: bool = True,
    surface: str | None = None,
    follow_pace: bool = True,
) -> Comparison:
    """Scoreboard: the baseline, then the baseline with each effect added in turn.

    Parameters
    ----------
    data : CriticismData or Record
    effects : str, Effect, Effects, SMDModel or iterable of str or Effect
        Effects added cumulatively, in order (names or specs as in
        :func:`candidate_effects`). A model here is the same as ``model=``.
    model : SMDModel, optional
        A model whose effects are added first, in its order, and whose ``harmonics`` are
        those of the shared force shape (unless ``harmonics`` is given); ``effects`` follow.
    harmonics : int, optional
        Harmonics of the shared force shape; default the model's, else
        :data:`DEFAULT_HARMONICS`.
    folds : int, optional
        As in :func:`diagnose`.
    step_variation, response_modulation, follow_pace : bool, default True
        As in :func:`diagnose`.
    surface : {"coupled", "joint", "rigid"}, optional
        As in :func:`diagnose`.

    Returns
    -------
    Comparison
        A sequence of :class:`ScoreRow`, baseline first; ``rmse_drop_fraction`` and
        ``rmse_drop_se`` of each row are relative to the row before it.
    """
    if isinstance(data, Record):
        data = prepare(data)
    model, added, harmonics = compared_effects(effects, model, harmonics)
    data = _surface_frame(data, model, surface, "compare")
    names = [e.name for e in added]
    _refuse_base_motion_on_a_coupled_surface(data, names, "compare")
    cv, untestable = _build_cv(
        data, added, harmonics, folds, step_variation, response_modulation, follow_pace
    )
    if untestable:
        raise UsageError(
            f"compare: effect '{untestable[0]}' cannot be tested on {data.source} (for "
            "base_motion the record needs a ground_acc column); drop it from 'effects'",
            parameter="effects",
        )
    rows = [_row(cv, [], "baseline", None)]
    for i in range(len(names)):
        prev, _ = cv.fold_sse(names[:i])
        label = "baseline + " + " + ".join(names[: i + 1])
        rows.append(_row(cv, names[: i + 1], label, prev))
    return Comparison(tuple(rows), data.source)


# -- locate: where the error lives ----------------------------------------------------------
def error_by_gait_phase(data: CriticismData, residual: FloatArray, bins: int = 20) -> FloatArray:
    """RMS of the error in equal bins of the step, footfall to footfall [N].

    Parameters
    ----------
    data : CriticismData
    residual : ndarray
        Error on the data's samples [N].
    bins : int, optional

    Returns
    -------
    ndarray
        One RMS per bin, the first bin starting at footfall.
    """
    b = np.minimum((data.step_fraction * bins).astype(int), bins - 1)
    ss = np.bincount(b, weights=np.square(residual), minlength=bins)
    n = np.maximum(np.bincount(b, minlength=bins), 1)
    return np.asarray(np.sqrt(ss / n), dtype=np.float64)


def error_by_step(data: CriticismData, residual: FloatArray) -> FloatArray:
    """RMS of the error in each step [N]."""
    ss = np.bincount(data.step, weights=np.square(residual), minlength=data.n_steps)
    n = np.maximum(np.bincount(data.step, minlength=data.n_steps), 1)
    return np.asarray(np.sqrt(ss / n), dtype=np.float64)


def residual_spectrum(data: CriticismData, residual: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Welch power spectral density of the error (8-step Hann segments).

    Returns
    -------
    freq_hz, psd_n2_per_hz : ndarray
    """
    from scipy import signal

    nper = int(min(residual.size, round(8 * data.sample_rate_hz / data.pacing_hz)))
    f, p = signal.welch(residual, fs=data.sample_rate_hz, nperseg=nper)
    return np.asarray(f, dtype=np.float64), np.asarray(p, dtype=np.float64)


def state_features(data: CriticismData) -> dict[str, FloatArray]:
    """Return the state quantities the error is plotted against (docs/science.md 5)."""
    out = {
        "u [m]": data.disp_m,
        "u' [m/s]": data.vel_m_s,
        "u^3 [m^3]": data.disp_m**3,
        "|u'| u' [m^2/s^2]": np.abs(data.vel_m_s) * data.vel_m_s,
        "t u [s m]": _centred_time(data) * data.disp_m,
    }
    if data.ground is not None:
        out["ground acc [m/s^2]"] = data.ground[2]
    return out

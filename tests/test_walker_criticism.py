"""Model criticism over a walker's walks: pooling, whole-walk scores, coefficients, feet."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import statsmodels.api as sm

from workbench.diagnostics.criticism import _RIDGE, diagnose, prepare
from workbench.diagnostics.walker import (
    Walk,
    _pool,
    _steady,
    _walk_heldout_step_sse,
    compare_walker,
    diagnose_walker,
    first_foot,
    prepare_walks,
    start_stop_steps,
    walk_clustered_gain,
)
from workbench.errors import UsageError
from workbench.models.effects import effect_from_name
from workbench.synth import hidden_effect_walker


def _walks(hidden: str, seed: int, n: int, kind: str = "overground") -> list[Walk]:
    return [Walk(prepare(s.record)) for s in hidden_effect_walker(hidden, seed, n, kind=kind)]


def _with_feet(sim, swap: bool = False):  # type: ignore[no-untyped-def]
    """The record with foot channels: the simulator's even steps on the left foot.

    Each foot carries half the force plus or minus a step-long share that alternates with
    the simulated steps, so the channels say which foot a step is on (the real channels do
    through single support).
    """
    rec = sim.record
    starts = np.asarray(sim.truth["step_start_s"], dtype=np.float64)
    step = np.clip(np.searchsorted(starts, rec.time_s, side="right") - 1, 0, None)
    share = np.where(step % 2 == 0, 150.0, -150.0)
    if swap:
        share = -share
    return dataclasses.replace(
        rec, grf_left_n=0.5 * rec.grf_n + share, grf_right_n=0.5 * rec.grf_n - share
    )


def test_one_walk_pooled_is_the_single_record_diagnosis() -> None:
    """With one walk the pooled engine is the single record's: same scores and calls
    (the same arithmetic, so agreement to rounding; 1e-9 relative allows for the order of
    the Gram sums)."""
    data = prepare(hidden_effect_walker("heel_impact", 3, 1)[0].record)
    single = diagnose(data, surface="rigid")
    pooled = diagnose_walker([data], surface="rigid", start_stop=False)
    assert [c.effect for c in single.candidates] == [c.effect for c in pooled.candidates]
    for a, b in zip(single.candidates, pooled.candidates, strict=True):
        assert a.significant == b.significant
        assert a.score == pytest.approx(b.score, rel=1e-9, abs=1e-12)
        assert a.p_value == pytest.approx(b.p_value, rel=1e-9, abs=1e-12)
    assert pooled.baseline["heldout_rmse_n"] == pytest.approx(
        single.baseline["heldout_rmse_n"], rel=1e-9
    )
    assert pooled.baseline["walk_heldout_rmse_n"] is None


def _ridge_solve(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    g = x.T @ x
    ridge = _RIDGE * np.trace(g) / g.shape[0]
    return np.asarray(np.linalg.solve(g + ridge * np.eye(g.shape[0]), x.T @ y))


def test_walk_heldout_error_equals_a_direct_refit() -> None:
    """Whole walks held out: the shared coefficients refitted on the other walks and the
    walk's own columns fitted in its folds, each by a direct solve with the engine's ridge
    (1e-8 of the mean diagonal, numerical safety), give the same per-step error to
    rounding."""
    walks = _walks("heel_impact", 5, 3)
    effect = effect_from_name("heel_impact")
    pool = _pool(walks, [effect], 6, 10, True, True, True)
    sse = _walk_heldout_step_sse(pool, ["heel_impact"])
    assert sse is not None
    cv = pool.cv
    x = cv.x
    idx = cv.columns(["heel_impact"])
    direct = np.zeros(cv.data.n_steps)
    for i, piece in enumerate(cv.pieces):
        rows = np.zeros(cv.y.size, dtype=bool)
        rows[piece.rows] = True
        own = np.intersect1d(idx, pool.own[i])
        other = np.setdiff1d(idx, pool.own[i])
        beta = _ridge_solve(x[~rows][:, other], cv.y[~rows])
        y = cv.y[rows] - x[rows][:, other] @ beta
        xo = x[rows][:, own]
        fold = cv.fold_of[rows]
        resid = np.empty_like(y)
        for f in np.unique(fold):
            test = fold == f
            coef = _ridge_solve(xo[~test], y[~test])
            resid[test] = y[test] - xo[test] @ coef
        direct += np.bincount(cv.data.step[rows], resid**2, minlength=cv.data.n_steps)
    np.testing.assert_allclose(sse, direct, rtol=1e-8)


def test_walker_coefficients_match_a_cluster_robust_ols() -> None:
    """The effect's coefficients and standard errors are OLS with block-clustered errors
    (statsmodels, its small-sample factor (N - 1) / (N - K) taken out; the ridge leaves
    1e-6 relative)."""
    walks = _walks("heel_impact", 7, 2)
    board = compare_walker(walks, ["heel_impact"], surface="rigid", start_stop=False)
    pool = _pool(walks, [effect_from_name("heel_impact")], 6, 10, True, True, True)
    cv = pool.cv
    x, y = cv.x, cv.y
    keep = np.any(x != 0, axis=0)
    fit = sm.OLS(y, x[:, keep]).fit(cov_type="cluster", cov_kwds={"groups": cv.block_of})
    n, k = x.shape[0], int(keep.sum())
    mine = cv.slices["heel_impact"]
    pos = np.cumsum(keep) - 1
    coef = fit.params[pos[mine]] / cv.scale[mine]
    se = fit.bse[pos[mine]] / cv.scale[mine] * np.sqrt((n - k) / (n - 1))
    got = board.coefficients[0]
    np.testing.assert_allclose(got.coefficients, coef, rtol=1e-5, atol=1e-9 * np.abs(coef).max())
    np.testing.assert_allclose(got.standard_errors, se, rtol=1e-4)
    assert got.force_rms_n > 5 * got.force_rms_se_n > 0


def test_first_foot_reads_the_foot_channels() -> None:
    """The first kept step's foot follows the channels; swapping them swaps it."""
    sim = hidden_effect_walker("none", 2, 1)[0]
    rec = _with_feet(sim)
    data = prepare(rec)
    foot, share = first_foot(rec, data)
    swapped, share2 = first_foot(_with_feet(sim, swap=True), data)
    assert foot in ("left", "right") and swapped in ("left", "right") and foot != swapped
    assert share is not None and share >= 0.9 and share2 == share
    assert first_foot(sim.record, data) == (None, None)


@pytest.mark.slow
def test_asymmetry_aligned_by_the_feet_transfers_to_held_out_walks() -> None:
    """With the feet known the asymmetry is one coefficient set: learned on the other
    walks, it predicts a held-out walk (its whole-walk score is most of its step score).
    Labelled wrongly on every other walk, the shared set cancels and the whole-walk score
    falls; sign-free (no channels), each walk has its own set and a held-out walk gains
    nothing from the others."""
    sims = hidden_effect_walker("gait_asymmetry", 4, 4, level=2)
    right = list(prepare_walks([_with_feet(s) for s in sims]))
    # The first walk cut to ten steps keeps its start and stop (fewer than twelve steps),
    # so its first foot is read as given, while the others' flip with the three steps left
    # out: the alignment must hold across both.
    short = right[0]
    right[0] = dataclasses.replace(short, data=short.data.step_range(0, 10))
    wrong = prepare_walks([_with_feet(s, swap=i % 2 == 1) for i, s in enumerate(sims)])
    free = prepare_walks([s.record for s in sims])
    scores = {}
    board = compare_walker(right, ["gait_asymmetry"], surface="rigid")
    assert board.coefficients[0].walk_of_coefficient == (None,) * 8
    for label, walks in (("right", right), ("wrong", wrong), ("free", free)):
        diag = diagnose_walker(walks, surface="rigid")
        mine = next(c for c in diag.candidates if c.effect == "gait_asymmetry")
        scores[label] = (mine.score, diag.walk_scores["gait_asymmetry"][0], diag.sharing)
    assert scores["right"][2]["gait_asymmetry"] == "aligned by the foot channels"
    assert scores["free"][2]["gait_asymmetry"] == "per walk"
    assert scores["right"][0] > 0.1
    assert scores["right"][1] > 0.7 * scores["right"][0]
    assert scores["wrong"][1] < 0.5 * scores["right"][1]
    assert scores["free"][1] == pytest.approx(scores["free"][0], abs=0.05)


def test_walker_criticism_refuses_what_it_cannot_pool() -> None:
    walks = _walks("none", 1, 2)
    with pytest.raises(UsageError, match="at least one walk"):
        diagnose_walker([])
    with pytest.raises(UsageError, match="at least one effect"):
        compare_walker(walks, [])
    with pytest.raises(UsageError, match="cannot be tested on any of the walks"):
        compare_walker(walks, ["base_motion"], surface="rigid")
    with pytest.raises(UsageError, match="records, prepared records or Walk"):
        prepare_walks(["not a record"])  # type: ignore[list-item]
    with pytest.raises(UsageError, match="list of records"):
        prepare_walks(3.0)  # type: ignore[arg-type]
    assert len(prepare_walks(walks[0])) == 1  # one walk alone is a list of one
    with pytest.raises(UsageError, match="harmonics must be a whole number"):
        diagnose_walker(walks, harmonics=0)
    with pytest.raises(UsageError, match="folds must be a whole number"):
        compare_walker(walks, ["heel_impact"], folds=1)
    with pytest.raises(UsageError, match="keeps 4 whole steps"):
        diagnose_walker([walks[0], Walk(walks[1].data.step_range(0, 4))])
    with pytest.raises(UsageError, match="level must be 0, 1 or 2"):
        hidden_effect_walker("none", 1, 2, level=7)
    with pytest.raises(UsageError, match="walks must be a whole number"):
        hidden_effect_walker("none", 1, None)  # type: ignore[arg-type]


def test_step_range_cuts_a_record_at_its_steps() -> None:
    """The steps between keep their samples, phase (0 at the new first footfall), step
    numbers and boundaries; the start and stop left out are three steps at each end."""
    data = prepare(hidden_effect_walker("none", 6, 1)[0].record)
    part = data.step_range(3, data.n_steps - 3)
    keep = (data.step >= 3) & (data.step < data.n_steps - 3)
    assert part.n_steps == data.n_steps - 6
    np.testing.assert_array_equal(part.time_s, data.time_s[keep])
    np.testing.assert_array_equal(part.step, data.step[keep] - 3)
    np.testing.assert_array_equal(part.footfall_times_s, data.footfall_times_s[3:-3])
    np.testing.assert_allclose(part.phase_rad, data.phase_rad[keep] - 6 * np.pi, atol=1e-12)
    assert np.all(np.floor(part.phase_rad / (2 * np.pi)) == part.step)
    assert start_stop_steps(data) == (3, 3)
    assert start_stop_steps(data.step_range(0, 11)) == (0, 0)


def test_walk_clustered_gain_is_the_ratio_with_walks_as_clusters() -> None:
    """Against the linearised cluster-robust error of a ratio computed by hand."""
    rng = np.random.default_rng(3)
    walk = np.repeat(np.arange(4), [5, 7, 6, 8])
    base = rng.uniform(1.0, 2.0, walk.size)
    ext = base * rng.uniform(0.6, 1.0, walk.size)
    gain, se = walk_clustered_gain(base, ext, walk)
    d = np.array([np.sum((base - ext)[walk == w]) for w in range(4)])
    b = np.array([np.sum(base[walk == w]) for w in range(4)])
    assert gain == pytest.approx(d.sum() / b.sum(), rel=1e-12)
    var = 4 / 3 * np.sum((d - gain * b) ** 2) / b.sum() ** 2
    assert se == pytest.approx(np.sqrt(var), rel=1e-12)


def test_per_walk_coefficients_carry_the_walks_jackknife() -> None:
    """Sign-free asymmetry: each walk its own coefficients, labelled by walk; no
    per-coefficient errors (too few clusters per walk), the force's error the jackknife over
    the walks; the surface's columns join each walk's baseline over a deck."""
    walks = _walks("gait_asymmetry", 8, 3)
    got = compare_walker(walks, ["gait_asymmetry"], surface="rigid").coefficients[0]
    assert got.sharing == "per walk"
    assert got.walk_of_coefficient == (0,) * 8 + (1,) * 8 + (2,) * 8
    assert all(np.isnan(got.standard_errors))
    assert got.to_json()["standard_errors"] == [None] * 24
    assert 0 < got.force_rms_se_n < got.force_rms_n
    deck = _walks("none", 8, 2, kind="deck")
    coupled = _pool(_steady(deck, True), [], 6, 10, True, True, True)
    rigid_frame = [
        dataclasses.replace(w, data=dataclasses.replace(w.data, ground=None)) for w in deck
    ]
    plain = _pool(_steady(rigid_frame, True), [], 6, 10, True, True, True)
    assert coupled.cv.slices["baseline"].size == plain.cv.slices["baseline"].size
    framed = [dataclasses.replace(w, data=w.data.coupled_to_surface()) for w in deck]
    with_surface = _pool(_steady(framed, True), [], 6, 10, True, True, True)
    assert with_surface.cv.slices["baseline"].size == plain.cv.slices["baseline"].size + 6

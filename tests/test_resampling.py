"""Resampling schemes: unbiasedness, exact offspring variances, bounds, degenerate weights."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from workbench.errors import UsageError
from workbench.inference.core.resampling import SCHEMES, ess, normalise_log_weights, resample

# A fixed weight vector with a spread of sizes, a zero weight and an exactly-integer
# expected count (n w = 2 for the 0.2 weight with n = 10), so every code path is exercised.
WEIGHTS = np.array([0.2, 0.31, 0.005, 0.0, 0.12, 0.075, 0.09, 0.037, 0.063, 0.1])
DRAWS = 20_000


def _exact_variance(w: np.ndarray, n: int, scheme: str) -> np.ndarray:
    """Exact variance of the offspring counts N_i of each scheme (Douc & Cappé 2005)."""
    expected = n * w
    if scheme == "multinomial":
        return n * w * (1.0 - w)
    if scheme == "systematic":
        # N_i is floor or ceil of n w_i (a fixed comb of spacing 1 over an interval of
        # length n w_i): a two-point law with mean n w_i.
        frac = expected - np.floor(expected)
        return frac * (1.0 - frac)
    if scheme == "residual":
        r = expected - np.floor(expected)
        return r * (1.0 - r / r.sum())
    # Stratified: one independent uniform per stratum [j, j+1) of the scaled axis; particle
    # i gets it with probability p_ij = overlap of its interval with the stratum.
    upper = np.cumsum(expected)
    lower = upper - expected
    var = np.zeros_like(w)
    for j in range(n):
        p = np.clip(np.minimum(upper, j + 1) - np.maximum(lower, j), 0.0, None)
        var += p * (1.0 - p)
    return var


def _counts(w: np.ndarray, scheme: str, n: int, draws: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lw = np.log(w)
    out = np.empty((draws, w.size), dtype=np.int64)
    for r in range(draws):
        out[r] = np.bincount(resample(lw, rng, scheme, n=n), minlength=w.size)
    return out


@pytest.fixture(scope="module")
def offspring() -> dict[tuple[str, int], np.ndarray]:
    with np.errstate(divide="ignore"):
        return {
            (scheme, n): _counts(WEIGHTS, scheme, n, DRAWS, seed=11 + k)
            for k, scheme in enumerate(SCHEMES)
            for n in (10, 7)
        }


@pytest.mark.parametrize("n", [10, 7])
@pytest.mark.parametrize("scheme", SCHEMES)
def test_unbiased_offspring_counts(offspring, scheme, n):
    counts = offspring[(scheme, n)]
    assert np.all(counts.sum(axis=1) == n)
    expected = n * WEIGHTS
    var = _exact_variance(WEIGHTS, n, scheme)
    mean = counts.mean(axis=0)
    # Where the count is deterministic the mean must be exact; elsewhere a z-score with the
    # exact variance. 4.5 sd with 10 particles x 8 cases: a false alarm has probability ~1e-4.
    fixed = var < 1e-12
    np.testing.assert_allclose(mean[fixed], expected[fixed], atol=1e-12)
    z = (mean[~fixed] - expected[~fixed]) / np.sqrt(var[~fixed] / DRAWS)
    assert np.max(np.abs(z)) < 4.5, (scheme, n, z)


@pytest.mark.parametrize("n", [10, 7])
@pytest.mark.parametrize("scheme", SCHEMES)
def test_offspring_variance_matches_theory(offspring, scheme, n):
    counts = offspring[(scheme, n)]
    var = _exact_variance(WEIGHTS, n, scheme)
    sample_var = counts.var(axis=0, ddof=1)
    big = var > 0.05
    # The sample variance of 20 000 bounded counts is within a few % of the truth.
    np.testing.assert_allclose(sample_var[big], var[big], rtol=0.08)
    np.testing.assert_allclose(sample_var[~big], var[~big], atol=0.01)


def test_variance_ordering(offspring):
    """Systematic <= stratified <= multinomial and residual <= multinomial, exact and sampled."""
    for n in (10, 7):
        exact = {s: _exact_variance(WEIGHTS, n, s) for s in SCHEMES}
        assert np.all(exact["systematic"] <= exact["stratified"] + 1e-12)
        assert np.all(exact["stratified"] <= exact["multinomial"] + 1e-12)
        assert np.all(exact["residual"] <= exact["multinomial"] + 1e-12)
        total = {s: offspring[(s, n)].var(axis=0).sum() for s in SCHEMES}
        assert total["systematic"] < total["stratified"] < total["multinomial"]
        assert total["residual"] < total["multinomial"]
        # The sampled totals reproduce the exact ones, so the ordering above is not luck.
        for s in SCHEMES:
            assert total[s] == pytest.approx(exact[s].sum(), rel=0.05)


@pytest.mark.parametrize("n", [10, 7])
def test_offspring_bounds(offspring, n):
    expected = n * WEIGHTS
    lo, hi = np.floor(expected), np.ceil(expected)
    sys_counts = offspring[("systematic", n)]
    assert np.all((sys_counts >= lo) & (sys_counts <= hi))
    strat = offspring[("stratified", n)]
    assert np.all(np.abs(strat - expected) < 2.0)
    assert np.all(offspring[("residual", n)] >= lo)
    # The bounds discriminate: multinomial leaves floor/ceil often.
    multi = offspring[("multinomial", n)]
    assert np.mean((multi < lo) | (multi > hi)) > 0.05
    # A zero weight is never drawn by any scheme.
    for scheme in SCHEMES:
        assert np.all(offspring[(scheme, n)][:, 3] == 0)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    raw=st.lists(st.floats(-30.0, 5.0), min_size=1, max_size=40),
    n=st.integers(1, 60),
    seed=st.integers(0, 2**32 - 1),
)
def test_bounds_hold_for_any_weights(raw, n, seed):
    lw = np.asarray(raw)
    w = np.exp(lw - lw.max())
    expected = n * w / w.sum()
    rng = np.random.default_rng(seed)
    for scheme in SCHEMES:
        idx = resample(lw, rng, scheme, n=n)
        assert idx.shape == (n,) and idx.dtype == np.int64
        assert np.all(np.diff(idx) >= 0)
        assert idx.min() >= 0 and idx.max() < lw.size
        counts = np.bincount(idx, minlength=lw.size)
        if scheme == "systematic":
            assert np.all(counts >= np.floor(expected - 1e-9))
            assert np.all(counts <= np.ceil(expected + 1e-9))
        elif scheme == "stratified":
            assert np.all(np.abs(counts - expected) < 2.0 + 1e-9)
        elif scheme == "residual":
            assert np.all(counts >= np.floor(expected - 1e-9))


@pytest.mark.parametrize("scheme", SCHEMES)
def test_degenerate_weights(scheme):
    rng = np.random.default_rng(3)
    one_hot = np.full(50, -np.inf)
    one_hot[17] = 0.0
    assert np.all(resample(one_hot, rng, scheme) == 17)
    # Enormous but finite gaps behave like -inf, and large offsets do not overflow.
    lw = np.full(50, -1e6)
    lw[31] = 1e6
    assert np.all(resample(lw, rng, scheme, n=20) == 31)
    with pytest.raises(UsageError, match="collapsed"):
        resample(np.full(5, -np.inf), rng, scheme)
    with pytest.raises(UsageError, match="NaN"):
        resample(np.array([0.0, np.nan]), rng, scheme)
    with pytest.raises(UsageError, match=r"\+inf"):
        resample(np.array([0.0, np.inf]), rng, scheme)


@pytest.mark.parametrize("scheme", ["systematic", "stratified", "residual"])
def test_equal_weights_keep_every_particle_once(scheme):
    # n w_i = 1 exactly: these schemes must return each particle once whatever the draw.
    for seed in range(5):
        idx = resample(np.full(64, 3.7), np.random.default_rng(seed), scheme)
        np.testing.assert_array_equal(idx, np.arange(64))


@pytest.mark.parametrize("scheme", SCHEMES)
def test_determinism(scheme):
    lw = np.random.default_rng(0).normal(size=300)
    a = resample(lw, np.random.default_rng(42), scheme)
    b = resample(lw, np.random.default_rng(42), scheme)
    c = resample(lw, np.random.default_rng(43), scheme)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_bad_arguments():
    rng = np.random.default_rng(0)
    with pytest.raises(UsageError, match="unknown scheme"):
        resample(np.zeros(3), rng, "bogus")
    with pytest.raises(UsageError, match="'n'"):
        resample(np.zeros(3), rng, n=0)
    with pytest.raises(UsageError, match="1-D"):
        resample(np.zeros((2, 2)), rng)


def test_ess():
    assert ess(np.zeros(123)) == pytest.approx(123.0, rel=1e-14)
    # Unnormalised and shifted log-weights give the same ESS.
    w = np.array([0.5, 0.25, 0.125, 0.125])
    assert ess(np.log(w)) == pytest.approx(1.0 / np.sum(w**2), rel=1e-14)
    assert ess(np.log(w) + 1234.5) == pytest.approx(1.0 / np.sum(w**2), rel=1e-14)
    one_hot = np.full(10, -np.inf)
    one_hot[2] = -5.0
    assert ess(one_hot) == 1.0
    assert ess(np.array([0.0, -800.0])) == pytest.approx(1.0, abs=1e-12)


def test_normalise_log_weights():
    lw = np.array([-1.0, 2.0, 0.5, -np.inf])
    norm, log_mean = normalise_log_weights(lw)
    assert np.sum(np.exp(norm)) == pytest.approx(1.0, rel=1e-14)
    assert log_mean == pytest.approx(np.log(np.mean(np.exp(lw))), rel=1e-14)
    assert norm[3] == -np.inf
    # Shift invariance of the normalised weights, without overflow at huge offsets.
    norm2, log_mean2 = normalise_log_weights(lw + 1e5)
    np.testing.assert_allclose(norm2, norm, atol=1e-9)
    assert log_mean2 == pytest.approx(log_mean + 1e5, rel=1e-14)
    with pytest.raises(UsageError, match="collapsed"):
        normalise_log_weights(np.full(3, -np.inf))

"""Compiled per-sample loop of the seed-faithful particle filter (method ``"pf"``).

At a few thousand particles a numpy filter spends most of its time in the fixed cost of the
dozens of array calls each sample needs and in passes over memory, not in arithmetic; the
library reference (``particles``) pays the same. These kernels, compiled by numba, fuse the
work of one sample into three passes over the particles:

1. Euler step with its process noise (drawn inline from the caller's numpy ``Generator``,
   which numba drives through numpy's own algorithms: the same stream numpy would give),
   predicted acceleration, the one-step-ahead prediction sums, the log-likelihood and the
   new log-weights with their maximum;
2. the exponentials (log-sum-exp), ESS and the weighted moments of C and K;
3. normalisation.

Systematic resampling (the default scheme; the same algorithm, the same uniform and so the
same ancestors as :func:`workbench.inference.core.resampling.draw_ancestors`) runs inside the loop
too. The kernel returns to Python only at a piece start (the force coefficients are
regenerated in numpy), at the end of a block of the precomputed force, and, for the other
resampling schemes or with jitter, at a resampling.

The force of every particle at the samples of a block is one matrix product, ``F =
basis[block] @ table.T`` of shape (samples, table rows); a particle reads the column of the
table row it points into, so resampling moves pointers, never force coefficients.

:func:`advance` takes the filter's buffers in five bundles by role (:class:`Cloud`,
:class:`Correction`, :class:`Scratch`, :class:`FilterConstants`, :class:`Traces`), typed
``NamedTuple`` classes that numba compiles as records of their fields. Against the revision
that passed the 41 buffers one by one the results are bit-identical, and compile, cache-load
and run times stayed within 0.90-1.04 of it, the noise of a shared machine
(``analyses/benchmarks/kernel_arguments.py``; ``pf per sample`` times a call per sample).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

__all__ = [
    "STATUS_COLLAPSED",
    "STATUS_DONE",
    "STATUS_RESAMPLE",
    "Cloud",
    "Correction",
    "FilterConstants",
    "Scratch",
    "Traces",
    "advance",
    "fill_standard_normal",
    "systematic_ancestors",
    "transition",
]

#: ``advance`` ran every sample it was given.
STATUS_DONE = 0
#: ``advance`` stopped after the returned sample, whose ESS fell below the threshold, for the
#: caller to resample (schemes other than systematic, or jitter).
STATUS_RESAMPLE = 1
#: ``advance`` stopped at the returned sample: no particle has a finite weight.
STATUS_COLLAPSED = 2


class Cloud(NamedTuple):
    """The particles, moved, weighted and resampled in place by the kernel."""

    state: np.ndarray  # (4, P) rows u, u', C, K
    acc: np.ndarray  # (P,) acceleration at the last sample run
    lw: np.ndarray  # (P,) normalised log-weights
    w: np.ndarray  # (P,) normalised weights exp(lw)
    pointer: np.ndarray  # (P,) int64: each particle's row of the force coefficient table
    origin: np.ndarray  # (P,) int64: each particle's initial ancestor
    counters: np.ndarray  # (3,) int64: distinct initial ancestors, distinct C, distinct K


class Correction(NamedTuple):
    """The regression proposal's importance correction (``active`` False: the prior's)."""

    active: bool
    by_row: np.ndarray  # (table rows,) log p(theta) - log q(theta) of each table row
    now: np.ndarray  # (P,) the correction of each particle's row
    relative: np.ndarray  # (P,) exp(now - max(now)): the same as a weight factor


class Scratch(NamedTuple):
    """Work arrays of one particle each, contents undefined between calls."""

    ancestors: np.ndarray  # (P,) int64
    values: np.ndarray  # (P,) float64
    ints: np.ndarray  # (P,) int64
    weights: np.ndarray  # (P,) float64: corrected weights in the log domain


class FilterConstants(NamedTuple):
    """What stays fixed through a run: the model's constants and the filter's settings."""

    move_sd: np.ndarray  # (2 or 4,) process noise sd of the moving columns
    half_prec_sd: np.ndarray  # (3,) sqrt(0.5) / obs_sd
    inv_mass: float
    dt: float
    log_norm_const: float  # constant of the Gaussian log-density of one sample
    ess_limit: float  # resample below this ESS
    n_samples: int
    random_walk: np.ndarray  # (2,) bool: C, K take a random walk
    fixed: bool  # C and K fixed
    resample_here: bool  # the kernel resamples itself (systematic, no jitter)
    is_end: np.ndarray  # (N,) bool: last sample of a piece


class Traces(NamedTuple):
    """The per-sample outputs, one row per sample."""

    mean: np.ndarray  # (N, 2) C, K
    sd: np.ndarray  # (N, 2)
    ess: np.ndarray  # (N,)
    loglik_increments: np.ndarray  # (N,)
    predicted_obs: np.ndarray  # (N, 3)
    distinct_ancestors: np.ndarray  # (N,) int64
    unique_values: np.ndarray  # (N, 2) int64
    resampled: np.ndarray  # (N,) bool


_jit = numba.njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
# The hot loop may reorder its sums (vectorised reductions; about 10 % faster measured by
# analyses/benchmarks/pf_throughput.py) but keeps IEEE infinities and NaNs, which it tests.
_jit_hot = numba.njit(
    cache=True,
    nogil=True,
    error_model="numpy",
    boundscheck=False,
    fastmath={"reassoc", "contract", "nsz", "arcp"},
)


@_jit
def transition(
    state: np.ndarray,
    acc: np.ndarray,
    rng: np.random.Generator,
    move_sd: np.ndarray,
    dt: float,
) -> None:
    """Euler step (seed eq. 20) of every particle with its process noise, in place.

    ``state`` is (4, P) = (u, u', C, K); ``acc`` the acceleration of the state being left;
    ``move_sd`` (n_moving,) the noise sds: n_moving is 4 (u, u', C, K) or 2 (u, u' only,
    when C and K are fixed). Per particle the normals are drawn in the order u, u', C, K.
    """
    n_moving = move_sd.shape[0]
    s0 = move_sd[0]
    s1 = move_sd[1]
    u = state[0]
    v = state[1]
    c = state[2]
    kk = state[3]
    if n_moving == 4:
        s2 = move_sd[2]
        s3 = move_sd[3]
        for p in range(u.shape[0]):
            u_new = u[p] + dt * v[p] + s0 * rng.standard_normal()
            v[p] = v[p] + dt * acc[p] + s1 * rng.standard_normal()
            u[p] = u_new
            c[p] += s2 * rng.standard_normal()
            kk[p] += s3 * rng.standard_normal()
    else:
        for p in range(u.shape[0]):
            u_new = u[p] + dt * v[p] + s0 * rng.standard_normal()
            v[p] = v[p] + dt * acc[p] + s1 * rng.standard_normal()
            u[p] = u_new


@_jit
def fill_standard_normal(rng: np.random.Generator, out: np.ndarray) -> None:
    """Fill the C-contiguous ``out`` with standard normals from ``rng``.

    The same values, in the same order, as ``rng.standard_normal(out.shape)`` (numba drives
    numpy's own algorithm), at a third of the cost for large arrays.
    """
    flat = out.reshape(-1)
    for i in range(flat.shape[0]):
        flat[i] = rng.standard_normal()


@_jit
def systematic_ancestors(w: np.ndarray, uniform: float, out: np.ndarray) -> None:
    """Systematic resampling of ``len(out)`` ancestors from weights ``w`` with offset ``uniform``.

    Bit for bit the systematic branch of
    :func:`workbench.inference.core.resampling.draw_ancestors` given the same uniform: particle
    ``i`` receives ``ceil(S_i - U) - ceil(S_{i-1} - U)`` copies, ``S`` the cumulative weights
    scaled to the count.
    """
    count = out.shape[0]
    total = 0.0
    for i in range(w.shape[0]):
        total += w[i]
    scale = count / total
    cumulative = 0.0
    below_prev = 0.0
    j = 0
    for i in range(w.shape[0]):
        cumulative += w[i]
        below = math.ceil(cumulative * scale - uniform)
        below = min(max(below, 0.0), float(count))
        for _ in range(int(below - below_prev)):
            out[j] = i
            j += 1
        below_prev = below


@_jit
def _gather_in_place(values: np.ndarray, idx: np.ndarray, scratch: np.ndarray) -> None:
    """``values[:] = values[idx]`` through ``scratch`` (same dtype and length)."""
    for p in range(idx.shape[0]):
        scratch[p] = values[idx[p]]
    for p in range(idx.shape[0]):
        values[p] = scratch[p]


@_jit
def _resample_in_place(
    k: int,
    rng: np.random.Generator,
    cloud: Cloud,
    work: Scratch,
    random_walk: np.ndarray,
    fixed: bool,
    resampled_tr: np.ndarray,
) -> None:
    """Systematic resampling after sample ``k`` with the diagnostics of ``pf.py``."""
    state, acc, lw, w, pointer, origin, counters = cloud
    idx = work.ancestors
    scratch = work.values
    int_scratch = work.ints
    n_part = w.shape[0]
    systematic_ancestors(w, rng.random(), idx)
    for row in range(4):
        _gather_in_place(state[row], idx, scratch)
    _gather_in_place(acc, idx, scratch)
    _gather_in_place(pointer, idx, int_scratch)
    _gather_in_place(origin, idx, int_scratch)
    log_w = -math.log(n_part)
    for p in range(n_part):
        lw[p] = log_w
        w[p] = 1.0 / n_part
    resampled_tr[k] = True
    # Distinct initial ancestors: origins are gathered in ascending order of ancestors, so
    # count distinct values by marking.
    for p in range(n_part):
        int_scratch[p] = 0
    distinct = 0
    for p in range(n_part):
        if int_scratch[origin[p]] == 0:
            int_scratch[origin[p]] = 1
            distinct += 1
    counters[0] = distinct
    if not fixed:
        parents = 1
        for p in range(1, n_part):
            if idx[p] != idx[p - 1]:
                parents += 1
        for j in range(2):
            if random_walk[j] or k == 0:
                # With a random walk every value was distinct before resampling, so the
                # distinct values are the distinct parents.
                counters[1 + j] = parents
            else:
                vals = np.sort(state[2 + j])
                n_unique = 1
                for p in range(1, n_part):
                    if vals[p] != vals[p - 1]:
                        n_unique += 1
                counters[1 + j] = n_unique


@_jit_hot
def _exp_weights(
    lw: np.ndarray,
    top: float,
    w: np.ndarray,
    factor: np.ndarray,
    use_factor: bool,
    c: np.ndarray,
    kk: np.ndarray,
    shift_c: float,
    shift_k: float,
) -> tuple[float, float, float, float, float, float, float]:
    """``w = exp(lw - top)`` with its sum and sum of squares, and the moments of C and K.

    The moments use the weights ``w * factor`` when ``use_factor`` (the regression
    proposal's correction), ``w`` otherwise, and are taken about ``shift`` against
    cancellation. Returns ``(total, total_sq, weight_sum, s_c, s_k, q_c, q_k)``.
    """
    total = 0.0
    total_sq = 0.0
    t_est = 0.0
    s_c = 0.0
    s_k = 0.0
    q_c = 0.0
    q_k = 0.0
    for p in range(lw.shape[0]):
        e = math.exp(lw[p] - top)
        w[p] = e
        total += e
        total_sq += e * e
        we = e * factor[p] if use_factor else e
        t_est += we
        dc = c[p] - shift_c
        dk = kk[p] - shift_k
        s_c += we * dc
        s_k += we * dk
        q_c += we * dc * dc
        q_k += we * dk * dk
    return total, total_sq, t_est, s_c, s_k, q_c, q_k


@_jit_hot
def advance(
    k_start: int,
    k_stop: int,
    skip_first_transition: bool,
    block_start: int,
    y: np.ndarray,
    force: np.ndarray,
    rng: np.random.Generator,
    cloud: Cloud,
    correction: Correction,
    work: Scratch,
    const: FilterConstants,
    traces: Traces,
) -> tuple[int, int]:
    """Run samples ``k_start .. k_stop - 1`` of the filter; return ``(last sample, status)``.

    The bundles hold the buffers of :func:`workbench.inference.methods.pf.run_pf` by role.
    ``force`` is the (block samples, table rows) force of every table row at the block's
    samples (row ``k - block_start``). ``cloud.acc`` on entry holds the acceleration of the
    current particles at ``k_start - 1`` (unused when the caller made the first
    transition). ``cloud.counters`` holds (distinct initial ancestors, distinct C values,
    distinct K values) and is kept up to date; ``const.random_walk`` says whether C and K
    take a random walk. With ``const.resample_here`` the kernel resamples itself
    (systematic); otherwise it returns ``STATUS_RESAMPLE``. The correction serves the
    regression proposal (``correction.active``): ``correction.now`` and
    ``correction.relative`` hold each particle's log p/q and its exponential relative to
    the maximum.
    """
    state = cloud.state
    acc = cloud.acc
    lw = cloud.lw
    w = cloud.w
    pointer = cloud.pointer
    counters = cloud.counters
    use_correction, correction_by_row, corr_now, corr_exp = correction
    w_aux = work.weights
    move_sd = const.move_sd
    half_prec_sd = const.half_prec_sd
    inv_mass = const.inv_mass
    dt = const.dt
    log_norm_const = const.log_norm_const
    ess_limit = const.ess_limit
    n_samples = const.n_samples
    random_walk = const.random_walk
    fixed = const.fixed
    resample_here = const.resample_here
    is_end = const.is_end
    mean_tr, sd_tr, ess_tr, incr_tr, pred_tr, distinct_tr, unique_tr, resampled_tr = traces
    n_part = pointer.shape[0]
    u = state[0]
    v = state[1]
    c = state[2]
    kk = state[3]
    h0 = half_prec_sd[0]
    h1 = half_prec_sd[1]
    h2 = half_prec_sd[2]
    four = move_sd.shape[0] == 4
    s0 = move_sd[0]
    s1 = move_sd[1]
    s2 = move_sd[2] if four else 0.0
    s3 = move_sd[3] if four else 0.0
    refresh = use_correction
    k = k_start
    while k < k_stop:
        if refresh:
            # Pointers changed (entry or resampling): gather each particle's correction.
            cmax = -np.inf
            for p in range(n_part):
                val = correction_by_row[pointer[p]]
                corr_now[p] = val
                if val > cmax:
                    cmax = val
            for p in range(n_part):
                corr_exp[p] = math.exp(corr_now[p] - cmax)
            refresh = False
        row = k - block_start
        move = k > 0 and not (skip_first_transition and k == k_start)
        if move:
            if random_walk[0]:
                counters[1] = n_part
            if random_walk[1]:
                counters[2] = n_part
        f_row = force[row]
        y0 = y[k, 0]
        y1 = y[k, 1]
        y2 = y[k, 2]

        # Pass 1: Euler step with process noise (the normals in the order of `transition`),
        # acceleration, prediction sums under the carried weights (corrected for the
        # regression proposal, which saw y_k; see pf.py), log-likelihood, new log-weights.
        total_pred = 0.0
        p_u = 0.0
        p_v = 0.0
        p_a = 0.0
        top = -np.inf
        if k > 0:
            for p in range(n_part):
                up = u[p]
                vp = v[p]
                cp = c[p]
                kp = kk[p]
                if move:
                    u_new = up + dt * vp + s0 * rng.standard_normal()
                    vp = vp + dt * acc[p] + s1 * rng.standard_normal()
                    up = u_new
                    u[p] = up
                    v[p] = vp
                    if four:
                        cp += s2 * rng.standard_normal()
                        kp += s3 * rng.standard_normal()
                        c[p] = cp
                        kk[p] = kp
                a = (f_row[pointer[p]] - kp * up - cp * vp) * inv_mass
                acc[p] = a
                wp = w[p] * corr_exp[p] if use_correction else w[p]
                total_pred += wp
                p_u += wp * up
                p_v += wp * vp
                p_a += wp * a
                r0 = (up - y0) * h0
                r1 = (vp - y1) * h1
                r2 = (a - y2) * h2
                val = lw[p] - (r0 * r0 + r1 * r1 + r2 * r2)
                lw[p] = val
                top = max(top, val)
        else:
            for p in range(n_part):
                a = (f_row[pointer[p]] - kk[p] * u[p] - c[p] * v[p]) * inv_mass
                acc[p] = a
                wp = w[p] * corr_exp[p] if use_correction else w[p]
                total_pred += wp
                # Before y_0 the state is its prior N(0, s0^2): predict with u = u' = 0; u,
                # u' of y_0 are in the initial draw (pf.py), so only u'' weights.
                p_a += wp * (a + (kk[p] * u[p] + c[p] * v[p]) * inv_mass)
                r2 = (a - y2) * h2
                val = lw[p] - r2 * r2
                lw[p] = val
                top = max(top, val)
        if not (math.isfinite(top) and math.isfinite(p_a)):
            # Overflow or NaN of a diverging Euler step (NaN never wins a max): such particles
            # get zero weight; the prediction is left to what the finite particles say.
            top = -np.inf
            for p in range(n_part):
                if not math.isfinite(lw[p]):
                    lw[p] = -np.inf
                top = max(top, lw[p])
            if not math.isfinite(top):
                return k, STATUS_COLLAPSED
        if use_correction and not total_pred > 0.0:
            # Both factors tiny on every particle: redo the prediction in the log domain.
            ptop = -np.inf
            for p in range(n_part):
                w_aux[p] = math.log(w[p]) + corr_now[p] if w[p] > 0.0 else -np.inf
                if w_aux[p] > ptop:
                    ptop = w_aux[p]
            total_pred = 0.0
            p_u = 0.0
            p_v = 0.0
            p_a = 0.0
            for p in range(n_part):
                wp = math.exp(w_aux[p] - ptop)
                total_pred += wp
                if k > 0:
                    p_u += wp * u[p]
                    p_v += wp * v[p]
                    p_a += wp * acc[p]
                else:
                    p_a += wp * (acc[p] + (kk[p] * u[p] + c[p] * v[p]) * inv_mass)
        inv_pred = 1.0 / total_pred
        pred_tr[k, 0] = p_u * inv_pred
        pred_tr[k, 1] = p_v * inv_pred
        pred_tr[k, 2] = p_a * inv_pred

        # Pass 2: exponentials (log-sum-exp), ESS and the moments of C and K under the
        # estimate's weights, shifted by the previous estimate against cancellation.
        shift_c = mean_tr[k - 1, 0] if k > 0 else c[0]
        shift_k = mean_tr[k - 1, 1] if k > 0 else kk[0]
        piece_end_corr = use_correction and is_end[k]
        est_corr = use_correction and not is_end[k]
        total, total_sq, t_est, s_c, s_k, q_c, q_k = _exp_weights(
            lw, top, w, corr_exp, est_corr, c, kk, shift_c, shift_k
        )
        log_incr = top + math.log(total)
        incr_tr[k] = log_incr + log_norm_const
        ess = total * total / total_sq
        inv_total = 1.0 / total
        # Pass 3: normalise.
        for p in range(n_part):
            lw[p] -= log_incr
            w[p] *= inv_total

        if piece_end_corr:
            # Piece end: the importance correction p/q joins the weights and the likelihood
            # increment (log of its weighted mean); moments under the corrected weights.
            top = -np.inf
            for p in range(n_part):
                lw[p] += corr_now[p]
                if lw[p] > top:
                    top = lw[p]
            total, total_sq, t_est, s_c, s_k, q_c, q_k = _exp_weights(
                lw, top, w, corr_exp, False, c, kk, shift_c, shift_k
            )
            log_corr = top + math.log(total)
            incr_tr[k] += log_corr
            ess = total * total / total_sq
            inv_total = 1.0 / total
            for p in range(n_part):
                lw[p] -= log_corr
                w[p] *= inv_total
        elif est_corr and not t_est > 0.0:
            # Both factors tiny on every particle: the estimate's weights in the log domain.
            etop = -np.inf
            for p in range(n_part):
                val = lw[p] + corr_now[p]
                w_aux[p] = val
                if val > etop:
                    etop = val
            _, _, t_est, s_c, s_k, q_c, q_k = _exp_weights(
                w_aux, etop, w_aux, corr_exp, False, c, kk, shift_c, shift_k
            )
        ess_tr[k] = ess
        m_c = s_c / t_est
        m_k = s_k / t_est
        mean_tr[k, 0] = shift_c + m_c
        mean_tr[k, 1] = shift_k + m_k
        sd_tr[k, 0] = math.sqrt(max(q_c / t_est - m_c * m_c, 0.0))
        sd_tr[k, 1] = math.sqrt(max(q_k / t_est - m_k * m_k, 0.0))

        if ess < ess_limit and k < n_samples - 1:
            if not resample_here or is_end[k]:
                # The caller resamples (other schemes, jitter) or first summarises the
                # piece's coefficients under the weights before resampling.
                return k, STATUS_RESAMPLE
            _resample_in_place(k, rng, cloud, work, random_walk, fixed, resampled_tr)
            refresh = use_correction
        distinct_tr[k] = counters[0]
        unique_tr[k, 0] = counters[1]
        unique_tr[k, 1] = counters[2]
        k += 1
    return k_stop - 1, STATUS_DONE

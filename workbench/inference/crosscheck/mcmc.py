"""A small, deterministic emcee runner with convergence checks that hold up.

:func:`run_ensembles` samples any log-density (it knows nothing of the SMD model) with
several *independent* emcee ensembles and judges convergence in two separate ways:

Within each ensemble: the 50-tau rule
    The chain is run in chunks. After every chunk the integrated autocorrelation time
    ``tau`` of every parameter is estimated with :func:`emcee.autocorr.integrated_time`
    (autocorrelation function averaged over the walkers, Sokal's automatic window with
    ``c = 5``). The rule is met when the chain is at least ``tau_factor * max(tau)`` steps
    long (emcee's recommendation, ``tau_factor = 50``) *and* the estimate has settled:
    every ``tau`` changed by less than ``tau_rtol`` (relative) since the previous check.
    A short chain under-estimates ``tau``, so a rule checked against an unstable estimate
    can pass too early; the second condition is emcee's own guard (its tutorial uses 1 %,
    we use 10 % by default, for the reasons given under ``tau_rtol``).
    While the rule fails in any ensemble, all ensembles are extended together (they stay
    the same length, which R-hat needs) up to ``max_steps``.

Across ensembles: R-hat and ESS with arviz
    The walkers of one ensemble are not independent chains (every stretch move uses the
    other walkers), so R-hat across walkers would compare things that are coupled by
    construction and could hide a whole ensemble sitting in the wrong place. Instead each
    *ensemble* is one arviz chain. After discarding a burn-in of ``burn_tau * max(tau)``
    steps and thinning by about ``min(tau) / 2``, the walkers of an ensemble are pooled
    walker by walker: arviz's draw axis is ``walker 0's trace, then walker 1's trace, ...``
    (walker-major). This keeps every stretch of the draw axis a real time series, so
    arviz's autocorrelation-based ESS sees each walker's own autocorrelation (only
    ``n_walkers - 1`` joins are artificial, a negligible share). The alternative orders
    are worse: step-major interleaving puts nearly uncorrelated walkers next to each other,
    which makes Geyer's truncation stop early and over-states ESS; the walker mean per step
    is a different quantity with a much smaller spread, so its R-hat and tail ESS say
    nothing about the posterior itself. Caveats, stated rather than hidden: the ESS does
    not count the (weak) correlation between walkers of one ensemble, so it is somewhat
    optimistic; and arviz's *split* R-hat splits each chain into halves, which here are
    two groups of walkers rather than two halves in time (non-stationarity in time is
    what the 50-tau rule and the burn-in cover).

A run is called converged when all of these hold (thresholds are module constants):

* the 50-tau rule was met in every ensemble;
* rank-normalised split R-hat < :data:`RHAT_MAX` (1.01, Vehtari et al. 2021) for every
  parameter;
* bulk and tail ESS >= :data:`ESS_MIN` (400, Vehtari et al. 2021: enough for R-hat and
  MCSE estimates to be reliable with four chains) for every parameter;
* the mean acceptance fraction of every ensemble lies in
  [:data:`ACCEPTANCE_MIN`, :data:`ACCEPTANCE_MAX`] = [0.1, 0.9]: outside it the stretch
  move is either stuck (scale badly mismatched, walkers trapped at ``-inf``) or barely
  moving anything (a flat or degenerate target).

Every failed condition adds one plain sentence to :attr:`McmcResult.reasons`.

One call of the target per round, for all ensembles
    A log density that costs a Kalman filter per call is dominated by per-call overhead at
    a few dozen points, so the ensembles step in lockstep: every time one of them asks for
    log densities the request waits until every running ensemble has asked, then all are
    evaluated in one call of ``log_prob`` (ensemble order, so the batch, and with a
    row-wise target the result, is the same on every run). The ensembles stay independent:
    each keeps its own walkers and random stream; only the arithmetic is shared.
    ``lockstep=False`` evaluates them one after the other instead. By default
    (``engine="batched"``) one thread steps all ensembles, each a generator that yields its
    proposals and draws exactly what emcee's sampler would; ``engine="emcee"`` runs emcee's
    own sampler, one thread per ensemble, the reference that gives the same samples bit for
    bit. With a cheap target (the cross-check's grid surrogate) the threads' hand-overs and
    emcee's per-walker Python loops cost more than the target itself.

Determinism
    ``np.random.SeedSequence(seed).spawn(n_ensembles)`` gives every ensemble its own
    sequence; each of those is spawned once more into a stream for the starting positions
    (a :class:`numpy.random.Generator`) and a stream for emcee. emcee 3 draws its moves
    from a legacy :class:`numpy.random.RandomState` that it owns; its supported way in is
    the ``random_state`` carried by the starting :class:`emcee.State`, which
    ``EnsembleSampler.sample`` installs before the first step. We hand it the state of a
    ``RandomState`` built on an ``MT19937`` bit generator seeded from the ensemble's
    sequence, so the global ``np.random`` state is never read or changed and the same seed
    gives bit-identical samples.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import emcee
import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.inference.crosscheck.mcmc_diagnostics import _integrated_time, rhat_ess
from workbench.inference.crosscheck.mcmc_lockstep import (
    _BatchedEnsemble,
    _EnsembleError,
    _Lockstep,
    _run_batched,
    _run_chunk,
    batched_moves,
)
from workbench.inference.crosscheck.mcmc_result import McmcResult

# The result type and the lockstep drivers live in their own modules (each one idea);
# McmcResult stays importable from here.
__all__ = [
    "ACCEPTANCE_MAX",
    "ACCEPTANCE_MIN",
    "ENGINES",
    "ESS_MIN",
    "RHAT_MAX",
    "Initial",
    "LogProb",
    "McmcResult",
    "run_ensembles",
]

FloatArray = NDArray[np.float64]
LogProb = Callable[[FloatArray], ArrayLike]
Initial = Callable[[np.random.Generator], ArrayLike] | ArrayLike

#: Who steps the ensembles (``run_ensembles``'s ``engine``), default first.
ENGINES = ("batched", "emcee")
#: Largest rank-normalised split R-hat accepted (Vehtari et al. 2021 recommend 1.01).
RHAT_MAX = 1.01
#: Smallest bulk and tail ESS accepted, per parameter (Vehtari et al. 2021).
ESS_MIN = 400.0
#: Range of the mean acceptance fraction of an ensemble that counts as healthy.
ACCEPTANCE_MIN = 0.1
ACCEPTANCE_MAX = 0.9
#: Each extension adds at least this share of the current chain length: the tau estimates
#: compared by the stability check then come from chains that differ materially.
_MIN_GROWTH = 0.25
#: Aim for this much more than ``tau_factor * tau`` when extending, since the estimate of
#: tau usually keeps growing a little as the chain gets longer.
_EXTEND_MARGIN = 1.2


class _CountingLogProb:
    """Wrap a vectorised log density: check its output and count evaluations.

    emcee only rejects NaN; a wrong shape would otherwise surface as an obscure broadcasting
    error deep inside a move, and +inf would silently capture every walker.
    """

    def __init__(self, log_prob: LogProb, n_dim: int) -> None:
        self.log_prob = log_prob
        self.n_dim = n_dim
        self.calls = 0

    def __call__(self, coords: FloatArray) -> FloatArray:
        coords = np.asarray(coords, dtype=np.float64)
        lp = np.asarray(self.log_prob(coords), dtype=np.float64)
        if lp.shape != (coords.shape[0],):
            raise UsageError(
                f"log_prob must return one log density per row, shape ({coords.shape[0]},), "
                f"for an input of shape {coords.shape}; it returned shape {lp.shape}"
            )
        if np.any(np.isnan(lp)) or np.any(lp == np.inf):
            raise UsageError(
                "log_prob returned NaN or +inf; return -inf outside the support and a finite "
                "value inside it"
            )
        self.calls += coords.shape[0]
        return lp


def run_ensembles(
    log_prob: LogProb,
    initial: Initial,
    *,
    n_ensembles: int = 4,
    n_walkers: int | None = None,
    seed: int = 0,
    min_steps: int = 500,
    max_steps: int = 20_000,
    tau_factor: float = 50.0,
    tau_rtol: float = 0.1,
    burn_tau: float = 3.0,
    vectorize: bool = True,
    param_names: Sequence[str] | None = None,
    moves: str | Any = "de",
    lockstep: bool = True,
    engine: str = "batched",
) -> McmcResult:
    """Sample a log density with several independent emcee ensembles and check convergence.

    Parameters
    ----------
    log_prob : callable
        With ``vectorize=True`` (the default): ``log_prob(x)`` takes an ``(n, d)`` array and
        returns ``n`` log densities (unnormalised; ``-inf`` outside the support, never NaN or
        ``+inf``). With ``vectorize=False`` it takes one ``(d,)`` point and returns a float;
        it is then called row by row (slow; for targets that cannot be batched).
    initial : callable or array_like
        Where each ensemble starts. A callable ``initial(rng) -> (n_walkers, d)`` is called
        once per ensemble, in ensemble order, with that ensemble's own
        :class:`numpy.random.Generator`, so ensembles start independently (give it an
        over-dispersed spread: R-hat can only detect what different starts expose). An
        array of shape ``(2, d)`` is read as a centre (row 0) and a scale (row 1, > 0):
        walkers start at ``centre + scale * N(0, 1)``. Every starting point must have a
        finite log density.
    n_ensembles : int, default 4
        Number of independent ensembles (arviz chains); at least 2.
    n_walkers : int, optional
        Walkers per ensemble, even and at least ``2 d``. Default ``max(32, 4 d)`` rounded up
        to even: with a vectorised target more walkers cost little per step and give more
        draws per autocorrelation time.
    seed : int, default 0
        Fixes every random number (module docstring, "Determinism").
    min_steps : int, default 500
        Steps per walker of the first chunk (and the least any run does).
    max_steps : int, default 20000
        Most steps per walker; the run stops there even if the 50-tau rule is not met (the
        result then says so).
    tau_factor : float, default 50
        The chain must be at least ``tau_factor`` times the largest autocorrelation time.
    tau_rtol : float, default 0.1
        Largest relative change of every tau estimate between two consecutive checks for
        the estimate to count as settled. Not emcee's tutorial 1 %: our checks are spaced by
        at least 25 % more chain (not emcee's 100 steps), and between such checks the
        estimate from 32 walkers over about 50 tau moves by a few per cent from noise alone.
        A tolerance at that noise level turns the check into a lottery that extends the run
        again and again (with 1 % the 2-D Gaussian of the tests ran on to ``max_steps``),
        while the failure it exists for, a tau that keeps
        growing because the chain has not yet seen its slow directions, changes it by much
        more than 10 %.
    burn_tau : float, default 3
        Burn-in, in units of the largest tau over ensembles and parameters (a few tau, as
        emcee recommends; the walkers forget their start after a few tau).
    vectorize : bool, default True
        Whether ``log_prob`` takes a batch of points (see ``log_prob``).
    param_names : sequence of str, optional
        Names of the parameters (default ``x0, x1, ...``); used in the InferenceData, the
        JSON and the reason sentences.
    moves : {"de", "stretch"} or emcee moves, default "de"
        The proposal. ``"de"`` is the mixture emcee's documentation suggests for targets
        that are roughly Gaussian, 80 % differential evolution and 20 % DE snooker moves
        (both affine invariant, like the stretch move); on the correlated Gaussians of the
        tests its autocorrelation time is several times shorter than the stretch move's at
        the same cost per step, so the 50-tau rule is met that much sooner, which is what
        matters when every step costs a Kalman filter. ``"stretch"`` is
        emcee's default move; anything else is passed to
        :class:`emcee.EnsembleSampler` as ``moves`` unchanged.
    lockstep : bool, default True
        Evaluate the requests of all ensembles in one call of ``log_prob`` per round
        (module docstring); the samples are the same either way for a row-wise target.
    engine : {"batched", "emcee"}, default "batched"
        Who steps the ensembles. ``"batched"``: one thread steps them all, drawing exactly
        what emcee's sampler draws (:class:`~workbench.inference.crosscheck.mcmc_lockstep.
        _BatchedEnsemble`; red-blue moves, every other move falls back to emcee).
        ``"emcee"``: :class:`emcee.EnsembleSampler` itself, in one thread per ensemble
        when ``lockstep``: the reference. The samples are the same bit for bit
        (``tests/test_mcmc.py``); the batched engine saves the threads' hand-overs and
        emcee's per-walker Python loops, most of the cost of a cheap target.

    Returns
    -------
    McmcResult

    Raises
    ------
    UsageError
        For arguments that do not make sense, starting points with a non-finite log
        density, or a ``log_prob`` that returns the wrong shape, NaN or ``+inf``.
    """
    t0 = time.perf_counter()
    if not callable(log_prob):
        raise UsageError("log_prob must be a callable returning log densities")
    _check_int("n_ensembles", n_ensembles, 2)
    _check_int("min_steps", min_steps, 10)
    _check_int("max_steps", max_steps, 10)
    if max_steps < min_steps:
        raise UsageError(f"max_steps ({max_steps}) must be at least min_steps ({min_steps})")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise UsageError(f"seed must be a non-negative integer, got {seed!r}")
    for name, value in (("tau_factor", tau_factor), ("burn_tau", burn_tau)):
        if not np.isfinite(value) or value <= 0:
            raise UsageError(f"{name} must be a positive number, got {value!r}")
    if not np.isfinite(tau_rtol) or not 0 < tau_rtol < 1:
        raise UsageError(f"tau_rtol must lie strictly between 0 and 1, got {tau_rtol!r}")

    if engine not in ENGINES:
        raise UsageError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    move_spec = _moves(moves)
    batched = engine == "batched" and batched_moves(move_spec())
    # Each ensemble gets two independent streams: one for its start, one for emcee's moves.
    children = np.random.SeedSequence(int(seed)).spawn(n_ensembles)
    streams = [child.spawn(2) for child in children]

    n_dim, starts = _starting_points(initial, streams, n_walkers)
    if n_walkers is None:
        n_walkers = starts[0].shape[0]
    names = _param_names(param_names, n_dim)

    # emcee always runs with `vectorize=True`: a point-wise target is batched here instead.
    target = _CountingLogProb(log_prob if vectorize else _row_by_row(log_prob), n_dim)

    batcher = _Lockstep(target, n_ensembles) if lockstep and not batched else None
    samplers: list[Any] = []  # emcee.EnsembleSampler or _BatchedEnsemble
    states: list[emcee.State] = []
    for e, start in enumerate(starts):
        lp0 = target(start)
        if not np.all(np.isfinite(lp0)):
            bad = int(np.sum(~np.isfinite(lp0)))
            raise UsageError(
                f"{bad} of {n_walkers} starting points of ensemble {e} have a non-finite log "
                "density; start the walkers inside the support (a smaller scale or a "
                "different centre)"
            )
        rng_state = np.random.RandomState(np.random.MT19937(streams[e][1])).get_state()
        if batched:
            samplers.append(_BatchedEnsemble(move_spec(), start, lp0, rng_state))
            continue
        fn = batcher.proxy(e) if batcher is not None else target
        sampler = emcee.EnsembleSampler(n_walkers, n_dim, fn, vectorize=True, moves=move_spec())
        samplers.append(sampler)
        states.append(emcee.State(start, log_prob=lp0, random_state=rng_state))

    # -- run in chunks until the 50-tau rule holds in every ensemble, or max_steps --------
    n_steps = 0
    target_steps = min_steps
    previous_tau: FloatArray | None = None
    while True:
        chunk = target_steps - n_steps
        try:
            if batched:
                _run_batched(samplers, chunk, target, lockstep)
            else:
                _run_chunk(samplers, states, chunk, batcher)
        except _EnsembleError as failure:
            err = failure.__cause__
            if err is None:
                raise
            if n_steps or not isinstance(err, ValueError):
                raise err from None
            # emcee refuses starting points that are (nearly) linearly dependent.
            raise UsageError(
                f"emcee cannot start ensemble {failure.ensemble}: {err}; spread the starting points"
            ) from err
        n_steps = target_steps
        tau = np.array([_tau(sampler.get_chain()) for sampler in samplers])
        long_enough = n_steps >= tau_factor * np.nanmax(tau, axis=1)
        if previous_tau is None:
            stable = np.zeros(n_ensembles, dtype=bool)
        else:
            change = np.abs(tau - previous_tau) / tau
            stable = np.all(change < tau_rtol, axis=1)
        stable &= np.all(np.isfinite(tau), axis=1)
        rule_met = long_enough & stable
        previous_tau = tau
        if np.all(rule_met) or n_steps >= max_steps:
            break
        tau_max = float(np.nanmax(tau)) if np.any(np.isfinite(tau)) else float(n_steps)
        wanted = math.ceil(_EXTEND_MARGIN * tau_factor * tau_max)
        grown = math.ceil((1.0 + _MIN_GROWTH) * n_steps)
        target_steps = min(max_steps, max(wanted, grown))

    # -- burn-in, thinning, pooling ---------------------------------------------------------
    finite_tau = tau[np.isfinite(tau)]
    tau_hi = float(finite_tau.max()) if finite_tau.size else float(n_steps)
    tau_lo = float(finite_tau.min()) if finite_tau.size else 1.0
    # Keep at least half the chain whatever tau says, so a failed run still yields draws
    # (and diagnostics) instead of an empty array.
    burn_in = min(math.ceil(burn_tau * tau_hi), n_steps // 2)
    thin = max(1, int(tau_lo // 2))
    chains = np.stack([s.get_chain(discard=burn_in, thin=thin) for s in samplers])  # (E, S, W, d)
    lps = np.stack([s.get_log_prob(discard=burn_in, thin=thin) for s in samplers])  # (E, S, W)
    # Walker-major pooling per ensemble (module docstring): (E, S, W, d) -> (E, W*S, d).
    n_e, n_s, n_w = chains.shape[:3]
    draws = chains.transpose(0, 2, 1, 3).reshape(n_e, n_w * n_s, n_dim)
    draw_lp = lps.transpose(0, 2, 1).reshape(n_e, n_w * n_s)
    samples = draws.reshape(-1, n_dim)
    acceptance = np.array([float(np.mean(s.acceptance_fraction)) for s in samplers])
    stuck = np.array([int(_stuck_walkers(s.get_chain()).sum()) for s in samplers])

    rhat, ess_bulk, ess_tail = rhat_ess(draws)

    reasons = _reasons(
        names=names,
        tau=tau,
        rule_met=rule_met,
        n_steps=n_steps,
        tau_factor=tau_factor,
        max_steps=max_steps,
        rhat=rhat,
        ess_bulk=ess_bulk,
        ess_tail=ess_tail,
        acceptance=acceptance,
        stuck=stuck,
    )
    cov = np.atleast_2d(np.cov(samples, rowvar=False))
    return McmcResult(
        param_names=names,
        samples=samples,
        mean=samples.mean(axis=0),
        sd=samples.std(axis=0, ddof=1),
        cov=cov,
        tau=tau,
        acceptance_fraction=acceptance,
        rhat=rhat,
        ess_bulk=ess_bulk,
        ess_tail=ess_tail,
        n_steps=int(n_steps),
        n_walkers=int(n_walkers),
        n_ensembles=int(n_ensembles),
        burn_in=int(burn_in),
        thin=int(thin),
        n_evaluations=int(target.calls),
        tau_rule_met=rule_met,
        converged=not reasons,
        reasons=reasons,
        draws=draws,
        draw_lp=draw_lp,
        seconds=time.perf_counter() - t0,
    )


# -- helpers ------------------------------------------------------------------------------
def _check_int(name: str, value: object, least: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < least:
        raise UsageError(f"{name} must be an integer of at least {least}, got {value!r}")


def _moves(moves: str | Any) -> Callable[[], Any]:
    """Return a factory of fresh move objects (moves may keep state; ensembles must not share)."""
    if isinstance(moves, str):
        if moves == "de":
            return lambda: [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
        if moves == "stretch":
            return lambda: emcee.moves.StretchMove()
        raise UsageError(f"moves must be 'de', 'stretch' or emcee move objects, got {moves!r}")
    return lambda: moves


def _row_by_row(log_prob: LogProb) -> LogProb:
    """Batch a point-wise log density (``vectorize=False``) by calling it row by row."""

    def batched(coords: FloatArray) -> FloatArray:
        return np.array([float(np.asarray(log_prob(row))) for row in coords], dtype=float)

    return batched


def _param_names(param_names: Sequence[str] | None, n_dim: int) -> tuple[str, ...]:
    if param_names is None:
        return tuple(f"x{i}" for i in range(n_dim))
    if isinstance(param_names, str):
        raise UsageError("param_names must be a sequence of names, not one string")
    names = tuple(str(n) for n in param_names)
    if len(names) != n_dim or len(set(names)) != n_dim or any(not n for n in names):
        raise UsageError(
            f"param_names must hold {n_dim} distinct non-empty names, got {list(names)!r}"
        )
    return names


def _starting_points(
    initial: Initial,
    streams: list[list[np.random.SeedSequence]],
    n_walkers: int | None,
) -> tuple[int, list[FloatArray]]:
    """Draw every ensemble's starting positions; return ``(d, [(W, d) per ensemble])``."""
    if n_walkers is not None:
        _check_int("n_walkers", n_walkers, 2)
        if n_walkers % 2:
            # emcee's red-blue moves split the walkers into two halves.
            raise UsageError(f"n_walkers must be even, got {n_walkers}")

    def default_walkers(n_dim: int) -> int:
        w = max(32, 4 * n_dim)
        return w + w % 2

    starts: list[FloatArray] = []
    if callable(initial):
        for init_stream, _ in streams:
            arr = np.asarray(initial(np.random.default_rng(init_stream)), dtype=np.float64)
            if arr.ndim != 2 or arr.shape[1] < 1:
                raise UsageError(
                    f"initial(rng) must return an (n_walkers, d) array, got shape {arr.shape}"
                )
            starts.append(arr)
        n_dim = starts[0].shape[1]
        if any(s.shape != starts[0].shape for s in starts):
            raise UsageError("initial(rng) must return the same shape for every ensemble")
        if n_walkers is not None and starts[0].shape[0] != n_walkers:
            raise UsageError(
                f"initial(rng) returned {starts[0].shape[0]} walkers but n_walkers is {n_walkers}"
            )
    else:
        spec = np.asarray(initial, dtype=np.float64)
        if spec.ndim != 2 or spec.shape[0] != 2 or spec.shape[1] < 1:
            raise UsageError(
                "initial must be a callable rng -> (n_walkers, d) or an array of shape "
                f"(2, d) holding a centre and a scale, got shape {spec.shape}"
            )
        centre, scale = spec
        if not (np.all(np.isfinite(spec)) and np.all(scale > 0)):
            raise UsageError("initial centre must be finite and its scale finite and positive")
        n_dim = spec.shape[1]
        w = default_walkers(n_dim) if n_walkers is None else n_walkers
        for init_stream, _ in streams:
            rng = np.random.default_rng(init_stream)
            starts.append(centre + scale * rng.standard_normal((w, n_dim)))
    w = starts[0].shape[0]
    if w < 2 * n_dim or w % 2:
        raise UsageError(
            f"emcee needs an even number of walkers of at least 2 d = {2 * n_dim}, got {w}"
        )
    if not all(np.all(np.isfinite(s)) for s in starts):
        raise UsageError("initial positions must be finite")
    return n_dim, starts


def _tau(chain: FloatArray) -> FloatArray:
    """Integrated autocorrelation time per parameter of a (steps, walkers, d) chain.

    ``tol=0`` switches off emcee's own length check (it would log a warning); the 50-tau rule
    is applied by the caller, which also records the outcome. Walkers that never moved are
    left out (their autocorrelation is 0/0 and would turn the whole estimate into NaN); the
    caller reports them separately. If no walker moved, tau is NaN.
    """
    moved = ~_stuck_walkers(chain)
    if not np.any(moved):
        return np.full(chain.shape[2], np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        return _integrated_time(chain[:, moved, :], c=5)


def _stuck_walkers(chain: FloatArray) -> NDArray[np.bool_]:
    """Walkers of a (steps, walkers, d) chain that never left their first position."""
    return np.asarray(np.all(chain == chain[:1], axis=(0, 2)), dtype=np.bool_)


def _reasons(
    *,
    names: tuple[str, ...],
    tau: FloatArray,
    rule_met: NDArray[np.bool_],
    n_steps: int,
    tau_factor: float,
    max_steps: int,
    rhat: FloatArray,
    ess_bulk: FloatArray,
    ess_tail: FloatArray,
    acceptance: FloatArray,
    stuck: NDArray[np.int_],
) -> list[str]:
    """One plain sentence per failed convergence check."""
    reasons: list[str] = []
    for e in np.flatnonzero(~rule_met):
        row = tau[e]
        if not np.all(np.isfinite(row)):
            frozen = [n for n, t in zip(names, row, strict=True) if not np.isfinite(t)]
            reasons.append(
                f"Ensemble {e}: the autocorrelation time of {', '.join(frozen)} could not be "
                "estimated (no walker moved)."
            )
            continue
        t_max = float(row.max())
        worst = names[int(np.argmax(row))]
        if n_steps < tau_factor * t_max:
            reasons.append(
                f"Ensemble {e}: the 50-tau rule was not met within max_steps = {max_steps}: "
                f"{n_steps} steps is {n_steps / t_max:.1f} times the autocorrelation time of "
                f"{worst} ({t_max:.1f} steps), fewer than {tau_factor:g}."
            )
        else:
            reasons.append(
                f"Ensemble {e}: the autocorrelation time estimate had not settled by "
                f"max_steps = {max_steps} (largest tau {t_max:.1f} steps, for {worst})."
            )
    for name, r in zip(names, rhat, strict=True):
        if not (np.isfinite(r) and r < RHAT_MAX):
            reasons.append(
                f"R-hat of {name} across ensembles is {r:.3f}, not below {RHAT_MAX}: the "
                "ensembles disagree (not mixed, or the posterior is multimodal)."
            )
    for name, eb, et in zip(names, ess_bulk, ess_tail, strict=True):
        if not (np.isfinite(eb) and eb >= ESS_MIN and np.isfinite(et) and et >= ESS_MIN):
            reasons.append(
                f"Effective sample size of {name} is {eb:.0f} (bulk) and {et:.0f} (tail), "
                f"below {ESS_MIN:.0f}."
            )
    for i_ens, a in enumerate(acceptance):
        if not ACCEPTANCE_MIN <= a <= ACCEPTANCE_MAX:
            reasons.append(
                f"Ensemble {i_ens}: acceptance fraction {a:.2f} is outside "
                f"[{ACCEPTANCE_MIN}, {ACCEPTANCE_MAX}]."
            )
    for i_ens, n_stuck in enumerate(stuck):
        if n_stuck:
            reasons.append(
                f"Ensemble {i_ens}: {n_stuck} walker(s) never moved during the run (stuck, "
                "for example in a region the others left behind)."
            )
    return reasons

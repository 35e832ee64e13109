"""Rao-Blackwellised particle filter over (C, K) (method ``"rbpf"``).

One filter whose parts share one particle cloud: the cloud with its per-particle Kalman
statistics, the batched piece filter, the tempered assimilation of a piece, the moves after
resampling (Liu-West, exact Metropolis) and the driver all index the same rows and draw from
one random stream in an order that fixes a seed's result.

Given damping C and stiffness K the model of :mod:`workbench.inference.core.problem` is
linear-Gaussian in ``(u, u', theta)``, so only (C, K) need particles: each particle carries
the exact Kalman statistics of ``(u, u')`` given its (C, K), and each piece's force
coefficients ``theta`` are integrated out analytically
(:func:`workbench.inference.kalman.filter.piece_filter`). Particles start uniform in
``problem.prior`` with ``(u, u')`` from :func:`~workbench.inference.kalman.filter.initial_state`.

Per piece ``j``
    1. Every particle runs the piece's Kalman filter from its hand-over state, giving the
       exact ``l_i = log p(y_piece_j | y_earlier, C_i, K_i)``.
    2. The piece is assimilated in *tempered* steps: ``log w_i += alpha l_i`` with the
       largest ``alpha`` (of what remains of 1) that keeps ``ESS >= ess_threshold * P``.
       Usually one step (alpha = 1) does it. When the piece alone would drop the ESS below
       the threshold, the filter resamples
       (:func:`workbench.inference.core.resampling.resample`) and moves the particles (below),
       re-runs the piece at the moved (C, K) and assimilates the rest of the piece. This is
       resampling "when ESS < threshold * P" done at the right moment inside the piece
       rather than after it, so one surprising piece can never collapse the cloud onto a
       single particle (Jasra et al. 2011, adaptive tempering).
    3. The estimate of ``log p(y_piece_j | y_earlier)`` is the sum over the steps of the log
       weighted mean of ``exp(alpha l_i)`` (log-sum-exp); ``loglik`` sums the pieces.
    4. Traces at the piece's last sample: weighted mean and sd of C and K, the ESS, the
       force coefficients' posterior mean and sd as mixture moments over the particles (law
       of total variance), distinct initial ancestors, distinct values of C and of K.

Moves after resampling
    *Liu-West kernel* (the usual case for a resampling late in the record):
    ``z <- a z + (1 - a) mean(z) + sqrt(1 - a^2) L eps`` with ``L L^T`` the weighted
    cloud's covariance before resampling and ``a = shrinkage`` (default 0.9, a jitter of
    0.44 posterior sd; Liu & West 2001). It keeps the cloud's mean and covariance and renews
    the values that resampling duplicated, at no extra likelihood cost; a moved particle
    keeps the ``(u, u')`` statistics and the history of its parent, an approximation of the
    order of the jitter. Values leaving the prior box are reflected at the bound (clipped
    if they jump across it), which keeps a uniform prior uniform near its edges.
    ``shrinkage=1`` switches it off. The default 0.9 was chosen on the record of
    ``analyses/benchmarks/identify_speed.py``, where a larger jitter than the earlier 0.98
    renewed the cloud better.

    *Exact Metropolis moves* (a second or later resampling inside one piece; the first
    resamplings of the record while ``exact_budget`` lasts; every resampling with
    ``rejuvenate="always"``). After a second resampling the piece has moved the posterior
    by more than the cloud's own spread, which a jitter-sized kernel cannot follow (it
    collapses onto the few particles nearest the new mass: measured on a simulated walking
    record whose fifth step moved the posterior of C by seven sd, from about 2600 to about
    290 N s/m, the Liu-West cloud stopped at 800 N s/m with a fifth of the exact width).
    The first resamplings are where the cloud collapses from the prior box onto a posterior
    a hundred times smaller, so that the rest of the record works with the descendants of
    a few prior draws; there the history is short and exact moves cheap (the budget, 0.3
    passes over the record by default, bounds their cost; on the benchmark record it pays
    for the moves at the first two resamplings). Each particle takes ``exact_moves``
    random-walk Metropolis steps (proposal covariance ``2.38^2 / 2`` times the cloud's)
    targeting the exact tempered posterior
    ``p(C, K) p(y_before_j | C, K) p(y_j | ...)^alpha``, whose likelihood the batched
    Kalman filter recomputes for the proposals from the first piece (resample-move / IBIS,
    Chopin 2002). This is exact but costs a pass over the pieces so far per step, so each
    proposal is first screened by a quadratic fitted to the cloud's exact log-targets and
    only those that pass are filtered (delayed acceptance, Christen and Fox 2005: the chain
    still targets the exact posterior; ``settings["metropolis_exact_evaluations"]`` counts
    the proposals that reach the exact stage, about a third on realistic walks,
    docs/validation/benchmarks.md);
    ``exact_moves=0`` falls back to Liu-West moves throughout.

Known limitation: a posterior that drifts. The Liu-West kernel only knows the cloud's
mean and covariance, so it cannot *transport* particles. When the record's pieces disagree
(a misspecified noise model, a preprocessing artefact, a parameter that really changes),
the exact posterior can keep its width while its mean walks along the record. Measured on a
30 s, 100 Hz simulated walking record (``simulate_walking(mass_kg=70, pacing_hz=1.8,
noise_sd_n=3, start="steady", seed=1)``, seed noise, n = 10): the exact posterior mean of C
moves from 411 to 701 N s/m (about 5 posterior sd of 61) between the 13th and the last
step; with the default settings the filter's cloud narrows to a third of that width and ends
3-4 sd short of the exact mean (seeds 0-2, 256 particles, measured with the earlier
shrinkage 0.98 and no exact budget). ``rejuvenate="always"`` (exact moves after every
resampling) agreed within 0.13 sd at about five times the cost. On records whose posterior
contracts steadily the default agrees with the exact posterior within about 0.3 sd
(``tests/test_rbpf.py``; on the benchmark record, 256 particles, ``identify_speed.py
--rbpf-seeds 10``: rms 0.14 (C) and 0.12 (K), at most 0.27 posterior sd). The exact method
(:mod:`workbench.inference.methods.exact`) is the reference when in doubt; a growing gap between the
two is itself a sign of misfit.

On a deck record with the joint time-history model the drift is the rule, not the
exception: the deck's information arrives in bursts with its envelope, and each burst moves
the posterior of C and K. ``rejuvenate="auto"`` (the default) therefore runs exact moves
after every resampling when the problem has a surface; docs/validation/deck.md measures the
step-by-step cross-check both ways.

Noise model, discretisation and the piece-boundary convention are those of
:mod:`workbench.inference.kalman.filter` (``"foh"`` by default); the random walks of C and K in
``problem.noise`` belong to the seed-faithful filter and are not used here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from tqdm.auto import tqdm

from workbench.errors import UsageError
from workbench.inference.core import (
    SCHEMES,
    IdentificationProblem,
    ParticleFilterOutput,
    StiffnessDampingPrior,
    ess,
    normalise_log_weights,
    resample,
)
from workbench.inference.kalman import (
    DISCRETISATIONS,
    Dynamics,
    PieceResult,
    filter_piece,
    force_input,
    initial_state,
    run_compiled,
    sample_dynamics,
)

__all__ = ["RBPF_PARTICLES", "REJUVENATE", "liu_west_move", "run_rbpf"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Particles when none are given: the default of :func:`run_rbpf` and of the ``RBPF`` method.
RBPF_PARTICLES = 256
#: When the particles get exact moves: chosen by the record ("auto"), on surprise, or always.
REJUVENATE = ("auto", "surprise", "always")

# Most tempering steps per piece; the last one assimilates whatever remains.
_MAX_STEPS = 50
# Optimal random-walk Metropolis scaling for a 2-D near-Gaussian target (Roberts et al.).
_RW_SCALE = 2.38**2 / 2.0


@dataclass
class _Cloud:
    """The particles and the Kalman statistics of the current piece, row per particle."""

    damping: FloatArray
    stiffness: FloatArray
    x_mean: FloatArray  # hand-in (u, u') of the current piece
    x_cov: FloatArray
    origin: IntArray  # index of the initial particle each descends from
    loglik: FloatArray  # the current piece's log-likelihood
    x_mean_next: FloatArray
    x_cov_next: FloatArray
    theta_mean: FloatArray
    theta_cov: FloatArray
    history: FloatArray | None  # exact log p(y before the piece | C, K), when known
    dyn: Dynamics | None = None  # the Kalman filter's constants of (damping, stiffness)

    def set_values(self, damping: FloatArray, stiffness: FloatArray) -> None:
        """Replace the (C, K) values (a move); their filter constants are recomputed later."""
        self.damping, self.stiffness = damping, stiffness
        self.dyn = None

    def set_piece(self, res: PieceResult, rows: NDArray[np.bool_] | None = None) -> None:
        """Store a piece result (for all particles, or for the ``rows`` given)."""
        for name in ("loglik", "x_mean_next", "x_cov_next", "theta_mean", "theta_cov"):
            if rows is None:
                setattr(self, name, getattr(res, name))
            else:
                getattr(self, name)[rows] = getattr(res, name)

    def take(self, idx: IntArray) -> None:
        """Keep the particles ``idx`` (resampling)."""
        for name in (
            "damping",
            "stiffness",
            "x_mean",
            "x_cov",
            "origin",
            "loglik",
            "x_mean_next",
            "x_cov_next",
            "theta_mean",
            "theta_cov",
        ):
            setattr(self, name, getattr(self, name)[idx])
        if self.history is not None:
            self.history = self.history[idx]
        if self.dyn is not None:
            self.dyn = self.dyn.take(idx)


class _Pieces:
    """The batched Kalman filter of one problem: pieces for a batch of (C, K) pairs."""

    def __init__(self, problem: IdentificationProblem, discretisation: str) -> None:
        self.problem = problem
        self.discretisation = discretisation
        self.force = force_input(problem)

    def dynamics(self, damping: FloatArray, stiffness: FloatArray) -> Dynamics:
        """Filter constants of the pairs (transition matrices etc.)."""
        return sample_dynamics(self.problem, damping, stiffness, self.discretisation)

    def run(
        self,
        piece: int,
        dyn: Dynamics,
        x_mean: FloatArray,
        x_cov: FloatArray,
        predictive: bool = False,
        theta_cov: bool = True,
    ) -> PieceResult:
        """Filter piece ``piece`` from the hand-in state (``kalman.piece_filter``)."""
        return filter_piece(
            self.problem, piece, dyn, x_mean, x_cov, self.force, predictive, theta_cov
        )

    def run_cloud(self, piece: int, cloud: _Cloud, predictive: bool = False) -> PieceResult:
        """Filter a piece for every particle of the cloud, reusing its filter constants."""
        if cloud.dyn is None:
            cloud.dyn = self.dynamics(cloud.damping, cloud.stiffness)
        return self.run(piece, cloud.dyn, cloud.x_mean, cloud.x_cov, predictive)


def run_rbpf(
    problem: IdentificationProblem,
    *,
    n_particles: int = RBPF_PARTICLES,
    seed: int | np.random.Generator | None = None,
    resampling: str = "systematic",
    ess_threshold: float = 0.5,
    shrinkage: float = 0.9,
    discretisation: str = "foh",
    progress: bool = False,
    exact_moves: int = 3,
    rejuvenate: str = "auto",
    exact_budget: float = 0.3,
    predictive: bool = False,
    delayed_acceptance: bool = True,
) -> ParticleFilterOutput:
    """Run the Rao-Blackwellised particle filter over (C, K).

    Parameters
    ----------
    problem : IdentificationProblem
        The identification problem; (C, K) start uniform in ``problem.prior``.
    n_particles : int, default :data:`RBPF_PARTICLES` (256)
        Number of (C, K) particles P.
    seed : int, Generator or None
        Randomness of the prior draws, resampling and moves (the only randomness).
    resampling : {"systematic", "stratified", "residual", "multinomial"}
        Resampling scheme.
    ess_threshold : float, default 0.5
        Resample (inside a piece, by tempering) so that the ESS never falls below
        ``ess_threshold * P``; 0 never resamples (plain importance sampling); 1 resamples
        after every piece (no tempering).
    shrinkage : float, default 0.9
        Liu-West shrinkage ``a`` in (0, 1]; 1 switches the kernel move off.
    discretisation : {"foh", "zoh", "euler"}
        See :func:`workbench.inference.kalman.filter.transition_matrices`.
    progress : bool, default False
        Show a tqdm progress bar over the pieces.
    exact_moves : int, default 3
        Metropolis steps per particle of an exact move (module docstring); 0 uses Liu-West
        moves only.
    rejuvenate : {"auto", "surprise", "always"}, default "auto"
        When to use exact moves instead of the Liu-West kernel: after a second resampling
        inside one piece and while ``exact_budget`` lasts, or after every resampling
        (resample-move / IBIS: exact whatever the record, several times slower; use it
        when the posterior drifts along the record, see the module docstring). ``"auto"``
        is ``"always"`` when the problem has a surface acting through K and C and
        ``"surprise"`` otherwise; ``settings["rejuvenate"]`` records the choice.
    exact_budget : float, default 0.3
        With ``rejuvenate="surprise"``: an ordinary resampling (the first in its piece)
        uses exact moves as long as the exact moves of such resamplings have cost at most
        this many passes over the record in total (a move at piece j costs
        ``exact_moves`` (+1 if the particles' history must be recomputed) times ``j + 1``
        piece filters). The first resamplings, where the cloud collapses from the prior
        onto the posterior and exact moves are cheap, then use them; 0 leaves them to the
        Liu-West kernel.
    delayed_acceptance : bool, default True
        Screen the exact moves' proposals by a quadratic fitted to the cloud's exact
        log-targets (module docstring); False runs plain Metropolis moves (the same target,
        every proposal filtered exactly).
    predictive : bool, default False
        Also return the one-step-ahead predictive mean of ``y`` at every sample: the mixture
        of the particles' exact predictions, weighted by their weights given the data before
        that sample (memory ``P L m^2`` doubles per piece of L samples).

    Returns
    -------
    ParticleFilterOutput
        ``method="rbpf"``, one trace row per piece (at its last sample). ``ess`` is the ESS
        after assimilating the piece (tempering keeps it >= ``ess_threshold * P``);
        ``resampled`` whether the piece needed a resampling; ``settings`` records the
        tempering steps per piece and the Metropolis acceptance rate.
    """
    n_part, a, n_mh = _check_args(
        problem, n_particles, resampling, ess_threshold, shrinkage, discretisation, exact_moves
    )
    if rejuvenate not in REJUVENATE:
        raise UsageError(f"rejuvenate must be one of {', '.join(REJUVENATE)}, got {rejuvenate!r}")
    if rejuvenate == "auto":
        # A deck's drive comes in bursts (a narrow-band deck's envelope), and each burst
        # moves the joint model's posterior of C and K by more than the cloud's width:
        # the drift the surprise rule cannot follow (module docstring).
        rejuvenate = "always" if problem.surface is not None else "surprise"
    if not (
        isinstance(exact_budget, int | float)
        and not isinstance(exact_budget, bool)
        and math.isfinite(exact_budget)
        and exact_budget >= 0
    ):
        raise UsageError(f"exact_budget must be a number >= 0, got {exact_budget!r}")
    always_exact = rejuvenate == "always"
    rng = np.random.default_rng(seed)
    n_p, m = problem.n_pieces, problem.n_coefficients
    log_p = math.log(n_part)
    box = problem.prior
    target_ess = ess_threshold * n_part
    tempering = 0.0 < ess_threshold < 1.0
    damping, stiffness = box.sample(n_part, rng)
    x_mean, x_cov = initial_state(problem, n_part)
    empty = np.empty(0)
    cloud = _Cloud(
        damping=damping,
        stiffness=stiffness,
        x_mean=x_mean,
        x_cov=x_cov,
        origin=np.arange(n_part, dtype=np.int64),
        loglik=empty,
        x_mean_next=empty,
        x_cov_next=empty,
        theta_mean=empty,
        theta_cov=empty,
        history=np.zeros(n_part),  # nothing before the first piece
    )
    lw = np.full(n_part, -log_p)  # normalised log-weights

    mean_tr = np.empty((n_p, 2))
    sd_tr = np.empty((n_p, 2))
    ess_tr = np.empty(n_p)
    resampled_tr = np.zeros(n_p, dtype=bool)
    distinct_tr = np.empty(n_p, dtype=np.int64)
    unique_tr = np.empty((n_p, 2), dtype=np.int64)
    incr_tr = np.zeros(n_p)
    coef_mean = np.empty((n_p, m))
    coef_sd = np.empty((n_p, m))
    steps_tr = np.ones(n_p, dtype=np.int64)
    counts = {
        "resamplings": 0,
        "liu_west_moves": 0,
        "exact_move_events": 0,
        "proposals": 0,
        "accepted": 0,
        "exact_evaluations": 0,
    }
    pred = np.empty((problem.n_samples, 3)) if predictive else None

    pieces = _Pieces(problem, discretisation)
    budget = exact_budget * n_p  # piece-runs for exact moves at ordinary resamplings
    spent = 0.0

    bar = tqdm(total=n_p, desc="rbpf", unit="piece", disable=not progress)
    try:
        for j in range(n_p):
            res = pieces.run_cloud(j, cloud, predictive)
            cloud.set_piece(res)
            if pred is not None:
                s, e = problem.piece_starts[j], problem.piece_starts[j + 1]
                pred[s:e] = _mixture_prediction(lw, res)
            remaining, done = 1.0, 0.0
            for step in range(_MAX_STEPS):
                alpha = remaining
                if tempering and step < _MAX_STEPS - 1:
                    alpha = _step_size(lw, cloud.loglik, remaining, target_ess)
                # Adding log P makes the log mean weight the estimate of this step's
                # log E[p(y_piece | y_earlier, C, K)^alpha] (the SMC likelihood estimate).
                lw, increment = normalise_log_weights(lw + log_p + alpha * cloud.loglik)
                incr_tr[j] += increment
                remaining -= alpha
                done += alpha
                if remaining <= 0.0:
                    break
                steps_tr[j] = step + 2
                resampled_tr[j] = True
                reference = (cloud.damping, cloud.stiffness, np.exp(lw))
                cloud.take(resample(lw, rng, resampling))
                lw = np.full(n_part, -log_p)
                counts["resamplings"] += 1
                # Exact moves: always, after a second resampling in one piece, or while
                # their cost (Metropolis steps, plus the history if unknown, over pieces
                # 0..j) fits the budget; otherwise the Liu-West kernel.
                cost = (n_mh + (cloud.history is None)) * (j + 1)
                exact = n_mh > 0 and (always_exact or step > 0 or spent + cost <= budget)
                if exact and not always_exact and step == 0:
                    spent += cost
                if exact:
                    counts["exact_move_events"] += 1
                    if cloud.history is None:
                        _exact_history(pieces, j, cloud)
                    _metropolis(pieces, j, cloud, done, n_mh, box, rng, counts, delayed_acceptance)
                elif a < 1.0:
                    cloud.set_values(
                        *liu_west_move(
                            cloud.damping, cloud.stiffness, box, a, rng, reference=reference
                        )
                    )
                    cloud.history = None  # moved values inherit their parents' history
                    counts["liu_west_moves"] += 1
                    cloud.set_piece(pieces.run_cloud(j, cloud))
            if ess_threshold >= 1.0:
                # ess_threshold = 1: resample after the piece, Liu-West move; the moved
                # particles start the next piece from their parents' hand-over states.
                resampled_tr[j] = True
                reference = (cloud.damping, cloud.stiffness, np.exp(lw))
                cloud.take(resample(lw, rng, resampling))
                lw = np.full(n_part, -log_p)
                counts["resamplings"] += 1
                if n_mh > 0 and always_exact:
                    counts["exact_move_events"] += 1
                    if cloud.history is None:
                        _exact_history(pieces, j, cloud)
                    _metropolis(pieces, j, cloud, 1.0, n_mh, box, rng, counts, delayed_acceptance)
                elif a < 1.0:
                    cloud.set_values(
                        *liu_west_move(
                            cloud.damping, cloud.stiffness, box, a, rng, reference=reference
                        )
                    )
                    cloud.history = None
                    counts["liu_west_moves"] += 1
            w = np.exp(lw)
            params = np.column_stack([cloud.damping, cloud.stiffness])
            mean_tr[j] = w @ params
            sd_tr[j] = np.sqrt(np.maximum(w @ (params - mean_tr[j]) ** 2, 0.0))
            # Mixture moments of the piece's force coefficients (law of total variance).
            coef_mean[j] = w @ cloud.theta_mean
            within = w @ np.diagonal(cloud.theta_cov, axis1=1, axis2=2)
            between = w @ (cloud.theta_mean - coef_mean[j]) ** 2
            coef_sd[j] = np.sqrt(within + between)
            ess_tr[j] = ess(lw)
            distinct_tr[j] = np.unique(cloud.origin).size
            unique_tr[j] = (np.unique(cloud.damping).size, np.unique(cloud.stiffness).size)
            # Hand over to the next piece.
            if cloud.history is not None:
                cloud.history = cloud.history + cloud.loglik
            cloud.x_mean, cloud.x_cov = cloud.x_mean_next, cloud.x_cov_next
            bar.update(1)
    finally:
        bar.close()

    ends = problem.piece_starts[1:] - 1
    settings: dict[str, Any] = {
        "resampling": resampling,
        "ess_threshold": float(ess_threshold),
        "shrinkage": a,
        "exact_moves": n_mh,
        "rejuvenate": rejuvenate,
        "exact_budget": float(exact_budget),
        "discretisation": discretisation,
        "n_particles": n_part,
        "prior": box.label,
        "resample_count": counts["resamplings"],
        "liu_west_moves": counts["liu_west_moves"],
        "exact_move_events": counts["exact_move_events"],
        "metropolis_acceptance": (
            counts["accepted"] / counts["proposals"] if counts["proposals"] else None
        ),
        "delayed_acceptance": delayed_acceptance,
        "metropolis_proposals": counts["proposals"],
        "metropolis_exact_evaluations": counts["exact_evaluations"],
        "tempering_steps": steps_tr.tolist(),
        "theta": "integrated out per piece (Kalman)",
    }
    return ParticleFilterOutput(
        method="rbpf",
        trace_time_s=np.asarray(problem.time_s[ends], dtype=np.float64),
        mean=mean_tr,
        sd=sd_tr,
        ess=ess_tr,
        resampled=resampled_tr,
        distinct_ancestors=distinct_tr,
        unique_values=unique_tr,
        loglik=float(incr_tr.sum()),
        loglik_increments=incr_tr,
        particles=np.column_stack([cloud.damping, cloud.stiffness]),
        log_weights=lw,
        piece_mean=mean_tr.copy(),
        piece_sd=sd_tr.copy(),
        piece_coefficients_mean=coef_mean,
        piece_coefficients_sd=coef_sd,
        predicted_obs=pred,
        n_particles=n_part,
        seed=seed if isinstance(seed, int) else None,
        settings=settings,
    )


def _mixture_prediction(lw: FloatArray, res: PieceResult) -> FloatArray:
    """One-step-ahead mean of the particle mixture at every sample of a piece."""
    assert res.predicted_obs is not None and res.partial_loglik is not None
    # Weight of particle i at sample k: its weight before the piece times the likelihood of
    # the piece's samples before k.
    within = lw[:, None] + res.partial_loglik
    within -= within.max(axis=0)
    wk = np.exp(within)
    wk /= wk.sum(axis=0)
    return np.einsum("pl,plr->lr", wk, res.predicted_obs)


def _exact_history(pieces: _Pieces, piece: int, cloud: _Cloud) -> None:
    """Recompute the particles' statistics exactly from the first piece up to ``piece``."""
    if cloud.dyn is None:
        cloud.dyn = pieces.dynamics(cloud.damping, cloud.stiffness)
    hist, x_mean, x_cov, res = _run_up_to(pieces, piece, cloud.dyn)
    cloud.history, cloud.x_mean, cloud.x_cov = hist, x_mean, x_cov
    cloud.set_piece(res)


def _run_up_to(
    pieces: _Pieces, piece: int, dyn: Dynamics
) -> tuple[FloatArray, FloatArray, FloatArray, PieceResult]:
    """Kalman filter from the first piece through ``piece`` for a batch of (C, K).

    Returns the log-likelihood of the pieces before ``piece``, the hand-in state of
    ``piece`` and its :class:`PieceResult`.
    """
    n = dyn.k_m.size
    x_mean, x_cov = initial_state(pieces.problem, n)
    hist = np.zeros(n)
    if piece > 0:
        # The pieces before ``piece`` in one compiled call: only their likelihood and the
        # hand-over state are needed.
        run = run_compiled(pieces.problem, dyn, pieces.force, 0, piece, x_mean, x_cov, False)
        hist = run[0].sum(axis=1)
        x_mean, x_cov = run[5], run[6]
    return hist, x_mean, x_cov, pieces.run(piece, dyn, x_mean, x_cov)


def _metropolis(
    pieces: _Pieces,
    piece: int,
    cloud: _Cloud,
    temperature: float,
    n_steps: int,
    box: StiffnessDampingPrior,
    rng: np.random.Generator,
    counts: dict[str, int],
    delayed_acceptance: bool = True,
) -> None:
    """Random-walk Metropolis steps on ``p(C, K | y_before) p(y_piece | ...)^temperature``.

    Delayed acceptance (Christen and Fox 2005): a proposal is first screened against a
    quadratic fitted to the cloud's exact log-targets, and only the proposals that pass are
    filtered exactly and accepted with the ratio of the exact to the screened odds. The
    chain targets the exact posterior whatever the quadratic's quality (a poor fit only
    passes more or fewer proposals to the exact stage); a good one spares the exact filter
    of the pieces so far for most of the proposals that plain Metropolis would reject.
    """
    assert cloud.history is not None
    z = np.column_stack([cloud.damping, cloud.stiffness])
    cov = np.cov(z, rowvar=False, bias=True)
    root = _sym_sqrt(_RW_SCALE * cov)
    target = cloud.history + temperature * cloud.loglik
    screen = _quadratic_screen(z, target) if delayed_acceptance else None
    moved = False
    for _ in range(n_steps):
        proposal = z + rng.standard_normal(z.shape) @ root.T
        log_u = np.log(rng.uniform(size=z.shape[0]))
        log_u_screen = np.log(rng.uniform(size=z.shape[0]))
        inside = box.contains(proposal[:, 0], proposal[:, 1])
        counts["proposals"] += z.shape[0]
        screened = np.zeros(z.shape[0]) if screen is None else screen(proposal) - screen(z)
        inside &= log_u_screen < screened
        if not np.any(inside):
            continue
        counts["exact_evaluations"] += int(np.count_nonzero(inside))
        dyn = pieces.dynamics(proposal[inside, 0], proposal[inside, 1])
        hist, x_mean, x_cov, res = _run_up_to(pieces, piece, dyn)
        new_target = hist + temperature * res.loglik
        accept = log_u[inside] < new_target - target[inside] - screened[inside]
        rows = np.flatnonzero(inside)[accept]
        counts["accepted"] += rows.size
        if rows.size == 0:
            continue
        moved = True
        z[rows] = proposal[rows]
        target[rows] = new_target[accept]
        cloud.history[rows] = hist[accept]
        cloud.x_mean[rows] = x_mean[accept]
        cloud.x_cov[rows] = x_cov[accept]
        for name in ("loglik", "x_mean_next", "x_cov_next", "theta_mean", "theta_cov"):
            getattr(cloud, name)[rows] = getattr(res, name)[accept]
    if moved:
        cloud.set_values(np.ascontiguousarray(z[:, 0]), np.ascontiguousarray(z[:, 1]))


def _quadratic_screen(
    z: FloatArray, target: FloatArray
) -> Callable[[FloatArray], FloatArray] | None:
    """Return a quadratic in (C, K) fitted to exact log-targets, or None without a fit.

    Least squares over the cloud's distinct values, in coordinates standardised by the
    cloud's spread; None (every proposal goes to the exact stage) with too few distinct
    values or a fit that is not concave, whose odds would screen out the mode.
    """
    values, first = np.unique(z, axis=0, return_index=True)
    if values.shape[0] < 12:
        return None
    centre = values.mean(axis=0)
    scale = values.std(axis=0)
    if not np.all(scale > 0):
        return None

    def design(points: FloatArray) -> FloatArray:
        a, b = ((points - centre) / scale).T
        return np.column_stack([np.ones_like(a), a, b, a * a, a * b, b * b])

    coef, *_ = np.linalg.lstsq(design(values), target[first], rcond=None)
    hessian = np.array([[2.0 * coef[3], coef[4]], [coef[4], 2.0 * coef[5]]])
    if not np.all(np.isfinite(coef)) or np.any(np.linalg.eigvalsh(hessian) >= 0.0):
        return None
    return lambda points: design(points) @ coef


def _sym_sqrt(cov: FloatArray) -> FloatArray:
    """Return ``L`` with ``L L^T = cov``, also for a singular ``cov``."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    return vecs * np.sqrt(np.clip(vals, 0.0, None))


def _step_size(lw: FloatArray, loglik: FloatArray, remaining: float, target_ess: float) -> float:
    """Largest tempering exponent alpha <= remaining with ESS(lw + alpha loglik) >= target.

    ESS decreases with alpha for all practical weights; bisection on alpha to a relative
    precision of 1e-3 is plenty (the exponent only sets when to resample).
    """
    if ess(lw + remaining * loglik) >= target_ess:
        return remaining
    lo, hi = 0.0, remaining
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if ess(lw + mid * loglik) >= target_ess:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-3 * hi:
            break
    # A step of zero would not advance; the smallest positive one still makes progress.
    return max(lo, 1e-6 * remaining)


def liu_west_move(
    damping: FloatArray,
    stiffness: FloatArray,
    box: StiffnessDampingPrior,
    shrinkage: float,
    rng: np.random.Generator,
    *,
    reference: tuple[FloatArray, FloatArray, FloatArray] | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Liu-West kernel move of equally weighted (C, K) particles, kept inside the prior box.

    Parameters
    ----------
    damping, stiffness : ndarray, shape (P,)
        Particles (after resampling, so equally weighted).
    box : StiffnessDampingPrior
        Prior box; values that leave it are reflected at the bound, then clipped.
    shrinkage : float
        ``a`` in (0, 1): ``z <- a z + (1 - a) mean + sqrt(1 - a^2) L eps``.
    rng : numpy.random.Generator
        Source of the jitter.
    reference : (damping, stiffness, weights), optional
        The weighted cloud before resampling, whose mean and covariance the kernel uses
        (less noisy than the resampled copies'); default the particles themselves.

    Returns
    -------
    damping, stiffness : ndarray, shape (P,)
        Moved particles; the cloud's mean and covariance are preserved in expectation.
    """
    z = np.column_stack([damping, stiffness])
    if reference is None:
        centre = z.mean(axis=0)
        cov = np.atleast_2d(np.cov(z, rowvar=False, bias=True))
    else:
        ref = np.column_stack(reference[:2])
        w = reference[2] / np.sum(reference[2])
        centre = w @ ref
        cov = (ref - centre).T @ ((ref - centre) * w[:, None])
    root = _sym_sqrt(cov)
    eps = rng.standard_normal(z.shape)
    moved = (
        shrinkage * z + (1.0 - shrinkage) * centre + math.sqrt(1.0 - shrinkage**2) * (eps @ root.T)
    )
    lo = np.array([box.damping_ns_per_m[0], box.stiffness_n_per_m[0]])
    hi = np.array([box.damping_ns_per_m[1], box.stiffness_n_per_m[1]])
    moved = np.where(moved < lo, 2.0 * lo - moved, moved)
    moved = np.where(moved > hi, 2.0 * hi - moved, moved)
    moved = np.clip(moved, lo, hi)
    return np.ascontiguousarray(moved[:, 0]), np.ascontiguousarray(moved[:, 1])


def _check_args(
    problem: IdentificationProblem,
    n_particles: int,
    resampling: str,
    ess_threshold: float,
    shrinkage: float,
    discretisation: str,
    exact_moves: int,
) -> tuple[int, float, int]:
    if not isinstance(problem, IdentificationProblem):
        raise UsageError("run_rbpf needs an IdentificationProblem (see build_problem)")
    if isinstance(n_particles, bool) or int(n_particles) != n_particles or n_particles < 2:
        raise UsageError(
            f"'n_particles' must be a whole number of at least 2, got {n_particles!r}",
            parameter="n_particles",
        )
    if resampling not in SCHEMES:
        raise UsageError(
            f"unknown resampling scheme {resampling!r}; use one of {', '.join(SCHEMES)}"
        )
    if not (isinstance(ess_threshold, int | float) and 0.0 <= ess_threshold <= 1.0):
        raise UsageError(f"ess_threshold must be between 0 and 1, got {ess_threshold!r}")
    if not (isinstance(shrinkage, int | float) and 0.0 < shrinkage <= 1.0):
        raise UsageError(
            f"shrinkage must be in (0, 1] (1 switches the Liu-West move off), got {shrinkage!r}"
        )
    if discretisation not in DISCRETISATIONS:
        raise UsageError(
            f"unknown discretisation {discretisation!r}; use one of {', '.join(DISCRETISATIONS)}"
        )
    if isinstance(exact_moves, bool) or int(exact_moves) != exact_moves or exact_moves < 0:
        raise UsageError(f"exact_moves must be a whole number >= 0, got {exact_moves!r}")
    return int(n_particles), float(shrinkage), int(exact_moves)

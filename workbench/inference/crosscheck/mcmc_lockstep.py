"""Several emcee ensembles in lockstep, one call of the target per round.

Two drivers of the same rounds (:mod:`workbench.inference.crosscheck.mcmc`, "One call of the target
per round, for all ensembles"):

* threads (the reference, ``engine="emcee"``): :class:`_Lockstep` gathers the log-density
  requests of emcee's samplers, one thread each, and evaluates them in one batched call
  (ensemble order, so the batch is the same on every run); :func:`_run_chunk` advances
  every ensemble by a chunk of steps, in such threads or one after the other, and reports
  the first ensemble that failed;
* one thread (the default, ``engine="batched"``): :class:`_BatchedEnsemble` steps an
  ensemble as a generator that yields each proposal and receives its log densities, with
  the draws of emcee's sampler; :func:`_run_batched` serves the ensembles' requests round
  by round, the same batches as the threads.

Its own idea: driving several ensembles through shared rounds, with failure propagation,
knowing nothing of convergence or of what the target computes.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Generator
from typing import Any

import emcee
import numpy as np
from emcee.ensemble import walkers_independent
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class _EnsembleError(Exception):
    """An ensemble's run failed; ``__cause__`` is the original exception."""

    def __init__(self, ensemble: int) -> None:
        super().__init__(f"ensemble {ensemble} failed")
        self.ensemble = ensemble


class _PeerFailure(RuntimeError):
    """Raised in an ensemble waiting on a round whose evaluation failed in another thread."""


class _Lockstep:
    """Gather the log-density requests of all running ensembles into one call per round."""

    def __init__(self, target: Callable[[FloatArray], FloatArray], n: int) -> None:
        self._target = target
        self._cond = threading.Condition()
        self._active = set(range(n))
        self._pending: dict[int, FloatArray] = {}
        self._results: dict[int, FloatArray] = {}
        self._error: BaseException | None = None

    def proxy(self, e: int) -> Callable[[FloatArray], FloatArray]:
        """Return the log density that ensemble ``e`` sees."""
        return lambda coords: self._submit(e, coords)

    def restart(self, n: int) -> None:
        """Before a chunk: all ``n`` ensembles run again."""
        self._active = set(range(n))
        self._error = None

    def retire(self, e: int) -> None:
        """Ensemble ``e`` finished its chunk (or failed): stop waiting for it."""
        with self._cond:
            self._active.discard(e)
            self._evaluate_if_ready()

    def _submit(self, e: int, coords: FloatArray) -> FloatArray:
        with self._cond:
            self._pending[e] = np.asarray(coords, dtype=np.float64)
            self._evaluate_if_ready()
            while e not in self._results and self._error is None:
                self._cond.wait()
            if e in self._results:
                return self._results.pop(e)
            raise _PeerFailure("another ensemble's log-density call failed") from self._error

    def _evaluate_if_ready(self) -> None:
        # Called with the lock held, by whichever thread completes the round.
        if not self._pending or set(self._pending) != self._active:
            return
        keys = sorted(self._pending)
        batch = [self._pending.pop(k) for k in keys]
        try:
            lp = self._target(np.concatenate(batch))
        except BaseException as err:
            self._error = err
            self._cond.notify_all()
            raise
        edges = np.cumsum([len(x) for x in batch])[:-1]
        for k, part in zip(keys, np.split(lp, edges), strict=True):
            self._results[k] = part
        self._cond.notify_all()


def _run_chunk(
    samplers: list[emcee.EnsembleSampler],
    states: list[emcee.State],
    chunk: int,
    batcher: _Lockstep | None,
) -> None:
    """Advance every ensemble by ``chunk`` steps (in lockstep threads when batching)."""
    if batcher is None:
        for e, sampler in enumerate(samplers):
            try:
                states[e] = sampler.run_mcmc(states[e], chunk, progress=False)
            except Exception as err:
                raise _EnsembleError(e) from err
        return
    batcher.restart(len(samplers))
    errors: dict[int, BaseException] = {}

    def run(e: int) -> None:
        try:
            states[e] = samplers[e].run_mcmc(states[e], chunk, progress=False)
        except BaseException as err:
            errors[e] = err
        finally:
            batcher.retire(e)

    threads = [threading.Thread(target=run, args=(e,)) for e in range(len(samplers))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        # The original failure, not the "another ensemble failed" of those waiting on it.
        first = min(errors, key=lambda e: (isinstance(errors[e], _PeerFailure), e))
        raise _EnsembleError(first) from errors[first]


# -- one thread: the ensembles as generators ----------------------------------------------
class _BatchedEnsemble:
    """One emcee ensemble stepped by hand: the arithmetic of emcee's sampler, no thread.

    It draws from its own :class:`numpy.random.RandomState` exactly what
    :meth:`emcee.EnsembleSampler.sample` and :meth:`emcee.moves.RedBlueMove.propose` draw,
    in the same order (the move, the split, the proposal, one uniform per walker for the
    acceptance), so a run gives the samples of emcee's own sampler bit for bit
    (``tests/test_mcmc.py``). What it leaves out costs time and draws nothing: a thread and
    two lock hand-overs per log-density request, the random state copied after every step,
    the per-walker Python loops of the acceptance and of emcee's blob handling.

    Only red-blue moves (every move of emcee's ensemble family: stretch, DE, DE snooker,
    KDE, and :class:`~workbench.inference.crosscheck.step_target.GaussianFitMove`) are stepped here;
    :func:`batched_moves` says whether a move list qualifies.
    """

    def __init__(
        self,
        moves: Any,
        coords: FloatArray,
        log_prob: FloatArray,
        random_state: Any,
    ) -> None:
        if isinstance(moves, list | tuple):
            pairs = [m if isinstance(m, tuple) else (m, 1.0) for m in moves]
            self.moves = [m for m, _ in pairs]
            weights = np.atleast_1d([w for _, w in pairs]).astype(float)
        else:
            self.moves, weights = [moves], np.ones(1)
        self.weights = weights / np.sum(weights)
        # The cumulative weights RandomState.choice forms from ``p`` (it draws one uniform
        # and searches them), formed once.
        cdf = self.weights.cumsum()
        cdf /= cdf[-1]
        self._cdf = cdf
        self.random = np.random.RandomState()
        self.random.set_state(random_state)
        self.coords = np.array(coords, dtype=np.float64)
        self.log_prob = np.array(log_prob, dtype=np.float64)
        self.n_walkers, self.n_dim = self.coords.shape
        self.chain = np.empty((0, self.n_walkers, self.n_dim))
        self.lp = np.empty((0, self.n_walkers))
        self.accepted = np.zeros(self.n_walkers)
        self.iteration = 0

    def walk(self, n_steps: int) -> Generator[FloatArray, FloatArray, None]:
        """Advance ``n_steps``: yield every proposal, receive its log densities."""
        if not walkers_independent(self.coords):
            raise ValueError(
                "Initial state has a large condition number. Make sure that your walkers are "
                "linearly independent for the best performance"
            )
        start = self.iteration
        self.chain = np.concatenate([self.chain, np.empty((n_steps, *self.coords.shape))])
        self.lp = np.concatenate([self.lp, np.empty((n_steps, self.n_walkers))])
        coords, log_prob, random = self.coords, self.log_prob, self.random
        all_inds = np.arange(self.n_walkers)
        for step in range(n_steps):
            # RandomState.choice(moves, p=weights): one uniform, searched in the cdf.
            move = self.moves[int(self._cdf.searchsorted(random.random_sample(), side="right"))]
            if self.n_walkers < 2 * self.n_dim and not move.live_dangerously:
                raise RuntimeError(
                    "It is unadvisable to use a red-blue move with fewer walkers than twice "
                    "the number of dimensions."
                )
            move.setup(coords)
            accepted = np.zeros(self.n_walkers, dtype=bool)
            inds = all_inds % move.nsplits
            if move.randomize_split:
                random.shuffle(inds)
            masks = [inds == j for j in range(move.nsplits)]
            for split in range(move.nsplits):
                subset = masks[split]
                sets = [coords[m] for m in masks]
                q, factors = move.get_proposal(
                    sets[split], sets[:split] + sets[split + 1 :], random
                )
                q = np.atleast_2d(q)
                if not np.isfinite(q).all():
                    what = "infinite" if np.isinf(q).any() else "NaN"
                    raise ValueError(f"At least one parameter value was {what}")
                # ``new`` is free of NaN (the runner's wrapper checks every evaluation).
                new = yield q
                # One uniform per walker of the half, drawn in the order emcee draws them.
                draws = random.rand(q.shape[0])
                take = factors + new - log_prob[subset] > np.log(draws)
                accepted[subset] = take
                rows = subset & accepted
                coords[rows] = q[take]
                log_prob[rows] = new[take]
            self.chain[start + step] = coords
            self.lp[start + step] = log_prob
            self.accepted += accepted
            self.iteration += 1

    def get_chain(self, discard: int = 0, thin: int = 1) -> FloatArray:
        """Return the stored chain (steps, walkers, d), as emcee's ``get_chain``."""
        return self.chain[discard + thin - 1 : self.iteration : thin]

    def get_log_prob(self, discard: int = 0, thin: int = 1) -> FloatArray:
        """Return the stored log densities (steps, walkers)."""
        return self.lp[discard + thin - 1 : self.iteration : thin]

    @property
    def acceptance_fraction(self) -> FloatArray:
        """Accepted share of every walker's proposals."""
        return self.accepted / float(self.iteration)


def batched_moves(moves: Any) -> bool:
    """Whether :class:`_BatchedEnsemble` can step these moves (red-blue moves only)."""
    items = moves if isinstance(moves, list | tuple) else [moves]
    return all(
        isinstance(m[0] if isinstance(m, tuple) else m, emcee.moves.RedBlueMove) for m in items
    )


def _run_batched(
    ensembles: list[_BatchedEnsemble],
    chunk: int,
    target: Callable[[FloatArray], FloatArray],
    lockstep: bool,
) -> None:
    """Advance every ensemble by ``chunk`` steps, all requests of a round in one call.

    Round r serves the r-th request of every ensemble still running, in ensemble order:
    the batches of the threaded lockstep (:class:`_Lockstep`). Without ``lockstep`` each
    request is evaluated on its own.
    """
    walks = {}
    pending: dict[int, FloatArray] = {}
    for e, ens in enumerate(ensembles):
        walks[e] = ens.walk(chunk)
        try:
            pending[e] = next(walks[e])
        except StopIteration:
            continue
        except Exception as err:
            raise _EnsembleError(e) from err
    while pending:
        keys = sorted(pending)
        batch = [pending.pop(k) for k in keys]
        if lockstep:
            try:
                lp = target(np.concatenate(batch))
            except Exception as err:
                raise _EnsembleError(keys[-1]) from err
            parts, start = [], 0
            for x in batch:
                parts.append(lp[start : start + len(x)])
                start += len(x)
        else:
            parts = []
            for k, x in zip(keys, batch, strict=True):
                try:
                    parts.append(target(x))
                except Exception as err:
                    raise _EnsembleError(k) from err
        for k, part in zip(keys, parts, strict=True):
            try:
                pending[k] = walks[k].send(part)
            except StopIteration:
                continue
            except Exception as err:
                raise _EnsembleError(k) from err

"""Several emcee ensembles in lockstep threads, one call of the target per round.

:class:`_Lockstep` gathers the log-density requests of all running ensembles and evaluates
them in one batched call (ensemble order, so the batch is the same on every run);
:func:`_run_chunk` advances every ensemble by a chunk of steps, in such threads or one after
the other, and reports the first ensemble that failed (:mod:`workbench.inference.mcmc`, "One
call of the target per round, for all ensembles").

Its own idea: thread coordination with its failure propagation, which knows nothing of
convergence or of what the target computes.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import emcee
import numpy as np
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

"""The Kalman engine: the exact likelihood of the SMD model given (C, K), batched over (C, K).

The filter (:mod:`~workbench.inference.kalman.filter`) and its per-sample numpy loop, the
discretisation of the state over one sample interval, the compiled routes (the structured
Kalman kernel, and the harmonic sufficient statistics where the problem allows), the
readable reference filter and the result containers. The methods, the surface route and
the cross-check take their likelihood from here.
"""

from workbench.inference.kalman.compiled import ForceInput, force_input, run_compiled
from workbench.inference.kalman.discretisation import (
    DISCRETISATIONS,
    Dynamics,
    sample_dynamics,
    transition_matrices,
)
from workbench.inference.kalman.filter import (
    filter_piece,
    initial_state,
    piece_filter,
    record_loglik,
)
from workbench.inference.kalman.reference import dense_kalman_loglik
from workbench.inference.kalman.results import DenseResult, PieceResult, RecordResult

__all__ = [
    "DISCRETISATIONS",
    "DenseResult",
    "Dynamics",
    "ForceInput",
    "PieceResult",
    "RecordResult",
    "dense_kalman_loglik",
    "filter_piece",
    "force_input",
    "initial_state",
    "piece_filter",
    "record_loglik",
    "run_compiled",
    "sample_dynamics",
    "transition_matrices",
]

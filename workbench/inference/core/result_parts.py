"""The typed parts of an identification result beside its posterior.

An :class:`~workbench.inference.core.results.IdentificationResult` holds the posterior every
method shares (draws of C and K, force coefficients per piece, the identifiability report)
and, beside it, what only some runs produce:

- :class:`Route`: which method ran and where C and K came from, with the reason (always set
  by :func:`~workbench.inference.pipeline.identification.identify`);
- :class:`FilterResults`: the traces and diagnostics only a particle filter has (None for
  the exact grid);
- :class:`GridResults`: the exact grid posterior's summary (None for the filters);
- :class:`SurfaceReport`: what the walking surface contributed (the JSON's ``surface``);
- :class:`EffectPosterior`: the posterior of the model's effects (the JSON's ``effects``).

Each is frozen, so a result stays immutable, and plain data, so results pickle between
the processes of batch work.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "TIME_HISTORY",
    "TRANSMISSIBILITY",
    "EffectPosterior",
    "FilterResults",
    "GridResults",
    "Route",
    "SurfaceReport",
]

FloatArray = NDArray[np.float64]

#: Where C and K come from: the deck's transmissibility (the surface route) or the time
#: history of the response (every method's own likelihood).
TRANSMISSIBILITY = "transmissibility"
TIME_HISTORY = "time history"


@dataclass(frozen=True)
class Route:
    """Which method ran on a problem, where C and K came from, and why.

    The method the settings asked for is kept beside the one that ran: on the surface route
    the exact grid runs on the deck's transmissibility whatever was asked for, and the route
    says so.

    Attributes
    ----------
    requested_method : str
        The method the settings named (``"exact"``, ``"rbpf"``, ``"pf"``).
    method : str
        The method that ran (``"exact"`` on the surface route).
    c_and_k_from : {"transmissibility", "time history"}
        Where the posterior of C and K came from.
    reason : str
        One sentence: why this route.
    bins : int or None
        Frequency bins of the transmissibility likelihood (transmissibility route only).
    band_hz : (float, float) or None
        Lowest and highest bin frequency [Hz] (transmissibility route only).
    deck_only_near_gait_harmonics : bool
        The record's surface was coupled, but its deck moved only near the walker's gait
        harmonics, so the route fell back to the time history.
    """

    requested_method: str
    method: str
    c_and_k_from: Literal["transmissibility", "time history"]
    reason: str
    bins: int | None = None
    band_hz: tuple[float, float] | None = None
    deck_only_near_gait_harmonics: bool = False

    @property
    def through_surface(self) -> bool:
        """Whether C and K were read from the deck's transmissibility."""
        return self.c_and_k_from == TRANSMISSIBILITY


@dataclass(frozen=True, eq=False)
class FilterResults:
    """What only a particle filter returns: traces, per-piece values and its diagnostics.

    The trace arrays have one row per update point of the filter (every sample for the
    seed's pf, every piece end for the rbpf).

    Attributes
    ----------
    n_particles : int
        Particles of the filter.
    settings : dict
        The filter's own settings (resampling, threshold, moves, random walks of C and K),
        JSON-able.
    collapse_on_few_ancestors : bool
        Whether particles descending from a handful of initial ones mean a collapsed cloud
        for this filter: true for the seed's pf, whose values only the random walk renews;
        false for the rbpf, whose moves renew them (there it is normal path degeneracy).
    piece_mean, piece_sd : ndarray, shape (P, 2)
        (C, K) estimate after each piece: the per-step values.
    trace_time_s : ndarray, shape (T,)
        Time of each update point [s].
    trace_mean, trace_sd : ndarray, shape (T, 2)
        Convergence traces of (C, K).
    ess : ndarray, shape (T,)
        Effective sample size at each update point.
    distinct_ancestors : ndarray of int, shape (T,)
        Distinct initial particles with descendants.
    unique_values : ndarray of int, shape (T, 2)
        Distinct values of C and of K among the particles.
    """

    n_particles: int
    settings: Mapping[str, Any]
    collapse_on_few_ancestors: bool
    piece_mean: FloatArray
    piece_sd: FloatArray
    trace_time_s: FloatArray
    trace_mean: FloatArray
    trace_sd: FloatArray
    ess: FloatArray
    distinct_ancestors: NDArray[np.int64]
    unique_values: NDArray[np.int64]


@dataclass(frozen=True)
class GridResults:
    """The exact grid posterior's summary (what ``ExactPosterior.to_json`` returns).

    Attributes
    ----------
    summary : dict
        Posterior means, sd, intervals, C-K correlation, MAP, contraction, log evidence,
        the Laplace check and the grid's size, JSON-able (no grid arrays).
    """

    summary: Mapping[str, Any]

    def to_json(self) -> dict[str, Any]:
        """Return the summary as a JSON-able dict."""
        return dict(self.summary)


@dataclass(frozen=True)
class SurfaceReport:
    """What a record's surface motion contributed to C and K (the JSON's ``surface``).

    Built by :func:`~workbench.inference.surface.information.surface_report`; the fields
    after ``sentence`` are set only when the model coupled a measured surface motion
    (``rms_acc_m_s2`` also when it ignored one).

    Attributes
    ----------
    model : str
        ``"coupled"``, ``"ignored (rigid floor)"`` or ``"rigid floor (no ground_acc)"``.
    sentence : str
        Plain-words account.
    rms_acc_m_s2 : float or None
        RMS acceleration of the surface [m/s^2].
    c_and_k_from : {"transmissibility", "time history"} or None
        Where C and K came from (coupled surface only).
    source : str or None
        Where the surface motion came from.
    dominant_hz : float or None
        Frequency of the surface acceleration's largest peak [Hz].
    information : dict or None
        Per parameter, the local sd with and without the surface and the surface's share.
    transmissibility : dict or None
        The transmissibility estimate of C and K (None when the deck has no power away from
        the gait harmonics).
    """

    model: str
    sentence: str
    rms_acc_m_s2: float | None = None
    c_and_k_from: str | None = None
    source: str | None = None
    dominant_hz: float | None = None
    information: Mapping[str, Any] | None = None
    transmissibility: Mapping[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        """Return the JSON's ``surface`` section (keys in the order the contract shows)."""
        if self.c_and_k_from is None:
            out: dict[str, Any] = {"model": self.model}
            if self.rms_acc_m_s2 is not None:
                out["rms_acc_m_s2"] = self.rms_acc_m_s2
            out["sentence"] = self.sentence
            return out
        return {
            "model": self.model,
            "c_and_k_from": self.c_and_k_from,
            "source": self.source,
            "rms_acc_m_s2": self.rms_acc_m_s2,
            "dominant_hz": self.dominant_hz,
            "information": self.information,
            "transmissibility": self.transmissibility,
            "sentence": self.sentence,
        }


@dataclass(frozen=True)
class EffectPosterior:
    """The posterior of the model's effects (the JSON's ``effects``).

    Attributes
    ----------
    parameters : dict
        ``{effect: {parameter: {"mean", "sd", "ci95", "prior_sd"}}}``: each effect
        parameter's posterior mixed over the posterior of (C, K).
    pilot : dict
        ``{"effect.parameter": {"mean", "sd"}}``: the pilot fit that set the effects' prior.
    """

    parameters: Mapping[str, Mapping[str, Mapping[str, Any]]]
    pilot: Mapping[str, Mapping[str, float]] = field(default_factory=dict)

    def means(self) -> dict[str, dict[str, float]]:
        """Return ``{"effect.parameter": {"mean", "sd"}}`` of every effect parameter."""
        return {
            f"{effect}.{param}": {"mean": stats["mean"], "sd": stats["sd"]}
            for effect, post in self.parameters.items()
            for param, stats in post.items()
        }

    def to_json(self) -> dict[str, Any]:
        """Return the JSON's ``effects`` section: the parameters, then ``"pilot"``."""
        return {**self.parameters, "pilot": self.pilot}

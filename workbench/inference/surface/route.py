"""Identify C and K through the surface: the deck's transmissibility, then the force given them.

The default surface model (``SMDModel(surface="coupled")``) on a record that measures its
surface's motion. Why C and K are not taken from the joint time-history likelihood there:
the default force model redraws ten harmonics at every step, and over one step those can
represent almost any smooth signal, the deck-driven response included, so on realistic
walks the joint likelihood's information on C and K comes from how the force model
misfits, not from the deck (measured in docs/validation/deck.md). The transmissibility
likelihood (:mod:`workbench.inference.surface.frf`) uses only the response coherent with
the measured deck motion away from the gait's harmonics, which no step force can copy.

So the identification is modular: the posterior of (C, K) is the exact grid posterior
(:func:`~workbench.inference.methods.exact.exact_posterior`) of the transmissibility likelihood
over the prior box, and each piece's force coefficients are the Kalman filter's Gaussian
posterior given (C, K), mixed over that grid. Given (C, K) every method's force posterior
is that Kalman posterior (the RBPF's exactly, the seed-faithful PF's up to its Monte Carlo
error), so it is computed once, whatever method was asked for; the result's
:class:`~workbench.inference.core.result_parts.Route` says so (the method asked for, the
method that ran, the bins and band, and why). The force-model check does not apply: the
force model cannot move C and K here.

Where the deck has no power away from the gait harmonics, or the model has effects (whose
coefficients need the time history), the identification falls back to the joint model and
the result says that too.
"""

from __future__ import annotations

from typing import Any

from workbench.inference.core import IdentificationProblem, IdentificationResult, Route
from workbench.inference.methods import Exact, exact_posterior, exact_result, kalman_force_moments
from workbench.inference.surface.frf import DeckSpectra, deck_spectra
from workbench.wording import count

__all__ = ["identify_through_surface", "transmissibility_route"]


def transmissibility_route(spectra: DeckSpectra, requested_method: str) -> Route:
    """Return the route of C and K read from the deck's transmissibility (module docstring).

    Parameters
    ----------
    spectra : DeckSpectra
        The transmissibility likelihood's bins.
    requested_method : str
        The method the settings named; the exact grid runs whatever it is.

    Returns
    -------
    Route
    """
    bins = int(spectra.frequency_hz.size)
    lo, hi = float(spectra.frequency_hz.min()), float(spectra.frequency_hz.max())
    return Route(
        requested_method=requested_method,
        method="exact",
        c_and_k_from="transmissibility",
        reason=(
            f"The deck moved away from the walker's gait harmonics ({count(bins, 'bin')} at "
            f"{lo:.2f}-{hi:.2f} Hz), where no step force can copy its drive, so C and K were "
            "read from its transmissibility on the exact grid, whatever method was asked for "
            f"({requested_method} here), and the force is the time history's given them "
            "(Kalman filter, mixed over the grid)."
        ),
        bins=bins,
        band_hz=(lo, hi),
    )


def identify_through_surface(
    problem: IdentificationProblem,
    *,
    seed: int,
    common: dict[str, Any],
    requested_method: str,
    spectra: DeckSpectra | None = None,
) -> IdentificationResult | None:
    """C and K from the transmissibility, the force given them (module docstring).

    Parameters
    ----------
    problem : IdentificationProblem
        A problem with the surface coupled and its observation noise set.
    seed : int
        Seed of the posterior draws.
    common : dict
        Noise, settings and model entries of the result.
    requested_method : str
        The method the settings named (reported in the result's route).
    spectra : DeckSpectra, optional
        The problem's :func:`~workbench.inference.surface.frf.deck_spectra`, if already built.

    Returns
    -------
    IdentificationResult or None
        None when the deck has no power away from the gait harmonics. Its ``route`` is the
        :func:`transmissibility_route`.
    """
    if spectra is None:
        spectra = deck_spectra(problem)
    if spectra is None:
        return None
    post = exact_posterior(
        problem, loglik=spectra.loglik, force_moments=kalman_force_moments("foh")
    )
    # As many draws from the grid posterior as the exact method keeps.
    result = exact_result(post, problem, Exact.n_draws, seed, common)
    return result.replace(route=transmissibility_route(spectra, requested_method))

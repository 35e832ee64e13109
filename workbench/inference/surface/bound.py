"""The Cramer-Rao bound of (C, K, f_n, zeta) from what the deck drives (docs/science.md 6).

Whatever estimator reads C and K from a deck record, its sd cannot be below what the
record's deck-driven response carries against the walker's own noise. The bound is the
inverse Fisher information of the transmissibility's bins (:mod:`.frf`):

- the tapered DFT of the deck-driven body acceleration ``mu_j(C, K) = sum_d c_d T(f_{j-d})
  Z_{j-d}`` at every bin the likelihood uses (the deck's bins and their neighbours, the gait's
  line cores excluded: there the walker's own force dwarfs the deck's);
- the gait noise there complex normal with the variance ``s_j^2`` of a given noise spectrum
  (the record's own estimate, or the true one a simulated or replayed record knows), the
  correlation the taper gives neighbouring bins and the nugget;
- Fisher information ``I = 2 Re(G^H S^-1 G)`` with ``G`` the derivatives of ``mu`` by C, K
  and the response's common complex gain, and ``S`` that covariance; the gain's prior
  (:data:`~.frf.CALIBRATION_SD`) added, the information left on (C, K) is the Schur
  complement; ``cov = I^-1``, and f_n and zeta by the delta method
  (:meth:`~.frf.DeckSpectra.information`).

It is local (at one (C, K)), ignores the prior box and assumes the noise spectrum is known;
an estimator that must also estimate it, or protect itself against it being wrong, sits a
little above the bound. ``efficiency`` is a posterior sd over the bound's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.inference.surface.frf import DeckSpectra

__all__ = ["PARAMETERS", "InformationBound", "information_bound", "local_sd"]

FloatArray = NDArray[np.float64]

PARAMETERS = ("damping_ns_per_m", "stiffness_n_per_m", "natural_frequency_hz", "damping_ratio")


def local_sd(info: FloatArray, centre: FloatArray, mass_kg: float) -> dict[str, float]:
    """Return the local sd of C, K, f_n and zeta from an information matrix of (C, K).

    Every sd is inf where the matrix is singular.
    """
    evals = np.linalg.eigvalsh(info)
    if not (np.all(np.isfinite(evals)) and evals[0] > 1e-12 * max(evals[-1], 1e-300)):
        return dict.fromkeys(PARAMETERS, float("inf"))
    cov = np.linalg.inv(info)
    cov = 0.5 * (cov + cov.T)
    c, k = centre
    fn = np.sqrt(k / mass_kg) / (2 * np.pi)
    zeta = c / (2 * np.sqrt(k * mass_kg))
    # Gradients of f_n and zeta with respect to (C, K).
    jac = np.array([[0.0, fn / (2 * k)], [zeta / c, -zeta / (2 * k)]])
    cov_fz = jac @ cov @ jac.T
    var = [cov[0, 0], cov[1, 1], cov_fz[0, 0], cov_fz[1, 1]]
    return {name: float(np.sqrt(max(v, 0.0))) for name, v in zip(PARAMETERS, var, strict=True)}


@dataclass(frozen=True)
class InformationBound:
    """The Cramer-Rao bound of a deck record (module docstring).

    Attributes
    ----------
    damping_ns_per_m, stiffness_n_per_m : float
        Where it was evaluated.
    information : ndarray, shape (2, 2)
        Fisher information of (C, K).
    sd : dict
        The bound's sd of C, K, f_n and zeta.
    bins : int
        Bins that carried it.
    """

    damping_ns_per_m: float
    stiffness_n_per_m: float
    information: FloatArray
    sd: dict[str, float]
    bins: int

    def efficiency(self, posterior_sd: dict[str, float]) -> dict[str, float]:
        """Posterior sd over the bound's sd, per parameter (NaN where the bound is 0 or inf)."""
        out = {}
        for name in PARAMETERS:
            b = self.sd[name]
            ok = np.isfinite(b) and b > 0 and name in posterior_sd
            out[name] = float(posterior_sd[name] / b) if ok else float("nan")
        return out

    def to_json(self, posterior_sd: dict[str, float] | None = None) -> dict[str, Any]:
        """JSON-able form, with the efficiency when a posterior sd is given."""
        # Evaluated at the posterior mean, which the result reports (or withholds) itself.
        out: dict[str, Any] = {
            "bound_sd": dict(self.sd),
            "bins": self.bins,
        }
        if posterior_sd is not None:
            out["efficiency"] = self.efficiency(posterior_sd)
        return out


def information_bound(
    spectra: DeckSpectra,
    damping_ns_per_m: float,
    stiffness_n_per_m: float,
    noise_var: FloatArray | None = None,
    nugget: float | None = None,
) -> InformationBound:
    """Return the Cramer-Rao bound at one (C, K) (module docstring).

    Parameters
    ----------
    spectra : DeckSpectra
        The record's transmissibility bins (:func:`~.frf.deck_spectra`).
    damping_ns_per_m, stiffness_n_per_m : float
        Where to evaluate (the truth in a study, the posterior mean in a report).
    noise_var : ndarray, optional
        Variance of the gait part of the tapered DFT at each of the spectra's bins; default
        the record's own estimate (``spectra.noise_var``).
    nugget : float, optional
        Share of that noise independent from bin to bin; default the record's own
        (``spectra.nugget``).

    Returns
    -------
    InformationBound
    """
    info = spectra.information(damping_ns_per_m, stiffness_n_per_m, noise_var, nugget)
    centre = np.array([damping_ns_per_m, stiffness_n_per_m])
    return InformationBound(
        damping_ns_per_m=float(damping_ns_per_m),
        stiffness_n_per_m=float(stiffness_n_per_m),
        information=info,
        sd=local_sd(info, centre, spectra.mass_kg),
        bins=int(spectra.frequency_hz.size),
    )

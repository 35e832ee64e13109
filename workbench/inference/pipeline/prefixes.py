"""Convergence of an identification along a record: the posterior given the data up to t.

The seed shows its filter's running estimate of C and K (its figs. 2, 3, 7 and 8). A running
estimate is only the posterior given the data so far when the method is a filter, and the
default route on a vibrating deck (C and K from the transmissibility) is not one. The honest
equivalent for every method is to identify the record's first t seconds for a few t: each
point is then exactly what a user with that much record would have been told, its flag
included, so a short prefix that cannot identify C and K says so instead of drawing a
confident line.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.records.record import Record

__all__ = ["PrefixConvergence", "identify_on_prefixes"]

#: The two parameters followed, in this order (columns of the arrays below).
PARAMETERS = ("damping_ns_per_m", "stiffness_n_per_m")


@dataclass(frozen=True, eq=False)
class PrefixConvergence:
    """Identifications of a record's first ``time_s`` seconds.

    Attributes
    ----------
    time_s : ndarray, shape (T,)
        Length of each prefix [s].
    mean, sd : ndarray, shape (T, 2)
        Posterior mean and sd of (C [N s/m], K [N/m]) given the prefix.
    interval : ndarray, shape (T, 2, 2)
        95 % interval (low, high) of C and K.
    identified : ndarray of bool, shape (T,)
        Whether the identification of the prefix reported C and K identified.
    levels : tuple of str
        The identifiability level of each prefix ("well identified", "not identified", ...).
    """

    time_s: np.ndarray
    mean: np.ndarray
    sd: np.ndarray
    interval: np.ndarray
    identified: np.ndarray
    levels: tuple[str, ...]

    @property
    def first_identified_s(self) -> float | None:
        """Shortest prefix from which every longer one is identified [s] (None: never)."""
        for i in range(len(self.time_s)):
            if bool(np.all(self.identified[i:])):
                return float(self.time_s[i])
        return None

    def to_json(self) -> dict[str, Any]:
        """Plain-JSON form."""
        return {
            "time_s": self.time_s.tolist(),
            "damping_ns_per_m": {
                "mean": self.mean[:, 0].tolist(),
                "sd": self.sd[:, 0].tolist(),
                "interval": self.interval[:, 0].tolist(),
            },
            "stiffness_n_per_m": {
                "mean": self.mean[:, 1].tolist(),
                "sd": self.sd[:, 1].tolist(),
                "interval": self.interval[:, 1].tolist(),
            },
            "identified": self.identified.tolist(),
            "levels": list(self.levels),
            "first_identified_s": self.first_identified_s,
        }


def identify_on_prefixes(
    record: Record, settings: Any, times_s: Sequence[float], *, progress: bool = False
) -> PrefixConvergence:
    """Identify the first ``t`` seconds of a record for every ``t`` in ``times_s``.

    Parameters
    ----------
    record : Record
        The record.
    settings : IdentifySettings
        The settings of every identification (the same seed for each prefix).
    times_s : sequence of float
        Prefix lengths [s], each at most the record's duration; sorted on return.
    progress : bool, default False
        Show a progress bar over the prefixes.

    Returns
    -------
    PrefixConvergence
    """
    from tqdm import tqdm

    from workbench.errors import UsageError
    from workbench.inference.pipeline.identification import identify

    times = np.sort(np.asarray(times_s, dtype=float))
    t0 = float(record.time_s[0])
    if times.size == 0 or times[0] <= 0 or times[-1] > record.duration_s + 1e-9:
        raise UsageError(
            f"prefix lengths must lie in (0, {record.duration_s:.3g}] s, the length of "
            f"{record.name}; got {times.tolist()}"
        )
    mean, sd = np.zeros((times.size, 2)), np.zeros((times.size, 2))
    ci = np.zeros((times.size, 2, 2))
    identified = np.zeros(times.size, dtype=bool)
    levels: list[str] = []
    for i, t in enumerate(tqdm(times, desc="prefixes", unit="prefix", disable=not progress)):
        part = record if t >= record.duration_s - 1e-9 else record.slice(t0, t0 + t)
        result = identify(part, settings=settings)
        est, post_sd, interval = result.estimates, result.posterior_sd, result.interval()
        for j, key in enumerate(PARAMETERS):
            mean[i, j], sd[i, j] = est[key], post_sd[key]
            ci[i, j] = interval[key]
        ident = result.identifiability
        levels.append(str(ident.get("level", "not assessed")))
        identified[i] = bool(ident.get("identified_damping")) and bool(
            ident.get("identified_stiffness")
        )
    return PrefixConvergence(times, mean, sd, ci, identified, tuple(levels))

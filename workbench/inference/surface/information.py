"""How much of what a record says about C and K came from the walking surface's motion.

On a rigid floor C and K are fixed only by what the force model cannot absorb
(docs/science.md 4); a moving surface drives the same spring and damper with a measured
input and pins them (docs/science.md 6). An identification that coupled the surface reports
the share of the information that the surface carried:

- the observed information matrix ``I = -d^2 log p(y | C, K)`` (force coefficients
  integrated out, the exact Kalman likelihood) at the posterior mean, by central finite
  differences with steps of half the posterior sd (9 likelihood evaluations, one vectorised
  call per model), once for the coupled model and once for the same data and noise with the
  surface ignored (a rigid floor);
- per parameter the local posterior sd ``sqrt((I^-1)_ii)`` with and without the surface, for
  C, K, f_n and zeta (delta method), and the fraction of the information that came from the
  surface, ``1 - sd_with^2 / sd_without^2`` (1 when the rigid-floor likelihood alone does not
  bound the parameter there).

The comparison is local (a Laplace view at one point) and ignores the prior box; the method's
own posterior sd stays the reported uncertainty. It answers "would the number be there
without the deck?", which is what an experimenter planning a shaker or footbridge test asks.

Beside it the report carries the surface's transmissibility estimate
(:mod:`workbench.inference.surface.frf`): C and K from the deck-driven part of the response
alone, which the force model cannot absorb (``transmissibility``, None when the deck has no
power away from the gait harmonics).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from workbench.inference.core import IdentificationProblem, SurfaceReport
from workbench.inference.kalman import record_loglik
from workbench.inference.surface.bound import PARAMETERS, information_bound, local_sd
from workbench.inference.surface.frf import deck_spectra, surface_transmissibility
from workbench.records.record import Record

if TYPE_CHECKING:
    from workbench.inference.core import IdentificationResult

__all__ = ["information_with_and_without", "rigid_floor_problem", "surface_report"]

FloatArray = NDArray[np.float64]

#: Finite-difference step of the information matrix, in posterior sd.
STEP_SD = 0.5
#: Below this fraction of the information on C or K from the surface, the sentence says the
#: deck carried little of it.
LITTLE_FROM_SURFACE = 0.5


def rigid_floor_problem(problem: IdentificationProblem) -> IdentificationProblem:
    """Return the same data and noise with the surface's motion ignored (absolute frame)."""
    if problem.surface is None:
        return problem
    return dataclasses.replace(problem, y=problem.absolute_y, surface=None)


def _information(
    problem: IdentificationProblem, centre: FloatArray, step: FloatArray
) -> FloatArray:
    """Observed information of ``log p(y | C, K)`` at ``centre`` (2 x 2)."""
    offsets = np.array([(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1)], dtype=np.float64)
    pts = centre[None, :] + offsets * step[None, :]
    # Stay on the physical side (a step below zero would be a negative spring).
    pts = np.maximum(pts, 1e-9)
    ll = record_loglik(problem, pts[:, 0], pts[:, 1]).loglik.reshape(3, 3)
    h = np.empty((2, 2))
    h[0, 0] = (ll[2, 1] - 2 * ll[1, 1] + ll[0, 1]) / step[0] ** 2
    h[1, 1] = (ll[1, 2] - 2 * ll[1, 1] + ll[1, 0]) / step[1] ** 2
    h[0, 1] = h[1, 0] = (ll[2, 2] - ll[2, 0] - ll[0, 2] + ll[0, 0]) / (4 * step[0] * step[1])
    return -h


def information_with_and_without(
    problem: IdentificationProblem,
    damping_ns_per_m: float,
    stiffness_n_per_m: float,
    step: tuple[float, float],
) -> dict[str, dict[str, float]]:
    """Local posterior sd with and without the surface, and the surface's share.

    Parameters
    ----------
    problem : IdentificationProblem
        A problem with the surface coupled (``problem.surface`` set), noise set.
    damping_ns_per_m, stiffness_n_per_m : float
        Where to evaluate (the posterior mean).
    step : (float, float)
        Finite-difference steps of C and K (module docstring: half the posterior sd).

    Returns
    -------
    dict
        Per parameter (C, K, f_n, zeta): ``local_sd_with_surface``, ``local_sd_rigid_floor``
        (inf where the rigid-floor likelihood does not bound it) and ``fraction_from_surface``.
    """
    centre = np.array([damping_ns_per_m, stiffness_n_per_m], dtype=np.float64)
    h = np.asarray(step, dtype=np.float64)
    with_sd = local_sd(_information(problem, centre, h), centre, problem.mass_kg)
    rigid = rigid_floor_problem(problem)
    without_sd = local_sd(_information(rigid, centre, h), centre, problem.mass_kg)
    out: dict[str, dict[str, float]] = {}
    for name in PARAMETERS:
        a, b = with_sd[name], without_sd[name]
        if not np.isfinite(a):
            frac = float("nan")
        elif not np.isfinite(b):
            frac = 1.0
        else:
            frac = float(np.clip(1.0 - (a / b) ** 2, 0.0, 1.0)) if b > 0 else 0.0
        out[name] = {
            "local_sd_with_surface": a,
            "local_sd_rigid_floor": b,
            "fraction_from_surface": frac,
        }
    return out


def _dominant_hz(problem: IdentificationProblem) -> float:
    """Frequency of the largest peak of the surface acceleration's spectrum [Hz]."""
    assert problem.surface is not None
    acc = problem.surface.acc_m_s2
    spec = np.abs(np.fft.rfft(acc * np.hanning(acc.size)))
    freq = np.fft.rfftfreq(acc.size, problem.dt_s)
    return float(freq[int(np.argmax(spec[1:])) + 1]) if acc.size > 2 else float("nan")


def surface_report(
    result: IdentificationResult,
    problem: IdentificationProblem,
    record: Record,
    surface_model: str,
) -> SurfaceReport:
    """Return what the surface contributed: the JSON's ``surface`` (module docstring).

    Parameters
    ----------
    result : IdentificationResult
        The identification (its posterior mean and sd set the evaluation point and steps).
    problem : IdentificationProblem
        The problem it solved.
    record : Record
        The record (whether it measures a surface motion at all).
    surface_model : {"coupled", "joint", "rigid"}
        The model's surface setting.

    Returns
    -------
    SurfaceReport
        ``model`` (``"coupled"``, ``"ignored (rigid floor)"`` or ``"rigid floor (no
        ground_acc)"``), ``sentence``, and with a coupled surface where C and K came from,
        its ``source``, ``rms_acc_m_s2``, ``dominant_hz``, ``information`` per parameter and
        the ``transmissibility`` estimate. C and K came from the transmissibility when the
        result's route says so (:class:`~workbench.inference.core.result_parts.Route`).
    """
    if record.ground_acc_m_s2 is None:
        return SurfaceReport(
            model="rigid floor (no ground_acc)",
            sentence="The record measures no surface motion; it was identified as a walk on "
            "a rigid floor.",
        )
    if surface_model == "rigid" or problem.surface is None:
        rms = float(np.sqrt(np.mean(np.square(record.ground_acc_m_s2))))
        return SurfaceReport(
            model="ignored (rigid floor)",
            rms_acc_m_s2=rms,
            sentence=f"The record measures a surface motion ({rms:.3g} m/s^2 RMS) but the "
            "model ignored it (rigid floor).",
        )
    est, sd = result.estimates, result.posterior_sd
    c, k = est["damping_ns_per_m"], est["stiffness_n_per_m"]
    step = (STEP_SD * sd["damping_ns_per_m"], STEP_SD * sd["stiffness_n_per_m"])
    rms = problem.surface.rms_acc_m_s2
    route = result.route if result.route is not None and result.route.through_surface else None
    if route is None:
        info = information_with_and_without(problem, c, k, step)
    else:
        info = _route_information(problem, c, k, step, sd)
    if route is not None:
        # C and K already are the transmissibility's posterior: report it, not again, with
        # its information bound at the posterior mean.
        spectra = deck_spectra(problem)
        bound = None if spectra is None else information_bound(spectra, c, k)
        frf_json: dict[str, Any] | None = {
            "estimates": dict(est),
            "posterior_sd": dict(sd),
            "interval_95": {k: list(v) for k, v in result.interval().items()},
            "level": result.identifiability.get("level"),
            "bins": route.bins,
            "band_hz": list(route.band_hz or ()),
            "information_bound": None if bound is None else bound.to_json(sd),
        }
    else:
        frf = surface_transmissibility(problem)
        frf_json = None if frf is None else frf.to_json()
    dominant = _dominant_hz(problem)
    if route is not None:
        level = str(result.identifiability.get("level", ""))
        lo, hi = route.band_hz or (float("nan"), float("nan"))
        fn = est["natural_frequency_hz"]
        sd_rel = sd["natural_frequency_hz"] / fn
        bound_rel = float("nan") if bound is None else bound.sd["natural_frequency_hz"] / fn
        if level in ("well identified", "weakly identified"):
            precision = f"the posterior sd of f_n is {100 * sd_rel:.1f} % of it" + _against_bound(
                sd_rel, bound_rel
            )
        else:
            # Not identified: its sd is withheld like its estimate; the record's bound is not
            # an estimate of the walker and stays.
            precision = f"f_n is {level}" + (
                f"; the record's information bound (docs/science.md 6) is {100 * bound_rel:.2g} %"
                if np.isfinite(bound_rel)
                else ""
            )
        sentence = (
            f"C and K were read from the deck's transmissibility ({route.bins} bins at "
            f"{lo:.2f}-{hi:.2f} Hz, {rms:.3g} m/s^2 RMS), the force given them; "
            + precision
            + enough_vibration(rms, sd_rel, level, bound_rel, problem.n_samples * problem.dt_s)
        )
    elif frf_json is None:
        sentence = (
            f"The deck moved ({rms:.3g} m/s^2 RMS, mostly at {dominant:.2f} Hz) "
            "only near the walker's gait harmonics, where its drive cannot be told from the "
            "walker's own force, so C and K came from the time history. " + _sentence(rms, info)
        )
    else:
        sentence = _sentence(rms, info)
    return SurfaceReport(
        model="coupled",
        sentence=sentence,
        rms_acc_m_s2=rms,
        c_and_k_from="transmissibility" if route is not None else "time history",
        source=problem.surface.source,
        dominant_hz=dominant,
        information=info,
        transmissibility=frf_json,
    )


#: The posterior sd of f_n, as a fraction of f_n, that the advice on more vibration aims at.
TARGET_SD_FN = 0.03
#: Within this factor of the bound the sentence calls the posterior "at the bound".
AT_BOUND = 1.25


def _against_bound(sd_rel: float, bound_rel: float) -> str:
    """Set the posterior sd beside the record's information bound, in words."""
    if not (np.isfinite(bound_rel) and bound_rel > 0):
        return ", and the record's information bound could not be computed"
    ratio = sd_rel / bound_rel
    if ratio < 1.0 / AT_BOUND:
        where = "below it: the prior box narrows the posterior"
    elif ratio <= AT_BOUND:
        where = "at it"
    else:
        where = f"{ratio:.2g} times it"
    return (
        f"; the record's information bound (the least sd any estimator can reach from what the "
        f"deck drives, docs/science.md 6) is {100 * bound_rel:.2g} %, and the posterior is {where}"
    )


def enough_vibration(
    rms_m_s2: float, sd_fn_rel: float, level: str, bound_fn_rel: float, duration_s: float
) -> str:
    """Finish the route's sentence: the deck motion, or the record length, that pins f_n to 3 %.

    The information bound scales with the deck's RMS (the deck-driven response, and so its
    signal-to-noise ratio, is proportional to it) and with the record's length (for a
    stationary walk the information grows in proportion to it), so the bound's sd of f_n
    falls as ``1 / (RMS sqrt(length))`` while the gait noise limits it (the channels'
    unknown common gain sets a floor far below 3 %). The advice scales the larger of the
    posterior sd and the bound: a posterior that the prior box narrows below the bound does
    not know more.
    ``analyses/deck_bound.py`` measures both scalings on records whose variability is measured
    (docs/validation/deck-information.md).

    Parameters
    ----------
    rms_m_s2 : float
        The deck's RMS acceleration over the record [m/s^2].
    sd_fn_rel : float
        Posterior sd of f_n over f_n.
    level : str
        The identifiability level.
    bound_fn_rel : float
        The information bound's sd of f_n over f_n (NaN when it could not be computed).
    duration_s : float
        The record's length [s].

    Returns
    -------
    str
        ``"."`` when f_n is pinned to 3 % or better, else the advice, ending with a full stop.
    """
    identified = level in ("well identified", "weakly identified")
    if identified and sd_fn_rel <= TARGET_SD_FN:
        return "."
    known = max(sd_fn_rel, bound_fn_rel) if np.isfinite(bound_fn_rel) else sd_fn_rel
    factor = max(known / TARGET_SD_FN, 1.0)
    head = "" if identified else f"; the deck's {rms_m_s2:.3g} m/s^2 carries too little information"
    # Where the posterior is not identified its mean, and so the bound there, is uncertain too.
    about = "about" if identified else "at least"
    times = f"{factor**2:.0f}" if factor**2 >= 10 else f"{factor**2:.2g}"
    return (
        f"{head}; sd(f_n) falls in proportion to the deck's RMS and to one over the square root "
        f"of the record's length, so {about} {rms_m_s2 * factor:.2g} m/s^2 RMS at these "
        f"frequencies, or a record {about} {times} times as long (about "
        f"{duration_s * factor**2:.0f} s of steady walking), would bring it to "
        f"{100 * TARGET_SD_FN:.0f} % (docs/validation/deck-information.md)."
    )


def _route_information(
    problem: IdentificationProblem,
    damping_ns_per_m: float,
    stiffness_n_per_m: float,
    step: tuple[float, float],
    posterior_sd: dict[str, float],
) -> dict[str, dict[str, float]]:
    """Report the information when C and K came from the transmissibility alone.

    All of it came from the surface: the sd with the surface is the transmissibility's
    posterior sd; beside it the local sd the rigid-floor time history would give.
    """
    centre = np.array([damping_ns_per_m, stiffness_n_per_m], dtype=np.float64)
    rigid = rigid_floor_problem(problem)
    without = local_sd(_information(rigid, centre, np.asarray(step)), centre, problem.mass_kg)
    return {
        name: {
            "local_sd_with_surface": float(posterior_sd[name]),
            "local_sd_rigid_floor": without[name],
            "fraction_from_surface": 1.0,
        }
        for name in PARAMETERS
    }


def _sentence(rms: float, info: dict[str, dict[str, float]]) -> str:
    """Plain-words account of what the surface contributed."""
    parts = []
    for name, sym in (("damping_ns_per_m", "C"), ("stiffness_n_per_m", "K")):
        frac = info[name]["fraction_from_surface"]
        parts.append((sym, frac))
    weak = [sym for sym, frac in parts if not (np.isfinite(frac) and frac >= LITTLE_FROM_SURFACE)]
    shares = ", ".join(
        f"{100 * frac:.0f} % of the information on {sym}"
        for sym, frac in parts
        if np.isfinite(frac)
    )
    if not weak:
        return (
            f"The surface's motion ({rms:.3g} m/s^2 RMS) acted through K and C and carried "
            f"{shares}."
        )
    # A flat or non-concave likelihood at the estimate has no local sd to compare, so the
    # share cannot be measured; say so rather than print empty parentheses.
    measured = shares or "its share could not be measured: the likelihood has no curvature there"
    return (
        f"The surface's motion ({rms:.3g} m/s^2 RMS) acted through K and C but carried too "
        f"little information on {' and '.join(weak)} ({measured}); a stronger or longer "
        "deck excitation is needed to pin them."
    )

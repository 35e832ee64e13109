"""The records a sensor on each walker of a footbridge crossing would give, with their truth.

A walker of the interaction model is an SMD whose base moves with the deck (docs/science.md
6 and 7)::

    M y'' + C (y' - w') + K (y - w) = F_bio(t),     GRF = M (g + y''),
    w = sum_j phi_j(x(t)) q_j

so the record of that walker -- its total vertical GRF and the acceleration of the deck
under its feet, ``w'' = sum_j phi_j(x(t)) q_j''`` -- is exactly the input of the
identification on a vibrating surface, with known C and K. Both columns come from the
integrator's own end-of-step state (:class:`~workbench.hsi.simulate.WalkerHistory`), so
they satisfy the walker's equation of motion to rounding; nothing is differentiated.

A record covers the samples with the walker on the deck (``0 <= x(t) <= span``, entry and
exit included) within the simulated window, optionally with ``margin_s`` of rigid ground
before and after where the simulation has it (there ``ground_acc`` is exactly 0). Its time
column is the crossing's clock, on which the truth's force coefficients (``time_basis``
``"absolute"``) give ``F_bio``. No measurement noise is added.

The files (a folder of records, their truth and a batch manifest) are written by
:mod:`workbench.hsi.record_files`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.hsi.pedestrians import G
from workbench.hsi.simulate import HsiHistory, WalkerHistory
from workbench.models.smd import SMDModel
from workbench.records.record import G_M_S2, Record

__all__ = [
    "WalkerResponse",
    "crossing_records",
    "record_name",
    "walker_records",
    "walker_responses",
]

#: What the truth's ``generator`` says (the sidecar layout of ``workbench simulate``).
GENERATOR = "workbench.hsi.walker_records"
FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class WalkerResponse:
    """One walker's record with the integrator's states behind it (Python API only).

    Every array has the samples of ``record`` (``record.time_s``). With the truth C, K and
    ``model``'s force, ``record.grf_n - M g = force_n - C (vel_m_s - base_vel_m_s) - K
    (disp_m - base_disp_m)`` to rounding, and ``record.ground_acc_m_s2 = base_acc_m_s2``.

    Attributes
    ----------
    record : Record
        ``time``, ``grf`` = ``M (g + y'')`` and ``ground_acc`` = ``w''``; body mass, pacing,
        subject and ``metadata["truth"]``.
    crossing : int
        The crossing (scenario) it belongs to.
    walker : int
        The walker's index in its crossing.
    model : SMDModel
        The walker as the integrator saw it (mass, K, C, pacing, force coefficients on the
        crossing's clock).
    position_m : ndarray
        ``x(t)`` [m] (outside ``[0, span]`` off the deck).
    disp_m, vel_m_s, acc_m_s2 : ndarray
        COM ``y, y', y''`` (absolute, upwards from the static position).
    base_disp_m, base_vel_m_s, base_acc_m_s2 : ndarray
        The deck under the feet ``w, w', w''`` (0 off the deck).
    force_n : ndarray
        The biomechanical force ``F_bio(t)`` the integrator applied [N].
    """

    record: Record
    crossing: int
    walker: int
    model: SMDModel
    position_m: FloatArray
    disp_m: FloatArray
    vel_m_s: FloatArray
    acc_m_s2: FloatArray
    base_disp_m: FloatArray
    base_vel_m_s: FloatArray
    base_acc_m_s2: FloatArray
    force_n: FloatArray

    @property
    def time_s(self) -> FloatArray:
        """Sample times [s] on the crossing's clock (those of the record)."""
        return self.record.time_s


def _walker_history(history: HsiHistory | WalkerHistory) -> tuple[WalkerHistory, FloatArray]:
    """Return the kept per-walker histories of an interaction run and their time axis."""
    if isinstance(history, WalkerHistory):
        raise UsageError(
            "'history' must be the HsiHistory that holds the walkers (it has the time axis "
            "and the model); pass the result of integrate(..., keep_walkers=True)",
            parameter="history",
        )
    if not isinstance(history, HsiHistory):
        raise UsageError(
            f"'history' must be an HsiHistory, got {type(history).__name__}; simulate with "
            "simulate_pedestrians(..., keep_walkers=True)",
            parameter="history",
        )
    if history.model != "interaction":
        raise UsageError(
            f"'history' is a {history.model!r} run, whose walkers walk on rigid ground while "
            "the deck moves; walker records come from model='interaction'",
            parameter="history",
        )
    if history.walkers is None:
        raise UsageError(
            "'history' kept no per-walker histories; simulate with keep_walkers=True",
            parameter="history",
        )
    return history.walkers, history.time_s


def _model(w: WalkerHistory, b: int, p: int) -> SMDModel:
    """Return the walker's SMD with the force the integrator applied (arrays inverted)."""
    batch = w.batch
    m = float(batch.mass_kg[b, p])
    amplitude = batch.blf[b, p] * m * G
    coef = np.zeros(1 + 2 * amplitude.size)
    coef[0] = batch.a0_n[b, p]
    coef[1::2] = amplitude * np.cos(batch.phase_rad[b, p])
    coef[2::2] = -amplitude * np.sin(batch.phase_rad[b, p])
    return SMDModel(
        mass_kg=m,
        stiffness_n_per_m=float(batch.stiffness_n_per_m[b, p]),
        damping_ns_per_m=float(batch.damping_ns_per_m[b, p]),
        harmonics=int(amplitude.size),
        time_basis="absolute",
        pieces="whole",
        pacing_hz=float(batch.pacing_hz[b, p]),
        force_coefficients_n=tuple(float(c) for c in coef),
    )


def _force(w: WalkerHistory, b: int, p: int, t: FloatArray) -> FloatArray:
    """``F_bio(t)`` as :meth:`CrowdBatch.force` evaluates it, at many times for one walker."""
    batch = w.batch
    i = np.arange(1, batch.blf.shape[-1] + 1)
    arg = 2 * np.pi * i * batch.pacing_hz[b, p] * t[:, None] + batch.phase_rad[b, p]
    dynamic = G * batch.mass_kg[b, p] * np.sum(batch.blf[b, p] * np.cos(arg), axis=-1)
    return np.asarray(dynamic + batch.a0_n[b, p], dtype=np.float64)


def _truth(
    w: WalkerHistory,
    b: int,
    p: int,
    model: SMDModel,
    crossing: int,
    time: FloatArray,
    dt_s: float,
) -> dict[str, Any]:
    """Return the truth in the layout of ``workbench simulate`` plus the crossing's facts."""
    batch, span = w.batch, w.structure.span_m
    v, x0 = float(batch.speed_m_s[b, p]), float(batch.x0_m[b, p])
    coef = np.asarray(model.force_coefficients_n, float)
    force = model.fourier_force
    return {
        "generator": GENERATOR,
        "mass_kg": model.mass_kg,
        "stiffness_n_per_m": model.stiffness_n_per_m,
        "damping_ns_per_m": model.damping_ns_per_m,
        "natural_frequency_hz": model.natural_frequency_hz,
        "damping_ratio": model.damping_ratio,
        "harmonics": model.harmonics,
        "effects": [],
        "pacing_hz": model.pacing_hz,
        "time_basis": "absolute",
        "coefficient_names": list(force.coefficient_names),
        "force_coefficients": coef.tolist(),
        "blf": force.blf(coef, model.require("mass_kg")).tolist(),
        "phases_rad": force.phases_rad(coef).tolist(),
        "noise_sd_n": 0.0,
        "sample_rate_hz": 1.0 / dt_s,
        "duration_s": float(time.size * dt_s),
        # The integrator starts every walker in its rigid-ground steady state at t = 0.
        "start": "steady",
        "ground_motion": "footbridge deck under the walker (human-structure interaction)",
        "speed_m_s": v,
        "step_length_m": v / float(batch.pacing_hz[b, p]),
        # Standing pedestrians (speed 0) have a position and no entry or exit.
        "entry_time_s": 0.0 - x0 / v if v > 0 else None,  # 0.0 - : no "-0.0" at x0 = 0
        "exit_time_s": (span - x0) / v if v > 0 else None,
        "position_m": x0 if v == 0 else None,
        "crossing": crossing,
        "walker": p,
        "model": "interaction",
        "dt_s": dt_s,
        "static_weight": w.static_weight,
        "structure": w.structure.to_json(),
    }


def walker_responses(
    history: HsiHistory,
    *,
    crossing_ids: ArrayLike | None = None,
    margin_s: float = 0.0,
    truth_extra: Mapping[str, Any] | None = None,
) -> list[WalkerResponse]:
    """Each walker's record and the states behind it, from an interaction run.

    Parameters
    ----------
    history : HsiHistory
        Of ``model="interaction"``, integrated with ``keep_walkers=True``.
    crossing_ids : array_like of int, optional
        The crossing number of each scenario (default ``0, 1, ...``); it names the records.
    margin_s : float
        Rigid ground kept before the walker steps on and after it steps off the deck [s],
        where the simulated window has it (default 0: entry to exit).
    truth_extra : mapping, optional
        More JSON-able entries for every truth (the Monte Carlo seed, for example).

    Returns
    -------
    list of WalkerResponse
        One per walker that is on the deck at some sample, by crossing then walker. Records
        shorter than the loaders accept (2 s) are included;
        :func:`~workbench.hsi.record_files.write_walker_records` skips them.
    """
    w, time = _walker_history(history)
    b_count, p_count = w.batch.mass_kg.shape
    ids = (
        np.arange(b_count)
        if crossing_ids is None
        else np.atleast_1d(np.asarray(crossing_ids)).astype(int)
    )
    if ids.shape != (b_count,):
        raise UsageError(
            f"'crossing_ids' needs one number per scenario ({b_count}), got {ids.size}",
            parameter="crossing_ids",
        )
    margin = float(margin_s)
    if not (np.isfinite(margin) and margin >= 0):
        raise UsageError(
            f"'margin_s' must be zero or a positive time in s, got {margin_s!r}",
            parameter="margin_s",
        )
    extra = dict(truth_extra or {})
    pad = round(margin / history.dt_s)
    x_all = w.positions_m(time)
    span = w.structure.span_m
    out = []
    for b in range(b_count):
        for p in range(p_count):
            if not w.batch.active[b, p]:
                continue
            x = x_all[b, p]
            on = np.flatnonzero((x >= 0.0) & (x <= span))
            if on.size == 0:
                continue
            sl = slice(max(0, on[0] - pad), min(time.size, on[-1] + 1 + pad))
            out.append(_response(w, b, p, int(ids[b]), time, sl, x[sl], history.dt_s, extra))
    return out


def _response(
    w: WalkerHistory,
    b: int,
    p: int,
    crossing: int,
    time: FloatArray,
    sl: slice,
    x: FloatArray,
    dt_s: float,
    extra: dict[str, Any],
) -> WalkerResponse:
    model = _model(w, b, p)
    t = time[sl]
    acc = w.acc_m_s2[b, p, sl]
    ground_acc = w.base_acc_m_s2[b, p, sl]
    truth = {**_truth(w, b, p, model, crossing, t, dt_s), **extra}
    name = record_name(crossing, p)
    m = model.require("mass_kg")
    record = Record(
        time_s=t,
        # The record's consumer subtracts its own g (records.G_M_S2), so that is the g here.
        grf_n=m * (G_M_S2 + acc),
        mass_kg=m,
        ground_acc_m_s2=ground_acc,
        pacing_hz=model.pacing_hz,
        subject=name,
        source=f"{GENERATOR}(crossing {crossing}, walker {p})",
        notes="simulated walker crossing a footbridge (interaction); ground_acc is the deck "
        "under the feet; the truth is in metadata['truth']",
        metadata={"format": "synthetic", "truth": truth},
    )
    arrays = [
        np.array(a, dtype=np.float64)
        for a in (
            x,
            w.disp_m[b, p, sl],
            w.vel_m_s[b, p, sl],
            acc,
            w.base_disp_m[b, p, sl],
            w.base_vel_m_s[b, p, sl],
            ground_acc,
            _force(w, b, p, t),
        )
    ]
    for a in arrays:
        a.setflags(write=False)
    return WalkerResponse(record, crossing, p, model, *arrays)


def record_name(crossing: int, walker: int) -> str:
    """File stem and subject of a walker's record: ``crossing0003_walker012``."""
    return f"crossing{crossing:04d}_walker{walker:03d}"


def walker_records(
    history: HsiHistory,
    *,
    crossing_ids: ArrayLike | None = None,
    margin_s: float = 0.0,
    truth_extra: Mapping[str, Any] | None = None,
) -> list[Record]:
    """Return the record a sensor on each walker would give: GRF and the deck under it.

    Parameters
    ----------
    history, crossing_ids, margin_s, truth_extra
        As :func:`walker_responses`.

    Returns
    -------
    list of Record
        ``time_s``, ``grf_n = M (g + y'')``, ``ground_acc_m_s2 = sum_j phi_j(x) q_j''``, body
        mass, pacing, subject ``crossingCCCC_walkerWWW`` and ``metadata["truth"]`` (the
        walker's M, K, C, f_n, damping ratio, force coefficients, BLFs, speed, entry and
        exit times, crossing).

    Examples
    --------
    >>> from workbench.hsi.pedestrians import design_pedestrian
    >>> from workbench.hsi.simulate import simulate_pedestrians
    >>> from workbench.hsi.structure import simply_supported_beam
    >>> beam = simply_supported_beam(20.0, 500.0, 2.0, 0.005)
    >>> hist = simulate_pedestrians(beam, design_pedestrian(), dt_s=0.01, keep_walkers=True)
    >>> (rec,) = walker_records(hist)
    >>> rec.subject, rec.metadata["truth"]["stiffness_n_per_m"]
    ('crossing0000_walker000', 14110.0)
    """
    responses = walker_responses(
        history, crossing_ids=crossing_ids, margin_s=margin_s, truth_extra=truth_extra
    )
    return [r.record for r in responses]


def crossing_records(spec: Any, seed: int, index: int) -> list[Record]:
    """Return the walker records of Monte Carlo crossing ``index``, redrawn from its seed.

    The crossing is drawn as :func:`~workbench.hsi.montecarlo.run_monte_carlo` draws it and
    integrated alone with interaction (the Monte Carlo integrates crossings side by side,
    so its numbers agree with these to rounding).

    Parameters
    ----------
    spec : CrossingSpec
        What a crossing is.
    seed : int
        The Monte Carlo's seed.
    index : int
        The crossing.

    Returns
    -------
    list of Record
        As :func:`walker_records`; the truth also holds ``monte_carlo_seed``.
    """
    from workbench.hsi.montecarlo import draw_crossing
    from workbench.hsi.simulate import CrowdBatch, integrate

    frame, x0, v, duration = draw_crossing(spec, seed, index)
    if len(frame) == 0:
        return []
    batch = CrowdBatch.from_scenarios([(frame, x0, v)])
    history = integrate(
        spec.structure,
        batch,
        duration_s=duration,
        dt_s=spec.dt_s,
        model="interaction",
        response_x_m=spec.response_x_m,
        static_weight=spec.static_weight,
        keep_walkers=True,
    )
    records = walker_records(history, crossing_ids=[index], truth_extra={"monte_carlo_seed": seed})
    if "walker_id" not in frame.columns:
        return records
    # A cohort's pedestrian: the record's subject is the person, so their crossings group.
    from workbench.population.cohort import walker_name

    ids = frame["walker_id"].to_numpy(int)
    out = []
    for record in records:
        truth = record.metadata["truth"]
        member = int(ids[int(truth["walker"])])
        metadata = {**record.metadata, "truth": {**truth, "walker_id": member}}
        out.append(record.replace(subject=walker_name(member), metadata=metadata))
    return out

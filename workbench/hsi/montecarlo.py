"""Crowds and Monte Carlo crossings, on a local process pool or a Dask cluster.

A *crossing* is one random scenario: either a single pedestrian walking over the span
(``crowd="single"``) or a stream of pedestrians over a time window (``crowd="stream"``),
with Poisson arrivals at the entry at a given flow, or at the flow ``density * width *
mean_speed`` that keeps the given mean density on the deck. Every crossing is simulated
twice: with interaction (coupled SMDs) and with the moving-force model of the same
pedestrians.

Determinism: crossing ``i`` draws everything from ``SeedSequence(seed, spawn_key=(i,))``,
and crossings are integrated in fixed chunks, so the results do not depend on the number of
workers or on where the chunks run.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from tqdm.auto import tqdm

from workbench.errors import UsageError, check_seed
from workbench.executor import run_tasks
from workbench.hsi.metrics import SETRA_LIMITS_M_S2, comfort_class, running_rms
from workbench.hsi.modes import apparent_structure_modes
from workbench.hsi.pedestrians import PedestrianSampler, validate_pedestrians
from workbench.hsi.simulate import CrowdBatch, Model, integrate
from workbench.hsi.structure import ModalStructure

__all__ = [
    "CrossingSpec",
    "crossing_metrics",
    "draw_crossing",
    "estimate_cost",
    "run_monte_carlo",
]

Crowd = Literal["single", "stream"]
MODELS_COMPARED: tuple[Model, ...] = ("interaction", "moving_force")


@dataclass(frozen=True)
class CrossingSpec:
    """What a Monte Carlo crossing is.

    Parameters
    ----------
    structure : ModalStructure
        The footbridge.
    sampler : callable
        ``sampler(n, seed=int) -> DataFrame`` of pedestrians (for example
        :func:`workbench.population.sampler.sample_pedestrians`).
    crowd : {"single", "stream"}
        One walker per crossing, or a Poisson stream.
    density_per_m2 : float, optional
        Mean crowd density on the deck (stream).
    flow_per_s : float, optional
        Arrival rate at the entry (stream); overrides the density.
    mean_speed_m_s : float
        Converts a density to a flow.
    duration_s : float
        Simulated time of a stream (single: until the walker leaves).
    dt_s : float
        Time step.
    response_x_m : float, optional
        Where the acceleration is evaluated (default midspan).
    comfort_limits_m_s2 : sequence of float
        The three comfort limits.
    static_weight : bool
        Add the walkers' weight as a moving load.
    """

    structure: ModalStructure
    sampler: PedestrianSampler
    crowd: Crowd = "single"
    density_per_m2: float | None = None
    flow_per_s: float | None = None
    mean_speed_m_s: float = 1.3
    duration_s: float = 120.0
    dt_s: float = 0.005
    response_x_m: float | None = None
    comfort_limits_m_s2: Sequence[float] = field(default=SETRA_LIMITS_M_S2)
    static_weight: bool = False

    def __post_init__(self) -> None:
        if self.crowd not in ("single", "stream"):
            raise UsageError(f"crowd must be 'single' or 'stream', got {self.crowd!r}")
        if self.crowd == "stream":
            rate = self.arrival_rate_per_s
            if not (np.isfinite(rate) and rate > 0):
                raise UsageError(
                    "a crowd stream needs a positive density_per_m2 (pedestrians per m^2, "
                    "--density on the command line) or flow_per_s (pedestrians per s, --flow)"
                )
            if not (np.isfinite(self.duration_s) and self.duration_s > 0):
                raise UsageError(f"the duration must be positive, got {self.duration_s}")
        comfort_class(0.0, self.comfort_limits_m_s2)  # checks the limits

    @property
    def arrival_rate_per_s(self) -> float:
        """Poisson arrival rate at the entry [pedestrians/s]."""
        if self.flow_per_s is not None:
            return float(self.flow_per_s)
        if self.density_per_m2 is None:
            return float("nan")
        return float(self.density_per_m2 * self.structure.width_m * self.mean_speed_m_s)


def _child(seed: int, index: int) -> np.random.SeedSequence:
    return np.random.SeedSequence(seed, spawn_key=(index,))


def draw_crossing(
    spec: CrossingSpec, seed: int, index: int
) -> tuple[pd.DataFrame, NDArray[np.float64], NDArray[np.float64], float]:
    """Draw crossing ``index``: pedestrians, start positions, speeds and the duration."""
    ss = _child(seed, index)
    rng = np.random.default_rng(ss)
    table_seed = int(ss.generate_state(1)[0])
    span = spec.structure.span_m
    if spec.crowd == "single":
        frame = _with_walker_ids(spec.sampler(1, seed=table_seed))
        v = frame["speed_m_s"].to_numpy(float)
        return frame, np.zeros(1), v, float(span / v[0])
    # Arrivals start one slow crossing before t = 0 so the deck is already populated.
    lead_s = span / 0.5
    rate = spec.arrival_rate_per_s
    n = int(rng.poisson(rate * (spec.duration_s + lead_s)))
    if n == 0:
        return empty_table(), np.zeros(0), np.zeros(0), spec.duration_s
    entry = rng.uniform(-lead_s, spec.duration_s, size=n)
    frame = _with_walker_ids(spec.sampler(n, seed=table_seed))
    v = frame["speed_m_s"].to_numpy(float)
    keep = (entry + span / v > 0) & (entry < spec.duration_s)
    frame = frame[keep].reset_index(drop=True)
    return frame, -v[keep] * entry[keep], v[keep], spec.duration_s


def _with_walker_ids(raw: pd.DataFrame) -> pd.DataFrame:
    """Check the sampler's table; keep its ``walker_id`` column, if any, for the records.

    A cohort sampler (:class:`~workbench.population.cohort.CohortSampler`) names the walker
    behind each pedestrian, so that records of one person's crossings group by subject.
    """
    frame = validate_pedestrians(raw, "the sampler's table")
    if isinstance(raw, pd.DataFrame) and "walker_id" in raw.columns:
        frame["walker_id"] = raw["walker_id"].to_numpy(int)
    return frame


def empty_table() -> pd.DataFrame:
    """Return an empty pedestrian table (a stream in which nobody arrived)."""
    from workbench.hsi.pedestrians import PEDESTRIAN_COLUMNS

    return pd.DataFrame({c: pd.Series(dtype=float) for c in PEDESTRIAN_COLUMNS})


def crossing_metrics(
    structure: ModalStructure,
    batch: CrowdBatch,
    durations_s: NDArray[np.float64],
    *,
    dt_s: float,
    response_x_m: float | None = None,
    comfort_limits_m_s2: Sequence[float] = SETRA_LIMITS_M_S2,
    static_weight: bool = False,
) -> pd.DataFrame:
    """Simulate a batch with and without interaction and summarise each scenario."""
    duration = float(np.max(durations_s))
    hist = {
        m: integrate(
            structure,
            batch,
            duration_s=duration,
            dt_s=dt_s,
            model=m,
            response_x_m=response_x_m,
            static_weight=static_weight,
        )
        for m in MODELS_COMPARED
    }
    t = hist["interaction"].time_s
    rows = []
    for b in range(batch.mass_kg.shape[0]):
        own = t <= durations_s[b] + 1e-9
        row: dict[str, Any] = {"n_pedestrians": int(batch.active[b].sum())}
        for m, h in hist.items():
            a = h.acceleration_m_s2[b, 0, own]
            peak_at = int(np.argmax(np.abs(a)))
            row[f"peak_{m}_m_s2"] = float(np.abs(a[peak_at]))
            row[f"rms1s_{m}_m_s2"] = float(np.max(running_rms(a, dt_s)))
            row[f"comfort_{m}"] = comfort_class(row[f"peak_{m}_m_s2"], comfort_limits_m_s2)
            if m == "interaction":
                t_peak = float(t[own][peak_at])
        row["interaction_ratio"] = row["peak_interaction_m_s2"] / row["peak_moving_force_m_s2"]
        act = batch.active[b]
        x = batch.positions(t_peak)[b][act]
        on = (x >= 0) & (x <= structure.span_m)
        mode = apparent_structure_modes(
            structure,
            batch.mass_kg[b][act][on],
            batch.stiffness_n_per_m[b][act][on],
            batch.damping_ns_per_m[b][act][on],
            x[on],
        )[0]
        row["apparent_frequency_hz"] = mode.frequency_hz
        row["apparent_damping_ratio"] = mode.damping_ratio
        row["on_deck_at_peak"] = int(on.sum())
        rows.append(row)
    return pd.DataFrame(rows)


# Cost model of :func:`run_monte_carlo`, fitted to wall times and peak resident sizes of the
# command line (``hsi --json``) on one core: single walkers with 1-300 modes (20 crossings up
# to 80 modes, 2 crossings at 200 and 300) and streams of density 2-16 P/m^2 (1 and 20 modes,
# 10 s to 120 s); the estimates came within a factor of 1.6 of those runs. One scenario-step (both
# models) costs a J + b J^2 + c J^3 s for J modes (the batched solve of the coupled modes is
# cubic) and (d + e J) s per walker on it; each crossing ends in the eigen-analysis of the
# occupied structure, 2 (J + walkers on the deck) first-order unknowns, f n^3 s and g n^2 bytes
# (the matrix, its complex eigenvectors and LAPACK's copies).
_S_PER_MODE = (3e-7, 6e-9, 2e-11)
_S_PER_WALKER = (3e-7, 5.6e-8)
_S_EIG_CUBE = 2.7e-10
_B_EIG_SQUARE = 56.0
_B_BASE = 180e6  # the interpreter and its libraries


def estimate_cost(
    spec: CrossingSpec, n_crossings: int, chunk_size: int = 50
) -> tuple[float, float]:
    """Estimate the computing time and the memory of :func:`run_monte_carlo`, before running it.

    Computed from the modes, the time steps, the expected number of walkers (a stream's
    density or flow times its length and duration) and the crossings, with coefficients
    measured on small runs; a rough guide (a factor of 2), meant to catch runaway inputs.

    Parameters
    ----------
    spec : CrossingSpec
    n_crossings : int
    chunk_size : int
        As given to :func:`run_monte_carlo`.

    Returns
    -------
    seconds : float
        Computing time in one process [s].
    peak_bytes : float
        Peak memory of one process running one chunk [bytes].
    """
    s = spec.structure
    j = float(s.n_modes)
    speed = spec.mean_speed_m_s
    if spec.crowd == "single":
        duration, walkers, on_deck = s.span_m / speed, 1.0, 1.0
    else:
        rate = spec.arrival_rate_per_s
        duration = spec.duration_s
        walkers = rate * (duration + s.span_m / speed)  # everyone on the deck in the window
        on_deck = rate * s.span_m / speed
    steps = n_crossings * duration / spec.dt_s
    a, b, c = _S_PER_MODE
    d, e = _S_PER_WALKER
    per_step = a * j + b * j**2 + c * j**3 + (d + e * j) * walkers
    n_eig = 2 * (j + on_deck)
    seconds = steps * per_step + n_crossings * _S_EIG_CUBE * n_eig**3
    batch = min(n_crossings, chunk_size)
    # Integration: some twenty (B, P, J + harmonics) temporaries and a few (B, J, J) systems.
    integration = 8.0 * batch * (20 * walkers * (j + 3) + 4 * j**2)
    return seconds, _B_BASE + integration + _B_EIG_SQUARE * n_eig**2


def _run_chunk(spec: CrossingSpec, seed: int, indices: Sequence[int]) -> pd.DataFrame:
    draws = [draw_crossing(spec, seed, i) for i in indices]
    batch = CrowdBatch.from_scenarios([(f, x0, v) for f, x0, v, _ in draws])
    durations = np.array([d for *_, d in draws])
    out = crossing_metrics(
        spec.structure,
        batch,
        durations,
        dt_s=spec.dt_s,
        response_x_m=spec.response_x_m,
        comfort_limits_m_s2=spec.comfort_limits_m_s2,
        static_weight=spec.static_weight,
    )
    out.insert(0, "crossing", list(indices))
    frames = [f for f, *_ in draws]
    out["mean_pacing_hz"] = [
        float(f["pacing_hz"].mean()) if len(f) else float("nan") for f in frames
    ]
    return out


def _run_chunk_task(task: tuple[CrossingSpec, int, Sequence[int]]) -> pd.DataFrame:
    return _run_chunk(*task)


def run_monte_carlo(
    spec: CrossingSpec,
    n_crossings: int,
    *,
    seed: int,
    workers: int = 1,
    scheduler: str | None = None,
    chunk_size: int = 50,
    progress: bool = False,
) -> pd.DataFrame:
    """Simulate ``n_crossings`` random crossings, with and without interaction.

    Parameters
    ----------
    spec : CrossingSpec
        What a crossing is.
    n_crossings : int
        Number of crossings.
    seed : int
        Fixes every result, whatever ``workers``, ``scheduler`` or the order of completion.
    workers : int
        Local processes (1: in this process).
    scheduler : str, optional
        Address of a Dask distributed scheduler; the chunks run there instead.
    chunk_size : int
        Crossings integrated side by side in one task.
    progress : bool
        Show a progress bar.

    Returns
    -------
    pandas.DataFrame
        One row per crossing (``crossing`` index order) with the peak and the largest 1 s
        RMS acceleration and comfort class of each model, their ratio, and the apparent
        frequency and damping ratio of the first structural mode with the pedestrians on the
        deck when the interaction response peaks.
    """
    if int(n_crossings) != n_crossings or n_crossings < 1:
        raise UsageError(f"the number of crossings must be a positive integer, got {n_crossings}")
    seed = check_seed(seed, "run_monte_carlo")
    if int(workers) != workers or workers < 1:
        raise UsageError(
            f"'workers' must be a positive integer, got {workers}", parameter="workers"
        )
    chunks = [
        list(range(i, min(i + chunk_size, n_crossings))) for i in range(0, n_crossings, chunk_size)
    ]
    results: list[pd.DataFrame] = []
    tasks = [(spec, seed, c) for c in chunks]
    # The batch engine's executor: this process, a spawned local pool or a Dask cluster.
    runs = run_tasks(
        _run_chunk_task,
        tasks,
        workers=min(int(workers), len(chunks)),
        scheduler=scheduler,
        keys=[f"workbench-hsi-{seed}-{c[0]}-{c[-1]}" for c in chunks],
    )
    with tqdm(total=n_crossings, disable=not progress, unit="crossing", desc="hsi") as bar:
        for frame in runs:
            results.append(frame)
            bar.update(len(frame))
    return pd.concat(results, ignore_index=True).sort_values("crossing", ignore_index=True)

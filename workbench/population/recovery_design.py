"""What a recovery simulates: the truth laws, the design and the population of records.

:func:`recovery_plan` draws a population whose SMD parameters follow a known law against
pacing (module :mod:`workbench.population.recovery` says why and how it is judged);
:func:`simulate_recovery_record` turns one row into a record.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from workbench.errors import UsageError, check_seed
from workbench.population.laws import LinearLaw, PopulationLaws, read_laws
from workbench.population.sampler import _masses
from workbench.population.study import FIXED_PACING_HZ

__all__ = [
    "CROSSING_SD",
    "DECK_RATIOS",
    "FLOORS",
    "RECORD_RANGES",
    "TRUTH_LAWS",
    "RecoveryDesign",
    "footbridge_plan",
    "generating_parameters",
    "recovery_plan",
    "simulate_recovery_record",
    "truth_laws",
    "walker_plan",
]

#: Floors the walkers walk on.
FLOORS = ("rigid", "deck")
#: A deck vibrates between the walker's pacing harmonics, at one of these ratios to the pacing
#: (as the criticism's deck walks): at a harmonic the walker's own force drives the same
#: motion, so the deck tells nothing apart from it, and a strong deck near a harmonic or a
#: half-harmonic upsets the step segmentation (docs/validation/recovery.md).
DECK_RATIOS = ((1.15, 1.35), (1.65, 1.85))
#: Ranges of a realistic record's details, drawn per record (uniform; deck RMS log-uniform).
#: Record length: the seed's 40 m walks last 20-30 s; variability and noise as the workbench's
#: realistic walks (:data:`workbench.synth.simulate.VARIED_WALK_RANGES`).
RECORD_RANGES: dict[str, tuple[float, float]] = {
    "duration_s": (20.0, 30.0),
    "noise_sd_n": (2.0, 15.0),
    "amplitude_sd": (0.02, 0.06),
    "step_duration_sd": (0.01, 0.03),
    "phase_sd_rad": (0.02, 0.06),
    "deck_rms_m_s2": (0.3, 1.0),
    "deck_bandwidth_fraction": (0.03, 0.10),
}


def _law(slope: float, intercept: float, residual_sd: float) -> LinearLaw:
    return LinearLaw(slope=slope, intercept=intercept, residual_sd=residual_sd)


def _named(fn: tuple[float, float], zeta: tuple[float, float], source: str) -> PopulationLaws:
    base = PopulationLaws()
    return base.replace(
        natural_frequency_hz=_law(*fn, base.natural_frequency_hz.residual_sd),
        damping_ratio=_law(*zeta, base.damping_ratio.residual_sd),
        source=source,
    )


#: The named truth laws: (f_n slope, intercept), (zeta slope, intercept) and a description.
TRUTH_LAWS: dict[str, tuple[tuple[float, float], tuple[float, float], str]] = {
    "seed": ((0.3049, 1.3670), (-0.2116, 0.8737), "the seed study's laws"),
    "constant": (
        (0.0, 2.85),
        (0.0, 0.29),
        "f_n 2.85 Hz and zeta 0.29 at every pacing (occupied-structure tests)",
    ),
    "zhang": ((1.1043, 0.0), (0.0, 0.30), "f_n = 1.1043 f_p, zeta 0.30 (Zhang et al.)"),
}


def truth_laws(spec: str) -> PopulationLaws:
    """Return the truth a recovery simulates: a name of :data:`TRUTH_LAWS` or a laws JSON file.

    Parameters
    ----------
    spec : str
        ``seed``, ``constant``, ``zhang``, or the path of a laws JSON (the object
        ``workbench population --json`` prints).

    Returns
    -------
    PopulationLaws
        Its ``source`` names the truth.
    """
    if spec in TRUTH_LAWS:
        fn, zeta, text = TRUTH_LAWS[spec]
        return _named(fn, zeta, f"{spec} ({text})")
    if not Path(spec).suffix.lower() == ".json":
        raise UsageError(
            f"the truth {spec!r} is neither one of {', '.join(TRUTH_LAWS)} nor a laws JSON "
            "file; name one of those, or give the path of a file ending in .json",
            parameter="truth",
        )
    return read_laws(spec)


@dataclass(frozen=True)
class RecoveryDesign:
    """What a recovery simulates.

    Parameters
    ----------
    truth : PopulationLaws
        The true laws (:func:`truth_laws`).
    floor : {"deck", "rigid"}
        Whether the walkers walk on a vibrating deck the record measures.
    n_records : int
        Records in the population (at least 8: one per metronome rate).
    sample_rate_hz : float
        Sample rate of every record [Hz].
    ranges : dict
        Ranges of the drawn record details (:data:`RECORD_RANGES` keys).
    """

    truth: PopulationLaws = field(default_factory=lambda: truth_laws("seed"))
    floor: str = "deck"
    n_records: int = 60
    sample_rate_hz: float = 100.0
    ranges: dict[str, tuple[float, float]] = field(default_factory=lambda: dict(RECORD_RANGES))

    def __post_init__(self) -> None:
        if self.floor not in FLOORS:
            raise UsageError(
                f"'floor' must be one of {', '.join(FLOORS)}, got {self.floor!r}",
                parameter="floor",
            )
        n = self.n_records
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < len(FIXED_PACING_HZ):
            raise UsageError(
                f"'n_records' must be an integer of at least {len(FIXED_PACING_HZ)} (one record "
                f"per metronome rate), got {n!r}",
                parameter="n_records",
            )
        fs = self.sample_rate_hz
        if not (isinstance(fs, int | float) and math.isfinite(fs) and 50.0 <= fs <= 2000.0):
            raise UsageError(
                f"'sample_rate_hz' must be between 50 and 2000 Hz, got {fs!r}",
                parameter="sample_rate_hz",
            )
        unknown = sorted(set(self.ranges) - set(RECORD_RANGES))
        if unknown:
            raise UsageError(
                f"unknown record range {unknown[0]!r}; choose from {', '.join(RECORD_RANGES)}",
                parameter="ranges",
            )

    def range(self, key: str) -> tuple[float, float]:
        """Return the range of one drawn detail (the design's, else the default)."""
        lo, hi = self.ranges.get(key, RECORD_RANGES[key])
        return float(lo), float(hi)

    def to_json(self) -> dict[str, Any]:
        """Return the design as JSON (the truth as its laws)."""
        return {
            "truth": self.truth.to_json(),
            "floor": self.floor,
            "n_records": int(self.n_records),
            "sample_rate_hz": float(self.sample_rate_hz),
            "ranges": {k: list(self.range(k)) for k in RECORD_RANGES},
        }


def recovery_plan(design: RecoveryDesign, *, seed: int = 0) -> pd.DataFrame:
    """Draw the population: one row per record with its truth and its recording details.

    Parameters
    ----------
    design : RecoveryDesign
        The truth, the floor and the ranges.
    seed : int
        Fixes every draw.

    Returns
    -------
    pandas.DataFrame
        Columns ``record, path, mass_kg, pacing_hz, natural_frequency_hz, damping_ratio,
        blf1-3, phase1-3_rad, duration_s, noise_sd_n, amplitude_sd, step_duration_sd,
        phase_sd_rad, deck_kind, deck_rms_m_s2, deck_frequency_hz, deck_bandwidth_hz,
        deck_phase_rad, deck_seed, seed`` (deck columns empty on a rigid floor).
    """
    from workbench.population.sampler import BLF1_BOUNDS, FN_BOUNDS_HZ, ZETA_BOUNDS, _law_draw

    rng = np.random.default_rng([check_seed(seed, "recovery_plan"), 0x5EC0])
    n = int(design.n_records)
    laws = design.truth
    # The seed's metronome rates in turn, so every population spans the pacing range evenly.
    pacing = np.resize(np.asarray(FIXED_PACING_HZ, dtype=float), n)
    plan = pd.DataFrame(
        {"record": [f"r{i:04d}" for i in range(n)], "mass_kg": _masses(rng, n, laws)}
    )
    plan.insert(1, "path", [f"records/{r}.csv" for r in plan["record"]])
    plan["pacing_hz"] = pacing
    plan["natural_frequency_hz"] = _law_draw(
        rng, laws, "natural_frequency_hz", pacing, (FN_BOUNDS_HZ[0], 10.0)
    )
    plan["damping_ratio"] = _law_draw(rng, laws, "damping_ratio", pacing, ZETA_BOUNDS)
    plan["blf1"] = _law_draw(rng, laws, "blf1", pacing, BLF1_BOUNDS)
    plan["blf2"] = np.exp(rng.normal(laws.blf2.mu, laws.blf2.sigma, n))
    plan["blf3"] = np.exp(rng.normal(laws.blf3.mu, laws.blf3.sigma, n))
    phases = rng.uniform(0.0, 2.0 * np.pi, (n, 3))
    for i in range(3):
        plan[f"phase{i + 1}_rad"] = phases[:, i]
    for key in ("duration_s", "noise_sd_n", "amplitude_sd", "step_duration_sd", "phase_sd_rad"):
        plan[key] = rng.uniform(*design.range(key), n)
    # Drawn on either floor, so a rigid and a deck population of one seed share their walkers.
    lo, hi = design.range("deck_rms_m_s2")
    deck = {
        "deck_kind": np.where(rng.random(n) < 0.5, "sine", "narrowband"),
        "deck_rms_m_s2": np.exp(rng.uniform(np.log(lo), np.log(hi), n)),
        "deck_frequency_hz": pacing
        * np.where(
            rng.random(n) < 0.5,
            rng.uniform(*DECK_RATIOS[0], n),
            rng.uniform(*DECK_RATIOS[1], n),
        ),
        "deck_bandwidth_fraction": rng.uniform(*design.range("deck_bandwidth_fraction"), n),
        "deck_phase_rad": rng.uniform(0.0, 2.0 * np.pi, n),
        "deck_seed": rng.integers(0, 2**31 - 1, n),
    }
    plan["seed"] = rng.integers(0, 2**31 - 1, n)
    if design.floor == "deck":
        for key, values in deck.items():
            plan[key] = values
    else:
        for key in deck:
            plan[key] = None
    return plan


def simulate_recovery_record(row: Any, sample_rate_hz: float) -> Any:
    """Simulate one planned record (a row of :func:`recovery_plan`).

    Returns
    -------
    Record
        With the body mass and the truth (``metadata["truth"]``).
    """
    from workbench.synth.decks import NarrowBandDeck, SineDeck
    from workbench.synth.simulate import simulate_walking

    deck: Any = None
    kind = row.get("deck_kind")
    if isinstance(kind, str) and kind:
        rms, freq = float(row["deck_rms_m_s2"]), float(row["deck_frequency_hz"])
        if kind == "sine":
            deck = SineDeck(rms, freq, float(row["deck_phase_rad"]))
        else:
            n_samples = round(float(row["duration_s"]) * sample_rate_hz)
            deck = NarrowBandDeck(
                rms,
                freq,
                freq * float(row["deck_bandwidth_fraction"]),
                seed=int(row["deck_seed"]),
                period_s=n_samples / sample_rate_hz,
            )
    sim = simulate_walking(
        mass_kg=float(row["mass_kg"]),
        pacing_hz=float(row["pacing_hz"]),
        duration_s=float(row["duration_s"]),
        natural_frequency_hz=float(row["natural_frequency_hz"]),
        damping_ratio=float(row["damping_ratio"]),
        blf=[float(row[f"blf{i}"]) for i in (1, 2, 3)],
        phases_rad=[float(row[f"phase{i}_rad"]) for i in (1, 2, 3)],
        step_duration_sd=float(row["step_duration_sd"]),
        amplitude_sd=float(row["amplitude_sd"]),
        phase_sd_rad=float(row["phase_sd_rad"]),
        noise_sd_n=float(row["noise_sd_n"]),
        sample_rate_hz=float(sample_rate_hz),
        start="steady",
        ground_acc_m_s2=deck,
        seed=int(row["seed"]),
    )
    subject = row.get("subject") if hasattr(row, "get") else None
    return sim.record.replace(subject=str(subject or row["record"]))


#: A walker's own spread from crossing to crossing about their mean law (sd of f_n [Hz],
#: zeta, BLF1, log BLF2, log BLF3): an assumption, a fraction of the population's residual
#: sd, since one person varies less than a population does.
CROSSING_SD = {
    "natural_frequency_hz": 0.03,
    "damping_ratio": 0.01,
    "blf1": 0.01,
    "blf2": 0.1,
    "blf3": 0.1,
}
#: A walker's mean self-chosen pacing is drawn over this range [Hz] (the seed's slow to fast
#: self-chosen cases), and each crossing's pacing about it with this sd [Hz].
WALKER_PACING_HZ = (1.65, 2.05)
CROSSING_PACING_SD_HZ = 0.08


def _check_crossings(crossings: Any) -> int:
    if isinstance(crossings, bool) or not isinstance(crossings, int | np.integer) or crossings < 1:
        raise UsageError(
            f"'crossings' must be a whole number of at least 1, got {crossings!r}",
            parameter="crossings",
        )
    return int(crossings)


def _one_walker(
    *,
    seed: int,
    crossings: int,
    laws: PopulationLaws,
    deck_rms_m_s2: tuple[float, float],
    duration_s: float | tuple[float, float],
    walker: int | None = None,
) -> pd.DataFrame:
    """Draw one walker of ``laws`` and their crossings (:func:`walker_plan`'s draws).

    Without ``walker`` the generator's key is ``[seed, 0x3A1C]`` and the records are named
    ``w<seed>_c<i>`` (:func:`walker_plan`); with it the key is ``[seed, 0x3A1C, walker]``
    and the names ``p<seed>_w<walker>_c<i>`` (:func:`footbridge_plan`). A range of
    ``duration_s`` is drawn per crossing after every other draw, so a fixed duration leaves
    the other draws as they were.
    """
    from workbench.population.sampler import BLF1_BOUNDS, FN_BOUNDS_HZ, ZETA_BOUNDS

    seed = check_seed(seed, "walker_plan")
    key = [seed, 0x3A1C] if walker is None else [seed, 0x3A1C, int(walker)]
    rng = np.random.default_rng(key)
    n = int(crossings)
    if walker is None:
        names = [f"w{seed:04d}_c{i:02d}" for i in range(n)]
        subject = f"walker{seed:04d}"
    else:
        subject = f"p{seed}_w{int(walker):03d}"
        names = [f"{subject}_c{i:02d}" for i in range(n)]
    mass = float(_masses(rng, 1, laws)[0])
    mean_pacing = float(rng.uniform(*WALKER_PACING_HZ))
    pacing = mean_pacing + rng.normal(0.0, CROSSING_PACING_SD_HZ, n)
    plan = pd.DataFrame(
        {
            "record": names,
            "subject": subject,
            "mass_kg": mass,
            "pacing_hz": pacing,
        }
    )
    plan.insert(1, "path", [f"records/{r}.csv" for r in plan["record"]])
    bounds = {
        "natural_frequency_hz": (FN_BOUNDS_HZ[0], 10.0),
        "damping_ratio": ZETA_BOUNDS,
        "blf1": BLF1_BOUNDS,
    }
    for name, (lo, hi) in bounds.items():
        law: LinearLaw = getattr(laws, name)
        own = law.mean(pacing) + rng.normal(0.0, law.residual_sd)
        plan[f"walker_{name}"] = own
        plan[name] = np.clip(own + rng.normal(0.0, CROSSING_SD[name], n), lo * 1.01, hi * 0.99)
    for name in ("blf2", "blf3"):
        lognormal = getattr(laws, name)
        median = float(np.exp(rng.normal(lognormal.mu, lognormal.sigma)))
        plan[f"walker_{name}"] = median
        plan[name] = median * np.exp(rng.normal(0.0, CROSSING_SD[name], n))
    phases = rng.uniform(0.0, 2.0 * np.pi, (n, 3))
    for i in range(3):
        plan[f"phase{i + 1}_rad"] = phases[:, i]
    drawn = isinstance(duration_s, tuple)
    plan["duration_s"] = 0.0 if drawn else float(duration_s)  # type: ignore[arg-type]
    for key_ in ("noise_sd_n", "amplitude_sd", "step_duration_sd", "phase_sd_rad"):
        plan[key_] = rng.uniform(*RECORD_RANGES[key_], n)
    which = rng.random(n) < 0.5
    ratio = np.where(which, rng.uniform(*DECK_RATIOS[0], n), rng.uniform(*DECK_RATIOS[1], n))
    plan["deck_kind"] = "sine"
    plan["deck_rms_m_s2"] = rng.uniform(*deck_rms_m_s2, n)
    plan["deck_frequency_hz"] = pacing * ratio
    plan["deck_bandwidth_fraction"] = 0.0
    plan["deck_phase_rad"] = rng.uniform(0.0, 2.0 * np.pi, n)
    plan["deck_seed"] = rng.integers(0, 2**31 - 1, n)
    plan["seed"] = rng.integers(0, 2**31 - 1, n)
    if isinstance(duration_s, tuple):
        plan["duration_s"] = rng.uniform(float(duration_s[0]), float(duration_s[1]), n)
    return plan


def walker_plan(
    *,
    seed: int,
    crossings: int = 10,
    truth: PopulationLaws | None = None,
    deck_rms_m_s2: tuple[float, float] = (0.2, 0.3),
    duration_s: float = 30.0,
) -> pd.DataFrame:
    """Draw one walker and their crossings of a deck moving in one mode (a sine).

    The walker is one member of the ``truth`` population: their mean law of f_n, zeta and
    BLF1 against pacing is the population's shifted by one residual draw (BLF2 and BLF3:
    one lognormal draw each), and every crossing adds its own small spread about it
    (:data:`CROSSING_SD`), at its own pacing. Each crossing's deck is a sine of RMS
    uniform over ``deck_rms_m_s2`` at a ratio to that crossing's pacing drawn from
    :data:`DECK_RATIOS` (between the gait's harmonics).

    Parameters
    ----------
    seed : int
        Fixes every draw.
    crossings : int, default 10
        Records of the walker.
    truth : PopulationLaws, optional
        The population (default the seed's laws).
    deck_rms_m_s2 : (float, float), default (0.2, 0.3)
        Range of the deck's RMS acceleration [m/s^2].
    duration_s : float, default 30
        Length of every crossing's record [s].

    Returns
    -------
    pandas.DataFrame
        One row per crossing with the columns of :func:`recovery_plan` (the record's truth)
        plus ``subject`` and ``walker_<law>``: the walker's mean law at the crossing's
        pacing (BLF2 and BLF3: the walker's median), the target of a walker fit.
    """
    laws = truth if truth is not None else truth_laws("seed")
    n = _check_crossings(crossings)
    return _one_walker(
        seed=seed, crossings=n, laws=laws, deck_rms_m_s2=deck_rms_m_s2, duration_s=duration_s
    )


def generating_parameters(truth: PopulationLaws) -> pd.Series:
    """Return the hierarchical model's parameters a walker population of ``truth`` is drawn from.

    As :func:`walker_plan` and :func:`footbridge_plan` draw walkers: a walker's own law is
    the population's shifted by one draw of the law's residual sd, which is therefore the
    model's walker sd; each crossing adds :data:`CROSSING_SD`, the model's residual (record)
    sd. For BLF2 and BLF3 (log scale): ``mu``, the walker sd ``sigma`` and the crossing sd.

    Returns
    -------
    pandas.Series
        Indexed by the names of :attr:`HierarchicalFit.params
        <workbench.population.hierarchy.HierarchicalFit.params>`: ``<law>.slope``,
        ``.intercept`` (the seed's form ``slope * f_p + intercept``), ``.walker_sd`` and
        ``.residual_sd`` for f_n, zeta and BLF1; ``<law>.mu``, ``.walker_sd`` and
        ``.residual_sd`` for BLF2 and BLF3.
    """
    values: dict[str, float] = {}
    for name in ("natural_frequency_hz", "damping_ratio", "blf1"):
        law: LinearLaw = getattr(truth, name)
        values[f"{name}.slope"] = float(law.slope)
        values[f"{name}.intercept"] = float(law.intercept)
        values[f"{name}.walker_sd"] = float(law.residual_sd)
        values[f"{name}.residual_sd"] = float(CROSSING_SD[name])
    for name in ("blf2", "blf3"):
        lognormal = getattr(truth, name)
        values[f"{name}.mu"] = float(lognormal.mu)
        values[f"{name}.walker_sd"] = float(lognormal.sigma)
        values[f"{name}.residual_sd"] = float(CROSSING_SD[name])
    return pd.Series(values)


def footbridge_plan(
    *,
    seed: int,
    walkers: int = 40,
    crossings: int = 3,
    truth: PopulationLaws | None = None,
    deck_rms_m_s2: tuple[float, float] = (0.1, 0.5),
    duration_s: tuple[float, float] = (20.0, 30.0),
) -> tuple[pd.DataFrame, pd.Series]:
    """Draw a footbridge's population: many walkers, each crossing a lively deck a few times.

    Every walker is drawn as :func:`walker_plan` draws one (their own generator, keyed by
    ``seed`` and the walker's index): a member of the ``truth`` population whose mean law
    of f_n, zeta and BLF1 is the population's shifted by one residual draw (BLF2, BLF3: one
    lognormal median each), with their own body mass and mean self-chosen pacing. Each of
    their ``crossings`` is at its own pacing about that mean and adds its own spread
    (:data:`CROSSING_SD`) about the walker's law. The deck moves in one mode (a sine) at a
    ratio to the crossing's pacing from :data:`DECK_RATIOS`, of RMS acceleration uniform
    over ``deck_rms_m_s2``; the crossing lasts a time uniform over ``duration_s``.

    Parameters
    ----------
    seed : int
        Fixes every draw.
    walkers : int, default 40
        Walkers in the population.
    crossings : int, default 3
        Crossings (records) per walker.
    truth : PopulationLaws, optional
        The population (default the seed's laws).
    deck_rms_m_s2 : (float, float), default (0.1, 0.5)
        Range of the deck's RMS acceleration [m/s^2].
    duration_s : (float, float), default (20, 30)
        Range of a crossing's length [s].

    Returns
    -------
    plan : pandas.DataFrame
        One row per crossing, columns as :func:`walker_plan`'s; records are named
        ``p<seed>_w<walker>_c<crossing>`` and the subject is ``p<seed>_w<walker>``.
    parameters : pandas.Series
        The generating parameters of the hierarchical model (:func:`generating_parameters`).
    """
    laws = truth if truth is not None else truth_laws("seed")
    seed = check_seed(seed, "footbridge_plan")
    n = _check_crossings(crossings)
    if isinstance(walkers, bool) or not isinstance(walkers, int | np.integer) or walkers < 1:
        raise UsageError(
            f"'walkers' must be a whole number of at least 1, got {walkers!r}",
            parameter="walkers",
        )
    lo, hi = (float(v) for v in duration_s)
    if not 0.0 < lo <= hi:
        raise UsageError(
            f"'duration_s' must be a range (low, high) of positive seconds, got {duration_s!r}",
            parameter="duration_s",
        )
    plan = pd.concat(
        [
            _one_walker(
                seed=seed,
                crossings=n,
                laws=laws,
                deck_rms_m_s2=deck_rms_m_s2,
                duration_s=(lo, hi),
                walker=j,
            )
            for j in range(int(walkers))
        ],
        ignore_index=True,
    )
    return plan, generating_parameters(laws)


@dataclass(frozen=True)
class _RecordTask:
    row: dict[str, Any]
    file: str
    sample_rate_hz: float


def _write_record(task: _RecordTask) -> str:
    from workbench.records.io import save_record

    save_record(simulate_recovery_record(task.row, task.sample_rate_hz), task.file)
    return task.file

"""Footfalls and pacing of simulated walks against their truth, and of the embedded records.

Usage::

    python analyses/footfall_accuracy.py [--seeds 0-71] [--records] [--no-surface]
        [--replays] [--recovery-decks] [--recovery-rigid]

Walks (seeds fixed in advance: 0-71 by default; walk ``s`` draws its details from
``numpy.random.default_rng([s, 0xF007])``): the kind cycles with the seed -- steady,
overground (standing, three steps to start, steady, three to stop, standing:
:meth:`GaitProfile.overground`), speed change (:meth:`GaitProfile.speed_change`: 18 steps,
a 4-step ramp, then 30 steps at 0.8-1.25 times the first pacing, so that the median pacing
is the new one) -- and every other triple of seeds walks on a deck (sine or narrow-band,
1.5-4 Hz, 0.1-1.5 m/s^2 RMS, log-uniform). Every walk has double-humped steps
(:func:`double_hump_force`, the push-off hump 0.8-1.25 times the loading hump, drawn
log-uniform, so the two humps differ by 0-20 % whichever is higher), mass 50-100 kg, pacing
1.5-2.3 Hz, f_n 1.8-3.4 Hz, damping ratio 0.2-0.5, 1-3 % step-duration jitter, 2-8 %
amplitude and 0.02-0.08 rad phase variability per harmonic, 0-20 N GRF noise, 100, 200 or
500 Hz. The record goes through ``inspect_record`` as every command does, with the pacing
the simulator states in it and with its deck channel; ``--no-stated-pacing`` and
``--no-surface`` leave those out. Without a stated pacing, a walker whose natural frequency
is near twice the pacing has a GRF whose second harmonic outweighs the first, and the
pacing is then found an octave high.

True event. A boundary is the peak of the pacing (first-harmonic) component of the walker's
own GRF (docs/science.md 2): for the simulated walker, the first harmonic of its mean step
force passed through the rigid-floor response ``-M w^2 / (K - M w^2 + i C w)`` at the walk's
pacing, at a fixed phase of every true step. Each footfall's phase in its true step is
compared with that event (``fundamental``); ``peak`` compares it instead with the highest
point of the true mean step's GRF (the "dominant peak" of the earlier convention, ill-defined
when the humps are of equal height); ``median`` with the walk's own median phase (no
convention at all). The true pacing is the median of ``2 / (d_j + d_j+1)`` over the true
walking steps (standing steps of an overground walk left out), the statistic the workbench
reports.

``--replays`` adds a 1 m/s^2 RMS sine deck at 2.9 Hz to the real records: the force of an
SMD (f_n 3.04 Hz, damping ratio 0.3, the record's body mass) riding the deck is added to
the measured GRF, and the record is inspected with and without the deck's acceleration.

``--recovery-decks`` (and ``--recovery-rigid``) inspects the records of a population
recovery: the plan of :func:`recovery_plan` for population seed 0 with each named truth
(seed, constant, zhang), 60 records each at 100 Hz on the deck floor (rigid floor),
simulated by :func:`simulate_recovery_record`. These walkers' forces follow the seed study's
load factors: the second and third harmonics are about a tenth of the first, so their steps
are close to a sinusoid. Reported per truth: footfalls within 0.1 step of the true event,
the pacing error's median and worst, the records more than 5 % off, and the records whose
pacing is within 3 % of the deck's frequency or of its half.

``--records`` also inspects the embedded records: the synthetic ones against their truth,
the real ones (treadmill, insole) against the heel strikes of their two feet's channels
(each side's force rising through 50 N after having been below 20 N): the lag from each
footfall to the last heel strike before it, its spread and the share of footfalls more than
0.15 step from the median lag (a footfall on the other hump).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np

from workbench import datasets
from workbench.records.inspection import inspect_record
from workbench.synth import GaitProfile, NarrowBandDeck, SineDeck, simulate_walking
from workbench.synth.gait import double_hump_force

#: A footfall within this of its true event is right [step].
WITHIN_STEP = 0.1
#: A footfall further than this from the walk's median phase is on the other hump [step].
OFF_HUMP_STEP = 0.15
KINDS = ("steady", "overground", "speed_change")


def draw_walker(rng: np.random.Generator) -> dict[str, Any]:
    """Draw a double-humped walker and its record's details (the study's ranges).

    ``analyses/diagnose_double_hump.py`` draws its walks with the same ranges.
    """
    return {
        "mass_kg": float(rng.uniform(50.0, 100.0)),
        "pacing_hz": float(rng.uniform(1.5, 2.3)),
        "natural_frequency_hz": float(rng.uniform(1.8, 3.4)),
        "damping_ratio": float(rng.uniform(0.2, 0.5)),
        "hump_ratio": float(np.exp(rng.uniform(np.log(0.8), np.log(1.25)))),
        "peak_fraction": float(rng.uniform(0.15, 0.35)),
        "step_duration_sd": float(rng.uniform(0.01, 0.03)),
        "amplitude_sd": float(rng.uniform(0.02, 0.08)),
        "phase_sd_rad": float(rng.uniform(0.02, 0.08)),
        "noise_sd_n": float(rng.uniform(0.0, 20.0)),
        "sample_rate_hz": float(rng.choice([100.0, 200.0, 500.0])),
        "duration_s": float(rng.uniform(30.0, 60.0)),
    }


def draw_walk(seed: int) -> tuple[Any, dict[str, Any]]:
    """Simulate walk ``seed`` of the study; returns the record and what was drawn."""
    rng = np.random.default_rng([seed, 0xF007])
    kind = KINDS[seed % 3]
    deck = (seed // 3) % 2 == 1
    d: dict[str, Any] = draw_walker(rng)
    # Drawn after the walker's details, in this order, whatever the walk's kind.
    d |= {
        "deck_rms_m_s2": float(np.exp(rng.uniform(np.log(0.1), np.log(1.5)))),
        "deck_frequency_hz": float(rng.uniform(1.5, 4.0)),
        "deck_kind": str(rng.choice(["sine", "narrowband"])),
        "deck_phase_rad": float(rng.uniform(0.0, 2.0 * np.pi)),
        "walking_steps": int(rng.integers(24, 41)),
        "pacing_ratio": float(np.exp(rng.uniform(np.log(0.8), np.log(1.25)))),
    }
    d["kind"], d["deck"] = kind, deck
    gait = None
    if kind == "overground":
        gait = GaitProfile.overground(walking_steps=d["walking_steps"], standing_steps=3)
    elif kind == "speed_change":
        gait = GaitProfile.speed_change(d["pacing_hz"], d["pacing_ratio"], 18, 4, 30)
    duration = d["duration_s"] if gait is None else gait.relative_length() / d["pacing_hz"]
    ground = None
    if deck:
        if d["deck_kind"] == "sine":
            ground = SineDeck(d["deck_rms_m_s2"], d["deck_frequency_hz"], d["deck_phase_rad"])
        else:
            ground = NarrowBandDeck(
                d["deck_rms_m_s2"],
                d["deck_frequency_hz"],
                0.05 * d["deck_frequency_hz"],
                seed=seed,
                period_s=round(duration * d["sample_rate_hz"]) / d["sample_rate_hz"],
            )
    return simulate_drawn_walker(d, duration, seed, ground, kind, gait), d


def simulate_drawn_walker(
    d: dict[str, Any],
    duration_s: float,
    seed: int,
    ground: Any = None,
    kind: str = "steady",
    gait: GaitProfile | None = None,
) -> Any:
    """Simulate the walker ``d`` (from :func:`draw_walker`) and return its record."""
    return simulate_walking(
        mass_kg=d["mass_kg"],
        pacing_hz=d["pacing_hz"],
        duration_s=duration_s,
        natural_frequency_hz=d["natural_frequency_hz"],
        damping_ratio=d["damping_ratio"],
        coefficients=double_hump_force(
            d["mass_kg"], d["hump_ratio"], peak_fraction=d["peak_fraction"]
        ),
        step_duration_sd=d["step_duration_sd"],
        amplitude_sd=d["amplitude_sd"],
        phase_sd_rad=d["phase_sd_rad"],
        noise_sd_n=d["noise_sd_n"],
        sample_rate_hz=d["sample_rate_hz"],
        ground_acc_m_s2=ground,
        start="rest" if kind == "overground" else "steady",
        seed=seed,
        gait=gait,
    ).record


def true_events(truth: dict[str, Any]) -> tuple[float, float]:
    """Step phase [share of a step] of the true boundary event and of the GRF's highest point."""
    mass = float(truth["mass_kg"])
    k = float(truth["stiffness_n_per_m"])
    c = float(truth["damping_ns_per_m"])
    coef = np.asarray(truth["force_coefficients"], dtype=np.float64)
    starts = np.asarray(truth["step_start_s"])
    durations = np.asarray(truth["step_duration_s"])
    w = 2.0 * np.pi / float(np.median(durations))
    orders = np.arange(1, (coef.size - 1) // 2 + 1)
    # a cos + b sin = Re[(a - i b) e^{i theta}]; the GRF minus M g is M u''.
    z = (coef[1::2] - 1j * coef[2::2]) * (
        -mass * (orders * w) ** 2 / (k - mass * (orders * w) ** 2 + 1j * c * orders * w)
    )
    fundamental = (-np.angle(z[0]) / (2.0 * np.pi)) % 1.0
    theta = np.arange(2000) / 2000.0
    grf = np.real(z[:, None] * np.exp(2j * np.pi * np.outer(orders, theta))).sum(axis=0)
    del starts
    return float(fundamental), float(theta[np.argmax(grf)])


def _wrap(x: np.ndarray) -> np.ndarray:
    return (x + 0.5) % 1.0 - 0.5


def footfall_phases(record: Any, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each footfall's phase in its true step [share] and whether that step is walking."""
    truth = record.metadata["truth"]
    starts = np.asarray(truth["step_start_s"], dtype=np.float64)
    durations = np.asarray(truth["step_duration_s"], dtype=np.float64)
    amplitude = np.asarray(truth.get("step_amplitude_factor", np.ones(starts.size)))
    k = np.searchsorted(starts, times_s, side="right") - 1
    ok = (k >= 0) & (k < durations.size)
    phase = np.full(times_s.shape, np.nan)
    phase[ok] = (times_s[ok] - starts[k[ok]]) / durations[k[ok]]
    walking = np.zeros(times_s.shape, dtype=bool)
    # A footfall at the event just before a step counts with the step it opens or closes.
    for shift in (-1, 0, 1):
        j = np.clip(k + shift, 0, amplitude.size - 1)
        walking |= ok & (amplitude[j] > 0)
    return phase, walking


def true_pacing(truth: dict[str, Any]) -> float:
    """Median of ``2 / (d_j + d_j+1)`` over the true walking steps."""
    durations = np.asarray(truth["step_duration_s"], dtype=np.float64)
    amplitude = np.asarray(truth.get("step_amplitude_factor", np.ones(durations.size)))
    walking = amplitude > 0
    pairs = walking[1:] & walking[:-1]
    return float(np.median(2.0 / (durations[1:] + durations[:-1])[pairs]))


def measure(record: Any) -> dict[str, Any]:
    """Inspect a simulated record and compare its footfalls and pacing with the truth."""
    truth = record.metadata["truth"]
    insp = inspect_record(record)
    times = np.asarray(insp.steps.footfall_times_s) - float(record.time_s[0])
    phase, walking = footfall_phases(record, times)
    fundamental, peak = true_events(truth)
    keep = np.isfinite(phase)
    frac = phase[keep] % 1.0
    centre = float(np.angle(np.mean(np.exp(2j * np.pi * frac))) / (2.0 * np.pi))
    dev_fund = np.abs(_wrap(frac - fundamental))
    dev_peak = np.abs(_wrap(frac - peak))
    dev_median = np.abs(_wrap(frac - centre))
    true_fp = true_pacing(truth)
    inst = np.asarray(insp.pacing.instantaneous_hz)
    json = insp.to_json()
    return {
        "n": int(keep.sum()),
        "standing": int(np.sum(keep & ~walking)),
        "within_fund": int(np.sum(dev_fund <= WITHIN_STEP)),
        "within_peak": int(np.sum(dev_peak <= WITHIN_STEP)),
        "off_median": int(np.sum(dev_median > OFF_HUMP_STEP)),
        "pacing_hz": float(insp.pacing.pacing_hz),
        "spectral_hz": float(insp.pacing.spectral_pacing_hz),
        "true_pacing_hz": true_fp,
        "pacing_error": abs(float(insp.pacing.pacing_hz) - true_fp) / true_fp,
        "p10": float(np.percentile(inst, 10)) / true_fp - 1.0,
        "p90": float(np.percentile(inst, 90)) / true_fp - 1.0,
        "varies": bool(insp.pacing.varies),
        "steps": int(insp.steps.n_steps),
        "split": json.get("split"),
        "richness": richness(insp),
        "locking": locking(insp),
        "warnings": len(insp.warnings),
        "octave_warning": any("fast for walking" in w for w in insp.warnings),
    }


def study(seeds: range, surface: bool, stated_pacing: bool) -> int:
    """Print the per-walk table and the summary over ``seeds``."""
    print(
        "| seed | kind | deck m/s^2, Hz | humps | pacing Hz | footfalls | within 0.1 step "
        "of the event | of the GRF peak | off median > 0.15 | pacing error % | "
        "per-step p10, p90 % | varies |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    )
    rows = []
    for seed in seeds:
        record, d = draw_walk(seed)
        if not stated_pacing:
            record = record.replace(pacing_hz=None)
        if not surface:
            record = record.replace(ground_acc_m_s2=None)
        try:
            m = measure(record)
        except Exception as err:  # a failed inspection is a result of the study too
            print(f"| {seed} | {d['kind']} | failed: {err} |", flush=True)
            rows.append({"seed": seed, **d, "failed": True})
            continue
        rows.append({"seed": seed, **d, **m, "failed": False})
        deck = f"{d['deck_rms_m_s2']:.2f}, {d['deck_frequency_hz']:.2f}" if d["deck"] else "-"
        print(
            f"| {seed} | {d['kind']} | {deck} | {d['hump_ratio']:.2f} | "
            f"{m['true_pacing_hz']:.3f} | "
            f"{m['n']} | {100 * m['within_fund'] / max(m['n'], 1):.0f} % | "
            f"{100 * m['within_peak'] / max(m['n'], 1):.0f} % | {m['off_median']} | "
            f"{100 * m['pacing_error']:.2f} | {100 * m['p10']:+.1f}, {100 * m['p90']:+.1f} | "
            f"{'yes' if m['varies'] else 'no'} |",
            flush=True,
        )
    summarise(rows)
    return 0


def summarise(rows: list[dict[str, Any]]) -> None:
    """Print the totals the issue asks for."""
    ok = [r for r in rows if not r["failed"]]
    print(f"\nwalks: {len(rows)}, inspected: {len(ok)}, failed: {len(rows) - len(ok)}")

    def share(sel: list[dict[str, Any]], key: str) -> str:
        n = sum(r["n"] for r in sel)
        return f"{100 * sum(r[key] for r in sel) / max(n, 1):.1f} % of {n}"

    groups = {
        "all": ok,
        "rigid": [r for r in ok if not r["deck"]],
        "deck <= 1 m/s^2": [r for r in ok if r["deck"] and r["deck_rms_m_s2"] <= 1.0],
        "deck > 1 m/s^2": [r for r in ok if r["deck"] and r["deck_rms_m_s2"] > 1.0],
        **{kind: [r for r in ok if r["kind"] == kind] for kind in KINDS},
    }
    for label, sel in groups.items():
        if not sel:
            continue
        errors = np.array([r["pacing_error"] for r in sel])
        flipped = sum(r["off_median"] > 0 for r in sel)
        print(
            f"{label} ({len(sel)} walks): footfalls within {WITHIN_STEP} step of the event "
            f"{share(sel, 'within_fund')}; of the GRF peak {share(sel, 'within_peak')}; "
            f"walks with footfalls > {OFF_HUMP_STEP} step off their median phase {flipped}; "
            f"median pacing error {100 * np.median(errors):.2f} % (max {100 * errors.max():.2f} %)"
        )
    rich = np.array([r["richness"] for r in ok if np.isfinite(r.get("richness", np.nan))])
    if rich.size:
        print(
            f"median step's power above its first harmonic: {100 * rich.min():.1f}-"
            f"{100 * rich.max():.1f} % over the walks"
        )
    steady = [r for r in ok if r["kind"] == "steady"]
    if steady:
        p10 = np.array([r["p10"] for r in steady])
        p90 = np.array([r["p90"] for r in steady])
        inside = np.sum((p10 >= -0.05) & (p90 <= 0.05))
        print(
            f"steady walks: per-step p10-p90 within +-5 % of the true median pacing in "
            f"{inside} of {len(steady)} (p10 lowest {100 * p10.min():+.1f} %, p90 highest "
            f"{100 * p90.max():+.1f} %); 'pacing varies' on {sum(r['varies'] for r in steady)}"
        )
    # An octave error: the pacing found at about twice (or half) the true pacing.
    octave = [r for r in ok if abs(np.log2(r["pacing_hz"] / r["true_pacing_hz"])) > 0.5]
    named = sum(r["octave_warning"] for r in octave)
    false_alarms = sum(r["octave_warning"] for r in ok) - named
    print(
        f"pacing an octave off: {len(octave)} of {len(ok)} walks, named by inspect's "
        f"'fast for walking' warning in {named}; the warning on walks at the right octave: "
        f"{false_alarms}"
    )
    decks = [r for r in ok if r["deck"]]
    on_deck = sum(
        abs(r["pacing_hz"] - r["deck_frequency_hz"]) < 0.03 * r["deck_frequency_hz"]
        and abs(r["deck_frequency_hz"] - r["true_pacing_hz"]) > 0.05 * r["true_pacing_hz"]
        for r in decks
    )
    spectral_on_deck = sum(
        abs(r["spectral_hz"] - r["deck_frequency_hz"]) < 0.03 * r["deck_frequency_hz"]
        and abs(r["deck_frequency_hz"] - r["true_pacing_hz"]) > 0.05 * r["true_pacing_hz"]
        for r in decks
    )
    print(
        f"deck walks: pacing at the deck's frequency in {on_deck} of {len(decks)}; spectral "
        f"pacing at the deck's frequency in {spectral_on_deck}"
    )


def heel_strike_times(time_s: np.ndarray, force_n: np.ndarray) -> np.ndarray:
    """Return the times where the force rises through 50 N after having been below 20 N."""
    strikes, loaded = [], bool(force_n[0] > 50.0)
    for i, value in enumerate(force_n):
        if not loaded and value > 50.0:
            strikes.append(time_s[i])
            loaded = True
        elif loaded and value < 20.0:
            loaded = False
    return np.asarray(strikes)


def embedded() -> None:
    """Inspect every embedded record and check its footfalls against truth or heel strikes."""
    print("\n| record | steps | pacing Hz | check |\n|---|---|---|---|")
    for name in datasets.names():
        record = datasets.load(name)
        if name == "seed_numerical_example":
            continue  # a benchmark of the seed's eq. 24, not a walk
        options = datasets.dataset_options(name)[0]
        mass = options.get("mass_kg")
        if record.mass_kg is None and mass is not None:
            record = record.replace(mass_kg=float(mass))
        if record.mass_kg is None:
            record = record.replace(mass_kg=REAL_MASS_KG.get(name))
        insp = inspect_record(record)
        times = np.asarray(insp.steps.footfall_times_s)
        truth = record.metadata.get("truth")
        if truth and "step_start_s" in truth:
            phase, _ = footfall_phases(record, times - float(record.time_s[0]))
            frac = phase[np.isfinite(phase)] % 1.0
            fundamental, peak = true_events(truth)
            centre = float(np.angle(np.mean(np.exp(2j * np.pi * frac))) / (2.0 * np.pi))
            check = (
                f"truth: {100 * np.mean(np.abs(_wrap(frac - fundamental)) <= WITHIN_STEP):.0f} % "
                f"within {WITHIN_STEP} step of the event "
                f"({100 * np.mean(np.abs(_wrap(frac - peak)) <= WITHIN_STEP):.0f} % of the GRF "
                "peak), "
                f"{int(np.sum(np.abs(_wrap(frac - centre)) > OFF_HUMP_STEP))} more than "
                f"{OFF_HUMP_STEP} step off the median phase; true pacing "
                f"{true_pacing(truth):.3f} Hz"
            )
        elif record.grf_left_n is not None and record.grf_right_n is not None:
            t = np.asarray(record.time_s)
            strikes = np.sort(
                np.concatenate(
                    [
                        heel_strike_times(t, record.grf_left_n),
                        heel_strike_times(t, record.grf_right_n),
                    ]
                )
            )
            k = np.searchsorted(strikes, times, side="right") - 1
            ok = (k >= 0) & (k < strikes.size - 1)
            span = strikes[k[ok] + 1] - strikes[k[ok]]
            lag = (times[ok] - strikes[k[ok]]) / span  # share of the step between heel strikes
            regular = (span > 0.3) & (span < 1.0)  # not across a turn or a missed strike
            lag = lag[regular]
            centre = float(np.median(lag))
            off = int(np.sum(np.abs(lag - centre) > OFF_HUMP_STEP))
            check = (
                f"heel strikes {strikes.size}: footfall at {centre:.3f} step after the last "
                f"heel strike (sd {np.std(lag):.3f}), {off} of {lag.size} more than "
                f"{OFF_HUMP_STEP} step from it"
            )
        else:
            check = "no truth, no foot channels"
        print(
            f"| {name} | {insp.steps.n_steps} | {insp.pacing.pacing_hz:.3f} | {check} |", flush=True
        )


REAL_MASS_KG = {"treadmill": 77.3, "insole": 83.0}
#: The replayed deck's frequency [Hz].
DECK_REPLAY_HZ = 2.9


def deck_replay(name: str, with_surface: bool) -> Any:
    """Return a real record plus the force of an SMD riding a 1 m/s^2 RMS sine deck at 2.9 Hz."""
    from scipy import signal

    record = datasets.load(name).replace(mass_kg=REAL_MASS_KG[name])
    fs = record.sample_rate_hz
    t = np.arange(record.n_samples) / fs
    deck = np.sqrt(2.0) * np.sin(2.0 * np.pi * DECK_REPLAY_HZ * t)
    w, zeta = 2.0 * np.pi * 3.04, 0.3
    # Body acceleration over deck acceleration of an SMD on a moving base.
    body = signal.lti([2.0 * zeta * w, w**2], [1.0, 2.0 * zeta * w, w**2])
    _, acc, _ = signal.lsim(body, deck, t)
    return record.replace(
        grf_n=record.grf_n + float(record.mass_kg) * acc,
        grf_left_n=None,
        grf_right_n=None,
        ground_acc_m_s2=deck if with_surface else None,
    )


def replays() -> None:
    """Inspect the real records with a strong deck added, with and without its channel."""
    print(
        "\n| record | deck channel | steps | pacing Hz | spectral Hz | off rhythm | "
        "median step above its first harmonic | harmonic locking of the steps; of steps cut "
        "at the deck's period |\n|---|---|---|---|---|---|---|---|"
    )
    for name in REAL_MASS_KG:
        plain = inspect_record(datasets.load(name).replace(mass_kg=REAL_MASS_KG[name]))
        print(
            f"| {name} | no deck | {plain.steps.n_steps} | {plain.pacing.pacing_hz:.3f} | "
            f"{plain.pacing.spectral_pacing_hz:.3f} | "
            f"{_off_rhythm(plain)} | {100 * richness(plain):.1f} % | {locking(plain):.0f} |"
        )
        for with_surface in (True, False):
            insp = inspect_record(deck_replay(name, with_surface))
            print(
                f"| {name} + deck 2.9 Hz | {'yes' if with_surface else 'no'} | "
                f"{insp.steps.n_steps} | {insp.pacing.pacing_hz:.3f} | "
                f"{insp.pacing.spectral_pacing_hz:.3f} | {_off_rhythm(insp)} | "
                f"{100 * richness(insp):.1f} % | {locking(insp):.0f}; "
                f"{_line_locking(insp, DECK_REPLAY_HZ):.1f} |",
                flush=True,
            )


def _lone_line_statistic(insp: Any, name: str, line_hz: float | None = None) -> float:
    """Evaluate a statistic of the split's lone-line check on an inspected record.

    ``name`` is ``step_shape_richness`` or ``step_harmonic_locking`` of
    :mod:`workbench.records.footfalls`, evaluated on the acceleration without the deck's
    response, at the record's footfalls or, with ``line_hz``, at that line's period (the
    split a lone line gives). NaN with a workbench that has no such check (the split before
    it), so that the study also measures that one.
    """
    try:
        from workbench.records import footfalls
    except ImportError:
        return float("nan")
    statistic = getattr(footfalls, name, None)
    if statistic is None:
        return float("nan")
    acc = np.asarray(insp.com.acc_m_s2)
    fs = insp.com.sample_rate_hz
    if insp.record.ground_acc_m_s2 is not None:
        acc = footfalls.without_surface(acc, insp.record.ground_acc_m_s2, fs)
    if line_hz is None:
        times = np.asarray(insp.steps.footfall_times_s) - float(insp.record.time_s[0])
    else:
        times = np.arange(0.5, acc.size / fs - 0.5, 1.0 / line_hz)
    return float(statistic(acc, fs, times))


def _line_locking(insp: Any, line_hz: float) -> float:
    """Harmonic locking of steps cut at a line's period (the split a lone line gives)."""
    return _lone_line_statistic(insp, "step_harmonic_locking", line_hz)


def richness(insp: Any) -> float:
    """Share of the median step's power above its first harmonic (the lone-line check)."""
    return _lone_line_statistic(insp, "step_shape_richness")


def _off_rhythm(insp: Any) -> str:
    split = insp.to_json().get("split")
    return "-" if split is None else str(len(split["off_rhythm_steps"]))


#: The population recovery's records: truths, population seed, records per truth.
RECOVERY_TRUTHS = ("seed", "constant", "zhang")
RECOVERY_SEED = 0
RECOVERY_RECORDS = 60
#: A record's pacing error beyond this is a failed split [share].
RECOVERY_OFF = 0.05
#: A pacing within this of the deck's frequency or of its half followed the deck [share].
ON_DECK = 0.03


def recovery(floor: str) -> None:
    """Inspect the records of the population recovery's plans against their truth."""
    from workbench.population.recovery_design import (
        RecoveryDesign,
        recovery_plan,
        simulate_recovery_record,
        truth_laws,
    )

    print(
        f"\n| truth ({floor}) | records | footfalls within {WITHIN_STEP} step of the event | "
        "median pacing error % | worst % | records > 5 % off | pacing at the deck or its half "
        "| harmonic locking min |\n|---|---|---|---|---|---|---|---|"
    )
    for truth in RECOVERY_TRUTHS:
        design = RecoveryDesign(truth=truth_laws(truth), floor=floor, n_records=RECOVERY_RECORDS)
        plan = recovery_plan(design, seed=RECOVERY_SEED)
        n = within = 0
        errors, off, on_deck, locking = [], [], [], []
        for row in plan.to_dict("records"):
            record = simulate_recovery_record(row, design.sample_rate_hz)
            m = measure(record)
            n += m["n"]
            within += m["within_fund"]
            signed = m["pacing_hz"] / m["true_pacing_hz"] - 1.0
            errors.append(signed)
            if abs(signed) > RECOVERY_OFF:
                off.append(f"{row['record']} {m['true_pacing_hz']:.3f}->{m['pacing_hz']:.3f}")
            locking.append(m["locking"])
            if floor == "deck":
                f_d = float(row["deck_frequency_hz"])
                if any(abs(m["pacing_hz"] - f) < ON_DECK * f for f in (f_d, 0.5 * f_d)):
                    on_deck.append(str(row["record"]))
        e = np.asarray(errors)
        worst = e[np.argmax(np.abs(e))]
        print(
            f"| {truth} | {len(errors)} | {100 * within / max(n, 1):.1f} % of {n} | "
            f"{100 * np.median(np.abs(e)):.2f} | {100 * worst:+.1f} | {len(off)}"
            f"{': ' + ', '.join(off) if off else ''} | "
            f"{len(on_deck) if floor == 'deck' else '-'}"
            f"{': ' + ', '.join(on_deck) if on_deck else ''} | "
            f"{_lowest(locking)} |",
            flush=True,
        )


def _lowest(values: list[float]) -> str:
    finite = [v for v in values if np.isfinite(v)]
    return f"{min(finite):.0f}" if finite else "-"


def locking(insp: Any) -> float:
    """Whether the split's harmonics 2-6 repeat from step to step (the lone-line check)."""
    return _lone_line_statistic(insp, "step_harmonic_locking")


def main(argv: list[str] | None = None) -> int:
    """Run the study."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="0-71", help="walk seeds, LOW-HIGH")
    ap.add_argument("--records", action="store_true", help="also check the embedded records")
    ap.add_argument("--no-surface", action="store_true", help="drop the deck channel")
    ap.add_argument(
        "--no-stated-pacing", action="store_true", help="drop the pacing stated in the record"
    )
    ap.add_argument("--replays", action="store_true", help="real records plus a strong deck")
    ap.add_argument(
        "--recovery-decks", action="store_true", help="the population recovery's deck records"
    )
    ap.add_argument(
        "--recovery-rigid", action="store_true", help="the same walkers on a rigid floor"
    )
    args = ap.parse_args(argv)
    lo, _, hi = args.seeds.partition("-")
    if args.recovery_decks:
        recovery("deck")
    if args.recovery_rigid:
        recovery("rigid")
    if args.records:
        embedded()
    if args.replays:
        replays()
    if args.seeds != "none":
        study(
            range(int(lo), int(hi or lo) + 1),
            surface=not args.no_surface,
            stated_pacing=not args.no_stated_pacing,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

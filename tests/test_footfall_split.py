"""The footfall split: one gait event per boundary, whatever the humps and the deck.

docs/science.md 2, step 5. Seeds and ranges are fixed in advance: double-humped walks are
seeds 100-111 of :func:`double_hump_walk` (steady, rigid and deck alternating), the hump
ratios 0.8, 0.9, 1.0, 1.1, 1.25 (seed 7); the deck-off comparison seeds 200-203.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from workbench import datasets
from workbench.diagnostics.criticism_data import prepare as prepare_criticism
from workbench.errors import InputError, UsageError
from workbench.inference.pipeline.identification import compile_problem
from workbench.inference.pipeline.identification import prepare as prepare_identification
from workbench.records.inspection import inspect_record
from workbench.records.steps import (
    OFF_RHYTHM_PHASE_STEPS,
    Steps,
    check_split,
)
from workbench.synth import SineDeck, simulate_walking
from workbench.synth.gait import DOUBLE_HUMP_PHASES_STEP, double_hump_force

from .test_steps import heel_strike_indices, read_insole_feet, read_treadmill_plates


def double_hump_walk(seed: int, hump_ratio: float, deck_rms: float = 0.0):
    """A steady 72 kg walker at 1.85 Hz with double-humped steps (2 % step jitter)."""
    rng = np.random.default_rng([seed, 33])
    deck = None
    if deck_rms > 0:
        deck = SineDeck(deck_rms, float(rng.uniform(2.3, 3.6)), float(rng.uniform(0, 6.28)))
    return simulate_walking(
        mass_kg=72.0,
        pacing_hz=1.85,
        duration_s=40.0,
        natural_frequency_hz=float(rng.uniform(2.0, 3.2)),
        damping_ratio=float(rng.uniform(0.2, 0.45)),
        coefficients=double_hump_force(72.0, hump_ratio),
        step_duration_sd=0.02,
        amplitude_sd=0.05,
        phase_sd_rad=0.05,
        noise_sd_n=5.0,
        sample_rate_hz=200.0,
        ground_acc_m_s2=deck,
        start="steady",
        seed=seed,
    ).record


def true_event_phase(truth: dict) -> float:
    """Phase [share of a step] of the peak of the true GRF's first harmonic."""
    mass, k, c = truth["mass_kg"], truth["stiffness_n_per_m"], truth["damping_ns_per_m"]
    a1, b1 = truth["force_coefficients"][1:3]
    w = 2 * np.pi / np.median(truth["step_duration_s"])
    z = (a1 - 1j * b1) * (-mass * w**2 / (k - mass * w**2 + 1j * c * w))
    return float((-np.angle(z) / (2 * np.pi)) % 1.0)


def boundary_errors(record, steps: Steps) -> np.ndarray:
    """Each boundary's distance [step] from the true event of its true step."""
    truth = record.metadata["truth"]
    starts = np.asarray(truth["step_start_s"])
    durations = np.asarray(truth["step_duration_s"])
    t = steps.footfall_times_s - record.time_s[0]
    k = np.searchsorted(starts, t, side="right") - 1
    phase = (t - starts[k]) / durations[k]
    return np.abs((phase - true_event_phase(truth) + 0.5) % 1.0 - 0.5)


@pytest.mark.parametrize("hump_ratio", [0.8, 0.9, 1.0, 1.1, 1.25])
def test_boundaries_stay_on_one_event_whatever_the_hump_heights(hump_ratio: float) -> None:
    record = double_hump_walk(7, hump_ratio)
    insp = inspect_record(record.replace(pacing_hz=None))
    errors = boundary_errors(record, insp.steps)
    assert np.all(errors < 0.1), errors.max()
    assert check_split(insp.steps).off_rhythm.size == 0
    # The per-step pacing of a steady walk stays within 5 % of the true median pacing.
    true_fp = 1.0 / np.median(record.metadata["truth"]["step_duration_s"])
    p10, p90 = np.percentile(insp.pacing.instantaneous_hz, [10, 90])
    assert 0.95 * true_fp < p10 and p90 < 1.05 * true_fp
    assert not insp.pacing.varies
    assert insp.pacing.pacing_hz == pytest.approx(true_fp, rel=0.005)


@pytest.mark.slow
def test_double_humped_walks_on_rigid_floors_and_decks() -> None:
    # Seeds 100-111: hump ratio 0.8-1.25 (log-uniform), every other walk on a 0.1-1 m/s^2
    # RMS sine deck at 2.3-3.6 Hz, measured.
    errors, pacing_errors = [], []
    for seed in range(100, 112):
        rng = np.random.default_rng(seed)
        ratio = float(np.exp(rng.uniform(np.log(0.8), np.log(1.25))))
        deck = float(np.exp(rng.uniform(np.log(0.1), np.log(1.0)))) if seed % 2 else 0.0
        record = double_hump_walk(seed, ratio, deck)
        insp = inspect_record(record.replace(pacing_hz=None))
        errors.append(boundary_errors(record, insp.steps))
        truth = np.asarray(record.metadata["truth"]["step_duration_s"])
        true_fp = float(np.median(2.0 / (truth[1:] + truth[:-1])))
        pacing_errors.append(abs(insp.pacing.pacing_hz - true_fp) / true_fp)
        p10, p90 = np.percentile(insp.pacing.instantaneous_hz, [10, 90])
        assert 0.95 * true_fp < p10 and p90 < 1.05 * true_fp, seed
    within = np.mean(np.concatenate(errors) < 0.1)
    assert within >= 0.98, within
    assert np.median(pacing_errors) < 0.005


@pytest.mark.parametrize("seed", [200, 201, 202, 203])
def test_a_measured_deck_does_not_move_the_boundaries(seed: int) -> None:
    # The same walker and the same draws with and without a 1 m/s^2 RMS deck at 2.7 Hz:
    # with the deck's acceleration in the record, the boundaries are those of the rigid
    # floor to within 0.05 step, and the pacing is not the deck's.
    base = dict(
        mass_kg=70.0, pacing_hz=1.7, duration_s=30.0, natural_frequency_hz=2.6,
        damping_ratio=0.3, coefficients=double_hump_force(70.0, 1.05), noise_sd_n=3.0,
        sample_rate_hz=100.0, start="steady", seed=seed,
    )  # fmt: skip
    rigid = inspect_record(simulate_walking(**base).record.replace(pacing_hz=None))
    deck = simulate_walking(**base, ground_acc_m_s2=SineDeck(1.0, 2.7, 0.4)).record
    on_deck = inspect_record(deck.replace(pacing_hz=None))
    # At most one footfall more or fewer at an end (filter edges); every other one is where
    # it was on the rigid floor.
    assert abs(on_deck.steps.n_steps - rigid.steps.n_steps) <= 1
    step_s = np.median(rigid.steps.durations_s)
    a, b = on_deck.steps.footfall_times_s, rigid.steps.footfall_times_s
    shift = np.abs(a[:, None] - b[None, :]).min(axis=1) / step_s
    assert np.sum(shift > 0.05) <= 1 and np.all(shift[1:-1] < 0.05)
    assert on_deck.pacing.pacing_hz == pytest.approx(rigid.pacing.pacing_hz, rel=0.005)
    assert on_deck.pacing.spectral_pacing_hz == pytest.approx(1.7, rel=0.03)


def test_embedded_synthetic_records_have_no_flipped_step() -> None:
    for name in (
        "cubic_stiffness",
        "population_typical",
        "seed_individual",
        "seed_individual_deck",
    ):
        record = datasets.load(name)
        insp = inspect_record(record)
        assert np.all(boundary_errors(record, insp.steps) < 0.1), name
        assert insp.split is not None and insp.split.off_rhythm.size == 0, name


@pytest.mark.parametrize(
    ("name", "mass_kg", "reader"),
    [("treadmill", 77.3, read_treadmill_plates), ("insole", 83.0, read_insole_feet)],
)
def test_real_records_keep_one_lag_after_heel_strike(name, mass_kg, reader) -> None:
    # The two feet's forces give every heel strike: each boundary follows the last heel
    # strike by the same share of the step, none by more than 0.15 step off that lag.
    insp = inspect_record(datasets.load(name).replace(mass_kg=mass_kg))
    t, left, right = reader(datasets.embedded_path(name))
    strikes = np.sort([t[i] for force in (left, right) for i in heel_strike_indices(force)])
    found = insp.steps.footfall_times_s
    k = np.searchsorted(strikes, found, side="right") - 1
    ok = (k >= 0) & (k < strikes.size - 1)
    span = strikes[k[ok] + 1] - strikes[k[ok]]
    lag = ((found[ok] - strikes[k[ok]]) / span)[(span > 0.3) & (span < 1.0)]
    assert lag.size > 0.9 * insp.steps.n_steps
    assert np.all(np.abs(lag - np.median(lag)) < 0.15)
    assert 0.0 < np.median(lag) < 0.2  # in double support, just after heel strike


def test_check_split_names_a_boundary_on_the_other_hump() -> None:
    record = double_hump_walk(7, 1.0)
    steps = inspect_record(record).steps
    assert check_split(steps).off_rhythm.size == 0
    times = steps.footfall_times_s.copy()
    times[20] += 0.45 * np.median(steps.durations_s)  # a jump to the other hump
    flipped = Steps(
        boundaries=np.rint(times * steps.sample_rate_hz).astype(np.intp),
        footfall_times_s=times,
        durations_s=np.diff(times),
        sample_rate_hz=steps.sample_rate_hz,
    )
    check = check_split(flipped)
    assert list(check.off_rhythm) == [19, 20]
    assert check.phase_off_steps[20] == pytest.approx(0.45, abs=0.05)
    assert np.nanmax(np.delete(check.phase_off_steps, 20)) < OFF_RHYTHM_PHASE_STEPS
    message = check.warning(flipped, "walk.csv")
    assert message is not None and message.startswith("walk.csv: 2 of ")
    assert "steps 20 (" in message and "21 (" in message
    json = check.to_json(flipped)
    assert json["off_rhythm_steps"] == [20, 21]
    assert json["off_rhythm_share"] == pytest.approx(2 / flipped.n_steps, abs=1e-4)


def test_inspect_reports_the_split_and_warns_on_a_pause() -> None:
    insp = inspect_record(datasets.load("insole").replace(mass_kg=83.0))
    split = insp.to_json()["split"]
    # The insole walk turns twice; the steps at the turns are named.
    assert 0 < len(split["off_rhythm_steps"]) < 0.05 * insp.steps.n_steps
    assert any("off the walker's rhythm" in w for w in insp.warnings)
    steady = inspect_record(datasets.load("seed_individual"))
    assert steady.to_json()["split"]["off_rhythm_steps"] == []
    assert not any("rhythm" in w for w in steady.warnings)


@pytest.mark.parametrize("name", datasets.names())
def test_inspect_identify_and_diagnose_use_one_set_of_steps_and_one_pacing(name: str) -> None:
    """Each command's own first stages on every embedded record, as its command line runs them.

    ``identify``: the embedded record's settings, :func:`prepare` and :func:`compile_problem`
    (the problem's pieces and pacing are what its JSON reports); ``diagnose``: the
    criticism's :func:`prepare`, whose steps and pacing its baseline reports.
    """
    record = datasets.load(name)
    settings = datasets.settings(name)
    try:
        insp = inspect_record(record)
    except InputError:
        # Not a walk (the seed's numerical example): no command finds steps in it.
        with pytest.raises(InputError):
            prepare_criticism(record)
        assert settings.model.pieces == "whole"
        return
    report = insp.to_json()
    problem = compile_problem(prepare_identification(record, settings), settings)
    data = prepare_criticism(record)
    assert report["steps"] == insp.steps.n_steps == problem.n_pieces == data.n_steps
    assert insp.pacing.pacing_hz == insp.steps.pacing_hz == problem.pacing_hz == data.pacing_hz
    assert data.split == report["split"]
    # The criticism's boundaries are the split's footfalls, up to the jitter its smooth phase
    # leaves out (a quarter of a step would be another footfall's).
    off = np.abs(data.footfall_times_s - insp.steps.footfall_times_s)
    assert np.max(off) < 0.25 * np.median(insp.steps.durations_s)


def test_double_hump_force_has_its_humps_where_and_as_high_as_asked() -> None:
    theta = np.arange(4000) / 4000
    for ratio in (0.8, 1.0, 1.25):
        c = np.asarray(double_hump_force(70.0, ratio, width_step=0.08, harmonics=8))
        force = sum(
            c[2 * i - 1] * np.cos(2 * np.pi * i * theta) + c[2 * i] * np.sin(2 * np.pi * i * theta)
            for i in range(1, 9)
        )
        assert c[0] == 0.0
        assert force.max() == pytest.approx(0.25 * 70.0 * 9.81, rel=1e-4)
        loading, push_off = (
            force[round(p * theta.size) % theta.size] - force.min() for p in DOUBLE_HUMP_PHASES_STEP
        )
        assert push_off / loading == pytest.approx(ratio, rel=0.05)
    with pytest.raises(UsageError, match="hump_ratio"):
        double_hump_force(70.0, 0.0)
    with pytest.raises(UsageError, match="harmonics"):
        double_hump_force(70.0, harmonics=1)


def test_an_unmeasured_deck_is_left_out_and_named() -> None:
    # Seed 200's walker on a 1 m/s^2 RMS sine deck at 2.9 Hz whose acceleration is not in
    # the record: the split finds that steps cut at 2.9 Hz average to a pure sinusoid,
    # notches the line out and follows the walker, and inspect says so.
    record = simulate_walking(
        mass_kg=70.0, pacing_hz=1.7, duration_s=30.0, natural_frequency_hz=3.0,
        damping_ratio=0.3, coefficients=double_hump_force(70.0, 0.9), noise_sd_n=3.0,
        sample_rate_hz=100.0, start="steady", seed=200, ground_acc_m_s2=SineDeck(1.0, 2.9),
    ).record.replace(pacing_hz=None, ground_acc_m_s2=None)  # fmt: skip
    insp = inspect_record(record)
    assert insp.steps.lone_line_hz == pytest.approx(2.9, rel=0.03)
    # The notch's filter edges can leave an end boundary off; the split check names it.
    errors = boundary_errors(record, insp.steps)
    assert np.mean(errors < 0.1) >= 0.95
    off = set(insp.split.off_rhythm) | {j + 1 for j in insp.split.off_rhythm}
    assert set(np.flatnonzero(errors >= 0.1)) <= off
    assert insp.pacing.pacing_hz == pytest.approx(1.7, rel=0.01)
    assert insp.pacing.spectral_pacing_hz == pytest.approx(1.7, rel=0.02)
    assert insp.to_json()["split"]["lone_line_hz"] == pytest.approx(2.9, rel=0.03)
    assert inspect_record(double_hump_walk(7, 1.0)).to_json()["split"]["lone_line_hz"] is None
    line = f"strong line at {insp.steps.lone_line_hz:.3f} Hz"
    assert any(line in w and "ground_acc" in w for w in insp.warnings)


def test_a_pacing_found_an_octave_high_is_named() -> None:
    # A slow walker (1.545 Hz) whose natural frequency is about twice the pacing: its GRF's
    # second harmonic outweighs the first, and with no pacing stated the spectrum cannot
    # tell this walk from one at twice the pace (the parameters of analyses/
    # footfall_accuracy.py's walk 54). inspect must say so and name the likely pacing;
    # stated, the pacing is right and nothing is said.
    walk = simulate_walking(
        mass_kg=79.94, pacing_hz=1.545, duration_s=52.0, natural_frequency_hz=3.227,
        damping_ratio=0.245, coefficients=double_hump_force(79.94, 1.178, peak_fraction=0.226),
        step_duration_sd=0.015, amplitude_sd=0.02, phase_sd_rad=0.044, noise_sd_n=1.6,
        sample_rate_hz=100.0, start="steady", seed=54,
    ).record  # fmt: skip
    unstated = inspect_record(walk.replace(pacing_hz=None))
    assert unstated.pacing.pacing_hz == pytest.approx(2 * 1.545, rel=0.03)
    octave = [w for w in unstated.warnings if "fast for walking" in w]
    assert len(octave) == 1 and "--pacing 1.5" in octave[0]
    stated = inspect_record(walk)
    assert stated.pacing.pacing_hz == pytest.approx(1.545, rel=0.01)
    assert not any("fast for walking" in w for w in stated.warnings)
    # An ordinary walk at 1.85 Hz, pacing not stated, raises nothing of the kind.
    plain = inspect_record(double_hump_walk(7, 1.0).replace(pacing_hz=None))
    assert not any("fast for walking" in w for w in plain.warnings)


def test_a_line_the_split_cannot_take_out_is_named(monkeypatch) -> None:
    # Every split judged a lone line: the notched repeat is one too, so the footfalls still
    # follow the first split, and inspect must say that its steps may be the line's.
    import workbench.records.footfalls as footfalls

    monkeypatch.setattr(footfalls, "_is_lone_line", lambda *args: True)
    insp = inspect_record(double_hump_walk(7, 1.0))
    assert insp.steps.lone_line_hz is None
    assert insp.steps.unremoved_line_hz == pytest.approx(insp.pacing.pacing_hz, rel=0.1)
    assert insp.to_json()["split"]["unremoved_line_hz"] == pytest.approx(
        insp.steps.unremoved_line_hz, abs=1e-4
    )
    assert any("could not be taken out" in w for w in insp.warnings)


def test_template_alignment_takes_candidates_up_to_a_step_past_either_end() -> None:
    # Candidates are clipped to one step beyond the record; at the upper clip the wide
    # correlation window once read one sample past its padding (an IndexError).
    from workbench.records.footfalls import _SAMPLES_PER_STEP, _align_to_template

    per_step = _SAMPLES_PER_STEP
    shape = np.sin(2 * np.pi * np.arange(20 * per_step) / per_step)
    peaks = np.arange(per_step // 4, shape.size, per_step)
    for extra in (shape.size + per_step, shape.size + 3 * per_step, -3 * per_step):
        positions, match = _align_to_template(shape, np.append(peaks, extra))
        assert positions.shape == match.shape == (peaks.size + 1,)
        assert np.all(np.isfinite(positions))


@pytest.mark.parametrize("seed", [300, 301])
def test_overground_and_speed_change_walks(seed: int) -> None:
    # Double-humped steps (humps 0.9 and 1.1) on an overground walk from standing to
    # standing (30 steps) and on a walk that speeds up by 20 % after 18 steps: the
    # boundaries sit on the true event; starting and stopping is not a change of pace, the
    # speed change is.
    from workbench.synth import GaitProfile

    base = dict(
        mass_kg=75.0, pacing_hz=1.8, natural_frequency_hz=2.4, damping_ratio=0.3,
        noise_sd_n=5.0, sample_rate_hz=200.0, seed=seed,
    )  # fmt: skip
    overground = GaitProfile.overground(walking_steps=30, standing_steps=3)
    speed_change = GaitProfile.speed_change(1.8, 1.2, 18, 4, 30)
    for gait, ratio, start, varies in (
        (overground, 0.9, "rest", False),
        (speed_change, 1.1, "steady", True),
    ):
        sim = simulate_walking(
            **base,
            duration_s=gait.relative_length() / 1.8,
            coefficients=double_hump_force(75.0, ratio),
            start=start,
            gait=gait,
        )
        record = sim.record.replace(pacing_hz=None)
        insp = inspect_record(record)
        errors = boundary_errors(record, insp.steps)
        assert np.mean(errors < 0.1) >= 0.95, gait.label
        assert insp.pacing.varies is varies, gait.label
        truth = np.asarray(sim.truth["step_duration_s"])
        amplitude = np.asarray(sim.truth["step_amplitude_factor"])
        walking = (amplitude[1:] > 0) & (amplitude[:-1] > 0)
        true_fp = np.median((2.0 / (truth[1:] + truth[:-1]))[walking])
        assert insp.pacing.pacing_hz == pytest.approx(true_fp, rel=0.005), gait.label


@pytest.mark.slow
def test_the_three_commands_print_one_step_count_and_one_pacing() -> None:
    """End to end on a short record: what each command's JSON says (analyses/pacing_agreement.py
    runs all the embedded records with the default settings)."""

    def run(*args: str) -> dict:
        out = subprocess.run(
            [sys.executable, "-m", "workbench", *args, "seed_individual", "--json"],
            capture_output=True,
            text=True,
            check=False,
        )
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout)

    seen = run("inspect")
    # The force check identifies the record again with other force models; it adds nothing
    # to the steps and pacing and would double the time.
    identified = run("identify", "--no-force-check")
    diagnosed = run("diagnose", "--no-one-step")["baseline"]
    assert seen["steps"] == identified["steps"] == diagnosed["steps"] == 51
    assert identified["pacing_hz"] == pytest.approx(seen["pacing_hz"], abs=0.5e-4)
    assert diagnosed["pacing_hz"] == pytest.approx(seen["pacing_hz"], abs=0.5e-4)


# The population recovery's records whose split followed a line before the lone-line check
# asked whether the steps' harmonics repeat (analyses/footfall_accuracy.py --recovery-decks
# and --recovery-rigid, population seed 0): the walker's force is nearly one harmonic (the
# seed study's load factors), its median step held 1-2 % of its power above the first
# harmonic, and the walker's own pacing was notched out as a lone line.
RECOVERY_SPLIT_RECORDS = {
    ("seed", "deck"): [6, 7, 13, 31, 35, 39, 45, 46, 55],
    ("constant", "deck"): [47],
    ("zhang", "deck"): [1, 2, 4, 6, 10, 13, 31, 35, 39, 43, 54],
    ("seed", "rigid"): [7, 13, 31, 35, 37, 39, 46, 54],
    ("constant", "rigid"): [47],
    ("zhang", "rigid"): [2, 6, 7, 10, 13, 31, 35, 39, 46, 47, 54],
}


def recovery_records(truth: str, floor: str, which: list[int]):
    from workbench.population.recovery_design import (
        RecoveryDesign,
        recovery_plan,
        simulate_recovery_record,
        truth_laws,
    )

    design = RecoveryDesign(truth=truth_laws(truth), floor=floor)
    plan = recovery_plan(design, seed=0).to_dict("records")
    return [(plan[i], simulate_recovery_record(plan[i], design.sample_rate_hz)) for i in which]


def test_a_nearly_sinusoidal_walker_is_not_a_lone_line() -> None:
    # Record r0006 of the seed-truth recovery: f_n 1.87 Hz below the 2.1 Hz pacing, load
    # factors 0.49, 0.07, 0.03. Its steps are close to a sinusoid, but their harmonics repeat
    # from step to step; steps cut at the period of a sine deck do not repeat theirs.
    from workbench.records.footfalls import (
        step_harmonic_locking,
        step_shape_richness,
        without_surface,
    )

    ((row, record),) = recovery_records("seed", "deck", [6])
    insp = inspect_record(record)
    assert insp.steps.lone_line_hz is None
    assert insp.pacing.pacing_hz == pytest.approx(2.106, rel=0.01)
    acc = without_surface(insp.com.acc_m_s2, record.ground_acc_m_s2, record.sample_rate_hz)
    times = insp.steps.footfall_times_s - record.time_s[0]
    assert step_shape_richness(acc, record.sample_rate_hz, times) < 0.02
    assert step_harmonic_locking(acc, record.sample_rate_hz, times) > 100
    # The same record with its deck channel left out, cut at the deck's period (2.61 Hz).
    raw = np.asarray(insp.com.acc_m_s2)
    cycles = np.arange(0.5, record.duration_s - 0.5, 1.0 / float(row["deck_frequency_hz"]))
    assert step_harmonic_locking(raw, record.sample_rate_hz, cycles) < 15


@pytest.mark.slow
@pytest.mark.parametrize(("truth", "floor"), list(RECOVERY_SPLIT_RECORDS))
def test_recovery_records_keep_their_pacing(truth: str, floor: str) -> None:
    within = []
    for row, record in recovery_records(truth, floor, RECOVERY_SPLIT_RECORDS[truth, floor]):
        insp = inspect_record(record)
        true_fp = 1.0 / np.median(record.metadata["truth"]["step_duration_s"])
        assert insp.pacing.pacing_hz == pytest.approx(true_fp, rel=0.02), row["record"]
        assert insp.steps.lone_line_hz is None, row["record"]
        errors = boundary_errors(record, insp.steps)
        assert np.sum(errors >= 0.1) <= 1, row["record"]  # an end boundary at most
        within.extend(errors < 0.1)
    assert np.mean(within) >= 0.98

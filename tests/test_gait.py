"""Gait profiles: walks that start from standing, stop, or change pace."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.errors import UsageError
from workbench.records.inspection import inspect_record
from workbench.synth import GaitProfile, simulate_walking
from workbench.synth.gait import INITIATION_AMPLITUDE, INITIATION_DURATION

PACING = 1.8
NOISE_N = 2.0


def _walk(profile: GaitProfile, seed: int = 1, **kwargs):
    return simulate_walking(
        pacing_hz=PACING,
        duration_s=profile.relative_length() / PACING,
        gait=profile,
        noise_sd_n=NOISE_N,
        seed=seed,
        **kwargs,
    )


def test_an_overground_walk_stands_starts_walks_stops_and_stands():
    profile = GaitProfile.overground(walking_steps=24, standing_steps=3)
    assert profile.n_steps == 30
    sim = _walk(profile)
    t, grf = sim.record.time_s, sim.record.grf_n
    weight = sim.truth["mass_kg"] * 9.80665
    # Standing: the GRF is the body weight plus the measurement noise (the body at rest).
    first = grf[t < 1.0]
    assert abs(first.mean() - weight) < 1.0 and first.std() < 1.5 * NOISE_N
    # Steady walking in the middle loads the floor with the first harmonic's full size.
    middle = (t > 0.35 * t[-1]) & (t < 0.65 * t[-1])
    assert grf[middle].std() > 50 * NOISE_N
    factors = np.asarray(sim.truth["step_amplitude_factor"])
    np.testing.assert_allclose(factors[:6], (0.0, 0.0, 0.0, *INITIATION_AMPLITUDE))
    # Initiation steps last longer than steady ones by the stated factors, within the
    # step-to-step variability (2 % sd, bounded at 3 sd).
    durations = np.asarray(sim.truth["step_duration_s"])
    ratio = durations[3:6] * PACING
    np.testing.assert_allclose(ratio, INITIATION_DURATION, rtol=3 * 0.02)
    assert sim.truth["gait"]["label"].startswith("overground")
    # The record's own step detection finds the walking steps, not the standing.
    steps = len(inspect_record(sim.record).steps.boundaries) - 1
    assert 20 <= steps <= 26, steps


def test_a_profile_of_steady_steps_is_the_steady_walk():
    """The profile scales the same random draws: with every factor 1 nothing changes."""
    plain = simulate_walking(pacing_hz=PACING, duration_s=8.0, seed=4)
    steady = simulate_walking(
        pacing_hz=PACING, duration_s=8.0, seed=4, gait=GaitProfile((1.0,), (1.0,))
    )
    np.testing.assert_array_equal(plain.record.grf_n, steady.record.grf_n)


@pytest.mark.parametrize("ratio", [0.85, 1.15])
def test_a_speed_change_moves_the_pacing_and_the_amplitude(ratio):
    profile = GaitProfile.speed_change(PACING, pacing_ratio=ratio)
    sim = _walk(profile, amplitude_sd=0.0)
    durations = np.asarray(sim.truth["step_duration_s"])
    before, after = durations[:12].mean(), durations[-12:-2].mean()
    # Mean of many steps with 2 % sd each: the ratio holds to well under 2 %.
    assert before / after == pytest.approx(ratio, rel=0.02)
    factors = np.asarray(sim.truth["step_amplitude_factor"])
    expected = (PACING * ratio - 0.95) / (PACING - 0.95)  # Young's BLF1 law
    assert factors[-3] == pytest.approx(expected)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: GaitProfile((1.0, 1.0), (1.0,)), "one duration factor and one amplitude"),
        (lambda: GaitProfile((3.0,), (1.0,)), "duration factors"),
        (lambda: GaitProfile((1.0,), (-0.1,)), "amplitude factors"),
        (lambda: GaitProfile.overground(walking_steps=5), "at least 8"),
        (lambda: GaitProfile.overground(standing_steps=0), "at least 1"),
        (lambda: GaitProfile.speed_change(PACING, pacing_ratio=2.0), "0.7-1.4"),
        (lambda: GaitProfile.speed_change(1.0, pacing_ratio=0.9), "above 0.95 Hz"),
    ],
)
def test_bad_profiles_are_refused_in_one_sentence(make, match):
    with pytest.raises(UsageError, match=match):
        make()


@pytest.mark.parametrize(
    ("argv", "steps"),
    [
        (["--gait", "overground", "--walking-steps", "20"], (17, 22)),
        (["--gait", "speed-change"], (28, 34)),
    ],
)
def test_simulate_writes_a_gait_profile_walk(tmp_path, capsys, argv, steps):
    import json

    from workbench.cli import main

    out = tmp_path / "walk.csv"
    assert main(["simulate", "--out", str(out), "--pacing", "1.8", *argv, "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    truth = json.loads(Path(report["truth"]).read_text())
    assert truth["gait"]["label"].split(":")[0] == argv[1].replace("-", " ")
    # The record lasts as long as the walk: its own step detection finds the walking steps.
    from workbench.records.io import load_record

    found = len(inspect_record(load_record(out)).steps.boundaries) - 1
    assert steps[0] <= found <= steps[1], found


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--gait", "overground", "--start", "steady"], "starts from standing"),
        (["--gait", "overground", "--walking-steps", "5"], "--walking-steps 5"),
        (["--gait", "speed-change", "--pacing-ratio", "2"], "--pacing-ratio 2"),
    ],
)
def test_simulate_refuses_a_bad_gait_in_one_sentence(tmp_path, capsys, argv, message):
    from workbench.cli import main

    assert main(["simulate", "--out", str(tmp_path / "w.csv"), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1

"""Vibrating decks: their RMS, spectra and determinism, walks on them, and the CLI flags."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from workbench.cli import main
from workbench.errors import UsageError
from workbench.records.io import load_record
from workbench.records.record import G_M_S2
from workbench.synth import (
    DECK_WALK_RANGES,
    NarrowBandDeck,
    SineDeck,
    SweptSineDeck,
    deck_from_json,
    deck_walk,
    simulate_walking,
    surface_motion,
    varied_walk,
)
from workbench.synth.simulate import VARIED_WALK_RANGES


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def power_spectrum(x: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    return np.fft.rfftfreq(x.size, 1.0 / fs), np.abs(np.fft.rfft(x)) ** 2


# -- the decks ------------------------------------------------------------------------------
def test_sine_deck_rms_peak_and_spectrum() -> None:
    deck = SineDeck(rms_m_s2=0.35, frequency_hz=2.5, phase_rad=0.7)
    fs = 200.0
    t = np.arange(round(40.0 * fs)) / fs  # exactly 100 periods
    acc = deck(t)
    assert rms(acc) == pytest.approx(0.35, rel=1e-12)
    assert deck.peak_m_s2 == pytest.approx(math.sqrt(2.0) * 0.35, rel=1e-15)
    t_peak = (np.pi / 2 - 0.7) / (2 * np.pi * 2.5)
    assert deck(t_peak) == pytest.approx(deck.peak_m_s2, rel=1e-15)
    assert np.max(np.abs(acc)) <= deck.peak_m_s2
    assert deck(0.0) == pytest.approx(deck.peak_m_s2 * math.sin(0.7), rel=1e-15)
    f, p = power_spectrum(acc, fs)
    assert f[np.argmax(p)] == pytest.approx(2.5, abs=1e-12)
    assert p[np.isclose(f, 2.5)].sum() / p.sum() == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize(("start_hz", "end_hz"), [(1.5, 4.0), (4.0, 1.5)])
def test_swept_sine_deck_rms_and_instantaneous_frequency(start_hz: float, end_hz: float) -> None:
    deck = SweptSineDeck(rms_m_s2=0.4, start_hz=start_hz, end_hz=end_hz, duration_s=120.0)
    fs = 200.0
    t = np.arange(round(120.0 * fs)) / fs
    acc = deck(t)
    # Constant amplitude: the RMS is the stated one up to the part of a cycle at the ends.
    assert rms(acc) == pytest.approx(0.4, rel=1e-4)
    assert np.max(np.abs(acc)) == pytest.approx(math.sqrt(2.0) * 0.4, rel=1e-4)
    # Frequency from the zero crossings (half a period apart) against the linear law.
    below = np.signbit(acc)
    i = np.flatnonzero(below[1:] != below[:-1])
    crossing = t[i] - acc[i] * (t[i + 1] - t[i]) / (acc[i + 1] - acc[i])
    measured_hz = 0.5 / np.diff(crossing)
    mid = 0.5 * (crossing[1:] + crossing[:-1])
    expected = start_hz + (end_hz - start_hz) * mid / 120.0
    np.testing.assert_allclose(measured_hz, expected, rtol=0, atol=1e-3)
    np.testing.assert_allclose(deck.instantaneous_frequency_hz(mid), expected, rtol=1e-14)
    assert measured_hz[0] == pytest.approx(start_hz, abs=0.02)
    assert measured_hz[-1] == pytest.approx(end_hz, abs=0.02)
    assert np.all(np.sign(np.diff(measured_hz)) == np.sign(end_hz - start_hz))
    f, p = power_spectrum(acc, fs)
    lo, hi = sorted((start_hz, end_hz))
    assert p[(f >= lo) & (f <= hi)].sum() / p.sum() >= 0.98
    # Outside the sweep the frequency holds, with the phase continuous.
    assert deck.instantaneous_frequency_hz(-5.0) == start_hz
    assert deck.instantaneous_frequency_hz(500.0) == end_hz
    eps = 1e-7
    for edge in (0.0, 120.0):
        jump = deck.phase_rad(edge + eps) - deck.phase_rad(edge - eps)
        assert jump == pytest.approx(2 * np.pi * deck.instantaneous_frequency_hz(edge) * 2 * eps)


@pytest.mark.parametrize(
    ("centre_hz", "bandwidth_hz"), [(1.5, 0.045), (2.5, 0.1), (4.0, 0.4), (1.5, 0.15)]
)
def test_narrow_band_deck_rms_mean_and_spectrum(centre_hz: float, bandwidth_hz: float) -> None:
    period = 200.0
    deck = NarrowBandDeck(0.3, centre_hz, bandwidth_hz, seed=7, period_s=period)
    fs = 100.0
    t = np.arange(round(period * fs)) / fs
    acc = deck(t)
    # Exact over one period (the record the deck was made for) ...
    assert rms(acc) == pytest.approx(0.3, rel=1e-9)
    assert abs(float(np.mean(acc))) < 1e-12
    # ... and over three periods, started anywhere.
    longer = 37.0 + np.arange(round(3 * period * fs)) / fs
    assert rms(deck(longer)) == pytest.approx(0.3, rel=1e-9)
    f, p = power_spectrum(acc, fs)
    assert abs(f[np.argmax(p)] - centre_hz) <= 1.0 / period
    assert p[np.abs(f - centre_hz) <= 2 * bandwidth_hz].sum() / p.sum() >= 0.90
    assert p[np.abs(f - centre_hz) > 3 * bandwidth_hz + 1e-9].sum() / p.sum() < 1e-20


def test_narrow_band_deck_is_its_resonator_sum_of_sinusoids() -> None:
    deck = NarrowBandDeck(0.5, 2.0, 0.2, seed=3, period_s=100.0)
    freq, amp, phase = deck.lines
    assert deck.damping_ratio == pytest.approx(0.05, rel=1e-15)
    np.testing.assert_allclose(freq * 100.0, np.round(freq * 100.0), atol=1e-9)  # k / period
    assert np.sum(amp**2) / 2 == pytest.approx(0.25, rel=1e-12)
    # Half-power bandwidth of the line amplitudes is the stated one (to the resolution).
    half = freq[amp**2 >= 0.5 * np.max(amp**2)]
    assert half.max() - half.min() == pytest.approx(0.2, abs=2.0 / 100.0)
    assert freq[np.argmax(amp)] == pytest.approx(2.0, abs=1e-12)
    t = np.linspace(-3.0, 250.0, 997)
    direct = np.sum(amp * np.cos(2 * np.pi * np.outer(t, freq) + phase), axis=1)
    np.testing.assert_allclose(deck(t), direct, rtol=0, atol=1e-12)


def test_narrow_band_deck_is_deterministic_and_grid_independent() -> None:
    deck = NarrowBandDeck(0.3, 2.2, 0.15, seed=11, period_s=30.0)
    coarse = np.arange(0.0, 30.0, 0.01)
    fine = np.arange(0.0, 30.0, 0.002)
    np.testing.assert_allclose(deck(coarse), deck(fine)[::5], rtol=0, atol=1e-13)
    np.testing.assert_allclose(deck(coarse[123:130]), deck(coarse)[123:130], rtol=0, atol=1e-13)
    assert float(deck(coarse[456])) == pytest.approx(float(deck(coarse)[456]), abs=1e-13)
    again = NarrowBandDeck(0.3, 2.2, 0.15, seed=11, period_s=30.0)
    np.testing.assert_array_equal(again(coarse), deck(coarse))
    other = NarrowBandDeck(0.3, 2.2, 0.15, seed=12, period_s=30.0)
    assert np.max(np.abs(other(coarse) - deck(coarse))) > 0.1
    assert deck(np.zeros((2, 3))).shape == (2, 3)
    # Periodic with its period: the record's length.
    np.testing.assert_allclose(deck(coarse + 30.0), deck(coarse), rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "deck",
    [
        SineDeck(0.2, 2.0, 0.5),
        SweptSineDeck(0.3, 1.0, 3.0, 30.0),
        NarrowBandDeck(0.4, 2.5, 0.2, seed=5, period_s=40.0),
    ],
)
def test_decks_describe_themselves_and_are_rebuilt(deck: object) -> None:
    description = deck.to_json()  # type: ignore[attr-defined]
    assert description["kind"] in {"sine", "sweep", "narrowband"}
    assert json.loads(json.dumps(description, allow_nan=False)) == description
    rebuilt = deck_from_json(description)
    assert rebuilt == deck
    t = np.linspace(0.0, 10.0, 101)
    np.testing.assert_array_equal(rebuilt(t), deck(t))  # type: ignore[operator]


@pytest.mark.parametrize(
    ("build", "parameter"),
    [
        (lambda: SineDeck(0.0, 2.0), "rms_m_s2"),
        (lambda: SineDeck(float("nan"), 2.0), "rms_m_s2"),
        (lambda: SineDeck(0.3, -1.0), "frequency_hz"),
        (lambda: SineDeck(0.3, 2.0, float("inf")), "phase_rad"),
        (lambda: SweptSineDeck(0.3, 2.0, 2.0, 30.0), "end_hz"),
        (lambda: SweptSineDeck(0.3, 0.0, 2.0, 30.0), "start_hz"),
        (lambda: SweptSineDeck(0.3, 1.0, 2.0, float("inf")), "duration_s"),
        (lambda: NarrowBandDeck(-0.3, 2.0, 0.2, seed=1), "rms_m_s2"),
        (lambda: NarrowBandDeck(0.3, 2.0, 2.0, seed=1), "bandwidth_hz"),
        (lambda: NarrowBandDeck(0.3, 2.0, 0.0, seed=1), "bandwidth_hz"),
        (lambda: NarrowBandDeck(0.3, "x", 0.2, seed=1), "centre_hz"),
        (lambda: NarrowBandDeck(0.3, 2.0, 0.2, seed=-1), "seed"),
        (lambda: NarrowBandDeck(0.3, 2.0, 0.2, seed=1.5), "seed"),
        (lambda: NarrowBandDeck(0.3, 2.0, 0.2, seed=1, period_s=0.1), "period_s"),
        (lambda: deck_from_json({"kind": "square"}), "description"),
        (lambda: deck_from_json({"kind": "sine", "rms": 1.0}), "description"),
    ],
)
def test_bad_deck_parameters_are_one_sentence_naming_the_parameter(build, parameter) -> None:
    with pytest.raises(UsageError) as err:
        build()
    assert err.value.parameter == parameter
    message = str(err.value)
    assert f"'{parameter}'" in message or parameter == "description"
    assert "\n" not in message and message.count(". ") == 0


# -- walking on a deck --------------------------------------------------------------------
@pytest.mark.parametrize(
    "deck",
    [
        SineDeck(0.5, 2.2, 0.3),
        NarrowBandDeck(0.4, 2.8, 0.2, seed=5, period_s=20.0),
        SweptSineDeck(0.3, 1.5, 6.0, 20.0),
    ],
)
def test_walking_on_a_deck_satisfies_the_equation_of_motion(deck) -> None:
    sim = simulate_walking(
        duration_s=20.0,
        sample_rate_hz=200.0,
        natural_frequency_hz=2.4,
        damping_ratio=0.3,
        ground_acc_m_s2=deck,
        seed=4,
    )
    t = sim.time_s
    assert sim.truth["ground_motion"] == deck.to_json()
    assert sim.record.metadata["truth"]["ground_motion"] == deck.to_json()
    np.testing.assert_allclose(sim.record.ground_acc_m_s2, deck(t), rtol=0, atol=1e-12)
    u_g, v_g, a_g = surface_motion(deck, t)
    np.testing.assert_array_equal(a_g, sim.record.ground_acc_m_s2)
    m = sim.truth["mass_kg"]
    k = sim.truth["stiffness_n_per_m"]
    c = sim.truth["damping_ns_per_m"]
    force = sim.force_n
    scale = float(np.max(np.abs(force)))
    residual = m * sim.acc_m_s2 + c * (sim.vel_m_s - v_g) + k * (sim.disp_m - u_g) - force
    assert np.max(np.abs(residual)) <= 1e-12 * scale
    np.testing.assert_allclose(sim.record.grf_n, m * (G_M_S2 + sim.acc_m_s2), rtol=1e-15)
    # The returned motion is the solution, not just consistent algebra: velocity is the
    # integral of the acceleration (which the surface motion drives by ~1 m/s^2 here).
    integral = CubicSpline(t, sim.acc_m_s2).antiderivative()(t)
    vel = sim.vel_m_s[0] + integral - integral[0]
    assert np.max(np.abs(vel - sim.vel_m_s)) <= 1e-4 * np.max(np.abs(sim.vel_m_s))
    assert np.max(np.abs(c * v_g + k * u_g)) / m > 0.3
    # The surface does not travel: its displacement has no linear trend.
    slope = np.polyfit(t, u_g, 1)[0]
    assert abs(slope) * t[-1] < 1e-3 * np.max(np.abs(u_g))


def test_plain_ground_acceleration_keeps_its_generic_description() -> None:
    sim = simulate_walking(
        duration_s=4.0, seed=1, ground_acc_m_s2=lambda t: 0.3 * np.sin(2 * np.pi * 2.0 * t)
    )
    assert sim.truth["ground_motion"] == "prescribed ground acceleration"
    assert simulate_walking(duration_s=4.0, seed=1).truth["ground_motion"] is None


def test_varied_walk_takes_a_deck_with_the_same_draws() -> None:
    amplitude, freq = 0.6, 2.7
    deck = SineDeck(amplitude / math.sqrt(2.0), freq)
    on_deck = varied_walk(3, duration_s=(20.0, 25.0), ground_acc_m_s2=deck)
    sine = varied_walk(3, duration_s=(20.0, 25.0), ground_amplitude_m_s2=amplitude)
    assert on_deck.truth["ground_motion"] == deck.to_json()
    assert sine.truth["ground_motion"] == "prescribed ground acceleration"
    np.testing.assert_allclose(on_deck.record.grf_n, sine.record.grf_n, rtol=0, atol=1e-9)
    with pytest.raises(UsageError, match="both set the surface motion") as err:
        varied_walk(3, ground_acc_m_s2=deck, ground_amplitude_m_s2=0.5)
    assert err.value.parameter == "ground_acc_m_s2"


def _inside(value: float, bounds: tuple[float, float]) -> bool:
    return bounds[0] <= value <= bounds[1]


def test_deck_walk_draws_stay_in_their_ranges() -> None:
    r = DECK_WALK_RANGES
    kinds = set()
    for seed in range(20):
        sim = deck_walk(seed)
        truth = sim.truth
        deck = truth["ground_motion"]
        kinds.add(deck["kind"])
        assert _inside(truth["mass_kg"], (50.0, 100.0))
        assert _inside(truth["natural_frequency_hz"], (1.8, 3.4))
        assert _inside(truth["damping_ratio"], (0.2, 0.5))
        assert _inside(deck["rms_m_s2"], (0.05, 1.0))
        assert _inside(truth["duration_s"], (20.0, 60.0 + 1e-9))
        assert truth["sample_rate_hz"] in (100.0, 200.0, 250.0, 500.0)
        assert truth["start"] == "steady" and truth["seed"] == seed
        for key in ("pacing_hz", "amplitude_sd", "step_duration_sd", "phase_sd_rad", "noise_sd_n"):
            assert _inside(truth[key], VARIED_WALK_RANGES[key]), key
        if deck["kind"] == "sine":
            assert _inside(deck["frequency_hz"], (1.5, 4.0))
        else:
            assert deck["kind"] == "narrowband"
            assert _inside(deck["centre_hz"], (1.5, 4.0))
            assert _inside(deck["bandwidth_hz"] / deck["centre_hz"], (0.03, 0.10))
            # The deck was made for the record: its RMS over the record is exact.
            assert deck["period_s"] == pytest.approx(truth["duration_s"], rel=1e-15)
            assert rms(sim.record.ground_acc_m_s2) == pytest.approx(deck["rms_m_s2"], rel=1e-9)
        np.testing.assert_allclose(
            sim.record.ground_acc_m_s2, deck_from_json(deck)(sim.time_s), rtol=0, atol=1e-12
        )
    assert kinds == set(r["deck_kind"])
    assert r["deck_rms_m_s2"] == (0.05, 1.0) and r["deck_frequency_hz"] == (1.5, 4.0)


def test_deck_walk_honours_overrides_and_keeps_the_other_draws() -> None:
    base = deck_walk(3)
    sim = deck_walk(3, deck_rms_m_s2=0.3, duration_s=30)
    assert sim.truth["duration_s"] == 30.0
    assert sim.truth["ground_motion"]["rms_m_s2"] == 0.3
    for key in ("mass_kg", "natural_frequency_hz", "damping_ratio", "pacing_hz", "noise_sd_n"):
        assert sim.truth[key] == base.truth[key], key
    assert sim.truth["ground_motion"]["kind"] == base.truth["ground_motion"]["kind"]
    fixed = deck_walk(
        4,
        mass_kg=80.0,
        natural_frequency_hz=2.0,
        damping_ratio=0.3,
        deck_kind="narrowband",
        deck_frequency_hz=2.5,
        deck_bandwidth_hz=0.2,
        sample_rate_hz=100.0,
        duration_s=20.0,
    )
    truth = fixed.truth
    assert truth["mass_kg"] == 80.0 and truth["sample_rate_hz"] == 100.0
    assert truth["natural_frequency_hz"] == pytest.approx(2.0, rel=1e-12)
    assert truth["damping_ratio"] == pytest.approx(0.3, rel=1e-12)
    assert truth["ground_motion"]["kind"] == "narrowband"
    assert truth["ground_motion"]["centre_hz"] == 2.5
    assert truth["ground_motion"]["bandwidth_hz"] == 0.2
    sweep = SweptSineDeck(0.2, 1.5, 4.0, 20.0)
    assert deck_walk(5, deck=sweep, duration_s=20.0).truth["ground_motion"] == sweep.to_json()
    again = deck_walk(3)
    np.testing.assert_array_equal(again.record.grf_n, base.record.grf_n)
    with pytest.raises(UsageError, match="unknown override 'deck_colour'") as err:
        deck_walk(1, deck_colour="red")
    assert err.value.parameter == "deck_colour"
    with pytest.raises(UsageError, match="'deck_kind' must be"):
        deck_walk(1, deck_kind="sweep")


# -- the command line -----------------------------------------------------------------------
NARROW = ["--deck", "narrowband", "--deck-rms", 0.3]


def run_cli(argv: list[object], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_narrow_band_deck_round_trip(tmp_path, capsys) -> None:
    out = tmp_path / "deck.csv"
    argv = ["simulate", "--out", out, "--duration", 25, "--seed", 3, "--deck", "narrowband"]
    argv += ["--deck-rms", 0.25, "--deck-hz", 2.6, "--deck-bandwidth-hz", 0.2, "--json"]
    code, stdout, _ = run_cli(argv, capsys)
    assert code == 0
    summary = json.loads(stdout)
    record = load_record(out)
    assert record.ground_acc_m_s2 is not None
    assert rms(record.ground_acc_m_s2) == pytest.approx(0.25, rel=1e-9)
    truth = json.loads((tmp_path / "deck.truth.json").read_text())
    expected = {"kind": "narrowband", "rms_m_s2": 0.25, "centre_hz": 2.6, "bandwidth_hz": 0.2}
    assert expected.items() <= truth["ground_motion"].items()
    assert truth["ground_motion"]["period_s"] == pytest.approx(25.0)
    assert summary["ground_motion"] == truth["ground_motion"]
    sidecar = json.loads((tmp_path / "deck.json").read_text())
    assert sidecar["truth"]["ground_motion"] == truth["ground_motion"]
    np.testing.assert_allclose(
        record.ground_acc_m_s2,
        deck_from_json(truth["ground_motion"])(record.time_s),
        rtol=0,
        atol=1e-12,
    )


def test_cli_sine_and_sweep_decks(tmp_path, capsys) -> None:
    sine = tmp_path / "sine.csv"
    argv = ["simulate", "--out", sine, "--duration", 20, "--deck", "sine"]
    code, _, _ = run_cli([*argv, "--deck-rms", 0.4, "--deck-hz", 2.5], capsys)
    assert code == 0
    assert rms(load_record(sine).ground_acc_m_s2) == pytest.approx(0.4, rel=1e-9)
    truth = json.loads((tmp_path / "sine.truth.json").read_text())
    assert truth["ground_motion"] == SineDeck(0.4, 2.5).to_json()
    sweep = tmp_path / "sweep.csv"
    argv = ["simulate", "--out", sweep, "--duration", 20, "--deck", "sweep", "--deck-rms", 0.3]
    code, _, _ = run_cli([*argv, "--deck-hz", 1.5, "--deck-hz-end", 4.0], capsys)
    assert code == 0
    truth = json.loads((tmp_path / "sweep.truth.json").read_text())
    assert truth["ground_motion"] == SweptSineDeck(0.3, 1.5, 4.0, 20.0).to_json()


def test_cli_peak_amplitude_sinusoid_still_works(tmp_path, capsys) -> None:
    out = tmp_path / "old.csv"
    argv = ["simulate", "--out", out, "--ground-acc-amplitude", 0.5, "--ground-acc-hz", 2.5]
    code, _, _ = run_cli([*argv, "--duration", 20], capsys)
    assert code == 0
    record = load_record(out)
    np.testing.assert_allclose(
        record.ground_acc_m_s2, 0.5 * np.sin(2 * np.pi * 2.5 * record.time_s), atol=1e-12
    )
    truth = json.loads((tmp_path / "old.truth.json").read_text())
    assert truth["ground_motion"] == {"kind": "sine", "amplitude_m_s2": 0.5, "frequency_hz": 2.5}


@pytest.mark.parametrize(
    ("flags", "expected"),
    [
        (["--deck", "sine", "--deck-hz", 2], "--deck sine needs --deck-rms"),
        (["--deck", "sine", "--deck-rms", 0.3], "--deck sine needs --deck-hz"),
        (["--deck-rms", 0.3], "--deck-rms describes a vibrating deck"),
        (["--deck-hz-end", 3], "--deck-hz-end describes a vibrating deck"),
        (
            ["--deck", "sine", "--deck-rms", 0.3, "--deck-hz", 2, "--ground-acc-amplitude", 0.5],
            "--deck and --ground-acc-amplitude/--ground-acc-hz both set the surface motion",
        ),
        (
            ["--deck", "sine", "--deck-rms", 0.3, "--deck-hz", 2, "--ground-acc-hz", 3],
            "both set the surface motion",
        ),
        (["--deck", "sine", "--deck-rms", -1, "--deck-hz", 2], "--deck-rms must be a positive"),
        (["--deck", "sine", "--deck-rms", "nan", "--deck-hz", 2], "--deck-rms must be a positive"),
        (["--deck", "sine", "--deck-rms", 0.3, "--deck-hz", 0], "--deck-hz must be a positive"),
        (
            ["--deck", "sine", "--deck-rms", 0.3, "--deck-hz", 2, "--deck-bandwidth-hz", 0.1],
            "--deck-bandwidth-hz applies to --deck narrowband only",
        ),
        (
            ["--deck", "narrowband", "--deck-rms", 0.3, "--deck-hz", 2, "--deck-hz-end", 3],
            "--deck-hz-end applies to --deck sweep only",
        ),
        (
            ["--deck", "sweep", "--deck-rms", 0.3, "--deck-hz", 2],
            "--deck sweep needs --deck-hz-end",
        ),
        (
            ["--deck", "sweep", "--deck-rms", 0.3, "--deck-hz", 2, "--deck-hz-end", 2],
            "--deck-hz-end equals --deck-hz",
        ),
        (
            ["--deck", "sweep", "--deck-rms", 0.3, "--deck-hz", 2, "--deck-hz-end", 150],
            "above half the sample rate",
        ),
        (
            ["--deck", "narrowband", "--deck-rms", 0.3, "--deck-hz", 2],
            "--deck narrowband needs --deck-bandwidth-hz",
        ),
        (
            ["--deck", "narrowband", "--deck-rms", 0.3, "--deck-hz", 2, "--deck-bandwidth-hz", 2],
            "--deck-bandwidth-hz 2 must be below --deck-hz 2",
        ),
        (
            [*NARROW, "--deck-hz", 0.1, "--deck-bandwidth-hz", 0.05, "--duration", 5],
            "--deck-hz 0.1 gives less than one cycle",
        ),
    ],
)
def test_cli_deck_errors_are_one_sentence_with_exit_2(tmp_path, capsys, flags, expected) -> None:
    code, stdout, err = run_cli(["simulate", "--out", tmp_path / "w.csv", *flags], capsys)
    assert code == 2
    assert stdout == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert lines[0].startswith("workbench: error: ")
    assert expected in lines[0]
    assert not list(tmp_path.iterdir())


def test_cli_unknown_deck_kind_is_an_argument_error(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--out", str(tmp_path / "w.csv"), "--deck", "square"])
    assert exc.value.code == 2
    assert "invalid choice" in capsys.readouterr().err

"""Simulate, write, read, preprocess and inspect: the foundation's end-to-end checks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.cli import main
from workbench.records.inspection import inspect_record
from workbench.records.io import load_record
from workbench.records.preprocess import highpass, preprocess
from workbench.synth.simulate import simulate_walking


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def _through_chain(x, fs, times):
    for _ in range(times):
        x = highpass(x, fs, 0.15)
    return x


def _relative_errors(com, vel_true, disp_true, mask):
    """RMS errors of u' and u relative to the true ones through the same filter chain."""
    fs = com.sample_rate_hz
    ref_vel = _through_chain(vel_true, fs, 2)  # filtered acc, integrated, filtered
    ref_disp = _through_chain(disp_true, fs, 3)  # and once more
    return (
        rms((com.vel_m_s - ref_vel)[mask]) / rms(ref_vel[mask]),
        rms((com.disp_m - ref_disp)[mask]) / rms(ref_disp[mask]),
    )


@pytest.mark.parametrize(
    ("mass_kg", "pacing_hz", "seed"),
    [(70.0, 1.8, 1), (58.0, 1.75, 2), (95.0, 2.2, 3), (50.0, 1.5, 4), (82.0, 2.0, 6)],
)
def test_preprocessed_response_matches_simulator(mass_kg, pacing_hz, seed):
    """u, u' from the GRF match the simulator's own u, u' through the same high-pass.

    Within 2 % RMS away from the filter's end margin (``COMResponse.edge_s``, 5.3 s), and
    u' within 2 % over the whole record; u over the whole record within 5 % (the ends of a
    record whose last steps are irregular are the hard part, see ``COMResponse.edge_s``).
    """
    sim = simulate_walking(
        mass_kg=mass_kg, pacing_hz=pacing_hz, duration_s=40.0, start="steady", seed=seed
    )
    com = preprocess(sim.record, highpass_hz=0.15)
    vel_in, disp_in = _relative_errors(com, sim.vel_m_s, sim.disp_m, com.interior())
    vel_all, disp_all = _relative_errors(com, sim.vel_m_s, sim.disp_m, slice(None))
    assert vel_in < 0.02 and disp_in < 0.02
    assert vel_all < 0.02
    assert disp_all < 0.05
    # Acceleration is not integrated: only the filter's end handling separates the two.
    ref_acc = highpass(sim.acc_m_s2, com.sample_rate_hz, 0.15)
    assert rms(com.acc_m_s2 - ref_acc) / rms(ref_acc) < 1e-6


@pytest.mark.parametrize("noise_sd_n", [2.0, 5.0])
def test_noise_adds_only_its_own_double_integral(noise_sd_n):
    """With sensor noise the error is the noise's own integrated contribution plus < 2 %.

    White force noise integrated twice concentrates just above the cut-off, so a noisy
    record's displacement carries a few per cent of it; that is physics, not preprocessing
    error, and the check separates the two by preprocessing the noise alone.
    """
    kwargs = dict(mass_kg=58.0, pacing_hz=1.75, duration_s=40.0, start="steady", seed=2)
    noisy = simulate_walking(noise_sd_n=noise_sd_n, **kwargs)
    clean = simulate_walking(noise_sd_n=0.0, **kwargs)
    noise_only = noisy.record.replace(grf_n=noisy.record.grf_n - clean.record.grf_n + 58 * 9.81)
    com = preprocess(noisy.record)
    com_noise = preprocess(noise_only)
    mask = com.interior()
    vel_err, disp_err = _relative_errors(com, clean.vel_m_s, clean.disp_m, mask)
    ref_disp = _through_chain(clean.disp_m, com.sample_rate_hz, 3)[mask]
    ref_vel = _through_chain(clean.vel_m_s, com.sample_rate_hz, 2)[mask]
    noise_disp = rms(com_noise.disp_m[mask]) / rms(ref_disp)
    noise_vel = rms(com_noise.vel_m_s[mask]) / rms(ref_vel)
    assert noise_disp > 0.01  # the noise is visible in u: the check below is not vacuous
    assert disp_err <= noise_disp + 0.02
    assert vel_err <= noise_vel + 0.02


def test_no_highpass_is_plain_integration_from_rest():
    """With the filter off (records starting at rest) u, u' are the trapezoidal integrals.

    Trapezoidal integration of the exact u'' at 1 kHz (the seed's numerical example rate)
    leaves an O(dt^2) velocity offset whose integral grows linearly in time.
    """
    sim = simulate_walking(
        mass_kg=75.0,
        pacing_hz=2.0,
        duration_s=10.0,
        sample_rate_hz=1000.0,
        start="rest",
        seed=5,
        step_duration_sd=0.0,
        amplitude_sd=0.0,
        phase_sd_rad=0.0,
    )
    com = preprocess(sim.record, highpass_hz=0.0)
    assert com.edge_s == 0.0
    np.testing.assert_array_equal(com.acc_m_s2, (sim.record.grf_n - 75.0 * 9.81) / 75.0)
    assert rms(com.vel_m_s - sim.vel_m_s) / rms(sim.vel_m_s) < 1e-3
    assert rms(com.disp_m - sim.disp_m) / rms(sim.disp_m) < 1e-2


@pytest.mark.parametrize("pacing_hz", [1.5, 1.83, 2.25])
def test_inspect_recovers_simulated_pacing(pacing_hz, tmp_path, capsys):
    out = tmp_path / "walk.csv"
    code = main(
        [
            "simulate",
            "--out",
            str(out),
            "--pacing",
            str(pacing_hz),
            "--duration",
            "40",
            "--seed",
            "11",
            "--json",
        ]
    )
    sim_json = json.loads(capsys.readouterr().out)
    assert code == 0
    assert json.loads((tmp_path / "walk.truth.json").read_text())["pacing_hz"] == pacing_hz
    # The sidecar states the pacing; drop it so inspect has to find it from the force alone.
    sidecar = tmp_path / "walk.json"
    meta = json.loads(sidecar.read_text())
    meta.pop("pacing_hz")
    sidecar.write_text(json.dumps(meta))
    code = main(["inspect", sim_json["record"], "--json"])
    r = json.loads(capsys.readouterr().out)
    assert code == 0
    assert r["pacing_hz"] == pytest.approx(pacing_hz, rel=0.01)
    assert r["static_balance"] == pytest.approx(1.0, abs=0.005)
    # 40 s of walking holds 40 f_p steps; peak-to-peak pieces lose at most one at each end,
    # and the detector skips footfalls within a fraction of a step of the record's ends.
    assert 40 * pacing_hz - 4 <= r["steps"] <= 40 * pacing_hz


def test_simulate_writes_loadable_formats_with_truth(tmp_path, capsys):
    for name in ("walk.csv", "walk2.mot"):
        code = main(
            [
                "simulate",
                "--out",
                str(tmp_path / name),
                "--mass",
                "64",
                "--seed",
                "4",
                "--effect",
                "cubic_stiffness:k3_n_per_m3=1e6",
                "--json",
            ]
        )
        assert code == 0
        res = json.loads(capsys.readouterr().out)
        rec = load_record(res["record"])
        truth = json.loads(Path(res["truth"]).read_text())
        assert rec.mass_kg == 64.0
        assert truth["effects"][0]["name"] == "cubic_stiffness"
        assert truth["mass_kg"] == 64.0
        assert rec.sample_rate_hz == pytest.approx(200.0)
    csv = load_record(tmp_path / "walk.csv")
    mot = load_record(tmp_path / "walk2.mot")
    np.testing.assert_array_equal(csv.grf_n, mot.grf_n)


def test_simulate_is_seeded(tmp_path, capsys):
    for name, seed in (("a.csv", 1), ("b.csv", 1), ("c.csv", 2)):
        assert main(["simulate", "--out", str(tmp_path / name), "--seed", str(seed)]) == 0
    capsys.readouterr()
    a, b, c = (load_record(tmp_path / n).grf_n for n in ("a.csv", "b.csv", "c.csv"))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_simulate_bad_effect_is_one_sentence(tmp_path, capsys):
    code = main(["simulate", "--out", str(tmp_path / "x.csv"), "--effect", "no_such_effect"])
    err = capsys.readouterr().err
    assert code == 2
    assert "no_such_effect" in err and len(err.strip().splitlines()) == 1
    code = main(["simulate", "--out", str(tmp_path / "x.txt")])
    assert code == 2
    assert ".csv or .mot" in capsys.readouterr().err


def test_inspect_of_simulation_in_memory():
    sim = simulate_walking(mass_kg=80.0, pacing_hz=2.0, duration_s=30.0, seed=8, start="steady")
    insp = inspect_record(sim.record)
    true_steps = np.asarray(sim.step_start_s)
    assert insp.pacing.pacing_hz == pytest.approx(2.0, rel=0.01)
    # Every detected boundary lies within a fifth of a step of a true step start + a fixed lag
    # (the acceleration peak comes at a fixed phase of the step).
    t_b = insp.record.time_s[np.asarray(insp.steps.boundaries)]
    phase = ((t_b[:, None] - true_steps[None, :]) * 2.0) % 1.0
    lag = np.median(np.min(phase, axis=1))
    assert np.all(np.min(np.abs(((phase - lag) + 0.5) % 1.0 - 0.5), axis=1) < 0.2)


@pytest.mark.slow
def test_demo_writes_report(tmp_path, capsys):
    out = tmp_path / "demo"
    code = main(["demo", "--out", str(out), "--json"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0
    html = (out / "index.html").read_text()
    md = (out / "report.md").read_text()
    labels = [r["label"] for r in res["records"]]
    assert labels[:2] == ["treadmill", "insole"]
    assert len(labels) >= 5
    for label in labels:
        assert label in html and label in md
    assert "Camargo" in html and "PhysioNet" in html
    figures = {p.name for p in (out / "figures").glob("*.png")}
    for key in ("treadmill", "insole", "synthetic_seed_individual"):
        for kind in ("grf", "com", "spectrum", "pacing"):
            assert f"{key}_{kind}.png" in figures
    insole = res["records"][1]
    assert insole["static_balance"] == pytest.approx(1.33, abs=0.03)
    assert insole["warnings"]
    # The rest of the chain: criticism on the whole treadmill trial (the error gathered at
    # its heel strikes is called a heel impact, added and re-scored), sensitivity, and the
    # population batch ending in the Table-2-style report.
    assert "Model criticism" in md and "Sensitivity" in md
    assert "Add heel_impact" in md
    assert "demo_criticism_scoreboard.png" in figures
    pop = res["population"]
    assert pop["failed"] == 0
    assert pop["records_used"] + pop["records_excluded"] == pop["records"] > 20
    table2 = (out / "population" / "table2.csv").read_text()
    assert "This study, hierarchical" in table2 and "This study, two-stage OLS" in table2
    assert "Zhang 2015" in table2
    assert (out / "population" / "index.html").is_file()
    assert "Table 2" in md and "This study" in md
    # Table 2 from footbridge walkers: several crossings each, so walker effects are fitted,
    # and at the demo's seed the hierarchical intervals hold the seed's slopes the cohort
    # was drawn from (docs/guide/demo.md; the rates over many populations are measured on
    # the population validation page).
    assert pop["walkers"] >= 5 and pop["hierarchical_records_used"] >= 20
    hier = json.loads((out / "population" / "hierarchical.json").read_text())["fit"]
    assert hier["walker_effects"]
    for law, truth in (("natural_frequency_hz", 0.3049), ("damping_ratio", -0.2116)):
        lo, hi = hier["laws"][law]["slope"]["ci95"]
        assert lo <= truth <= hi, (law, lo, hi)
    assert (out / "population" / "population_walkers.png").is_file()
    assert (out / "population" / "left_out.csv").is_file()
    # Individual identification (seed 5.3): the deck walk identified, its truth inside the
    # 95 % intervals, C and K converging, and the treadmill under both settings.
    assert "Individual identification" in md
    for name in ("individual_convergence", "individual_force"):
        assert f"{name}.png" in figures
    deck = res["individual"]["deck"]
    assert deck["identified"]
    for key in ("natural_frequency_hz", "damping_ratio", "stiffness_n_per_m"):
        _, lo, hi = deck["estimates"][key]
        assert lo <= deck["truth"][key] <= hi, key
    assert deck["convergence"]["first_identified_s"] is not None
    assert set(res["individual"]["treadmill"]) == {"default", "seed-faithful (pf, seed noise)"}
    assert res["individual"]["treadmill"]["default"]["level"] == "not identified"
    # The Table-2 report says what this pipeline recovers, from a recovery run beside it.
    pop_md = (out / "population" / "report.md").read_text()
    assert "What this pipeline recovers" in pop_md and "Conclusions" in pop_md
    assert res["recovery"]["records"]["simulated"] == 12
    # As at full size (docs/validation/recovery.md: 0 of 360 rigid-floor walks identified),
    # the pipeline identifies none of them and declines to fit a law.
    assert res["recovery"]["records"]["not_identified"] == res["recovery"]["records"]["processed"]
    assert res["recovery"]["verdict"]["pipeline"]["natural_frequency_hz"]["slope"] == "not fitted"


def test_preprocessed_response_from_rest_matches_inside_the_edge_margin():
    """Records that start from rest (a start-up transient) match away from the ends too."""
    sim = simulate_walking(mass_kg=70.0, pacing_hz=1.9, duration_s=40.0, start="rest", seed=2)
    com = preprocess(sim.record, highpass_hz=0.15)
    vel_in, disp_in = _relative_errors(com, sim.vel_m_s, sim.disp_m, com.interior())
    assert vel_in < 0.02 and disp_in < 0.02


def _assert_json_close(a: object, b: object, rtol: float, where: str) -> None:
    """Equal JSON trees: numbers to ``rtol`` of their size, everything else exactly."""
    if isinstance(a, dict) and isinstance(b, dict):
        assert a.keys() == b.keys(), where
        for key in a:
            _assert_json_close(a[key], b[key], rtol, f"{where}.{key}")
    elif isinstance(a, list) and isinstance(b, list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_json_close(x, y, rtol, f"{where}[{i}]")
    elif isinstance(a, float | int) and not isinstance(a, bool):
        assert isinstance(b, float | int), where
        assert b == pytest.approx(a, rel=rtol, abs=1e-12), where
    else:
        assert a == b, where


def test_embedded_synthetic_set_regenerates(tmp_path):
    """``analyses/make_demo_data.py`` reproduces the shipped synthetic records.

    Values, not bytes: the simulator integrates thousands of steps through BLAS and compiled
    code whose rounding differs from one processor to the next (the trailing digits of
    ``cubic_stiffness.csv`` did, 3e-11 relative). The tolerance, 1e-7 of each column's RMS,
    is far above that accumulated rounding and five orders below the records' own
    measurement noise (about 1 % of the GRF), so any change of the generator still fails.
    """
    import subprocess
    import sys

    import pandas as pd

    from workbench.datasets import benchmark_paths, synthetic_paths

    script = Path(__file__).resolve().parents[1] / "analyses" / "make_demo_data.py"
    subprocess.run(
        [sys.executable, str(script), "--out", str(tmp_path)], check=True, capture_output=True
    )
    shipped = [*synthetic_paths(), *benchmark_paths()]
    assert len(shipped) == 5
    for path in shipped:
        fresh = tmp_path / path.parent.name / path.name
        a, b = pd.read_csv(path.with_suffix(".csv")), pd.read_csv(fresh.with_suffix(".csv"))
        assert list(a.columns) == list(b.columns) and len(a) == len(b), path.name
        for column in a.columns:
            x, y = a[column].to_numpy(float), b[column].to_numpy(float)
            scale = float(np.sqrt(np.mean(x**2)))
            np.testing.assert_allclose(y, x, rtol=0, atol=1e-7 * scale, err_msg=column)
        _assert_json_close(
            json.loads(path.with_suffix(".json").read_text()),
            json.loads(fresh.with_suffix(".json").read_text()),
            rtol=1e-7,
            where=path.with_suffix(".json").name,
        )

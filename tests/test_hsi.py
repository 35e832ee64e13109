"""Human-structure interaction: analytic checks (docs/science.md 7), integrator, crowds, CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from workbench.errors import InputError, UsageError
from workbench.hsi.loads import moving_harmonic_force, setra_crowd_load, setra_psi
from workbench.hsi.metrics import comfort_class, running_rms
from workbench.hsi.modes import coupled_matrices, coupled_modes
from workbench.hsi.montecarlo import CrossingSpec, draw_crossing, run_monte_carlo
from workbench.hsi.pedestrians import (
    TableSampler,
    design_pedestrian,
    read_pedestrians,
    validate_pedestrians,
)
from workbench.hsi.reference import solve_ivp_crossing
from workbench.hsi.simulate import CrowdBatch, simulate_pedestrians
from workbench.hsi.structure import ModalStructure, simply_supported_beam

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def beam() -> ModalStructure:
    """docs/science.md 7: 50 m, 500 kg/m (modal mass 12 500 kg), 2 Hz, 0.5 %."""
    return simply_supported_beam(50.0, 500.0, 2.0, 0.005)


def _crowd(n: int, seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = [
        design_pedestrian(
            mass_kg=rng.uniform(55, 90),
            natural_frequency_hz=rng.uniform(1.7, 2.6),
            damping_ratio=rng.uniform(0.25, 0.45),
            pacing_hz=rng.uniform(1.7, 2.2),
            speed_m_s=rng.uniform(1.1, 1.5),
            blf=(rng.uniform(0.3, 0.45), rng.uniform(0.02, 0.1), rng.uniform(0.02, 0.08)),
            phase_rad=tuple(rng.uniform(0, 2 * np.pi, 3)),
        )
        for _ in range(n)
    ]
    return pd.concat(rows, ignore_index=True)


# --------------------------------------------------------------------------------------------
# Must show: the two-DOF check, the moving force check, resonance with and without interaction
# --------------------------------------------------------------------------------------------
def test_two_dof_coupled_modes_match_design(beam: ModalStructure) -> None:
    modes = coupled_modes(beam, design_pedestrian(), [25.0])
    (fs, zs), (fh, zh) = [(m.frequency_hz, m.damping_ratio) for m in modes]
    assert abs(fs - 1.991) < 0.002 and abs(100 * zs - 0.90) < 0.05
    assert abs(fh - 2.210) < 0.002 and abs(100 * zh - 29.7) < 0.05
    assert modes[0].structure_share > 0.9 > 0.1 > modes[1].structure_share


def test_integrator_advances_exactly_the_analysed_matrices(beam: ModalStructure) -> None:
    """The vectorised Schur-complement Newmark step equals a dense Newmark step on the
    matrices of :func:`coupled_matrices` (three modes, three walkers, moving)."""
    s3 = simply_supported_beam(50.0, 500.0, 2.0, [0.005, 0.01, 0.02], n_modes=3)
    crowd = _crowd(3, seed=4)
    te = np.array([0.0, 5.0, 12.0])
    dt, dur = 0.01, 30.0
    fast = simulate_pedestrians(s3, crowd, entry_times_s=te, duration_s=dur, dt_s=dt)
    a = validate_pedestrians(crowd)
    m, k, c = (a[c].to_numpy() for c in ("mass_kg", "stiffness_n_per_m", "damping_ns_per_m"))
    v = a["speed_m_s"].to_numpy()
    batch = CrowdBatch.from_scenarios([(a, -v * te, v)])
    n = 6
    x = np.zeros(n)
    xv = np.zeros(n)
    x[3:], xv[3:] = (u[0] for u in batch.steady_state(0.0))

    def load(t: float) -> np.ndarray:
        f = np.zeros(n)
        f[3:] = batch.force(t)[0]
        f[:3] = -s3.shapes(-v * te + v * t).T @ f[3:]
        return f

    mass, damp, stiff = coupled_matrices(s3, m, k, c, -v * te)
    xa = np.linalg.solve(mass, load(0.0) - damp @ xv - stiff @ x)
    phi_mid = s3.shapes(np.array([25.0]))[0]
    out = [phi_mid @ xa[:3]]
    for step in range(1, round(dur / dt) + 1):
        t = step * dt
        mass, damp, stiff = coupled_matrices(s3, m, k, c, -v * te + v * t)
        px = x + dt * xv + dt * dt / 4 * xa
        pv = xv + dt / 2 * xa
        xa = np.linalg.solve(
            mass + dt / 2 * damp + dt * dt / 4 * stiff, load(t) - damp @ pv - stiff @ px
        )
        x, xv = px + dt * dt / 4 * xa, pv + dt / 2 * xa
        out.append(phi_mid @ xa[:3])
    np.testing.assert_allclose(fast.acceleration_m_s2[0, 0], out, rtol=0, atol=1e-12)


def test_moving_harmonic_force_peak(beam: ModalStructure) -> None:
    f0 = 0.41 * (2 - 0.95) * 73.85 * 9.81
    assert f0 == pytest.approx(311.9, abs=0.05)
    hist = moving_harmonic_force(beam, amplitude_n=f0, frequency_hz=2.0, speed_m_s=1.25)
    peak = np.max(np.abs(hist.acceleration_m_s2))
    assert peak == pytest.approx(1.734, rel=0.01)
    # Standing at midspan long enough, the same force reaches the resonant bound F0/(2 zeta m).
    walker = design_pedestrian(blf=(f0 / (73.85 * 9.81), 0.0, 0.0))
    still = simulate_pedestrians(
        beam, walker, positions_m=[25.0], duration_s=200.0, model="biomechanical_force"
    )
    assert np.max(np.abs(still.acceleration_m_s2)) == pytest.approx(2.495, rel=0.005)


@pytest.mark.slow
def test_resonant_walker_interaction_below_moving_force_and_converges(
    beam: ModalStructure,
) -> None:
    walker = design_pedestrian()  # 73.85 kg at 2 Hz on the 2 Hz span, BLF1 0.4305
    ratios, peaks = [], []
    for dt in (0.01, 0.005, 0.0025):
        p = {
            m: np.max(
                np.abs(simulate_pedestrians(beam, walker, dt_s=dt, model=m).acceleration_m_s2)
            )
            for m in ("interaction", "moving_force")
        }
        peaks.append(p)
        ratios.append(p["interaction"] / p["moving_force"])
    diffs = np.abs(np.diff(ratios))
    # Second order: each halving of the step shrinks the change about fourfold.
    assert np.all(diffs[1:] < diffs[:-1] / 3)
    assert diffs[-1] < 0.005
    assert ratios[-1] < 0.75  # interaction cuts the resonant response by a quarter or more
    # Also below its biomechanical force applied as a moving load.
    bio = simulate_pedestrians(beam, walker, dt_s=0.0025, model="biomechanical_force")
    assert peaks[-1]["interaction"] < np.max(np.abs(bio.acceleration_m_s2))


@pytest.mark.slow
def test_newmark_converges_to_solve_ivp(beam: ModalStructure) -> None:
    walker = design_pedestrian(blf=(0.4305, 0.1, 0.05), phase_rad=(0.3, 1.0, 2.0))
    t = np.arange(0.0, 20.0 + 1e-9, 0.01)
    ref = solve_ivp_crossing(beam, walker, np.zeros(1), np.array([1.25]), t, rtol=1e-9)
    errs = []
    for dt in (0.005, 0.0025):
        h = simulate_pedestrians(beam, walker, dt_s=dt, duration_s=20.0)
        errs.append(np.max(np.abs(h.acceleration_m_s2[0, 0, :: round(0.01 / dt)] - ref)))
    assert errs[1] < errs[0] / 3.5
    assert errs[1] < 0.02 * np.max(np.abs(ref))


# --------------------------------------------------------------------------------------------
# Outputs
# --------------------------------------------------------------------------------------------
def test_running_rms_and_comfort_classes() -> None:
    dt = 0.001
    t = np.arange(0, 5, dt)
    rms = running_rms(1.3 * np.sin(2 * np.pi * 2.0 * t), dt)
    assert rms[-1] == pytest.approx(1.3 / np.sqrt(2), rel=1e-3)
    assert [comfort_class(a) for a in (0.4, 0.5, 0.9, 2.0, 2.6)] == [
        "maximum",
        "maximum",
        "mean",
        "minimum",
        "unacceptable",
    ]
    assert comfort_class(0.4, (0.1, 0.3, 0.6)) == "minimum"
    with pytest.raises(UsageError, match="increasing"):
        comfort_class(0.4, (1.0, 0.5, 2.5))


def test_apparent_damping_grows_with_crowd(beam: ModalStructure) -> None:
    one = coupled_modes(beam, design_pedestrian(), [25.0])[0]
    crowd = _crowd(20, seed=2)
    many = coupled_modes(beam, crowd, np.linspace(5, 45, 20))[0]
    assert many.damping_ratio > one.damping_ratio > 0.005


def test_setra_load(beam: ModalStructure) -> None:
    assert [setra_psi(f) for f in (1.0, 1.475, 2.0, 2.2, 3.8, 5.0)] == pytest.approx(
        [0.0, 0.5, 1.0, 0.5, 0.25, 0.0]
    )
    load = setra_crowd_load(beam, 0.5)
    n = 0.5 * 50 * 2.0
    assert load.equivalent_pedestrians == pytest.approx(10.8 * np.sqrt(0.005 * n))
    # Uniform load with the sign of a half sine: modal force p b 2L/pi, resonant amplitude.
    expected = load.load_n_per_m2 * 2.0 * 2 * 50 / np.pi / (2 * 0.005 * 12500)
    assert load.peak_acceleration_m_s2 == pytest.approx(expected, rel=1e-5)
    dense = setra_crowd_load(beam, 1.5)
    assert dense.equivalent_pedestrians == pytest.approx(1.85 * np.sqrt(150))


def test_user_mode_shapes_match_the_beam(beam: ModalStructure) -> None:
    x = np.linspace(0, 50, 501)
    user = ModalStructure(
        50.0, [2.0], [0.005], [12500.0], shape_x_m=x, shape_values=np.sin(np.pi * x / 50)[:, None]
    )
    a = coupled_modes(user, design_pedestrian(), [25.0])[0]
    b = coupled_modes(beam, design_pedestrian(), [25.0])[0]
    assert a.frequency_hz == pytest.approx(b.frequency_hz, rel=1e-6)
    assert user.shapes(np.array([-1.0, 51.0])).tolist() == [[0.0], [0.0]]


# --------------------------------------------------------------------------------------------
# Pedestrian table
# --------------------------------------------------------------------------------------------
def test_pedestrian_table_is_checked(tmp_path: Path) -> None:
    good = _crowd(3, seed=1)
    validate_pedestrians(good)
    with pytest.raises(InputError, match=r"column .blf2.: is missing"):
        validate_pedestrians(good.drop(columns="blf2"), "peds.csv")
    bad = good.copy()
    bad.loc[1, "stiffness_n_per_m"] *= 2
    with pytest.raises(InputError, match=r"peds.csv, column 'stiffness_n_per_m', row 2"):
        validate_pedestrians(bad, "peds.csv")
    bad = good.copy()
    bad["mass_kg"] = bad["mass_kg"].astype(object)
    bad.loc[2, "mass_kg"] = "heavy"
    with pytest.raises(InputError, match="row 3: is not a finite number"):
        validate_pedestrians(bad)
    path = tmp_path / "p.csv"
    good.to_csv(path, index=False)
    assert np.allclose(read_pedestrians(path).to_numpy(), good.to_numpy())


# --------------------------------------------------------------------------------------------
# Crowds and Monte Carlo
# --------------------------------------------------------------------------------------------
def test_poisson_arrivals_keep_the_density(beam: ModalStructure) -> None:
    sampler = TableSampler(_crowd(10, seed=3))
    spec = CrossingSpec(beam, sampler, crowd="stream", density_per_m2=0.1, duration_s=60.0)
    rate = spec.arrival_rate_per_s
    assert rate == pytest.approx(0.1 * 2.0 * 1.3)
    counts = []
    for i in range(300):
        _frame, x0, v, _ = draw_crossing(spec, 7, i)
        entry = -x0 / v
        counts.append(np.sum((entry >= 0) & (entry < 60.0)))
    mean = float(np.mean(counts))
    # Poisson: mean = var = rate * T.
    assert abs(mean - rate * 60) < 4 * np.sqrt(rate * 60 / 300)
    assert np.var(counts, ddof=1) == pytest.approx(rate * 60, rel=0.25)


@pytest.mark.slow
def test_monte_carlo_is_fixed_by_the_seed_on_any_engine(beam: ModalStructure) -> None:
    from distributed import LocalCluster

    sampler = TableSampler(_crowd(8, seed=5))
    spec = CrossingSpec(beam, sampler, crowd="stream", flow_per_s=0.3, duration_s=20.0, dt_s=0.01)
    one = run_monte_carlo(spec, 6, seed=11, chunk_size=2)
    pool = run_monte_carlo(spec, 6, seed=11, chunk_size=2, workers=2)
    pd.testing.assert_frame_equal(one, pool)
    with LocalCluster(n_workers=1, processes=False, dashboard_address=None) as cluster:
        dask = run_monte_carlo(spec, 6, seed=11, chunk_size=2, scheduler=cluster.scheduler_address)
    pd.testing.assert_frame_equal(one, dask)
    other = run_monte_carlo(spec, 6, seed=12, chunk_size=2)
    assert not np.allclose(one["peak_interaction_m_s2"], other["peak_interaction_m_s2"])
    assert (one["n_pedestrians"] > 0).all()
    assert (one["interaction_ratio"] < 1).all()
    assert (one["apparent_damping_ratio"] > 0.005).all()


def test_single_crossings_population_sampler(beam: ModalStructure) -> None:
    from workbench.population.sampler import sample_pedestrians

    spec = CrossingSpec(beam, sample_pedestrians, dt_s=0.01)
    res = run_monte_carlo(spec, 8, seed=3, chunk_size=4)
    res2 = run_monte_carlo(spec, 8, seed=3, chunk_size=8)
    np.testing.assert_allclose(
        res["peak_interaction_m_s2"], res2["peak_interaction_m_s2"], rtol=1e-12
    )
    assert (res["n_pedestrians"] == 1).all()
    assert res["apparent_frequency_hz"].between(1.9, 2.0).all()


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------
def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, cwd=ROOT, timeout=300
    )


def test_hsi_benchmarks_json_contract() -> None:
    res = _run("analyses/hsi_benchmarks.py", "--json", "--steps", "0.01")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    (fs, zs), (fh, zh) = ((m["frequency_hz"], m["damping_ratio"]) for m in out["two_dof"])
    assert abs(fs - 1.991) < 0.002 and abs(100 * zs - 0.90) < 0.05
    assert abs(fh - 2.210) < 0.002 and abs(100 * zh - 29.7) < 0.05
    assert out["moving_force_peak_acceleration_m_s2"] == pytest.approx(1.734, rel=0.01)


def test_cli_hsi(tmp_path: Path) -> None:
    from workbench.cli import main

    peds = tmp_path / "peds.csv"
    _crowd(4, seed=8).to_csv(peds, index=False)
    out = tmp_path / "run"
    args = [
        "hsi",
        "--pedestrians",
        str(peds),
        "--crossings",
        "3",
        "--dt",
        "0.01",
        "--seed",
        "2",
        "--json",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    assert (out / "crossings.csv").exists() and (out / "crossing_0.png").exists()
    hist = pd.read_csv(out / "crossing_0.csv")
    summary = json.loads((out / "summary.json").read_text())
    crossings = pd.read_csv(out / "crossings.csv")
    assert len(crossings) == 3 and summary["crossings"] == 3
    # Crossing 0's history is the one summarised in the table.
    assert np.abs(hist["interaction_m_s2"]).max() == pytest.approx(
        crossings["peak_interaction_m_s2"][0], rel=1e-6
    )
    bad = tmp_path / "bad.csv"
    _crowd(2, seed=8).drop(columns="mass_kg").to_csv(bad, index=False)
    assert main(["hsi", "--pedestrians", str(bad), "--crossings", "2"]) == 2
    assert main(["hsi", "--crowd", "stream", "--crossings", "2"]) == 2
    user = tmp_path / "bridge.json"
    x = [0.0, 10.0, 20.0, 30.0]
    user.write_text(
        json.dumps(
            {
                "span_m": 30.0,
                "frequencies_hz": [1.9],
                "damping_ratios": [0.006],
                "modal_masses_kg": [9000.0],
                "mode_shapes": {"x_m": x, "values": [[0], [1], [1], [0]]},
            }
        )
    )
    assert (
        main(["hsi", "--structure", str(user), "--crossings", "2", "--dt", "0.01", "--at", "15"])
        == 0
    )
    user.write_text(json.dumps({"span_m": 30.0}))
    assert main(["hsi", "--structure", str(user)]) == 2

"""Records of walkers on a footbridge: the walker's equation holds on every exported sample,
ground_acc is the deck under the feet, off the deck it is rigid ground, the files load and
the command line writes them (``workbench hsi --records DIR``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench import hsi, load_record
from workbench.errors import UsageError
from workbench.hsi.pedestrians import Walker
from workbench.hsi.record_files import check_records_folder, write_walker_records
from workbench.hsi.records import WalkerResponse, walker_records, walker_responses
from workbench.hsi.simulate import CrowdBatch, HsiHistory, simulate_pedestrians
from workbench.hsi.structure import ModalStructure, simply_supported_beam
from workbench.models import FourierForce, SMDModel
from workbench.records.collection import load_study_records
from workbench.records.manifest import load_manifest
from workbench.records.record import G_M_S2

DT = 0.005
SPAN = 20.0
#: Rounding of forces of a few hundred newtons after a few thousand steps.
ATOL_N = 1e-9


def _walker(mass: float, fn: float, zeta: float, fp: float, v: float, seed: int) -> Walker:
    rng = np.random.default_rng(seed)
    force = FourierForce(3).from_blf([0.4, 0.08, 0.05], rng.uniform(-np.pi, np.pi, 3), mass)
    model = SMDModel.from_modal(
        mass, fn, zeta, harmonics=3, pacing_hz=fp, force_coefficients_n=force
    )
    return Walker(model, v)


WALKERS = [
    _walker(73.0, 2.2, 0.3, 2.0, 1.25, 1),
    _walker(58.0, 2.5, 0.35, 1.8, 1.4, 2),
    _walker(91.0, 1.9, 0.28, 2.1, 1.1, 3),
]
ENTRY_S = [0.0, 2.0, 4.5]

BEAM3 = simply_supported_beam(SPAN, 400.0, 2.0, [0.005, 0.01, 0.02], n_modes=3)
#: Two modes given as sampled shapes (the interpolated path of ModalStructure.shapes).
SAMPLED = ModalStructure(
    span_m=SPAN,
    frequencies_hz=[1.95, 6.0],
    damping_ratios=[0.006, 0.01],
    modal_masses_kg=[4000.0, 4500.0],
    shape_x_m=np.array([0.0, 5.0, 10.0, 15.0, 20.0]),
    shape_values=np.array([[0.0, 0.0], [0.7, 1.0], [1.0, 0.0], [0.7, -1.0], [0.0, 0.0]]),
)


def _crossing(structure: ModalStructure, margin_s: float = 0.0) -> tuple[HsiHistory, list]:
    hist = simulate_pedestrians(
        structure,
        WALKERS,
        entry_times_s=ENTRY_S,
        duration_s=25.0,
        dt_s=DT,
        keep_walkers=True,
    )
    return hist, walker_responses(hist, margin_s=margin_s)


@pytest.fixture(scope="module")
def beam_crossing() -> tuple[HsiHistory, list[WalkerResponse]]:
    return _crossing(BEAM3, margin_s=1.0)


# --------------------------------------------------------------------------------------------
# (a) the walker's equation of motion on every record, in the integrator's own terms
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("structure", [BEAM3, SAMPLED], ids=["beam3", "sampled"])
def test_grf_satisfies_the_walkers_equation_of_motion(structure: ModalStructure) -> None:
    _, responses = _crossing(structure, margin_s=1.0)
    assert [r.walker for r in responses] == [0, 1, 2]
    for r, walker in zip(responses, WALKERS, strict=True):
        truth = r.record.metadata["truth"]
        m, c, k = truth["mass_kg"], truth["damping_ns_per_m"], truth["stiffness_n_per_m"]
        assert (m, c, k) == (
            walker.model.mass_kg,
            walker.model.damping_ns_per_m,
            walker.model.stiffness_n_per_m,
        )
        # The walker's own known force, evaluated by its model on the crossing's clock.
        f_bio = walker.model.biomechanical_force_n(r.time_s)
        grf = r.record.grf_n
        residual = (grf - m * G_M_S2) - (
            f_bio - c * (r.vel_m_s - r.base_vel_m_s) - k * (r.disp_m - r.base_disp_m)
        )
        assert np.max(np.abs(residual)) < ATOL_N
        # grf is M (g + y'') with the acceleration the step solved for.
        np.testing.assert_allclose(grf, m * (G_M_S2 + r.acc_m_s2), rtol=0, atol=1e-12)
        np.testing.assert_allclose(r.force_n, f_bio, rtol=0, atol=1e-10)
        # The model the record carries is the walker's.
        np.testing.assert_allclose(
            r.model.force_coefficients_n, walker.model.force_coefficients_n, atol=1e-10
        )
        np.testing.assert_allclose(truth["blf"], walker.model.blf, atol=1e-14)
        assert truth["natural_frequency_hz"] == pytest.approx(walker.model.natural_frequency_hz)
        assert truth["damping_ratio"] == pytest.approx(walker.model.damping_ratio)
        assert truth["speed_m_s"] == walker.speed_m_s and truth["pacing_hz"] == r.record.pacing_hz
        assert truth["crossing"] == 0 and truth["time_basis"] == "absolute"
        assert truth["entry_time_s"] == pytest.approx(ENTRY_S[r.walker], abs=1e-12)
        assert truth["exit_time_s"] == pytest.approx(ENTRY_S[r.walker] + SPAN / walker.speed_m_s)


def test_record_covers_the_walk_on_the_deck(
    beam_crossing: tuple[HsiHistory, list[WalkerResponse]],
) -> None:
    hist, _ = beam_crossing
    for r in walker_responses(hist):  # no margin: entry to exit
        truth = r.record.metadata["truth"]
        t = r.time_s
        assert t[0] - DT < truth["entry_time_s"] <= t[0] + 1e-12
        end = min(truth["exit_time_s"], hist.time_s[-1])
        assert t[-1] <= end + 1e-12 < t[-1] + DT
        assert np.all((r.position_m >= 0) & (r.position_m <= SPAN))
        np.testing.assert_allclose(np.diff(t), DT, rtol=1e-9)
        assert r.record.sample_rate_hz == pytest.approx(1 / DT)


# --------------------------------------------------------------------------------------------
# (b) ground_acc is the deck under the feet: phi(x) q'' of the crossing's modes
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("structure", [BEAM3, SAMPLED], ids=["beam3", "sampled"])
def test_ground_acc_is_the_deck_under_the_feet(structure: ModalStructure) -> None:
    hist, responses = _crossing(structure, margin_s=1.0)
    assert hist.walkers is not None
    q_acc = hist.walkers.modal_acc_m_s2[0]  # (J, N)
    for r, walker, entry in zip(responses, WALKERS, ENTRY_S, strict=True):
        idx = np.rint(r.time_s / DT).astype(int)
        np.testing.assert_array_equal(hist.time_s[idx], r.time_s)
        x = walker.speed_m_s * (r.time_s - entry)
        expected = np.sum(structure.shapes(x) * q_acc[:, idx].T, axis=1)
        np.testing.assert_allclose(r.record.ground_acc_m_s2, expected, rtol=0, atol=1e-12)
        np.testing.assert_allclose(r.position_m, x, rtol=0, atol=1e-9)
        assert np.max(np.abs(r.record.ground_acc_m_s2)) > 0.05  # the deck does move


# --------------------------------------------------------------------------------------------
# (c) off the deck and on a rigid deck: ground_acc 0 and the rigid-ground SMD
# --------------------------------------------------------------------------------------------
def test_off_the_deck_is_rigid_ground(
    beam_crossing: tuple[HsiHistory, list[WalkerResponse]],
) -> None:
    _, responses = beam_crossing
    rigid = simulate_pedestrians(
        BEAM3,
        WALKERS,
        entry_times_s=ENTRY_S,
        duration_s=25.0,
        dt_s=DT,
        model="moving_force",
        keep_walkers=True,
    )
    assert rigid.walkers is not None
    v = np.array([w.speed_m_s for w in WALKERS])
    batch = CrowdBatch.from_scenarios([(WALKERS, -v * np.array(ENTRY_S), v)])
    for r in responses[1:]:  # walkers 1 and 2 walk on rigid ground before stepping on
        off = r.position_m < 0
        assert off.sum() == round(1.0 / DT)  # the 1 s margin
        assert np.all(r.record.ground_acc_m_s2[off] == 0.0)
        assert np.all(r.base_disp_m[off] == 0.0) and np.all(r.base_vel_m_s[off] == 0.0)
        # Bit for bit the walker of the force-only model, whose walkers walk on rigid ground.
        idx = np.rint(r.time_s[off] / DT).astype(int)
        np.testing.assert_array_equal(r.disp_m[off], rigid.walkers.disp_m[0, r.walker, idx])
        np.testing.assert_array_equal(r.acc_m_s2[off], rigid.walkers.acc_m_s2[0, r.walker, idx])
        # ... which is the SMD's steady state on rigid ground, to Newmark accuracy.
        y = np.array([batch.steady_state(t)[0][0, r.walker] for t in r.time_s[off]])
        assert np.max(np.abs(r.disp_m[off] - y)) < 2e-3 * np.max(np.abs(y))
    # After a walker steps off (walker 0 leaves at 16 s of 25), rigid ground again.
    after = responses[0].position_m > SPAN
    assert after.sum() == round(1.0 / DT)
    assert np.all(responses[0].record.ground_acc_m_s2[after] == 0.0)


def test_rigid_deck_gives_the_rigid_ground_walker() -> None:
    # 1e13 kg of modal mass: the walker's force moves the deck by ~1e-9 m/s^2.
    rigid_deck = simply_supported_beam(SPAN, 1e12, 2.0, 0.005)
    hist = simulate_pedestrians(
        rigid_deck, WALKERS[:1], duration_s=10.0, dt_s=DT, keep_walkers=True
    )
    (rec,) = walker_records(hist)
    (resp,) = walker_responses(hist)
    assert rec.ground_acc_m_s2 is not None
    assert np.max(np.abs(rec.ground_acc_m_s2)) < 1e-7
    on_rigid = simulate_pedestrians(
        rigid_deck,
        WALKERS[:1],
        duration_s=10.0,
        dt_s=DT,
        model="moving_force",
        keep_walkers=True,
    )
    assert on_rigid.walkers is not None
    idx = np.rint(rec.time_s / DT).astype(int)
    m = WALKERS[0].model.mass_kg
    np.testing.assert_allclose(
        rec.grf_n, m * (G_M_S2 + on_rigid.walkers.acc_m_s2[0, 0, idx]), rtol=0, atol=1e-6
    )
    np.testing.assert_allclose(resp.disp_m, on_rigid.walkers.disp_m[0, 0, idx], atol=1e-12)


def test_keeping_walkers_changes_nothing_and_records_need_interaction() -> None:
    kept = simulate_pedestrians(BEAM3, WALKERS[:2], duration_s=6.0, dt_s=DT, keep_walkers=True)
    plain = simulate_pedestrians(BEAM3, WALKERS[:2], duration_s=6.0, dt_s=DT)
    np.testing.assert_array_equal(kept.acceleration_m_s2, plain.acceleration_m_s2)
    assert plain.walkers is None
    with pytest.raises(UsageError, match="keep_walkers=True") as err:
        walker_records(plain)
    assert err.value.parameter == "history"
    force_only = simulate_pedestrians(
        BEAM3, WALKERS[:1], duration_s=6.0, dt_s=DT, model="moving_force", keep_walkers=True
    )
    with pytest.raises(UsageError, match="interaction"):
        walker_records(force_only)
    with pytest.raises(UsageError, match="one number per scenario"):
        walker_records(kept, crossing_ids=[1, 2])
    # The lazy package names are the functions.
    assert hsi.walker_records is walker_records and hsi.walker_responses is walker_responses
    assert hsi.write_walker_records is write_walker_records


# --------------------------------------------------------------------------------------------
# (d) the files load, with their truth, and the manifest is the batch loader's
# --------------------------------------------------------------------------------------------
def test_written_records_load_and_the_manifest_is_a_batch(
    tmp_path: Path, beam_crossing: tuple[HsiHistory, list[WalkerResponse]]
) -> None:
    from workbench.sensitivity.analysis import truth_values

    hist, _ = beam_crossing
    # A late walker is on the deck for 1 s only: the loaders would refuse it, so it is skipped.
    late = simulate_pedestrians(
        BEAM3,
        WALKERS[:2],
        entry_times_s=[0.0, 9.0],
        duration_s=10.0,
        dt_s=DT,
        keep_walkers=True,
    )
    records = walker_records(hist) + walker_records(late, crossing_ids=[7])
    written = write_walker_records(records, tmp_path / "recs")
    assert [s["record"] for s in written.skipped] == ["crossing0007_walker001"]
    assert "too short" in written.skipped[0]["reason"]
    assert written.manifest == tmp_path / "recs" / "manifest.csv"
    names = [f"records/crossing0000_walker00{i}.csv" for i in range(3)]
    names.append("records/crossing0007_walker000.csv")
    assert [p.relative_to(tmp_path / "recs").as_posix() for p in written.records] == names
    entries = load_manifest(written.manifest)
    assert [e.path for e in entries] == [tmp_path / "recs" / n for n in names]
    loaded = load_study_records(written.manifest)
    assert [k for k, _ in loaded] == names
    for (_, back), rec, entry in zip(loaded, records, entries, strict=False):
        direct = load_record(entry.path)
        for r in (back, direct):
            assert r.mass_kg == rec.mass_kg == entry.mass_kg
            assert r.pacing_hz == rec.pacing_hz == entry.pacing_hz
            assert r.subject == rec.subject == entry.subject
            assert r.ground_acc_m_s2 is not None
            np.testing.assert_array_equal(r.ground_acc_m_s2, rec.ground_acc_m_s2)
            np.testing.assert_array_equal(r.grf_n, rec.grf_n)
            np.testing.assert_array_equal(r.time_s, rec.time_s)
            assert r.metadata["truth"] == rec.metadata["truth"]
            assert r.metadata["warnings"] == []
        truth_file = entry.path.with_name(entry.path.stem + ".truth.json")
        assert json.loads(truth_file.read_text()) == rec.metadata["truth"]
        # What the tools that compare with the truth read.
        values = truth_values(back.metadata["truth"])
        assert values["stiffness_n_per_m"] == rec.metadata["truth"]["stiffness_n_per_m"]
        assert {"damping_ns_per_m", "natural_frequency_hz", "damping_ratio", "blf1"} <= set(values)
    table = (tmp_path / "recs" / "truth.csv").read_text().splitlines()
    assert table[0].startswith("path,subject,crossing,walker,mass_kg,pacing_hz,speed_m_s")
    assert len(table) == 1 + len(names)
    with pytest.raises(UsageError, match="twice"):
        write_walker_records(records + records[:1], tmp_path / "again")
    assert not (tmp_path / "again").exists()  # refused before anything was written
    # Nothing loadable: no manifest, and none left over from an earlier run.
    nothing = write_walker_records(records[-1:], tmp_path / "recs")
    assert nothing.manifest is None and nothing.records == [] and len(nothing.skipped) == 1
    assert not (tmp_path / "recs" / "manifest.csv").exists()


def test_records_folder_is_checked(tmp_path: Path) -> None:
    file = tmp_path / "file.txt"
    file.write_text("x")
    with pytest.raises(UsageError, match="is a file") as err:
        check_records_folder(file)
    assert err.value.parameter == "folder"
    with pytest.raises(UsageError, match="cannot be written"):
        check_records_folder(file / "sub")
    assert check_records_folder(tmp_path / "new" / "dir").is_dir()


# --------------------------------------------------------------------------------------------
# (e) the command line
# --------------------------------------------------------------------------------------------
def test_cli_hsi_records(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from workbench.cli import main

    out = tmp_path / "recs"
    common = ["hsi", "--span", "20", "--dt", "0.01", "--seed", "3", "--json"]
    args = [*common, "--crossings", "3", "--records", str(out), "--records-crossings", "2"]
    assert main(args) == 0
    summary = json.loads(capsys.readouterr().out)
    entries = load_manifest(out / "manifest.csv")
    assert len(entries) == 2 == summary["records"]["records"]
    assert [e.subject for e in entries] == ["crossing0000_walker000", "crossing0001_walker000"]
    for e in entries:
        rec = load_record(e.path)
        truth = rec.metadata["truth"]
        assert rec.sample_rate_hz == pytest.approx(100.0)
        assert truth["monte_carlo_seed"] == 3 and truth["model"] == "interaction"
        assert rec.ground_acc_m_s2 is not None and np.max(np.abs(rec.ground_acc_m_s2)) > 0
        # A single walker is on the deck from t = 0 until it steps off.
        assert rec.time_s[0] == 0.0
        assert rec.time_s[-1] <= truth["exit_time_s"] < rec.time_s[-1] + 0.01 + 1e-9

    stream = tmp_path / "stream"
    args = [*common, "--crowd", "stream", "--flow", "0.4", "--duration", "15", "--crossings", "1"]
    assert main([*args, "--records", str(stream)]) == 0
    got = json.loads(capsys.readouterr().out)["records"]
    rows = load_manifest(stream / "manifest.csv")
    assert len(rows) == got["records"] >= 2
    assert all(load_record(e.path).duration_s >= 2.0 for e in rows)


def test_cli_bad_records_fail_before_the_simulation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from workbench.cli import main
    from workbench.hsi import montecarlo

    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError("the Monte Carlo ran")

    monkeypatch.setattr(montecarlo, "run_monte_carlo", never)
    file = tmp_path / "file.txt"
    file.write_text("x")
    for bad in (str(file), str(file / "sub")):
        assert main(["hsi", "--crossings", "2", "--records", bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("workbench: error: --records ")
    assert main(["hsi", "--crossings", "2", "--records-crossings", "2"]) == 2
    assert "add --records DIR" in capsys.readouterr().err
    rec = str(tmp_path / "ok")
    assert main(["hsi", "--crossings", "2", "--records", rec, "--records-crossings", "3"]) == 2
    assert "more than the 2 simulated crossings" in capsys.readouterr().err
    assert main(["hsi", "--crossings", "2", "--records", rec, "--records-crossings", "0"]) == 2

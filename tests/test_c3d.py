"""The C3D reader on real files written with ezc3d during the test run.

A walk from the workbench's own simulator is split over two force platforms, foot by foot,
written as a C3D file with ezc3d (analog channels, FORCE_PLATFORM parameters, the body mass
in PROCESSING:Bodymass) and read back: vertical axis, the sum over plates, the sign of
each plate, the analog clock and the mass are those of docs/contracts.md ("C3D").
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.cli import main
from workbench.errors import InputError
from workbench.records.io import load_record
from workbench.synth import simulate_walking

ezc3d = pytest.importorskip("ezc3d", reason="the c3d extra (ezc3d) is not installed")

POINT_RATE_HZ = 100.0
ANALOG_RATE_HZ = 1000.0
FIRST_FRAME = 9  # ezc3d counts frames from 0: the trial starts at 0.09 s
MASS_KG = 68.5
# C3D stores analog samples as 32-bit floats: 2^-24 relative rounding, so 1e-6 relative
# (with 1e-3 N absolute for samples near zero) holds every round trip.
RTOL, ATOL_N = 1e-6, 1e-3

# Platform corners [mm], listed counter-clockwise seen from above (the platform's z axis up,
# as the laboratory's) or clockwise (its z axis down: ezc3d turns its force over).
_CORNERS_UP = np.array([[600.0, 0.0, 0.0, 600.0], [400.0, 400.0, 0.0, 0.0], [0.0] * 4])


@pytest.fixture(scope="module")
def walk() -> dict[str, np.ndarray]:
    """A simulated walk at the analog rate, its GRF split over two plates foot by foot."""
    sim = simulate_walking(
        mass_kg=MASS_KG, duration_s=4.0, sample_rate_hz=ANALOG_RATE_HZ, noise_sd_n=2.0, seed=3
    )
    t, grf = sim.record.time_s, sim.record.grf_n
    starts = np.asarray(sim.truth["step_start_s"])
    foot = (np.searchsorted(starts, t, side="right") - 1) % 2  # alternate steps
    first = np.where(foot == 0, grf, 0.0)
    # Horizontal forces a tenth of the vertical one: the vertical axis must still be found.
    return {"first": first, "second": grf - first, "total": grf}


def _int_parameter(c3d: object, group: str, name: str, values: np.ndarray) -> None:
    """Add an integer parameter (ezc3d's add_parameter stores lists as floats).

    FORCE_PLATFORM:USED, TYPE and CHANNEL must be integers for ezc3d to read the platforms
    back; its Python wrapper has no public way to write integer arrays, so this builds the
    parameter as add_parameter does and hands it to the same storage.
    """
    core = ezc3d.ezc3d
    values = np.asarray(values, dtype=np.int64)
    param = core.Parameter(name, "")
    param.set(
        core.VecInt([int(v) for v in values.reshape(-1, order="F")]),
        core.VecUInt([int(d) for d in values.shape]),
    )
    c3d._storage["parameters"].add_parameter(group, param)  # type: ignore[attr-defined]


def write_two_plate_c3d(
    path: Path,
    first: np.ndarray,
    second: np.ndarray,
    *,
    plate_z_up: tuple[bool, bool] = (True, True),
    vertical_channel: int = 2,
    body_mass_kg: float | None = MASS_KG,
    force_unit: str = "N",
) -> Path:
    """Write a C3D file with two type-2 force platforms carrying the given vertical forces.

    ``vertical_channel`` 2 puts the vertical force on Fz (z up); 1 puts it on Fy, as a file
    in a y-up laboratory frame would.
    """
    c3d = ezc3d.c3d()
    n = first.size
    ratio = int(ANALOG_RATE_HZ / POINT_RATE_HZ)
    assert n % ratio == 0
    c3d["parameters"]["POINT"]["RATE"]["value"] = [POINT_RATE_HZ]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ("marker",)
    c3d["parameters"]["ANALOG"]["RATE"]["value"] = [ANALOG_RATE_HZ]
    names = [f"{q}{k}" for k in (1, 2) for q in ("Fx", "Fy", "Fz", "Mx", "My", "Mz")]
    c3d["parameters"]["ANALOG"]["LABELS"]["value"] = tuple(names)
    units = (force_unit,) * 3 + ("Nmm",) * 3
    c3d["parameters"]["ANALOG"]["UNITS"]["value"] = units * 2
    _int_parameter(c3d, "FORCE_PLATFORM", "USED", np.array([2]))
    _int_parameter(c3d, "FORCE_PLATFORM", "TYPE", np.array([2, 2]))
    _int_parameter(c3d, "FORCE_PLATFORM", "ZERO", np.array([1, 0]))
    corners = np.zeros((3, 4, 2))
    for k, up in enumerate(plate_z_up):
        plate = _CORNERS_UP + np.array([[600.0 * k], [0.0], [0.0]])
        corners[:, :, k] = plate if up else plate[:, ::-1]
    c3d.add_parameter("FORCE_PLATFORM", "CORNERS", corners)
    c3d.add_parameter("FORCE_PLATFORM", "ORIGIN", np.array([[0.0, 0.0], [0.0, 0.0], [-40.0] * 2]))
    _int_parameter(c3d, "FORCE_PLATFORM", "CHANNEL", np.arange(1, 13).reshape(6, 2, order="F"))
    c3d.add_parameter("FORCE_PLATFORM", "CAL_MATRIX", np.zeros((6, 6, 2)))
    if body_mass_kg is not None:
        c3d.add_parameter("PROCESSING", "Bodymass", np.array([body_mass_kg]))
    c3d["header"]["points"]["first_frame"] = FIRST_FRAME
    c3d["data"]["points"] = np.zeros((4, 1, n // ratio))
    analogs = np.zeros((1, 12, n))
    for k, force in enumerate((first, second)):
        analogs[0, 6 * k + vertical_channel] = force
        analogs[0, 6 * k + (2 if vertical_channel != 2 else 0)] = 0.1 * force  # horizontal
    c3d["data"]["analogs"] = analogs
    c3d.write(str(path))
    return path


@pytest.mark.parametrize(
    ("plate_z_up", "flipped"),
    [
        ((True, True), []),  # both report the force on the person (up)
        ((False, False), [1, 2]),  # both report the force on the plate, as many labs do
        ((True, False), [2]),  # one platform's corners listed the other way round
    ],
)
def test_two_plates_read_back_as_the_vertical_grf_on_the_analog_clock(
    walk, tmp_path, plate_z_up, flipped
):
    path = write_two_plate_c3d(
        tmp_path / "trial.c3d", walk["first"], walk["second"], plate_z_up=plate_z_up
    )
    rec = load_record(path)
    n = walk["total"].size
    # The sum of both plates' vertical force, each turned to the force on the person.
    np.testing.assert_allclose(rec.grf_n, walk["total"], rtol=RTOL, atol=ATOL_N)
    np.testing.assert_allclose(rec.grf_left_n, walk["first"], rtol=RTOL, atol=ATOL_N)
    np.testing.assert_allclose(rec.grf_right_n, walk["second"], rtol=RTOL, atol=ATOL_N)
    assert rec.grf_n.mean() > 0.9 * MASS_KG * 9.80665  # supports the body: positive, ~ M g
    # The analog clock (1000 Hz), not the point rate, from the first point frame.
    np.testing.assert_allclose(
        rec.time_s, FIRST_FRAME / POINT_RATE_HZ + np.arange(n) / ANALOG_RATE_HZ, atol=1e-12
    )
    info = rec.metadata["c3d"]
    assert info["analog_rate_hz"] == ANALOG_RATE_HZ and info["point_rate_hz"] == POINT_RATE_HZ
    assert info["vertical_axis"] == "z" and info["platforms"] == 2
    assert info["vertical_signs"] == [-1.0 if k in flipped else 1.0 for k in (1, 2)]
    flip_warnings = [w for w in rec.metadata["warnings"] if "flipped" in w]
    assert bool(flip_warnings) == bool(flipped)
    if flipped == [2]:
        assert "platforms 2 of 2" in flip_warnings[0] or "platform 2 of 2" in flip_warnings[0]
    # The mass from the file's PROCESSING:Bodymass.
    assert rec.mass_kg == pytest.approx(MASS_KG, rel=1e-6)  # stored as a 32-bit float
    assert rec.metadata["mass_source"] == "PROCESSING:Bodymass in the C3D file"


def test_the_mass_given_wins_and_a_file_without_one_needs_it(walk, tmp_path):
    path = write_two_plate_c3d(tmp_path / "trial.c3d", walk["first"], walk["second"])
    rec = load_record(path, mass_kg=80.0)
    assert rec.mass_kg == 80.0 and rec.metadata["mass_source"] == "given as --mass or mass_kg"
    bare = write_two_plate_c3d(
        tmp_path / "bare.c3d", walk["first"], walk["second"], body_mass_kg=None
    )
    with pytest.raises(InputError, match="no body mass was given"):
        load_record(bare)
    (tmp_path / "bare.json").write_text(json.dumps({"mass_kg": 75.0}))
    assert load_record(bare).mass_kg == 75.0  # a sidecar beside the file


def test_kilonewton_channels_are_converted_by_their_analog_unit(walk, tmp_path):
    """ezc3d labels every platform "N" (POINT:FORCE_UNITS); the channels' own unit counts."""
    path = write_two_plate_c3d(
        tmp_path / "kn.c3d", walk["first"] / 1000.0, walk["second"] / 1000.0, force_unit="kN"
    )
    assert [p["unit_force"] for p in ezc3d.c3d(str(path), True)["data"]["platform"]] == ["N"] * 2
    rec = load_record(path)
    np.testing.assert_allclose(rec.grf_n, walk["total"], rtol=RTOL, atol=ATOL_N)
    assert rec.metadata["c3d"]["force_units"] == ["kN", "kN"]


def test_a_file_whose_vertical_is_not_z_is_refused(walk, tmp_path, capsys):
    path = write_two_plate_c3d(
        tmp_path / "yup.c3d", walk["first"], walk["second"], vertical_channel=1
    )
    with pytest.raises(InputError) as err:
        load_record(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}, force platforms: ")
    assert "y axis" in msg and "z axis pointing up" in msg and "\n" not in msg
    code = main(["inspect", str(path), "--json"])
    _, stderr = capsys.readouterr()
    assert code == 2 and "Traceback" not in stderr and "z axis pointing up" in stderr


def test_inspect_reads_the_c3d_file_with_its_mass(walk, tmp_path, capsys):
    path = write_two_plate_c3d(tmp_path / "trial.c3d", walk["first"], walk["second"])
    code = main(["inspect", str(path), "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    report = json.loads(out)
    assert report["mass_kg"] == pytest.approx(MASS_KG, rel=1e-6)
    assert report["sample_rate_hz"] == pytest.approx(ANALOG_RATE_HZ)


def test_a_file_ezc3d_cannot_read_is_one_sentence(tmp_path):
    path = tmp_path / "broken.c3d"
    path.write_bytes(b"\x02\x50" + bytes(510))  # a C3D key and nothing else
    with pytest.raises(InputError) as err:
        load_record(path, mass_kg=70.0)
    msg = str(err.value)
    assert msg.startswith(f"{path}, whole file: ezc3d could not read") and "\n" not in msg


@pytest.mark.skipif(
    "fork" not in __import__("multiprocessing").get_all_start_methods(),
    reason="the stand-in crash reaches the child only when it is forked",
)
def test_ezc3d_crashing_on_a_damaged_file_is_one_sentence(walk, tmp_path, monkeypatch):
    """ezc3d segfaults on some damaged files; the child process dies, the workbench speaks.

    The crash is staged (the reading function kills its own process with SIGSEGV), since
    which damaged bytes crash a given ezc3d version is not stable.
    """
    import os
    import signal

    from workbench.records import c3d_file

    def crash(path: str) -> dict:
        os.kill(os.getpid(), signal.SIGSEGV)
        raise AssertionError("not reached")

    monkeypatch.setattr(c3d_file, "_read", crash)
    path = write_two_plate_c3d(tmp_path / "trial.c3d", walk["first"], walk["second"])
    with pytest.raises(InputError) as err:
        load_record(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}, whole file: ezc3d crashed reading the file (signal SIGSEGV)")
    assert "\n" not in msg

"""A C3D file's force platforms read with ezc3d in a child process.

ezc3d is C++: on some damaged files it does not raise but crashes the process (a
segmentation fault; files with a few bytes changed at random show it), which would end the
workbench without a word and lose any result it held. So the file is read
in a child process that sends back plain arrays and numbers; a child that dies becomes
one sentence naming the file. The reader proper (axis, sign, sum, clock) is
:mod:`workbench.records.formats.c3d_platforms`.
"""

from __future__ import annotations

import math
import multiprocessing
import signal
from typing import Any

import numpy as np

from workbench.errors import InputError

__all__ = ["read_force_platforms"]


def _body_mass(c3d: Any) -> float | None:
    """Return the body mass the file states in ``PROCESSING:Bodymass`` [kg], if any.

    Vicon's processing writes the subject's mass there; other software leaves it out.
    """
    try:
        value = c3d["parameters"]["PROCESSING"]["Bodymass"]["value"]
        mass = float(np.asarray(value, dtype=np.float64).reshape(-1)[0])
    except (KeyError, IndexError, TypeError, ValueError):
        return None
    return mass if math.isfinite(mass) and mass > 0 else None


def _vertical_channel_units(c3d: Any, n_platforms: int) -> list[str | None]:
    """Return the unit ``ANALOG:UNITS`` names for each platform's Fz channel, or None.

    ezc3d labels every platform's force with ``POINT:FORCE_UNITS`` (N when absent), but the
    samples are in their analog channels' units: for platforms of types 2 and 4 the third
    channel of ``FORCE_PLATFORM:CHANNEL`` is Fz (for type 4 after the calibration matrix,
    whose output unit the channel states only when it is a force unit).
    """
    units: list[str | None] = [None] * n_platforms
    try:
        params = c3d["parameters"]
        types = np.asarray(params["FORCE_PLATFORM"]["TYPE"]["value"]).reshape(-1)
        channels = np.asarray(params["FORCE_PLATFORM"]["CHANNEL"]["value"])
        analog_units = list(params["ANALOG"]["UNITS"]["value"])
    except (KeyError, TypeError, ValueError):
        return units
    for k in range(n_platforms):
        try:
            if int(types[k]) in (2, 4):
                units[k] = str(analog_units[int(channels[2, k]) - 1]).strip()  # 1-based
        except (IndexError, TypeError, ValueError):
            continue
    return units


def _read(path: str) -> dict[str, Any]:
    """Read the platforms, the rates, the first frame, the units and the mass (any process)."""
    import ezc3d

    c3d = ezc3d.c3d(path, extract_forceplat_data=True)
    platforms = list(c3d["data"]["platform"])
    return {
        "forces": [np.array(p["force"], dtype=np.float64) for p in platforms],
        "unit_force": [str(p.get("unit_force", "N")) for p in platforms],
        "channel_units": _vertical_channel_units(c3d, len(platforms)),
        "analog_rate": float(c3d["header"]["analogs"]["frame_rate"]),
        "point_rate": float(c3d["header"]["points"]["frame_rate"]),
        "first_frame": int(c3d["header"]["points"]["first_frame"]),
        "body_mass_kg": _body_mass(c3d),
    }


def _child(conn: Any, path: str) -> None:
    import faulthandler

    # A crash of ezc3d is expected here and reported by the parent in one sentence; a fault
    # handler inherited from the parent (pytest, python -X faulthandler) would add a dump.
    faulthandler.disable()
    try:
        conn.send(("ok", _read(path)))
    except Exception as exc:  # ezc3d raises plain RuntimeErrors for damaged files
        conn.send(("error", type(exc).__name__))
    finally:
        conn.close()


def read_force_platforms(path: str, source: str) -> dict[str, Any]:
    """Read a C3D file's force platforms in a child process (module docstring).

    Parameters
    ----------
    path : str
        The file.
    source : str
        Its name in sentences.

    Returns
    -------
    dict
        ``forces`` (one 3 x samples array per platform, laboratory frame), ``unit_force``
        (ezc3d's unit per platform), ``channel_units`` (the Fz channel's stated unit or
        None), ``analog_rate``, ``point_rate``, ``first_frame`` (from 0), ``body_mass_kg``.

    Raises
    ------
    InputError
        When ezc3d cannot read the file or its process dies.
    """
    if multiprocessing.current_process().daemon:
        # A daemonic process (a multiprocessing pool's worker) may have no children: read
        # here, with ezc3d's errors still turned into a sentence.
        try:
            return _read(path)
        except Exception as exc:
            raise InputError(
                source,
                "whole file",
                f"ezc3d could not read the force platforms ({type(exc).__name__})",
                "check that this is a complete C3D file with force platforms",
            ) from None
    # fork starts the child at once with ezc3d already imported; elsewhere spawn.
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    context: Any = multiprocessing.get_context(method)
    receive, send = context.Pipe(duplex=False)
    child = context.Process(target=_child, args=(send, path), daemon=True)
    child.start()
    send.close()
    try:
        status, payload = receive.recv()  # EOFError when the child died without a word
    except EOFError:
        status, payload = "died", None
    finally:
        receive.close()
        child.join()
    if status == "ok":
        return dict(payload)
    if status == "error":
        problem = f"ezc3d could not read the force platforms ({payload})"
    else:
        code = child.exitcode
        how = (
            f"signal {signal.Signals(-code).name}"
            if code is not None and code < 0 and -code in signal.valid_signals()
            else f"exit status {code}"
        )
        problem = f"ezc3d crashed reading the file ({how}), so the file is damaged"
    raise InputError(
        source, "whole file", problem, "check that this is a complete C3D file with force platforms"
    )

"""The C3D format: force platforms read with ezc3d (optional extra ``c3d``).

The vertical axis, the sign of each platform, the sum, the analog clock, the force units and
the mass are those of docs/contracts.md ("C3D"); :mod:`workbench.records.c3d_file` reads the
platforms in a child process.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from workbench.errors import InputError, UsageError
from workbench.records.formats.base import (
    _FORCE_UNIT_NAMES,
    FORCE_UNITS,
    RecordFormat,
    RecordTable,
    register_format,
)
from workbench.records.record import FloatArray

__all__ = ["C3dFormat"]

#: C3D files are at least one 512-byte block, whose second byte is the fixed key 0x50.
_C3D_BLOCK = 512
_C3D_KEY = 0x50


def _plate_sign(vertical: FloatArray) -> float:
    """+1 or -1: the sign that makes a platform's vertical force the force on the person.

    Platforms report the force the person exerts on the plate (pointing down) in some labs
    and the reaction (pointing up) in others, and a platform whose corners are listed the
    other way round has its axes turned over. The person pushes down, so the force on the
    person points up at the platform's largest load: its sign there decides.
    """
    if vertical.size == 0 or not np.any(vertical):
        return 1.0
    peak = vertical[int(np.argmax(np.abs(vertical)))]
    return -1.0 if peak < 0.0 else 1.0


@register_format
class C3dFormat(RecordFormat):
    """C3D motion-capture files: recognised by their binary header."""

    name = "c3d"
    extensions = (".c3d",)
    description = "C3D force platforms (needs the optional package ezc3d)"
    file_keys = ("c3d", "side_assignment")

    def sniff_bytes(self, raw: bytes) -> bool:
        """Claim a file of at least one 512-byte block with the key 0x50 as byte 2."""
        # A text file has no NUL byte in its first block; a C3D header has several.
        return len(raw) >= _C3D_BLOCK and raw[1] == _C3D_KEY and b"\x00" in raw[:_C3D_BLOCK]

    def read(self, path: Path, source: str) -> RecordTable:
        """Read the force platforms of a C3D file (docs/contracts.md, "C3D").

        The vertical GRF is the global z component of every platform's force (ezc3d turns
        each platform's force into the laboratory's frame with the platform's corners), each
        platform turned to the force on the person (:func:`_plate_sign`), summed, on the
        analog clock.
        """
        return _read_c3d(path, source)


def _read_c3d(path: Path, source: str) -> RecordTable:
    try:
        import ezc3d  # noqa: F401 - optional extra, imported only when a C3D file is read
    except ImportError:
        raise UsageError(
            f"reading the C3D file {source} needs the optional package ezc3d; install it with "
            "pip install 'workbench[c3d]'"
        ) from None
    from workbench.records.c3d_file import read_force_platforms

    read = read_force_platforms(str(path), source)
    platforms: list[FloatArray] = read["forces"]
    analog_rate, point_rate = read["analog_rate"], read["point_rate"]
    first_frame = read["first_frame"]
    if not platforms:
        raise InputError(
            source,
            "force platforms",
            "the C3D file has no force platform data",
            "give a trial recorded with force platforms",
        )
    if not (math.isfinite(analog_rate) and analog_rate > 0):
        raise InputError(
            source, "header", f"the analog rate {analog_rate!r} Hz is not valid", "repair the file"
        )
    if not (math.isfinite(point_rate) and point_rate > 0):
        raise InputError(
            source, "header", f"the point rate {point_rate!r} Hz is not valid", "repair the file"
        )
    forces: list[FloatArray] = []
    units: list[str] = []
    for k, (force, stated, labelled) in enumerate(
        zip(platforms, read["channel_units"], read["unit_force"], strict=True), start=1
    ):
        # The Fz channel's own unit when it names a force unit; else ezc3d's label.
        known = stated is not None and _FORCE_UNIT_NAMES.get(stated.lower()) is not None
        unit = stated if known else labelled.strip()
        units.append(unit)
        factor = FORCE_UNITS.get(_FORCE_UNIT_NAMES.get(unit.lower(), ""), None)
        if factor is None:
            raise InputError(
                source,
                f"force platform {k}",
                f"the force unit {unit!r} is not one the workbench converts",
                f"export the forces in {', '.join(FORCE_UNITS)}",
            )
        if force.ndim != 2 or force.shape[0] < 3:
            raise InputError(
                source,
                f"force platform {k}",
                f"the force data have shape {force.shape}, not 3 x samples",
                "check the force platform parameters of the file",
            )
        forces.append(force[:3] * factor)
    lengths = {f.shape[1] for f in forces}
    if len(lengths) != 1:
        raise InputError(
            source,
            "force platforms",
            f"the platforms have different numbers of samples ({sorted(lengths)})",
            "check the analog channels of the file",
        )
    # The body's weight is carried by the vertical axis: z must carry more force than x or y
    # (a file in a y-up frame would otherwise give a horizontal force as the GRF).
    carried = np.sum([np.mean(np.abs(f), axis=1) for f in forces], axis=0)
    if np.all(np.isfinite(carried)) and carried[2] < np.max(carried):
        axis = "xyz"[int(np.argmax(carried))]
        raise InputError(
            source,
            "force platforms",
            f"the platforms' z axis carries less force than their {axis} axis, so z is not "
            "vertical in this file's frame (the workbench reads the laboratory's z as vertical)",
            "export the trial with the laboratory's z axis pointing up",
        )
    signs = [_plate_sign(f[2]) for f in forces]
    vertical = [sign * f[2] for sign, f in zip(signs, forces, strict=True)]
    n = vertical[0].size
    # Analog samples run at analog_rate from the first point frame (ezc3d counts frames from
    # 0): one common time base, frame 0 at 0 s.
    time_s = first_frame / point_rate + np.arange(n, dtype=np.float64) / analog_rate
    total = np.sum(vertical, axis=0)
    warnings: list[str] = []
    flipped = [k for k, sign in enumerate(signs, start=1) if sign < 0]
    if flipped:
        which = (
            "The C3D platforms report"
            if len(flipped) == len(signs)
            else f"C3D platform{'s' if len(flipped) > 1 else ''} "
            f"{', '.join(str(k) for k in flipped)} of {len(signs)} report"
        )
        warnings.append(
            f"{which} the force on the plate (negative upwards), so its sign was flipped to "
            "the force on the person."
        )
    arrays: dict[str, FloatArray] = {"time_s": time_s, "grf_n": total}
    column_labels = {"time_s": "analog time base", "grf_n": "sum of platform Fz"}
    metadata: dict[str, Any] = {
        "c3d": {
            "platforms": len(platforms),
            "analog_rate_hz": analog_rate,
            "point_rate_hz": point_rate,
            "first_frame": first_frame,
            "vertical_axis": "z",
            "force_units": units,
            "vertical_sign": signs[0] if len(set(signs)) == 1 else None,
            "vertical_signs": signs,
            "body_mass_kg": read["body_mass_kg"],
        }
    }
    if len(vertical) == 2:
        arrays["grf_left_n"] = vertical[0]
        arrays["grf_right_n"] = vertical[1]
        column_labels["grf_left_n"] = "platform 1 Fz"
        column_labels["grf_right_n"] = "platform 2 Fz"
        metadata["side_assignment"] = (
            "grf_left_n is platform 1 and grf_right_n is platform 2 in file order; the file "
            "does not state which platform is under which foot"
        )
    metadata["columns"] = column_labels
    return RecordTable(
        arrays,
        metadata,
        warnings,
        mass_kg=read["body_mass_kg"],
        mass_source="PROCESSING:Bodymass in the C3D file",
    )

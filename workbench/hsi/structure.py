"""Modal model of a footbridge (vertical bending modes).

A structure is a set of modes, each with a frequency, a damping ratio, a modal mass and a
mode shape over the span. The modal mass is the one that goes with the mode shape as given
(for the simply supported beam, ``sin(j pi x / L)`` with unit amplitude and modal mass
``mu L / 2``). Outside the span the mode shapes are zero: a pedestrian there walks on rigid
ground.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import trapezoid

from workbench.errors import UsageError

__all__ = ["ModalStructure", "simply_supported_beam", "structure_from_json"]


@dataclass(frozen=True)
class ModalStructure:
    """Modes of a footbridge.

    Parameters
    ----------
    span_m : float
        Length walked over [m].
    frequencies_hz, damping_ratios, modal_masses_kg : array
        One value per mode.
    width_m : float
        Deck width [m], used to turn a crowd density into a flow.
    shape_x_m, shape_values : array, optional
        User-given mode shapes sampled at ``shape_x_m`` (ascending, inside ``[0, span_m]``),
        ``shape_values[i, j]`` the shape of mode ``j`` at ``shape_x_m[i]``, interpolated
        linearly. Left out, the modes are those of a simply supported beam,
        ``sin(j pi x / L)`` for mode ``j = 1, 2, ...``.
    """

    span_m: float
    frequencies_hz: NDArray[np.float64]
    damping_ratios: NDArray[np.float64]
    modal_masses_kg: NDArray[np.float64]
    width_m: float = 2.0
    shape_x_m: NDArray[np.float64] | None = None
    shape_values: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        for name in ("frequencies_hz", "damping_ratios", "modal_masses_kg"):
            object.__setattr__(self, name, np.atleast_1d(np.asarray(getattr(self, name), float)))
        n = self.frequencies_hz.size
        if not (np.isfinite(self.span_m) and self.span_m > 0):
            raise UsageError(f"the span must be a positive length in m, got {self.span_m}")
        if not (np.isfinite(self.width_m) and self.width_m > 0):
            raise UsageError(f"the deck width must be a positive length in m, got {self.width_m}")
        if n == 0 or self.damping_ratios.size != n or self.modal_masses_kg.size != n:
            raise UsageError(
                "give one frequency, one damping ratio and one modal mass per mode "
                f"(got {n}, {self.damping_ratios.size} and {self.modal_masses_kg.size})"
            )
        if not (np.all(np.isfinite(self.frequencies_hz)) and np.all(self.frequencies_hz > 0)):
            raise UsageError("the modal frequencies must be positive numbers in Hz")
        if not np.all((self.damping_ratios >= 0) & (self.damping_ratios < 1)):
            raise UsageError("the modal damping ratios must be between 0 and 1, e.g. 0.005")
        if not (np.all(np.isfinite(self.modal_masses_kg)) and np.all(self.modal_masses_kg > 0)):
            raise UsageError("the modal masses must be positive numbers in kg")
        if (self.shape_x_m is None) != (self.shape_values is None):
            raise UsageError("give both the mode-shape positions and their values, or neither")
        if self.shape_x_m is not None and self.shape_values is not None:
            x = np.asarray(self.shape_x_m, float)
            v = np.asarray(self.shape_values, float).reshape(x.size, -1)
            if v.shape[1] != n or x.size < 2 or np.any(np.diff(x) <= 0):
                raise UsageError(
                    f"the mode shapes need ascending positions and one column per mode ({n})"
                )
            if x[0] < 0 or x[-1] > self.span_m or not np.all(np.isfinite(v)):
                raise UsageError("the mode-shape positions must lie within the span")
            object.__setattr__(self, "shape_x_m", x)
            object.__setattr__(self, "shape_values", v)

    @property
    def n_modes(self) -> int:
        """Number of modes."""
        return int(self.frequencies_hz.size)

    @property
    def omegas(self) -> NDArray[np.float64]:
        """Circular frequencies [rad/s]."""
        return 2.0 * np.pi * self.frequencies_hz

    @property
    def stiffnesses_n_per_m(self) -> NDArray[np.float64]:
        """Modal stiffnesses ``m w^2``."""
        return self.modal_masses_kg * self.omegas**2

    @property
    def dampings_ns_per_m(self) -> NDArray[np.float64]:
        """Modal dampings ``2 zeta m w``."""
        return 2.0 * self.damping_ratios * self.modal_masses_kg * self.omegas

    def shapes(self, x_m: ArrayLike) -> NDArray[np.float64]:
        """Mode shapes at positions ``x_m`` (any shape), stacked on a new last axis.

        Zero outside ``[0, span_m]``, so that a pedestrian off the deck is uncoupled.
        """
        x = np.asarray(x_m, dtype=float)
        on = (x >= 0.0) & (x <= self.span_m)
        if self.shape_x_m is None or self.shape_values is None:
            j = np.arange(1, self.n_modes + 1)
            out = np.sin(np.pi * x[..., None] * j / self.span_m)
        else:
            flat = x.reshape(-1)
            cols = [
                np.interp(flat, self.shape_x_m, self.shape_values[:, k], left=0.0, right=0.0)
                for k in range(self.n_modes)
            ]
            out = np.stack(cols, axis=-1).reshape((*x.shape, self.n_modes))
        return np.where(on[..., None], out, 0.0)

    def abs_shape_integrals_m(self, n_points: int = 2001) -> NDArray[np.float64]:
        """``integral |phi_j(x)| dx`` over the span (for loads applied with the shape's sign)."""
        x = np.linspace(0.0, self.span_m, n_points)
        return np.asarray(trapezoid(np.abs(self.shapes(x)), x, axis=0))

    def to_json(self) -> dict[str, object]:
        """JSON description."""
        return {
            "span_m": self.span_m,
            "width_m": self.width_m,
            "frequencies_hz": self.frequencies_hz.tolist(),
            "damping_ratios": self.damping_ratios.tolist(),
            "modal_masses_kg": self.modal_masses_kg.tolist(),
            "mode_shapes": "sampled" if self.shape_x_m is not None else "simply supported",
        }


def simply_supported_beam(
    span_m: float,
    mass_per_m_kg: float,
    frequency_hz: float,
    damping_ratio: float | Sequence[float],
    *,
    n_modes: int = 1,
    width_m: float = 2.0,
) -> ModalStructure:
    """Uniform simply supported beam: ``f_j = j^2 f_1``, modal mass ``mu L / 2``.

    Parameters
    ----------
    span_m : float
        Span [m].
    mass_per_m_kg : float
        Mass per unit length [kg/m].
    frequency_hz : float
        First bending frequency [Hz].
    damping_ratio : float or sequence of float
        Damping ratio of every mode, or one per mode.
    n_modes : int
        Number of modes kept.
    width_m : float
        Deck width [m].

    Returns
    -------
    ModalStructure
        The modal model.
    """
    if n_modes < 1:
        raise UsageError(f"keep at least one mode, got {n_modes}")
    if not (np.isfinite(mass_per_m_kg) and mass_per_m_kg > 0):
        raise UsageError(f"the mass per length must be positive in kg/m, got {mass_per_m_kg}")
    j = np.arange(1, n_modes + 1)
    zeta = np.broadcast_to(np.asarray(damping_ratio, float), (n_modes,)).copy()
    return ModalStructure(
        span_m=float(span_m),
        frequencies_hz=np.asarray(frequency_hz * j**2, dtype=np.float64),
        damping_ratios=zeta,
        modal_masses_kg=np.full(n_modes, mass_per_m_kg * span_m / 2.0),
        width_m=float(width_m),
    )


def structure_from_json(obj: object, source: str = "the structure file") -> ModalStructure:
    """Build a structure from a JSON object (as :meth:`ModalStructure.to_json` describes).

    Keys: ``span_m``, ``frequencies_hz``, ``damping_ratios``, ``modal_masses_kg`` (one per
    mode), optional ``width_m`` and ``mode_shapes`` (``{"x_m": [...], "values": [[mode 1,
    mode 2, ...] per position]}``; left out, simply supported beam shapes).
    """
    from workbench.errors import InputError

    if not isinstance(obj, dict):
        raise InputError(source, "whole file", "is not a JSON object", "give an object")
    try:
        shapes = obj.get("mode_shapes")
        x = v = None
        if isinstance(shapes, dict):
            x = np.asarray(shapes["x_m"], float)
            v = np.asarray(shapes["values"], float)
        elif shapes is not None:
            raise InputError(
                source,
                "key 'mode_shapes'",
                "is not an object with 'x_m' and 'values'",
                "give the sampled mode shapes or leave the key out",
            )
        return ModalStructure(
            span_m=float(obj["span_m"]),
            frequencies_hz=np.asarray(obj["frequencies_hz"], float),
            damping_ratios=np.asarray(obj["damping_ratios"], float),
            modal_masses_kg=np.asarray(obj["modal_masses_kg"], float),
            width_m=float(obj.get("width_m", 2.0)),
            shape_x_m=x,
            shape_values=v,
        )
    except KeyError as err:
        raise InputError(
            source,
            f"key {err}",
            "is missing",
            "give span_m, frequencies_hz, damping_ratios and modal_masses_kg",
        ) from None
    except (TypeError, ValueError) as err:
        raise InputError(
            source, "whole file", f"has a value that is not a number ({err})", "fix it"
        ) from None
    except UsageError as err:
        raise InputError(source, "whole file", str(err).rstrip("."), "fix the file") from None

"""Conversions between physical and modal SMD parameters and biomechanical load factors.

All functions accept scalars or arrays (broadcast together, as numpy does) and return a
``float`` for scalar input and an ``ndarray`` otherwise. The formulas are docs/science.md 1:

* ``f_n = sqrt(K / M) / (2 pi)``
* ``zeta = C / (2 sqrt(K M))``
* ``BLF_i = sqrt(a_i^2 + b_i^2) / (M g)``

Examples
--------
The seed study's numerical example (75 kg, 2.5 Hz, damping ratio 0.4):

>>> k = stiffness_n_per_m(2.5, 75.0)
>>> round(k), round(damping_ns_per_m(0.4, k, 75.0))
(18506, 942)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.records.record import G_M_S2

__all__ = [
    "blf",
    "damping_ns_per_m",
    "damping_ratio",
    "natural_frequency_hz",
    "stiffness_n_per_m",
]

FloatOrArray = float | NDArray[np.float64]


def _as_float_array(value: ArrayLike, argument: str, function: str) -> NDArray[np.float64]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise UsageError(
            f"{function}: argument '{argument}' is not a number or an array of numbers "
            f"(got {value!r}); pass a value in the unit its name states"
        ) from None
    if not np.all(np.isfinite(arr)):
        raise UsageError(
            f"{function}: argument '{argument}' contains a NaN or infinite value; "
            "pass finite numbers only"
        )
    return arr


def _require(condition: NDArray[np.bool_] | np.bool_, function: str, message: str) -> None:
    if not np.all(condition):
        raise UsageError(f"{function}: {message}")


def _out(arr: NDArray[np.float64]) -> FloatOrArray:
    # Scalars come back as plain floats so that they print and serialise to JSON cleanly.
    return float(arr) if arr.ndim == 0 else arr


def natural_frequency_hz(stiffness_n_per_m: ArrayLike, mass_kg: ArrayLike) -> FloatOrArray:
    """Undamped natural frequency ``sqrt(K / M) / (2 pi)``.

    Parameters
    ----------
    stiffness_n_per_m : float or array_like
        Stiffness K [N/m], not negative.
    mass_kg : float or array_like
        Mass M [kg], positive.

    Returns
    -------
    float or ndarray
        Natural frequency f_n [Hz].
    """
    k = _as_float_array(stiffness_n_per_m, "stiffness_n_per_m", "natural_frequency_hz")
    m = _as_float_array(mass_kg, "mass_kg", "natural_frequency_hz")
    _require(m > 0, "natural_frequency_hz", "mass_kg must be positive; pass the body mass in kg")
    _require(
        k >= 0,
        "natural_frequency_hz",
        "stiffness_n_per_m must not be negative; pass the stiffness in N/m",
    )
    return _out(np.sqrt(k / m) / (2.0 * np.pi))


def damping_ratio(
    damping_ns_per_m: ArrayLike, stiffness_n_per_m: ArrayLike, mass_kg: ArrayLike
) -> FloatOrArray:
    """Damping ratio ``C / (2 sqrt(K M))``.

    Parameters
    ----------
    damping_ns_per_m : float or array_like
        Viscous damping C [N s/m].
    stiffness_n_per_m : float or array_like
        Stiffness K [N/m], positive.
    mass_kg : float or array_like
        Mass M [kg], positive.

    Returns
    -------
    float or ndarray
        Damping ratio zeta (dimensionless, 1 = critical).
    """
    c = _as_float_array(damping_ns_per_m, "damping_ns_per_m", "damping_ratio")
    k = _as_float_array(stiffness_n_per_m, "stiffness_n_per_m", "damping_ratio")
    m = _as_float_array(mass_kg, "mass_kg", "damping_ratio")
    _require(m > 0, "damping_ratio", "mass_kg must be positive; pass the body mass in kg")
    _require(
        k > 0,
        "damping_ratio",
        "stiffness_n_per_m must be positive for a damping ratio to exist; pass K in N/m",
    )
    return _out(c / (2.0 * np.sqrt(k * m)))


def stiffness_n_per_m(natural_frequency_hz: ArrayLike, mass_kg: ArrayLike) -> FloatOrArray:
    """Stiffness from natural frequency and mass, ``K = M (2 pi f_n)^2``.

    Parameters
    ----------
    natural_frequency_hz : float or array_like
        Undamped natural frequency f_n [Hz], not negative.
    mass_kg : float or array_like
        Mass M [kg], positive.

    Returns
    -------
    float or ndarray
        Stiffness K [N/m].
    """
    f = _as_float_array(natural_frequency_hz, "natural_frequency_hz", "stiffness_n_per_m")
    m = _as_float_array(mass_kg, "mass_kg", "stiffness_n_per_m")
    _require(m > 0, "stiffness_n_per_m", "mass_kg must be positive; pass the body mass in kg")
    _require(
        f >= 0,
        "stiffness_n_per_m",
        "natural_frequency_hz must not be negative; pass the frequency in Hz",
    )
    return _out(m * (2.0 * np.pi * f) ** 2)


def damping_ns_per_m(
    damping_ratio: ArrayLike, stiffness_n_per_m: ArrayLike, mass_kg: ArrayLike
) -> FloatOrArray:
    """Viscous damping from damping ratio, ``C = 2 zeta sqrt(K M)``.

    Parameters
    ----------
    damping_ratio : float or array_like
        Damping ratio zeta (dimensionless).
    stiffness_n_per_m : float or array_like
        Stiffness K [N/m], not negative.
    mass_kg : float or array_like
        Mass M [kg], positive.

    Returns
    -------
    float or ndarray
        Damping C [N s/m].
    """
    z = _as_float_array(damping_ratio, "damping_ratio", "damping_ns_per_m")
    k = _as_float_array(stiffness_n_per_m, "stiffness_n_per_m", "damping_ns_per_m")
    m = _as_float_array(mass_kg, "mass_kg", "damping_ns_per_m")
    _require(m > 0, "damping_ns_per_m", "mass_kg must be positive; pass the body mass in kg")
    _require(
        k >= 0,
        "damping_ns_per_m",
        "stiffness_n_per_m must not be negative; pass the stiffness in N/m",
    )
    return _out(2.0 * z * np.sqrt(k * m))


def blf(a: ArrayLike, b: ArrayLike, mass_kg: ArrayLike) -> FloatOrArray:
    """Biomechanical load factor ``sqrt(a^2 + b^2) / (M g)`` of one or more harmonics.

    Parameters
    ----------
    a, b : float or array_like
        Cosine and sine Fourier coefficients of the biomechanical force [N].
    mass_kg : float or array_like
        Body mass M [kg], positive.

    Returns
    -------
    float or ndarray
        Load factor(s), dimensionless, with g = 9.81 m/s^2.
    """
    a_arr = _as_float_array(a, "a", "blf")
    b_arr = _as_float_array(b, "b", "blf")
    m = _as_float_array(mass_kg, "mass_kg", "blf")
    _require(m > 0, "blf", "mass_kg must be positive; pass the body mass in kg")
    return _out(np.hypot(a_arr, b_arr) / (m * G_M_S2))

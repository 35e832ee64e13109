"""Argument checks shared by the simulators: positive numbers, the seed and the time grid.

Each check raises :class:`~workbench.errors.UsageError` naming the function and the argument
and saying what to pass instead. The seed check also turns ``None`` into fresh entropy that
is returned, so a record simulated without a seed can be reproduced from its truth.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError

FloatArray = NDArray[np.float64]


def _positive(value: Any, name: str, where: str, *, allow_zero: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        x = float("nan")
    if not np.isfinite(x) or x < 0 or (x == 0 and not allow_zero):
        bound = "zero or positive" if allow_zero else "positive"
        raise UsageError(
            f"{where}: argument '{name}' must be a finite {bound} number, got {value!r}; "
            "pass a value in the unit its name states"
        )
    return x


def _rng(
    seed: int | np.random.Generator | None,
) -> tuple[np.random.Generator, int | None]:
    if isinstance(seed, np.random.Generator):
        return seed, None
    if seed is None:
        # Fresh entropy, but recorded so the record can be reproduced from its truth.
        seed = int(np.random.SeedSequence().entropy)  # type: ignore[arg-type]
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise UsageError(
            f"simulate: argument 'seed' must be a non-negative integer, a "
            f"numpy.random.Generator or None, got {seed!r}; pass for example seed=1"
        )
    return np.random.default_rng(int(seed)), int(seed)


def _time_grid(time_s: ArrayLike, where: str) -> FloatArray:
    t = np.asarray(time_s, dtype=np.float64)
    if t.ndim != 1 or t.size < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise UsageError(
            f"{where}: 'time_s' must be at least two finite, strictly increasing times [s]; "
            "pass for example numpy.arange(0, 20, 0.005)"
        )
    return t

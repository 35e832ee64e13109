"""Words for sentences to users: parameters by name, counts with their noun, p-values.

Sentences a user reads name the model's quantities in the field's words ("stiffness K"), not
by the keys of the JSON and the code (``stiffness_n_per_m``); verbs and nouns agree with the
count; and a p-value below what a double can hold is printed as a bound, not as 0.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = [
    "count",
    "join_words",
    "p_value",
    "parameter_words",
    "parameters_in_words",
    "signed",
    "verb",
]

#: The field's words for each parameter key of the results.
PARAMETER_WORDS = {
    "damping_ns_per_m": "damping C",
    "stiffness_n_per_m": "stiffness K",
    "natural_frequency_hz": "natural frequency f_n",
    "damping_ratio": "damping ratio",
}

#: Smallest positive p-value printed as a number; below it the value is a rounding of 0.
SMALLEST_P = 1e-300


def parameter_words(key: str) -> str:
    """Return the field's words for a result key (``stiffness_n_per_m`` -> ``stiffness K``)."""
    return PARAMETER_WORDS.get(key, key.replace("_", " "))


def join_words(items: Sequence[str]) -> str:
    """Join words as ``a``, ``a and b``, ``a, b and c``."""
    items = list(items)
    if len(items) <= 1:
        return "".join(items)
    return ", ".join(items[:-1]) + " and " + items[-1]


def parameters_in_words(keys: Sequence[str]) -> str:
    """Name result keys in the field's words, joined: ``damping C and stiffness K``."""
    return join_words([parameter_words(k) for k in keys])


def verb(n: int, singular: str, plural: str) -> str:
    """Return the verb agreeing with ``n`` subjects (``verb(1, "sits", "sit")``: ``sits``)."""
    return singular if n == 1 else plural


def count(n: int, noun: str, plural: str | None = None) -> str:
    """Write a count with its noun: ``1 piece``, ``2 pieces`` (``plural`` if irregular)."""
    return f"{n} {noun if n == 1 else (plural or noun + 's')}"


def p_value(p: float, digits: int = 3) -> str:
    """Write a p-value in ``digits`` figures; ``< 1e-300`` when it underflowed to 0.

    A test statistic so large that the p-value rounds to 0 does not mean the p-value is 0;
    printing "0" would claim certainty the arithmetic does not have.
    """
    if not math.isfinite(p):
        return "not computed"
    if p < SMALLEST_P:
        return f"< {SMALLEST_P:.0e}"
    return f"{p:.{digits}g}"


def signed(x: float, decimals: int = 3) -> str:
    """Write ``x`` with its sign in ``decimals`` decimals; a value that rounds to zero is ``+0``.

    A score of -4e-7 is written ``+0.000``, not ``-0.000``: the sign of a value below the
    printed precision follows the last bits of the arithmetic, which differ between machines.
    """
    return f"{round(float(x), decimals) + 0.0:+.{decimals}f}"

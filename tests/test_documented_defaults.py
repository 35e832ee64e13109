"""The defaults the documentation states are the library's own constants.

The command line's help reads them (``workbench.cli.settings_flags``); the pages cannot, so
this test reads the pages: a default changed in the code and not on the page fails here.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from workbench.cli.settings_flags import modal_box_words, particles_help, seed_box_words
from workbench.inference.core import SEED_OBS_FRACTION, SEED_STATE_FRACTION
from workbench.inference.methods import DEFAULT_METHOD, PF, RBPF, method_class, method_names
from workbench.models.force import DEFAULT_FORCE_HARMONICS, HARMONICS_RANGE

DOCS = Path(__file__).resolve().parents[1] / "docs"


def _flat(page: str) -> str:
    """The page's text with its line breaks as spaces (sentences wrap anywhere)."""
    return " ".join((DOCS / page).read_text(encoding="utf-8").split())


def test_the_identify_guide_states_the_library_defaults() -> None:
    text = _flat("guide/identify.md")
    low, high = HARMONICS_RANGE
    expected = [
        f"| `--harmonics N` | {DEFAULT_FORCE_HARMONICS} | Fourier harmonics of the force, "
        f"from {low} to {high} |",
        f"`seed` is {SEED_OBS_FRACTION:.2f} |",
        f"| {SEED_STATE_FRACTION:g} for `pf`, 0 otherwise |",
        f"(C, K) box from {modal_box_words()} at the body mass, or the seed's {seed_box_words()} |",
        f"{RBPF.n_particles} particles; per-step traces",
        f"{PF.n_particles} particles |",
        f"| `{DEFAULT_METHOD}` (default) |",
    ]
    missing = [e for e in expected if e not in text]
    assert not missing, f"docs/guide/identify.md does not say: {missing}"
    # "0.005 for pf, 0 otherwise": the methods' own defaults of the process noise.
    fractions = {n: method_class(n).default_state_noise_fraction for n in method_names()}
    assert fractions == {"rbpf": 0.0, "pf": SEED_STATE_FRACTION, "exact": 0.0}


def test_the_contracts_state_the_library_defaults() -> None:
    text = _flat("contracts.md")
    low, high = HARMONICS_RANGE
    counts = particles_help().removeprefix("particles ")
    expected = [
        f"`--method {'|'.join(method_names())}` (default `{DEFAULT_METHOD}`;",
        f"`--particles N` {counts}",
        f"`--harmonics N` (default {DEFAULT_FORCE_HARMONICS}, from {low} to {high})",
        f"`seed` is {SEED_OBS_FRACTION:.2f};",
    ]
    missing = [e for e in expected if e not in text]
    assert not missing, f"docs/contracts.md does not say: {missing}"


@pytest.mark.parametrize("page", ["guide/identify.md", "contracts.md", "design.md"])
def test_the_pages_link_the_method_guide(page: str) -> None:
    assert "adding-a-method.md" in _flat(page)

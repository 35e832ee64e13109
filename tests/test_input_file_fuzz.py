"""Edited laws and structure files: a usable object, or one sentence naming the file.

The command line turns a WorkbenchError into one sentence and exit 2; any other exception
is an internal error (exit 3). So every edit of a valid file must either load and be used
(pedestrians sampled, a structure's modal matrices built) or raise a WorkbenchError whose
message is one line naming the file.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from workbench.errors import WorkbenchError
from workbench.hsi.structure import simply_supported_beam, structure_from_json
from workbench.population.laws import PopulationLaws, read_laws
from workbench.population.sampler import sample_pedestrians

# Values an edit can put anywhere: wrong types, non-finite and absurd numbers, containers.
_ODD_VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**12), 10**12),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -1.0, 1e-300, 1e300, math.nan, math.inf]),
    st.text(max_size=8),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)


def _paths(obj: object, prefix: tuple = ()) -> list[tuple]:
    """Every key path (dict keys and list indices) inside a JSON object."""
    out = [prefix] if prefix else []
    if isinstance(obj, dict):
        for key, value in obj.items():
            out += _paths(value, (*prefix, key))
    elif isinstance(obj, list):
        for i, value in enumerate(obj):
            out += _paths(value, (*prefix, i))
    return out


def _edited(obj: object, path: tuple, value: object, delete: bool) -> object:
    """A deep copy of ``obj`` with the entry at ``path`` replaced or deleted."""
    copy = json.loads(json.dumps(obj))
    parent = copy
    for key in path[:-1]:
        parent = parent[key]
    if delete and isinstance(parent, dict):
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    return copy


def _one_sentence(err: WorkbenchError, name: str) -> None:
    text = str(err)
    assert "\n" not in text.strip(), text
    assert name in text, text


EDITS = st.tuples(st.integers(0, 10**6), _ODD_VALUES, st.booleans())
FUZZ = settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


@FUZZ
@given(edits=st.lists(EDITS, min_size=1, max_size=3))
def test_edited_laws_sample_or_give_one_sentence(edits, tmp_path_factory):
    laws = PopulationLaws().to_json()
    for index, value, delete in edits:
        paths = _paths(laws)
        laws = _edited(laws, paths[index % len(paths)], value, delete)
    path = Path(tmp_path_factory.mktemp("laws")) / "population.json"
    # json.dumps writes NaN and Infinity, as a hand edit or another tool might.
    path.write_text(json.dumps(laws))
    try:
        table = sample_pedestrians(20, seed=0, laws=read_laws(path))
    except WorkbenchError as err:
        _one_sentence(err, "population.json")
        return
    numbers = table.select_dtypes("number").to_numpy()
    assert np.all(np.isfinite(numbers)), table


@FUZZ
@given(edits=st.lists(EDITS, min_size=1, max_size=3))
def test_edited_structures_build_or_give_one_sentence(edits):
    structure = simply_supported_beam(50.0, 500.0, 2.0, 0.005).to_json()
    for index, value, delete in edits:
        paths = _paths(structure)
        structure = _edited(structure, paths[index % len(paths)], value, delete)
    try:
        built = structure_from_json(structure, "bridge.json")
    except WorkbenchError as err:
        _one_sentence(err, "bridge.json")
        return
    assert np.all(np.isfinite(built.frequencies_hz)) and np.all(built.frequencies_hz > 0)
    assert np.all(np.isfinite(built.modal_masses_kg)) and np.all(built.modal_masses_kg > 0)

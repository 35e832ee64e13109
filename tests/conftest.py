"""Fixtures shared by several test modules."""

from __future__ import annotations

import pytest

from tests.walks import walking_problem
from workbench.inference.core.problem import IdentificationProblem


@pytest.fixture(scope="session")
def walking_steps_problem() -> tuple[IdentificationProblem, float, float]:
    """A realistic 10 s, 100 Hz walking record in footfall pieces, n = 4, and its (C, K)."""
    problem, sim = walking_problem(seed=11, duration_s=10.0, harmonics=4)
    return problem, sim.truth["damping_ns_per_m"], sim.truth["stiffness_n_per_m"]


#: The test files that take longest (``pytest --durations`` in CI: the deck cross-check alone
#: runs for minutes), collected first. Tests are spread over the workers a whole file at a
#: time (``--dist loadfile``), in collection order with ``--no-loadscope-reorder`` (by
#: default xdist orders files by their number of tests, which put the one-test deck
#: cross-check last and left one worker running it alone for minutes): longest first keeps
#: both workers busy to the end.
LONGEST_FILES = (
    "test_deck_crosscheck.py",
    "test_pipeline.py",
    "test_surface.py",
    "test_criticism.py",
    "test_architecture.py",
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Move the longest test files to the front (a stable sort keeps every other order)."""
    rank = {name: i for i, name in enumerate(LONGEST_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))

"""The method registry: a method registered once is known to the settings, every command and
the studies; unregistered, it is gone again."""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Iterator
from typing import Any, ClassVar

import pytest

import workbench as wb
from workbench.cli.main import build_parser
from workbench.errors import UsageError
from workbench.inference.core import IdentificationProblem, IdentificationResult
from workbench.inference.methods import (
    DEFAULT_METHOD,
    Exact,
    Method,
    as_method,
    method_class,
    method_names,
    particle_filter_names,
    register_method,
    unregister_method,
)
from workbench.inference.pipeline.settings import IdentifySettings
from workbench.reporting.studies import OTHER_COLOUR, method_colour
from workbench.sensitivity.design import default_levels
from workbench.synth.simulate import simulate_walking

#: The commands whose --method takes every registered method.
COMMANDS = ("identify", "batch", "recovery", "sensitivity")


@dataclasses.dataclass(frozen=True)
class RenamedExact(Exact):
    """The exact posterior under another name, with fewer draws by default."""

    name: ClassVar[str] = "renamed_exact"
    colour: ClassVar[str | None] = None
    n_draws: int = 500

    def run(
        self,
        problem: IdentificationProblem,
        *,
        seed: int = 0,
        progress: bool = False,
        common: dict[str, Any] | None = None,
    ) -> IdentificationResult:
        result = super().run(problem, seed=seed, progress=progress, common=common)
        return result.replace(method=self.name)


@pytest.fixture
def toy() -> Iterator[type[RenamedExact]]:
    """Register the toy method for one test, and take it out again afterwards."""
    register_method(RenamedExact)
    try:
        yield RenamedExact
    finally:
        unregister_method(RenamedExact.name)


def _method_choices(command: str) -> tuple[str, ...] | None:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    flag = next(a for a in sub.choices[command]._actions if a.dest == "method")
    return None if flag.choices is None else tuple(flag.choices)


def test_the_built_in_methods_are_registered_in_their_order() -> None:
    assert method_names() == ("rbpf", "pf", "exact")
    assert particle_filter_names() == ("rbpf", "pf")
    assert method_class(DEFAULT_METHOD) is Exact and type(as_method(None)) is Exact
    assert [method_colour(n) for n in ("pf", "rbpf", "exact")] == ["C0", "C1", "C2"]
    for command in COMMANDS:
        assert _method_choices(command) == method_names(), command
    assert _method_choices("crosscheck") == particle_filter_names()


def test_a_registered_method_appears_everywhere(toy: type[RenamedExact]) -> None:
    assert method_names() == ("rbpf", "pf", "exact", "renamed_exact")
    assert method_class("renamed_exact") is toy
    assert as_method("renamed_exact") == toy()
    # The command line reads the registry when its parser is built.
    for command in COMMANDS:
        assert "renamed_exact" in (_method_choices(command) or ()), command
    # Not a particle filter: crosscheck does not offer it.
    assert "renamed_exact" not in (_method_choices("crosscheck") or ())
    # The settings accept it, with its own defaults, and report its name.
    settings = IdentifySettings.from_flat(method="renamed_exact")
    assert settings.method == toy(n_draws=500)
    assert settings.n_particles == 0 and settings.to_json()["method"] == "renamed_exact"
    assert IdentifySettings().replace(method="renamed_exact").method == toy()
    # The sensitivity design varies over it, and the figures give it a free colour.
    levels = [lv.value for lv in default_levels("method", IdentifySettings())]
    assert levels == ["exact", "rbpf", "pf", "renamed_exact"]
    colour = method_colour("renamed_exact")
    assert colour not in {"C0", "C1", "C2", OTHER_COLOUR}


def test_identify_runs_a_registered_method(toy: type[RenamedExact]) -> None:
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=6.0,
        sample_rate_hz=100,
        noise_sd_n=3.0,
        start="rest",
        seed=5,
    )
    settings = IdentifySettings.from_flat(method="renamed_exact", harmonics=2, force_check=False)
    result = wb.identify(sim.record, settings=settings)
    assert result.method == "renamed_exact"
    assert result.draws.shape == (500, 2)  # the toy's default n_draws, not Exact's 4000
    assert result.settings["method"] == "renamed_exact"
    reference = wb.identify(sim.record, settings=settings.replace(method=Exact(n_draws=500)))
    assert result.estimates == pytest.approx(reference.estimates, rel=1e-12)


def test_unregistering_removes_it(toy: type[RenamedExact]) -> None:
    unregister_method(toy.name)
    try:
        assert "renamed_exact" not in method_names()
        with pytest.raises(UsageError, match="choose one of rbpf, pf, exact"):
            IdentifySettings.from_flat(method="renamed_exact")
        with pytest.raises(UsageError, match="choose one of rbpf, pf, exact"):
            as_method("renamed_exact")
        assert "renamed_exact" not in (_method_choices("identify") or ())
    finally:
        register_method(toy)  # the fixture unregisters it


class _NoName(Exact):
    name: ClassVar[str] = "Not Snake"


@dataclasses.dataclass(frozen=True)
class _NoRun(Method):
    name: ClassVar[str] = "no_run"


@dataclasses.dataclass(frozen=True)
class _NoDefault(Method):
    name: ClassVar[str] = "no_default"
    width: float

    def run(self, problem: IdentificationProblem, **kwargs: Any) -> IdentificationResult:
        raise NotImplementedError


class _NotADataclass(Exact):
    name: ClassVar[str] = "not_a_dataclass"


@dataclasses.dataclass(frozen=True)
class _TakenName(Exact):
    name: ClassVar[str] = "rbpf"


@pytest.mark.parametrize(
    ("cls", "words"),
    [
        (int, "not a subclass of Method"),
        (_NoName, "snake_case"),
        (_NoRun, "implement run"),
        (_NoDefault, "give one to width"),
        (_NotADataclass, "@dataclass"),
        (_TakenName, "'rbpf' is already registered"),
    ],
)
def test_a_method_class_that_cannot_work_is_refused(cls: Any, words: str) -> None:
    with pytest.raises(UsageError, match=words):
        register_method(cls)
    assert method_names() == ("rbpf", "pf", "exact")


def test_re_registering_the_same_class_keeps_its_place() -> None:
    register_method(method_class("rbpf"))
    assert method_names() == ("rbpf", "pf", "exact")


@dataclasses.dataclass(frozen=True)
class CautiousFilter(wb.RBPF):
    """An rbpf with other resampling defaults: the settings must keep them."""

    name: ClassVar[str] = "cautious_filter"
    resampling: str = "multinomial"
    ess_threshold: float = 0.8


@pytest.fixture
def cautious() -> Iterator[type[CautiousFilter]]:
    register_method(CautiousFilter)
    try:
        yield CautiousFilter
    finally:
        unregister_method(CautiousFilter.name)


def test_the_settings_keep_a_registered_methods_own_option_defaults(
    cautious: type[CautiousFilter],
) -> None:
    own = (cautious.resampling, cautious.ess_threshold)
    named = IdentifySettings.from_flat(method="cautious_filter").method
    assert (named.resampling, named.ess_threshold) == own  # type: ignore[attr-defined]
    switched = IdentifySettings().replace(method="cautious_filter").method
    assert (switched.resampling, switched.ess_threshold) == own  # type: ignore[attr-defined]
    # An option the caller sets wins over the class's default.
    set_ = IdentifySettings.from_flat(method="cautious_filter", resampling="systematic").method
    assert set_.resampling == "systematic"  # type: ignore[attr-defined]
    # Switching away from it: the new method takes its own defaults for options the old one
    # held at its class's defaults, and keeps those the caller moved.
    back = IdentifySettings.from_flat(method="cautious_filter").replace(method="rbpf").method
    assert (back.resampling, back.ess_threshold) == ("systematic", 0.5)  # type: ignore[attr-defined]
    moved = IdentifySettings.from_flat(method="rbpf", resampling="stratified").replace(method="pf")
    assert moved.method.resampling == "stratified"  # type: ignore[attr-defined]


def test_crosscheck_refuses_a_grid_result_naming_the_registered_filters(
    cautious: type[CautiousFilter],
) -> None:
    from workbench.inference.crosscheck import crosscheck

    rec = wb.datasets.load("seed_individual").slice(0, 6)
    exact = wb.identify(rec, wb.SMDModel(harmonics=3), method="exact", force_check=False)
    with pytest.raises(UsageError, match="cross-check rbpf or pf or cautious_filter"):
        crosscheck(exact.problem, exact, seed=0)

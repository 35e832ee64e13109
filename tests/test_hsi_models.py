"""HSI pedestrians are SMD models: a table row, its model and the integrator agree."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from workbench import hsi
from workbench.errors import UsageError
from workbench.hsi.modes import coupled_modes
from workbench.hsi.pedestrians import (
    G,
    PedestrianArrays,
    Walker,
    as_walkers,
    design_pedestrian,
    pedestrian_models,
    walkers,
)
from workbench.hsi.simulate import CrowdBatch, simulate_pedestrians
from workbench.hsi.structure import ModalStructure, simply_supported_beam
from workbench.models import CubicStiffness, FourierForce, SMDModel

BLF = (0.4305, 0.1, 0.05)
PHASE = (0.3, 1.0, 2.0)


@pytest.fixture(scope="module")
def beam() -> ModalStructure:
    """docs/science.md 7: 50 m, 500 kg/m, 2 Hz, 0.5 %."""
    return simply_supported_beam(50.0, 500.0, 2.0, 0.005)


@pytest.fixture(scope="module")
def row() -> pd.DataFrame:
    return design_pedestrian(blf=BLF, phase_rad=PHASE)


def _by_hand(row: pd.DataFrame) -> SMDModel:
    """The row's pedestrian written as a model: table phase = minus the model's phase."""
    r = row.iloc[0]
    m = float(r["mass_kg"])
    return SMDModel(
        mass_kg=m,
        stiffness_n_per_m=float(r["stiffness_n_per_m"]),
        damping_ns_per_m=float(r["damping_ns_per_m"]),
        harmonics=3,
        pacing_hz=2.0,
        force_coefficients_n=tuple(FourierForce(3).from_blf(BLF, -np.array(PHASE), m)),
    )


def test_table_row_becomes_the_equivalent_model(row: pd.DataFrame) -> None:
    (model,) = pedestrian_models(row)
    hand = _by_hand(row)
    for name in ("mass_kg", "stiffness_n_per_m", "damping_ns_per_m", "pacing_hz", "harmonics"):
        assert getattr(model, name) == getattr(hand, name)
    np.testing.assert_allclose(model.force_coefficients_n, hand.force_coefficients_n, atol=1e-12)
    assert model.force_coefficients_n[0] == 0.0  # the weight is not part of the force
    np.testing.assert_allclose(model.blf, BLF, rtol=1e-14)
    # The table's force, written out: sum_i blf_i M g cos(2 pi i f_p t + phase_i).
    t = np.linspace(0.0, 3.0, 301)
    m = float(row["mass_kg"].iloc[0])
    written = sum(
        b * m * G * np.cos(2 * np.pi * i * 2.0 * t + p)
        for i, (b, p) in enumerate(zip(BLF, PHASE, strict=True), start=1)
    )
    np.testing.assert_allclose(model.biomechanical_force_n(t), written, rtol=0, atol=1e-10)
    (walker,) = walkers(row)
    assert walker.model == model and walker.speed_m_s == 1.25


@pytest.mark.parametrize("model_name", ["interaction", "moving_force", "biomechanical_force"])
def test_row_and_hand_built_model_give_the_same_response(
    beam: ModalStructure, row: pd.DataFrame, model_name: str
) -> None:
    from_table = simulate_pedestrians(beam, row, dt_s=0.01, model=model_name)
    from_model = simulate_pedestrians(
        beam, [_by_hand(row)], speed_m_s=1.25, dt_s=0.01, model=model_name
    )
    np.testing.assert_array_equal(from_table.time_s, from_model.time_s)
    peak = np.max(np.abs(from_table.acceleration_m_s2))
    np.testing.assert_allclose(
        from_model.acceleration_m_s2, from_table.acceleration_m_s2, rtol=0, atol=1e-12 * peak
    )
    # The same through the package's lazy entry point, with a Walker.
    again = hsi.simulate_pedestrians(
        beam, [Walker(_by_hand(row), 1.25)], dt_s=0.01, model=model_name
    )
    np.testing.assert_array_equal(again.acceleration_m_s2, from_model.acceleration_m_s2)


def test_integrator_applies_the_models_biomechanical_force(row: pd.DataFrame) -> None:
    other = SMDModel.from_modal(
        60.0,
        1.9,
        0.35,
        harmonics=5,
        pacing_hz=1.8,
        force_coefficients_n=(12.0, 150.0, -80.0, 20.0, 35.0, 0.0, -9.0, 4.0, 0.0, 1.0, 2.0),
    )
    models = [_by_hand(row), other]
    batch = CrowdBatch.from_scenarios([(models, np.zeros(2), np.full(2, 1.3))])
    assert batch.blf.shape == (1, 2, 5)  # padded to the largest number of harmonics
    for t in (0.0, 0.123, 7.77, 41.3):
        applied = batch.force(t)[0]
        expected = [float(m.biomechanical_force_n(t)) for m in models]
        np.testing.assert_allclose(applied, expected, rtol=1e-12, atol=1e-9)


def test_constant_force_only_moves_the_equilibrium(beam: ModalStructure, row: pd.DataFrame) -> None:
    """a0 shifts the walker's static position by a0 / K: no deck load with interaction."""
    hand = _by_hand(row)
    coef = np.array(hand.force_coefficients_n)
    coef[0] = 250.0
    shifted = hand.replace(force_coefficients_n=tuple(coef))
    for m in ("interaction", "moving_force"):
        a = simulate_pedestrians(beam, [hand], speed_m_s=1.25, dt_s=0.01, model=m)
        b = simulate_pedestrians(beam, [shifted], speed_m_s=1.25, dt_s=0.01, model=m)
        peak = np.max(np.abs(a.acceleration_m_s2))
        np.testing.assert_allclose(b.acceleration_m_s2, a.acceleration_m_s2, atol=1e-9 * peak)


def test_coupled_modes_of_a_model_equal_those_of_its_row(
    beam: ModalStructure, row: pd.DataFrame
) -> None:
    from_row = coupled_modes(beam, row, [25.0])
    from_model = coupled_modes(beam, [_by_hand(row)], [25.0])
    assert from_model == from_row
    # Standing pedestrians need no speed.
    still = simulate_pedestrians(beam, _by_hand(row), positions_m=[25.0], duration_s=2.0)
    assert still.acceleration_m_s2.shape == (1, 1, 401)


def test_arrays_are_built_from_models(row: pd.DataFrame) -> None:
    crowd = pd.concat([row, design_pedestrian(mass_kg=60.0, pacing_hz=1.8)], ignore_index=True)
    direct = PedestrianArrays.from_frame(crowd)
    via = PedestrianArrays.from_models(pedestrian_models(crowd), crowd["speed_m_s"].to_numpy())
    for name in ("mass_kg", "stiffness_n_per_m", "pacing_hz", "speed_m_s", "blf", "phase_rad"):
        np.testing.assert_array_equal(getattr(via, name), getattr(direct, name))
    np.testing.assert_allclose(direct.blf[0], BLF, rtol=1e-14)
    np.testing.assert_allclose(direct.phase_rad[0], PHASE, rtol=1e-14)


def test_models_that_cannot_walk_are_refused(row: pd.DataFrame) -> None:
    hand = _by_hand(row)
    with pytest.raises(UsageError, match="no walking speed"):
        as_walkers([hand])
    with pytest.raises(UsageError, match="no known force"):
        Walker(hand.replace(force_coefficients_n=None), 1.25)
    with pytest.raises(UsageError, match="has effects"):
        Walker(hand + CubicStiffness(), 1.25)
    with pytest.raises(UsageError, match="no stiffness_n_per_m"):
        Walker(SMDModel(mass_kg=70.0), 1.25)
    with pytest.raises(UsageError, match="speed_m_s"):
        Walker(hand, -1.0)
    with pytest.raises(UsageError, match="speed 0"):
        simulate_pedestrians(simply_supported_beam(50.0, 500.0, 2.0, 0.005), [hand], speed_m_s=0)

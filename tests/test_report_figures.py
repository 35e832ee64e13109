"""The report's figures are readable: data inside the axes, axes labelled, units named.

Each figure is built from a small input (a short simulated walk, a hand-made scoreboard or
sensitivity table, a sampled population) so the checks run in seconds; the helper in
``figure_checks`` walks the figure's axes and what they draw.
"""

from __future__ import annotations

import types

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from tests.figure_checks import figure_problems, visible_axes
from tests.walks import simulated_walk
from workbench.diagnostics.criticism import diagnose, prepare
from workbench.diagnostics.criticism_results import ScoreRow
from workbench.population.fit import fit_population
from workbench.population.sampler import sample_pedestrians
from workbench.records.inspection import inspect_record
from workbench.reporting import criticism, figures, population, sensitivity
from workbench.reporting.identification import draw_force_window
from workbench.synth.step_force import force_from_truth


@pytest.fixture(scope="module")
def walk():
    """A 12 s simulated walk (seed 4): enough steps for criticism's folds, quick to make."""
    return simulated_walk(4, 12.0)


@pytest.fixture(scope="module")
def diagnosis(walk):
    return diagnose(prepare(walk.record))


def test_the_check_finds_a_clipped_axis_and_a_missing_unit():
    """The helper itself: a figure with both faults is caught, the mended one passes."""
    fig = Figure()
    ax = fig.add_subplot()
    ax.plot([0.0, 1.0], [49.0, 50.27])
    ax.set_ylim(0, 50)
    ax.set_xlabel("time")
    ax.set_ylabel("held-out RMSE [N]")
    found = figure_problems(fig)
    assert any("y limits" in p for p in found)
    assert any("names no unit" in p for p in found)
    ax.set_ylim(48, 51)
    ax.set_xlabel("time [s]")
    assert figure_problems(fig) == []


def _scoreboard_rows() -> list[ScoreRow]:
    # The demo's shape: a 50.27 N baseline and about 2 % gained over two effects.
    return [
        ScoreRow("baseline", 50.27, 90.0, 1e-320, 0.0),
        ScoreRow("baseline + pacing_drift", 49.61, 90.6, 1e-40, 0.02, 0.013, 0.004),
        ScoreRow("baseline + pacing_drift + gait_asymmetry", 49.25, 90.9, 1e-30, 0.03, 0.007, 3e-3),
    ]


def test_scoreboard_shows_the_baseline_and_the_gain():
    rows = _scoreboard_rows()
    fig = criticism.scoreboard_figure(rows)
    assert figure_problems(fig, dimensionless={"model (effects added in turn)"}) == []
    (ax,) = visible_axes(fig)
    lo, hi = ax.get_ylim()
    # The gain must be visible: the axis spans the data, not 0 to the top, so 2 % of the
    # baseline takes a good part of its height.
    assert (rows[0].heldout_rmse_n - rows[-1].heldout_rmse_n) / (hi - lo) > 0.3
    labels = [t.get_text() for t in ax.texts]
    assert labels == ["-1.3 %", "-2.0 %"]  # 49.61 / 50.27 - 1 and 49.25 / 50.27 - 1


def test_criticism_figures_are_readable(diagnosis):
    state = criticism.error_vs_state_figure(diagnosis)
    # Panels in rows of three, not five in a strip: each at least 3 inches wide.
    shown = visible_axes(state)
    assert len(shown) == len(criticism.state_features(diagnosis.data))
    width, _ = state.get_size_inches()
    assert width / min(len(shown), 3) >= 3.0
    for fig in (
        state,
        criticism.residual_spectrum_figure(diagnosis),
        criticism.error_by_phase_figure(diagnosis),
        criticism.overlay_figure(diagnosis),
    ):
        assert figure_problems(fig) == []
    spectrum = criticism.residual_spectrum_figure(diagnosis)
    legend = [t.get_text() for t in visible_axes(spectrum)[0].get_legend().get_texts()]
    assert r"harmonics $i\,f_p$" in legend and not any("i f_p" in t for t in legend)


def test_inspection_figures_are_readable(walk):
    insp = inspect_record(walk.record)
    assert figure_problems(figures.spectrum_figure(insp)) == []
    assert figure_problems(figures.pacing_figure(insp)) == []
    assert figure_problems(figures.com_response_figure(insp)) == []
    # Its lower panel zooms into a few seconds of the record on purpose.
    assert figure_problems(figures.grf_footfalls_figure(insp), clipped_x=True) == []


def test_tornado_legend_stays_off_the_bars():
    effects = pd.DataFrame(
        {
            "record": ["r"] * 3,
            "output": ["natural_frequency_hz"] * 3,
            "point": ["harmonics=2", "pieces=whole", "highpass_hz=0.3"],
            "effect": [0.05, 0.11, -0.09],
            "mc_halfwidth_95": [0.01, 0.02, 0.015],
        }
    )
    study = types.SimpleNamespace(records=["r"], effects=effects)
    fig = sensitivity.tornado_figure(study, "natural_frequency_hz")  # type: ignore[arg-type]
    assert figure_problems(fig, dimensionless={"setting varied"}) == []
    (ax,) = visible_axes(fig)
    assert ax.get_legend() is None and fig.legends  # the figure's legend, outside the axes
    fig.canvas.draw()
    legend_box = fig.legends[0].get_window_extent()
    assert legend_box.y1 <= ax.get_window_extent().y0


@pytest.fixture(scope="module")
def population_fit():
    """Laws fitted to 60 sampled pedestrians (seed 7), all identified."""
    peds = sample_pedestrians(60, seed=7)
    table = peds.assign(path=[f"r{i:03d}.csv" for i in range(len(peds))])
    table["identified_damping"] = True
    table["identified_stiffness"] = True
    table["identifiability"] = "well identified"
    return fit_population(table)


def test_population_laws_figure_keeps_its_legend_off_the_points(population_fit):
    fig = population.laws_figure(population_fit)
    assert figure_problems(fig, dimensionless={r"damping ratio $\zeta$", "BLF1"}) == []
    assert all(ax.get_legend() is None for ax in visible_axes(fig))
    fig.canvas.draw()
    legend_top = fig.legends[0].get_window_extent().y1
    assert all(legend_top <= ax.get_window_extent().y0 for ax in visible_axes(fig))
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    # Each panel's reference law is named, BLF1's (Young's) too.
    assert "seed's law" in texts and "Young (assumed)" in texts


def test_population_blf_figure_is_readable(population_fit):
    fig = population.blf_figure(population_fit)
    assert figure_problems(fig, dimensionless={"BLF2", "BLF3", "density"}) == []


def test_population_residual_panels_say_what_they_show(population_fit):
    fig = population.residuals_figure(population_fit)
    pure = {
        r"density of damping ratio $\zeta$",
        "density of BLF1",
        "standard normal quantile",
        r"residual of damping ratio $\zeta$",
        r"ordered residual of damping ratio $\zeta$",
        "residual of BLF1",
        "ordered residual of BLF1",
    }
    assert figure_problems(fig, dimensionless=pure) == []
    titles = [ax.get_title() for ax in visible_axes(fig) if ax.get_title()]
    assert len(titles) == 3
    for title in titles:
        assert "N(" not in title and "^2" not in title
        assert "residual sd" in title
    assert "Hz" in titles[0]  # the natural frequency's sd carries its unit


def test_force_window_is_drawn_against_the_truth_when_there_is_one(walk):
    """A simulated record's truth gives the true force; without it, M u'' is the reference."""
    rec = walk.record
    insp = inspect_record(rec)
    t = insp.com.time_s
    true_force = force_from_truth(walk.truth, t)
    assert true_force is not None
    starts = np.searchsorted(t, walk.truth["step_start_s"])
    result = types.SimpleNamespace(
        problem=types.SimpleNamespace(
            time_s=t,
            piece_starts=np.append(starts[starts < t.size], t.size),
            absolute_y=np.column_stack([insp.com.disp_m, insp.com.vel_m_s, insp.com.acc_m_s2]),
        ),
        mass_kg=rec.mass_kg,
        biomechanical_force_n=lambda: true_force + 1.0,
    )
    for truth, expected in ((walk.truth, r"true $F_\mathrm{bio}$"), (None, r"$M\,u''$ (measured)")):
        fig = Figure()
        ax = fig.add_subplot()
        draw_force_window(ax, result, 4.0, truth)
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert labels == (
            [expected, r"identified $F_\mathrm{bio}$"]
            if truth is not None
            else [r"identified $F_\mathrm{bio}$", expected]
        )
        assert figure_problems(fig) == []


def test_true_force_from_the_truth_matches_the_simulated_force(walk):
    """Inside the record the spline through the kept knots is the simulator's force.

    The truth keeps no knot outside the record, so the first and last two steps may differ;
    the middle agrees to 1e-3 of the force's range (measured: 7e-5 on seed 3).
    """
    t = walk.record.time_s
    got = force_from_truth(walk.truth, t)
    assert got is not None
    mid = (t > 3.0) & (t < t[-1] - 3.0)
    scale = np.ptp(walk.force_n)
    assert np.max(np.abs(got[mid] - walk.force_n[mid])) < 1e-3 * scale
    assert force_from_truth({"time_basis": "absolute"}, t) is None
    assert force_from_truth({}, t) is None

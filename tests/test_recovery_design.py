"""The walker populations a recovery simulates: walker_plan and footbridge_plan.

No record is simulated here: these check the plans (what is drawn, and what the generating
parameters mean), in well under a second each.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from workbench.errors import UsageError
from workbench.population.recovery_design import (
    CROSSING_SD,
    DECK_RATIOS,
    footbridge_plan,
    generating_parameters,
    truth_laws,
    walker_plan,
)
from workbench.population.sampler import BLF1_BOUNDS, FN_BOUNDS_HZ, ZETA_BOUNDS


def test_footbridge_plan_names_subjects_and_ranges() -> None:
    plan, _ = footbridge_plan(seed=7, walkers=12, crossings=4)
    assert len(plan) == 48
    assert plan["record"].is_unique and plan["path"].is_unique
    assert plan["record"].iloc[0] == "p7_w000_c00"
    # One subject per walker, each with all of its crossings and one body mass.
    per_subject = plan.groupby("subject")
    assert per_subject.size().tolist() == [4] * 12
    assert (per_subject["mass_kg"].nunique() == 1).all()
    assert all(r.startswith(s) for r, s in zip(plan["record"], plan["subject"], strict=True))
    assert plan["duration_s"].between(20.0, 30.0).all()
    assert plan["duration_s"].nunique() == len(plan)
    assert plan["deck_rms_m_s2"].between(0.1, 0.5).all()
    assert (plan["deck_kind"] == "sine").all()
    ratio = plan["deck_frequency_hz"] / plan["pacing_hz"]
    inside = np.zeros(len(plan), dtype=bool)
    for lo, hi in DECK_RATIOS:
        inside |= ratio.between(lo, hi).to_numpy()
    assert inside.all()
    # Another design's ranges are respected too.
    other, _ = footbridge_plan(seed=7, walkers=3, deck_rms_m_s2=(0.2, 0.3), duration_s=(5, 6))
    assert other["deck_rms_m_s2"].between(0.2, 0.3).all()
    assert other["duration_s"].between(5.0, 6.0).all()


def test_footbridge_plan_is_fixed_by_its_seed() -> None:
    a, pa = footbridge_plan(seed=3, walkers=5)
    b, pb = footbridge_plan(seed=3, walkers=5)
    pd.testing.assert_frame_equal(a, b)
    pd.testing.assert_series_equal(pa, pb)
    c, _ = footbridge_plan(seed=4, walkers=5)
    assert not np.allclose(a["natural_frequency_hz"], c["natural_frequency_hz"])
    # A walker's draws do not depend on how many walkers follow.
    d, _ = footbridge_plan(seed=3, walkers=8)
    pd.testing.assert_frame_equal(a, d.iloc[: len(a)])
    with pytest.raises(UsageError, match="walkers"):
        footbridge_plan(seed=3, walkers=0)
    with pytest.raises(UsageError, match="duration_s"):
        footbridge_plan(seed=3, duration_s=(30.0, 20.0))


def test_walker_plan_unchanged_by_the_footbridge_refactoring() -> None:
    # Values of walker_plan(seed=0) computed before its draws moved into the per-walker
    # function footbridge_plan shares (docs/validation/population.md quotes walkers 0-9).
    # The draws and their order are unchanged, so this machine reproduces them to the bit;
    # the relative tolerance only leaves room for another platform's last-bit rounding of
    # exp and log in numpy's generators.
    plan = walker_plan(seed=0)
    assert plan["record"].iloc[0] == "w0000_c00" and plan["subject"].iloc[0] == "walker0000"
    expected = {
        "mass_kg": [75.000662, 75.000662],
        "pacing_hz": [1.904649, 1.850521],
        "natural_frequency_hz": [1.8163611235895598, 1.7470363426034126],
        "damping_ratio": [0.41577808075434436, 0.4471344628254504],
        "blf1": [0.4247856334543874, 0.39708325679601814],
        "blf2": [0.06533094528304115, 0.07758715806042096],
        "deck_rms_m_s2": [0.28901976765753745, 0.2569983243481788],
    }
    for col, values in expected.items():
        # mass and pacing were printed to six decimals
        rtol = 1e-6 if col in ("mass_kg", "pacing_hz") else 1e-12
        np.testing.assert_allclose(plan[col].iloc[:2], values, rtol=rtol, err_msg=col)
    assert plan["seed"].iloc[:2].tolist() == [1460110180, 1448992666]
    assert (plan["duration_s"] == 30.0).all()


@pytest.mark.parametrize("truth", ["seed", "constant"])
def test_generating_parameters_are_the_hierarchical_model_s(truth: str) -> None:
    # What the hierarchical model calls the walker sd is the spread of the walkers' own
    # laws, and its residual sd the spread of one walker's crossings about their own law:
    # a one-way analysis of variance of the drawn values about the population law must
    # find them. 400 walkers of 3 crossings: 800 degrees of freedom within walkers (the
    # residual sd to about 2.5 %), 400 between (the walker sd to about 4 %).
    laws = truth_laws(truth)
    plan, par = footbridge_plan(seed=11, walkers=400, truth=laws)
    pd.testing.assert_series_equal(par, generating_parameters(laws))
    for law in ("natural_frequency_hz", "damping_ratio", "blf1", "blf2", "blf3"):
        if law in ("blf2", "blf3"):
            resid = np.log(plan[law]) - par[f"{law}.mu"]
        else:
            mean = par[f"{law}.slope"] * plan["pacing_hz"] + par[f"{law}.intercept"]
            resid = plan[law] - mean
        by = resid.groupby(plan["subject"])
        within = float(np.sqrt(((resid - by.transform("mean")) ** 2).sum() / (len(plan) - 400)))
        # sd of the walker means, less the crossings' share of it (3 crossings each)
        between = float(np.sqrt(by.mean().var(ddof=1) - within**2 / 3))
        assert within == pytest.approx(par[f"{law}.residual_sd"], rel=0.1), law
        assert within == pytest.approx(CROSSING_SD[law], rel=0.1), law
        assert between == pytest.approx(par[f"{law}.walker_sd"], rel=0.15), law
    # The plan's bounds never bind on these laws (a clipped value would bias both sds).
    for col, (lo, hi) in (
        ("natural_frequency_hz", (FN_BOUNDS_HZ[0], 10.0)),
        ("damping_ratio", ZETA_BOUNDS),
        ("blf1", BLF1_BOUNDS),
    ):
        assert plan[col].between(lo * 1.01, hi * 0.99, inclusive="neither").all(), col

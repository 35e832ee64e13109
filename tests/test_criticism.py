"""Model criticism: catalogue effects, the held-out engine, ranking, scoreboard and CLI."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from workbench.diagnostics.criticism import (
    _RIDGE,
    CATALOGUE,
    SLOW_STEPS,
    StepVariation,
    _build_cv,
    _moving_average,
    baseline_columns,
    compare,
    diagnose,
    ljung_box_p,
    prepare,
)
from workbench.models import (
    BaseMotion,
    Effect,
    EffectContext,
    GaitAsymmetry,
    HeelImpact,
    PacingDrift,
    Parameter,
    QuadraticDamping,
    SMDModel,
    StiffnessDrift,
    available_effects,
    register_effect,
    unregister_effect,
)
from workbench.records.io import save_record
from workbench.synth import hidden_effect_walk, simulate_walking, varied_walk


def _record(seed: int, effects=(), ground=None, base: int = 100):  # type: ignore[no-untyped-def]
    """A walking record whose generator details vary with the seed."""
    rng = np.random.default_rng(base + seed)
    fs = float(rng.choice([100, 200, 500, 1000]))
    return simulate_walking(
        duration_s=float(rng.uniform(20, 40)),
        sample_rate_hz=fs,
        noise_sd_n=float(rng.uniform(2, 15)),
        seed=seed,
        pacing_hz=float(rng.uniform(1.6, 2.3)),
        mass_kg=float(rng.uniform(55, 95)),
        step_duration_sd=float(rng.uniform(0.01, 0.03)),
        amplitude_sd=float(rng.uniform(0.02, 0.06)),
        phase_sd_rad=float(rng.uniform(0.02, 0.06)),
        start="steady",
        effects=effects,
        ground_acc_m_s2=ground,
    ).record


# -- catalogue ---------------------------------------------------------------------------
def test_catalogue_names_are_registered_and_compose() -> None:
    assert set(CATALOGUE) <= set(available_effects())
    model = SMDModel() + GaitAsymmetry() + HeelImpact()
    assert model.effects.names == ("gait_asymmetry", "heel_impact")


def test_catalogue_terms_match_their_formulas() -> None:
    starts = np.array([0.0, 0.5, 1.0, 1.5])
    ctx = EffectContext(step_start_s=starts)
    t = np.array([0.0, 0.25, 0.5 + 0.012, 0.75])
    # Step phase 0, pi, 2 pi + 0.048 pi, 3 pi.
    phi = np.array([0.0, np.pi, 2 * np.pi + 2 * np.pi * 0.024, 3 * np.pi])
    asym = GaitAsymmetry(a_half_n=10.0, b_half_n=4.0).force(0.0, 0.0, t, context=ctx)
    np.testing.assert_allclose(asym, -(10 * np.cos(phi / 2) + 4 * np.sin(phi / 2)), atol=1e-12)
    heel = HeelImpact(impact_n=100.0, decay_s=0.012).force(0.0, 0.0, t, context=ctx)
    assert heel[2] == pytest.approx(-100.0)  # the pulse peaks at decay_s after footfall
    assert heel[0] == 0.0
    v = np.array([-0.2, 0.1])
    np.testing.assert_allclose(
        QuadraticDamping(c2_ns2_per_m2=50.0).force(0.0, v, 0.0), 50 * np.abs(v) * v
    )
    np.testing.assert_allclose(
        StiffnessDrift(dk_n_per_m_s=3.0, dc_ns_per_m_s=2.0).force(0.01, 0.1, 4.0), 4 * (0.03 + 0.2)
    )
    drift = PacingDrift(drift_cos_n_per_s=2.0).force(0.0, 0.0, np.array([0.5, 1.0]), context=ctx)
    np.testing.assert_allclose(drift, [-1.0, -2.0], atol=1e-12)  # phase 0 at footfalls
    gctx = EffectContext(
        ground_time_s=np.array([0.0, 1.0]),
        ground_disp_m=np.array([0.0, 0.002]),
        ground_vel_m_s=np.array([0.01, 0.01]),
        ground_acc_m_s2=np.zeros(2),
    )
    base = BaseMotion(k_ground_n_per_m=1e4, c_ground_ns_per_m=500.0).force(
        0.0, 0.0, 0.5, context=gctx
    )
    assert base == pytest.approx(-(1e4 * 0.001 + 500 * 0.01))


# -- engine -----------------------------------------------------------------------------
def test_step_variation_takes_out_each_steps_own_size_and_timing() -> None:
    """The map removes per-step jitter of the shape's size and timing exactly, keeps their
    slow part and anything else, and is linear."""
    data = prepare(varied_walk(4, duration_s=(30.0, 30.0)).record)
    sv = StepVariation(data)
    rng = np.random.default_rng(0)
    n = data.n_steps
    coef = rng.normal(size=(n, 2))
    slow_coef = np.column_stack([_moving_average(coef[:, i], min(SLOW_STEPS, n)) for i in range(2)])
    per_step = np.einsum("sa,sa->s", sv.columns, coef[data.step])
    kept = np.einsum("sa,sa->s", sv.columns, slow_coef[data.step])
    slow = sv.columns @ np.array([0.7, -0.2]) * (1.0 + data.time_s / data.time_s[-1])
    other = np.sin(2 * np.pi * 13.0 * data.time_s)  # nothing like the shape
    np.testing.assert_allclose(sv(per_step), kept, atol=1e-9 * np.abs(per_step).max())
    # A slow change of size is kept up to the moving average's curvature at the ends.
    assert np.std(sv(slow) - slow) < 0.05 * np.std(slow)
    assert np.std(sv(other) - other) < 0.2 * np.std(other)
    a, b = rng.normal(size=(2, data.time_s.size))
    np.testing.assert_allclose(sv(2.0 * a - b), 2.0 * sv(a) - sv(b), atol=1e-9)
    np.testing.assert_allclose(sv(np.column_stack([a, b]))[:, 1], sv(b), atol=1e-12)


def test_fold_errors_equal_a_direct_refit() -> None:
    """The Gram-matrix shortcut gives the held-out error of refitting on the other folds."""
    data = prepare(_record(0, effects=[GaitAsymmetry(a_half_n=30.0)]))
    cv, _ = _build_cv(data, ["gait_asymmetry", "cubic_stiffness"], 6, 10)
    sse, _ = cv.fold_sse(["gait_asymmetry"])
    idx = cv.columns(["gait_asymmetry"])
    for f in (0, cv.n_folds - 1):
        test = cv.fold_of == f
        x_train, x_test = cv.x[~test][:, idx], cv.x[test][:, idx]
        g = x_train.T @ x_train
        ridge = _RIDGE * np.trace(g) / g.shape[0]
        beta = np.linalg.solve(g + ridge * np.eye(g.shape[0]), x_train.T @ cv.y[~test])
        direct = np.sum((cv.y[test] - x_test @ beta) ** 2)
        assert sse[f] == pytest.approx(direct, rel=1e-9)
        # The ridge is numerical safety only: plain least squares agrees closely (the
        # response-modulation columns are nearly collinear with the force harmonics).
        beta, *_ = np.linalg.lstsq(x_train, cv.y[~test], rcond=None)
        plain = np.sum((cv.y[test] - x_test @ beta) ** 2)
        assert sse[f] == pytest.approx(plain, rel=1e-5)
    # Whole blocks of three steps are held out together.
    for f in range(cv.n_folds):
        steps = np.unique(data.step[cv.fold_of == f])
        assert all(set(range(3 * (s // 3), 3 * (s // 3) + 3)) & set(steps) for s in steps)


def test_ljung_box_matches_its_definition() -> None:
    rng = np.random.default_rng(0)
    x = rng.standard_normal(400)
    xc = x - x.mean()
    rho = np.array([xc[k:] @ xc[:-k] for k in range(1, 6)]) / (xc @ xc)
    q = 400 * 402 * np.sum(rho**2 / (400 - np.arange(1, 6)))
    assert ljung_box_p(x, 5) == pytest.approx(stats.chi2.sf(q, 5), rel=1e-12)
    ar = np.zeros(400)
    for i in range(1, 400):
        ar[i] = 0.6 * ar[i - 1] + x[i]
    assert ljung_box_p(ar, 10) < 1e-10


# -- must-show properties that hold -------------------------------------------------------
# -- detection on varied walks: the generator's details vary with the seed -----------------
#: Records per effect in the detection tests: seeds 100-104 of ``hidden_effect_walk``
#: (20-120 s, 100-1000 Hz, 55-95 kg, pacing 1.6-2.3 Hz, noise and step variability varied,
#: the three sizes of each effect in turn). ``analyses/hidden_effect.py --sweep 10`` draws
#: seeds 0-9 of the same generator; these are other draws.
DETECTION_SEEDS = range(100, 105)
#: How many of the five records must find the effect (ranked first and significant, or
#: significant and named indistinguishable from the first); the sweep's rates are in
#: docs/validation/criticism.md.
DETECTION_NEEDED = {
    "gait_asymmetry": 5,
    "heel_impact": 5,
    "base_motion": 5,
    "pacing_drift": 3,
    "stiffness_drift": 3,
}


def _found(diag, name: str) -> bool:  # type: ignore[no-untyped-def]
    top = diag.candidates[0]
    mine = next(c for c in diag.candidates if c.effect == name)
    return bool(
        (top.effect == name and top.significant)
        or (mine.significant and top.effect in mine.indistinguishable_from)
    )


@pytest.mark.slow
def test_no_false_alarm_without_an_effect() -> None:
    alarms = 0
    for seed in range(100, 110):
        diag = diagnose(hidden_effect_walk("none", seed).record)
        alarms += any(c.significant for c in diag.candidates)
        assert [c.score for c in diag.candidates if c.testable] == sorted(
            (c.score for c in diag.candidates if c.testable), reverse=True
        )
    assert alarms <= 1


@pytest.mark.slow
@pytest.mark.parametrize("name", list(DETECTION_NEEDED))
def test_hidden_effect_is_found_and_compare_cuts_the_error(name: str) -> None:
    found = 0
    for seed in DETECTION_SEEDS:
        # The rigid-floor model: base_motion stands for the surface it leaves out.
        data = prepare(hidden_effect_walk(name, seed).record)
        diag = diagnose(data, surface="rigid")
        found += _found(diag, name)
        right = compare(data, [name], surface="rigid")[1]
        assert right.rmse_drop_fraction > right.rmse_drop_se, (seed, right)
        mine = next(c for c in diag.candidates if c.effect == name)
        if mine.score >= 0.5:  # the effect carries half of the baseline's error variance
            assert right.rmse_drop_fraction >= 0.2
    assert found >= DETECTION_NEEDED[name]


@pytest.mark.parametrize("seed", [0, 3])
def test_base_motion_is_untestable_without_ground_motion(seed: int) -> None:
    no_ground = diagnose(_record(seed))
    untestable = [c for c in no_ground.candidates if not c.testable]
    assert [c.effect for c in untestable] == ["base_motion"]
    assert no_ground.candidates[-1].effect == "base_motion"


def test_gait_asymmetry_reason_and_a_wrong_effect() -> None:
    data = prepare(_record(0, effects=[GaitAsymmetry(a_half_n=60.0, b_half_n=30.0)]))
    diag = diagnose(data)
    assert diag.candidates[0].effect == "gait_asymmetry"
    assert "every second step" in diag.verdict
    wrong = compare(data, ["heel_impact"])[1]
    assert wrong.rmse_drop_fraction < wrong.rmse_drop_se


@pytest.mark.slow
@pytest.mark.parametrize("amplitude_sd", [None, 0.15])
@pytest.mark.parametrize("name", ["cubic_stiffness", "quadratic_damping"])
def test_state_effect_on_nearly_periodic_walking_is_called_inseparable(
    name: str, amplitude_sd: float | None
) -> None:
    """u^3 and |u'|u' lie almost wholly in the span of the force shape, K u + C u' and the
    response modulation when steps vary by 2-6 % (and still at 15 %). The diagnosis never
    names another effect instead: every record either finds the hidden one (ranked first
    and significant) or says that the record cannot separate it."""
    for seed in DETECTION_SEEDS:
        diag = diagnose(hidden_effect_walk(name, seed, amplitude_sd=amplitude_sd).record)
        cand = next(c for c in diag.candidates if c.effect == name)
        assert not any(c.significant for c in diag.candidates if c.effect != name), seed
        if cand.significant:
            assert diag.candidates[0] is cand
            continue
        assert cand.separable_fraction < 0.05
        assert "cannot be separated" in cand.evidence
        assert name in diag.verdict and "cannot be separated" in diag.verdict


@pytest.mark.slow
@pytest.mark.parametrize(
    "variation",
    [{"amplitude_sd": 0.15}, {"step_duration_sd": 0.05}, {"phase_sd_rad": 0.15}],
    ids=["amplitudes-15pc", "durations-5pc", "phases-0.15rad"],
)
def test_no_false_alarm_when_steps_vary_much_more(variation: dict[str, float]) -> None:
    """Large step-to-step variation of the force drives a response that a linear model with
    one K misfits harmonic by harmonic; to first order in the variation u^3 and |u'|u' can
    take up that misfit, so without the response-modulation nuisance block u^3 was called
    significant on 5 and 4 of 10 such records without any effect (amplitudes 15 %,
    durations 5 %; sweep seeds 0-9, `--no-modulation`)."""
    alarms = 0
    for seed in range(100, 110):
        diag = diagnose(hidden_effect_walk("none", seed, **variation).record)
        alarms += any(c.significant for c in diag.candidates)
    assert alarms <= 1


@pytest.mark.slow
@pytest.mark.parametrize(
    ("first", "second"),
    [
        ("gait_asymmetry", "heel_impact"),
        ("pacing_drift", "base_motion"),
        ("heel_impact", "pacing_drift"),
    ],
)
def test_two_hidden_effects_are_both_in_the_top_three(first: str, second: str) -> None:
    for seed in range(100, 103):
        top = [
            c.effect
            for c in diagnose(
                hidden_effect_walk([first, second], seed).record, surface="rigid"
            ).candidates[:3]
        ]
        assert {first, second} <= set(top), (seed, top)


def test_current_effects_join_the_baseline() -> None:
    rec = _record(1, effects=[HeelImpact(impact_n=150.0, decay_s=0.015)])
    diag = diagnose(rec, effects=["heel_impact"])
    assert "heel_impact" not in [c.effect for c in diag.candidates]
    assert not any(c.significant for c in diag.candidates)


# -- extension point -----------------------------------------------------------------------
class BreathingModulation(Effect):
    """User-written effect: breathing at 0.3 Hz modulates the force's first harmonic.

    Both quadratures of the first harmonic (cos and sin of the step phase) are modulated:
    the criticism's step phase starts at the record's step boundaries, not at the
    simulator's step starts (docs/guide/criticise.md), so an effect on one quadrature only
    would be measured partly in the other one, by an amount that depends on where the
    boundary falls in the simulated step.
    """

    name = "breathing_modulation"
    reason = "the force's size rises and falls with breath"
    breathing_hz = 0.3
    parameters = (
        Parameter("mod_cos_n", "N", 0.0, "cos(2 pi f_b t) times the cos(step phase) term"),
        Parameter("mod_sin_n", "N", 0.0, "sin(2 pi f_b t) times the cos(step phase) term"),
        Parameter("mod_cos_q_n", "N", 0.0, "cos(2 pi f_b t) times the sin(step phase) term"),
        Parameter("mod_sin_q_n", "N", 0.0, "sin(2 pi f_b t) times the sin(step phase) term"),
    )

    def regressors(self, u, v, t_s, context=None):  # type: ignore[no-untyped-def]
        _, _, t = self.broadcast(u, v, t_s)
        phase = context.step_phase_rad(t)
        w = 2 * np.pi * self.breathing_hz * t
        c, s = np.cos(phase), np.sin(phase)
        return -np.stack([np.cos(w) * c, np.sin(w) * c, np.cos(w) * s, np.sin(w) * s], axis=-1)


@pytest.fixture
def breathing() -> Iterator[None]:
    register_effect(BreathingModulation)
    try:
        yield
    finally:
        unregister_effect("breathing_modulation")


@pytest.mark.parametrize("seed", [0, 3])
def test_user_written_effect_is_a_candidate(breathing: None, seed: int) -> None:
    hidden = BreathingModulation(mod_cos_n=100.0, mod_sin_n=50.0)
    diag = diagnose(_record(seed, effects=[hidden]))
    assert diag.candidates[0].effect == "breathing_modulation"
    assert diag.candidates[0].significant
    assert "breath" in diag.verdict
    # Without the hidden effect the new candidate raises no alarm. Only the new candidate is
    # asserted on: the catalogue's false-alarm rate on records without an effect is
    # calibrated over many records (docs/validation/criticism.md, "Family-wise control"),
    # and one record may carry a real chance pattern. Seed 0's does: its simulator drew the
    # step-by-step force coefficients independently, yet their odd/even contrast is 7.3 N
    # on the first harmonic's cosine and -3.4 N on its sine (the truth's
    # step_coefficients). gait_asymmetry's p-value on it moves with where the criticism's
    # step boundaries fall: 0.07 with one cycle per split step, 0.006 (called) while the
    # cycles were counted from the first crossing after the split's first footfall.
    quiet = diagnose(_record(seed)).candidates
    assert not next(c for c in quiet if c.effect == "breathing_modulation").significant
    assert all(c.effect == "gait_asymmetry" for c in quiet if c.significant)


@pytest.mark.slow
def test_demo_section_has_the_figures(tmp_path: Path) -> None:
    from workbench.reporting.criticism import criticism_demo_section

    rec = _record(0, effects=[GaitAsymmetry(a_half_n=60.0, b_half_n=30.0)])
    section = criticism_demo_section(rec, tmp_path, seed=0)
    pngs = sorted(p.name for p in (tmp_path / "figures").glob("*.png"))
    assert len(pngs) == 5  # overlay, phase, spectrum, state, scoreboard
    assert "gait_asymmetry" in section.to_markdown()


# -- command line ----------------------------------------------------------------------------
def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "workbench", *args], capture_output=True, text=True, check=False
    )


@pytest.mark.slow
def test_cli_diagnose_and_compare(tmp_path: Path) -> None:
    rec = _record(2, effects=[HeelImpact(impact_n=250.0, decay_s=0.02)])
    path = tmp_path / "walk.csv"
    save_record(rec, path)
    out = _cli("diagnose", str(path), "--json", "--out", str(tmp_path / "rep"))
    assert out.returncode == 0, out.stderr
    obj = json.loads(out.stdout)
    assert set(obj) >= {"baseline", "candidates", "verdict"}
    first = obj["candidates"][0]
    assert set(first) >= {
        "effect",
        "score",
        "significant",
        "evidence",
        "expected_error_drop",
        "indistinguishable_from",
    }
    assert first["effect"] == "heel_impact"
    assert Path(obj["report"]).exists()
    # One-step-ahead residuals of the identified model join the baseline, and the report.
    assert obj["baseline"]["one_step_rmse_n"] > 0
    assert 0.0 <= obj["baseline"]["one_step_ljung_box_p"] <= 1.0
    assert (tmp_path / "rep" / "figures" / "walk_criticism_one_step.png").exists()
    check = obj["posterior_predictive"]
    assert 0.0 < check["subharmonic_power"]["p_value"] <= 1.0
    out = _cli("compare", str(path), "--effects", "heel_impact,gait_asymmetry", "--json")
    assert out.returncode == 0, out.stderr
    rows = json.loads(out.stdout)["rows"]
    assert rows[0]["model"] == "baseline"
    assert len(rows) == 3
    assert set(rows[0]) >= {"model", "heldout_rmse_n", "fit_percent", "ljung_box_p", "score"}
    assert rows[1]["heldout_rmse_n"] < rows[0]["heldout_rmse_n"]
    # The raw error (step-to-step variation left in) is larger than the error beyond it.
    raw = _cli("compare", str(path), "--effects", "heel_impact", "--json", "--raw-error")
    assert raw.returncode == 0, raw.stderr
    raw_rows = json.loads(raw.stdout)["rows"]
    assert raw_rows[0]["heldout_rmse_n"] > rows[0]["heldout_rmse_n"]
    assert raw_rows[1]["heldout_rmse_n"] < raw_rows[0]["heldout_rmse_n"]
    assert obj["baseline"]["step_variation"] is True
    for args, word in [
        (("compare", str(path), "--effects", "wobble"), "wobble"),
        (("diagnose", str(path), "--harmonics", "0"), "--harmonics"),
        (("compare", str(path), "--effects", ","), "--effects"),
    ]:
        bad = _cli(*args)
        assert bad.returncode == 2
        assert word in bad.stderr
        assert "Traceback" not in bad.stderr


# -- double-humped steps -------------------------------------------------------------------
@pytest.mark.slow
def test_diagnose_calls_nothing_on_nine_in_ten_effect_free_double_humped_walks() -> None:
    """Walks 0-19 of ``analyses/diagnose_double_hump.py`` (rigid floor, no effect, the two
    humps of every step differing by 0-20 %), diagnosed with the default settings.

    The promise is at most one walk in ten calling an effect, so at most 2 of these 20 (the
    family-wise level is 0.05 per record). Measured: 1 of 20 (walk 1, quadratic_damping at
    p 0.0064). About a minute on one core.
    """
    path = Path(__file__).resolve().parents[1] / "analyses" / "diagnose_double_hump.py"
    spec = importlib.util.spec_from_file_location("analyses_diagnose_double_hump", path)
    assert spec is not None and spec.loader is not None
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    rows = [script.measure(seed) for seed in range(20)]
    calling = [(r["seed"], r["called"]) for r in rows if r["called"]]
    assert len(calling) <= 2, calling
    assert all(r["steps"] >= 40 for r in rows)


def test_heel_impact_columns_follow_each_steps_force() -> None:
    """The smooth step phase is 7-10 ms sd off the true step starts on an overground walk
    (more at its first and last steps), as wide as a heel-impact pulse; the phase re-timed
    to each step's force is tighter (analyses/heel_impact_timing.py: 8.1 to 1.9 ms on this
    walk), increasing, and the statistic finds the pulse near the boundary."""
    sim = hidden_effect_walk("heel_impact", 101, kind="overground", size_factor=2.0)
    data = prepare(sim.record)
    timed = data.force_timed_phase()
    assert np.all(np.diff(timed) > 0)
    starts = sim.step_start_s[
        (sim.step_start_s >= data.time_s[0]) & (sim.step_start_s <= data.time_s[-1])
    ]

    def jitter_ms(phase: np.ndarray) -> float:
        at = np.exp(1j * np.interp(starts, data.time_s, phase))
        err = np.angle(at / np.mean(at)) / (2.0 * np.pi)
        return float(np.std(err) / data.pacing_hz * 1000.0)

    smooth, retimed = jitter_ms(data.phase_rad), jitter_ms(timed)
    assert smooth > 6.0
    assert retimed < 0.5 * smooth
    x = baseline_columns(data)
    coef, *_ = np.linalg.lstsq(x, data.target_n, rcond=None)
    share, text = HeelImpact().statistic(data, data.target_n - x @ coef)
    # The pulse holds most of the baseline's error (72 % on this walk), in the tenth of the
    # step that starts within a tenth of the boundary.
    assert share > 0.5
    offset = float(text.split(" from ")[1].split(" step")[0])
    assert abs(offset) <= 0.1

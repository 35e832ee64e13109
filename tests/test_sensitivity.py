"""Sensitivity of the identified parameters to the settings (``workbench sensitivity``).

The synthetic record is in the model class (8 s at 100 Hz from rest, no step-to-step
variability, whole-record force on absolute time at the stated pacing), where the default
settings recover C and K; see :func:`workbench.sensitivity.study.demo_record`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.stats

from workbench.cli import main
from workbench.records.io import save_record
from workbench.sensitivity.design import build_design, parse_levels, point_seed
from workbench.sensitivity.run import OUTPUTS
from workbench.sensitivity.study import demo_record, demo_settings, demo_study, run_sensitivity

SMD = ("natural_frequency_hz", "damping_ratio", "stiffness_n_per_m", "damping_ns_per_m")


@pytest.fixture(scope="module")
def study():
    return demo_study(seed=0, replicates=2)


def _effects(study, point):
    e = study.effects
    return {r["output"]: r for _, r in e[e["point"] == point].iterrows()}


@pytest.mark.slow
def test_defaults_recover_the_truth_and_settings_bias_or_widen(study):
    key = study.records[0]
    # The default settings sit inside the region where the truth is recovered.
    assert study.default_recovers_truth() == {key: True}
    base = study.recovered[key]["baseline"]
    assert all(base[o] for o in SMD), base
    # Four times the noise of u'' costs precision, not accuracy: every band widens (the
    # posterior sd scales with the noise sd: x4 at most) and still holds the truth.
    widen = _effects(study, "obs_noise_ddu=x4")
    for o in SMD:
        assert widen[o]["verdict"] == "widens only", widen[o].to_dict()
        assert 2.0 < widen[o]["posterior_sd_ratio"] < 6.0
    # The seed's process noise of (u, u'), which the data do not have, moves f_n and K
    # beyond their bands (the exact posterior shows the same pull on the seed's example).
    proc = _effects(study, "state_noise=0.005")
    for o in ("natural_frequency_hz", "stiffness_n_per_m"):
        assert proc[o]["verdict"] == "bias", proc[o].to_dict()
        assert proc[o]["effect"] < 0
    # A prior box too narrow to hold the truth biases the damping, whatever the data say.
    box = _effects(study, "prior_box=x0.05")
    assert box["damping_ns_per_m"]["verdict"] == "bias"
    assert not study.recovered[key]["prior_box=x0.05"]["all"]
    words = " ".join(s["sentence"] for s in study.statements)
    assert "widens only" in words and "bias" in words


@pytest.mark.slow
def test_effects_carry_their_monte_carlo_uncertainty(study):
    reps = study.replicate_rows
    assert (reps["status"] == "done").all()
    # Replicates differ (the seeds differ) and the half-width is Welch's 95 % interval of
    # the difference of means, recomputed here from the replicate rows.
    for _, e in study.effects.iterrows():
        a = reps[reps["point"] == e["point"]][e["output"]].to_numpy(dtype=float)
        b = reps[reps["point"] == "baseline"][e["output"]].to_numpy(dtype=float)
        v1, v0 = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
        nu = (v1 + v0) ** 2 / (v1**2 / (a.size - 1) + v0**2 / (b.size - 1))
        hw = scipy.stats.t.ppf(0.975, nu) * math.sqrt(v1 + v0)
        assert e["mc_halfwidth_95"] == pytest.approx(hw, rel=1e-9)
        assert e["effect"] == pytest.approx(a.mean() - b.mean(), rel=1e-12, abs=1e-15)
        assert bool(e["distinguishable"]) == (abs(e["effect"]) > hw)
        # An effect inside its Monte Carlo uncertainty is never called a bias or a shift.
        if not e["distinguishable"]:
            assert e["verdict"] in ("not distinguishable", "widens only", "narrows"), e.to_dict()
    inside = study.effects[~study.effects["distinguishable"]]
    assert (inside["verdict"] == "not distinguishable").any()
    for s in study.statements:
        assert "Monte Carlo uncertainty of +-" in s["sentence"]
    # The statement of an indistinguishable effect says so.
    s = next(s for s in study.statements if s["point"] == "obs_noise_ddu=x4")
    assert "moves f_n by" in s["sentence"] and "inside the Monte Carlo" in s["sentence"]


def test_design_points_and_seeds():
    base = demo_settings()
    levels = parse_levels(["obs_noise_ddu=1,4", "harmonics=2,4,8"], base)
    _baseline, oat = build_design("oat", levels)
    assert [p.key for p in oat] == [
        "baseline",
        "obs_noise_ddu=x4",
        "harmonics=2",
        "harmonics=8",
    ]
    _, full = build_design("factorial", levels)
    assert len(full) == 2 * 3 and len({p.key for p in full}) == 6
    settings, over = full[-1].configure(base)
    assert settings.model.harmonics == 8 and over.obs_scale == (1.0, 1.0, 4.0)
    # A run's seed depends on the record, the point and the replicate only.
    s = point_seed(0, "rec", "harmonics=2", 1)
    assert s == point_seed(0, "rec", "harmonics=2", 1)
    assert (
        len({s, point_seed(0, "rec", "harmonics=2", 0), point_seed(1, "rec", "harmonics=2", 1)})
        == 3
    )


@pytest.mark.slow
def test_cli_json_contract_and_worker_independence(tmp_path, capsys):
    _key, record = demo_record()
    path = tmp_path / "walk.csv"
    save_record(record, path)
    out = tmp_path / "out"
    args = [
        "sensitivity", str(path), "--factors", "obs_noise_ddu", "--levels",
        "obs_noise_ddu=1,3", "--replicates", "2", "--seed", "5", "--workers", "2",
        "--method", "rbpf", "--particles", "32", "--harmonics", "4", "--pieces", "whole",
        "--time-basis", "absolute", "--pacing", "1.8", "--highpass-hz", "0",
        "--observe", "acc", "--no-force-check", "--out", str(out), "--json",
    ]  # fmt: skip
    code = main(args)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    r = json.loads(captured.out)
    # One row per setting and level, with the identified parameters and their spreads.
    assert [(x["setting"], x["level"], x["is_default"]) for x in r["rows"]] == [
        ("obs_noise_ddu", "x1", True),
        ("obs_noise_ddu", "x3", False),
    ]
    for row in r["rows"]:
        assert row["replicates"] == 2
        for o in OUTPUTS:
            assert o in row and f"{o}_mc_sd" in row and f"{o}_posterior_sd" in row
        assert 1.5 < row["natural_frequency_hz"] < 2.5
    assert set(r["rows"][1]["effects"]["natural_frequency_hz"]) >= {
        "effect",
        "mc_halfwidth_95",
        "verdict",
    }
    assert r["statements"] and r["default_recovers_truth"] == {"walk.csv": True}
    table = (out / "sensitivity.csv").read_text().splitlines()
    assert len(table) == 1 + 2 * 2 + 2  # header, 2 levels x 2 replicates, 2 summaries
    assert (out / "index.html").exists() and (out / "report.md").exists()
    assert list(out.glob("figures/sensitivity_tornado_*.png"))
    assert not list(out.glob("*.png"))  # figures live in figures/, as in every report
    # The same study in this process (one worker) gives the same numbers.
    from workbench.records.io import load_record

    again = run_sensitivity(
        [("walk.csv", load_record(path))],
        base=demo_settings(),
        factors=["obs_noise_ddu"],
        levels=parse_levels(["obs_noise_ddu=1,3"], demo_settings()),
        replicates=2,
        seed=5,
    )
    serial = {(x["level"], o): x[o] for x in again.rows() for o in OUTPUTS}
    pooled = {(x["level"], o): x[o] for x in r["rows"] for o in OUTPUTS}
    assert serial.keys() == pooled.keys()
    for k, v in serial.items():
        assert v == pytest.approx(pooled[k], rel=1e-12, abs=0.0) or (
            v is None and pooled[k] is None
        ), k
    assert np.isfinite(again.replicate_rows["natural_frequency_hz"]).all()


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--factors", "bogus"], "not a sensitivity factor"),
        (["--levels", "harmonics=two"], "not a number"),
        (["--factors", "harmonics", "--levels", "pieces=steps"], "not among --factors"),
        (["--replicates", "0"], "at least 1"),
    ],
)
def test_bad_input_is_one_sentence(tmp_path, capsys, extra, needle):
    _key, record = demo_record()
    path = tmp_path / "walk.csv"
    save_record(record, path)
    code = main(["sensitivity", str(path), "--out", str(tmp_path / "o"), "--json", *extra])
    captured = capsys.readouterr()
    assert code == 2
    msg = json.loads(captured.out)["error"]
    assert needle in msg and "Traceback" not in captured.err


@pytest.mark.slow
def test_factorial_grid_heat_map_and_seeds_shared_with_one_at_a_time(study, tmp_path):
    from workbench.reporting.sensitivity import sensitivity_section

    base = demo_settings()
    levels = parse_levels(["obs_noise_ddu=1,4", "state_noise=0,0.005"], base)
    grid = run_sensitivity(
        [demo_record()], base=base, levels=levels, factors=list(levels),
        design="factorial", replicates=1, seed=0,
    )  # fmt: skip
    assert sorted(grid.summary["point"]) == sorted(
        ["baseline", "obs_noise_ddu=x4", "state_noise=0.005", "obs_noise_ddu=x4; state_noise=0.005"]
    )
    # A point's runs have the same seeds in any design: the factorial baseline and the
    # u''-noise point reproduce the one-at-a-time study's first replicate exactly.
    for point in ("baseline", "obs_noise_ddu=x4"):
        a = grid.replicate_rows[grid.replicate_rows["point"] == point].iloc[0]
        reps = study.replicate_rows
        b = reps[(reps["point"] == point) & (reps["replicate"] == 0)].iloc[0]
        assert a["seed"] == b["seed"]
        for o in SMD:
            assert a[o] == b[o]
    # One replicate gives no Monte Carlo uncertainty: nothing is called distinguishable.
    assert not grid.effects["distinguishable"].any()
    assert all("no Monte Carlo uncertainty" in s["sentence"] for s in grid.statements)
    tidy = grid.tidy()
    assert set(tidy["setting"]) == {"factorial"} and len(tidy) == 4 * 2
    sec = sensitivity_section(grid, tmp_path)
    assert (tmp_path / "figures" / "sensitivity_heatmap_0_obs_noise_ddu_state_noise.png").exists()
    assert "Sensitivity" in sec.title


def test_pooled_effects_and_manifest_records(tmp_path, monkeypatch):
    import pandas as pd

    from workbench.records.collection import load_study_records
    from workbench.sensitivity.analysis import pooled_effects

    d = [0.10, 0.14, 0.12, 0.08]
    eff = pd.DataFrame(
        {"record": list("abcd"), "point": "x=2", "output": "natural_frequency_hz", "effect": d}
    )
    row = pooled_effects(eff).iloc[0]
    hw = scipy.stats.t.ppf(0.975, 3) * np.std(d, ddof=1) / 2.0
    assert row["mean_effect"] == pytest.approx(0.11) and row["halfwidth_95"] == pytest.approx(hw)
    assert row["verdict"] == "consistent shift"
    eff["effect"] = [0.1, -0.1, 0.05, -0.04]
    assert pooled_effects(eff).iloc[0]["verdict"] == "not distinguishable"
    assert pooled_effects(eff.iloc[:1]).empty
    # A manifest gives one (key, record) pair per row, keyed by the path as written.
    _, record = demo_record()
    for name in ("a.csv", "b.csv"):
        save_record(record, tmp_path / name)
    (tmp_path / "m.csv").write_text("path,mass_kg\na.csv,70\nb.csv,71\n")
    recs = load_study_records(str(tmp_path / "m.csv"))
    assert [k for k, _ in recs] == ["a.csv", "b.csv"]
    assert recs[1][1].mass_kg == 71.0
    # A manifest named relative to the working folder: its rows start from its own folder,
    # joined once (they were joined twice, and the records were not found).
    monkeypatch.chdir(tmp_path.parent)
    relative = load_study_records(f"{tmp_path.name}/m.csv")
    assert [k for k, _ in relative] == ["a.csv", "b.csv"]


@pytest.mark.parametrize("as_json", [False, True])
def test_cli_progress_reaches_the_runner(tmp_path, capsys, monkeypatch, as_json):
    # A study runs for minutes: typed as is, the command shows a bar on stderr as runs finish;
    # under --json it stays silent so that stderr holds nothing but warnings and errors.
    import workbench.sensitivity.study as study_module

    seen = []
    real = study_module.run_tasks

    def spy(tasks, **kwargs):
        seen.append(kwargs["progress"])
        return real(tasks, **kwargs)

    monkeypatch.setattr(study_module, "run_tasks", spy)
    _key, record = demo_record()
    path = tmp_path / "walk.csv"
    save_record(record, path)
    args = [
        "sensitivity", str(path), "--factors", "obs_noise_ddu", "--levels", "obs_noise_ddu=1,3",
        "--replicates", "1", "--method", "rbpf", "--particles", "16", "--harmonics", "2",
        "--pieces", "whole", "--time-basis", "absolute", "--pacing", "1.8", "--highpass-hz",
        "0", "--observe", "acc", "--no-force-check", "--out", str(tmp_path / "out"),
    ]  # fmt: skip
    code = main(args + (["--json"] if as_json else []))
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert seen == [not as_json]
    # The bar counts the runs (1 factor x 2 levels x 1 replicate) as they finish; how many
    # counts it draws depends on the runs' speed (tqdm redraws at most every 0.1 s).
    assert ("sensitivity: " in captured.err and "/2 [" in captured.err) is not as_json


def test_cli_takes_an_embedded_record_by_name(tmp_path, capsys, monkeypatch):
    # Like every one-record command, sensitivity resolves an embedded record's name (a
    # local file of that name would win); the study then runs on the embedded file.
    import workbench.records.collection as collection

    seen = []
    real = collection.load_study_records

    def spy(path, **kwargs):
        seen.append(Path(path).name)
        return real(path, **kwargs)

    monkeypatch.setattr(collection, "load_study_records", spy)
    monkeypatch.chdir(tmp_path)
    args = [
        "sensitivity", "seed_individual", "--factors", "obs_noise_ddu", "--levels",
        "obs_noise_ddu=1,3", "--replicates", "1", "--method", "rbpf", "--particles", "16",
        "--harmonics", "2", "--pieces", "whole", "--time-basis", "absolute", "--pacing", "1.75",
        "--observe", "acc", "--no-force-check", "--out", str(tmp_path / "out"), "--json",
    ]  # fmt: skip
    code = main(args)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert seen == ["seed_individual.csv"]
    assert json.loads(captured.out)["runs"]

"""``diagnose`` and ``compare`` over several walks of one walker: files or a manifest's rows.

One record keeps the one-record form; two or more (or ``--manifest`` with ``--subject``) give
the pooled diagnosis and scoreboard of :mod:`workbench.diagnostics.walker`. Every refusal
comes before the computation, in one sentence.
"""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest

from tests.cli_helpers import never, refused, run_cli
from workbench.cli import main
from workbench.errors import UsageError
from workbench.records.io import save_record
from workbench.synth import hidden_effect_walker

WALKS = 3


@pytest.fixture(scope="module")
def walker(tmp_path_factory) -> tuple[list[Path], Path]:
    """Three walks of one walker (a heel impact hidden) and a manifest of two subjects."""
    folder = tmp_path_factory.mktemp("walker")
    paths = []
    for i, sim in enumerate(hidden_effect_walker("heel_impact", 1, WALKS, kind="overground")):
        path = folder / f"walk{i}.csv"
        save_record(sim.record, path)
        paths.append(path)
    other = hidden_effect_walker("none", 2, 1, kind="overground")[0]
    save_record(other.record, folder / "other.csv")
    manifest = folder / "manifest.csv"
    # The other subject's row between the walker's: the walker's rows keep their order.
    manifest.write_text(
        "path,subject\nwalk0.csv,ann\nwalk1.csv,ann\nother.csv,bob\nwalk2.csv,ann\n"
    )
    return paths, manifest


@pytest.fixture(scope="module")
def run_once():
    """Run a command once per module and keep its exit status and output (pooled runs)."""
    runs: dict[tuple[str, ...], tuple[int, str, str]] = {}

    def run(argv) -> tuple[int, str, str]:
        key = tuple(str(a) for a in argv)
        if key not in runs:
            out, err = io.StringIO(), io.StringIO()
            with redirect_stdout(out), redirect_stderr(err):
                code = main(list(key))
            runs[key] = (code, out.getvalue(), err.getvalue())
        return runs[key]

    return run


def pooled_json(run_once, argv) -> dict:
    code, out, err = run_once([*argv, "--json"])
    assert code == 0, err
    return json.loads(out)


# -- the pooled results ------------------------------------------------------------------------
def test_diagnose_over_several_files_pools_the_walks(walker, run_once):
    paths, _ = walker
    obj = pooled_json(run_once, ["diagnose", *paths])
    base = obj["baseline"]
    assert base["walks"] == WALKS
    assert [w["source"] for w in base["per_walk"]] == [str(p) for p in paths]
    assert all(w["steps"] > 0 for w in base["per_walk"])
    assert all(w["start_stop_steps_left_out"] == [3, 3] for w in base["per_walk"])
    assert base["walk_heldout_rmse_n"] > 0
    assert base["asymmetry_labelling"] == "sign-free (per walk)"  # no foot channels
    # The one-step-ahead check is per record: said in the JSON, not run.
    assert base["one_step"] == "not run over several walks"
    assert "posterior_predictive" not in obj
    effects = {c["effect"]: c for c in obj["candidates"]}
    assert "heel_impact" in effects
    assert "walk_heldout_score" in effects["heel_impact"]
    assert "sharing" in effects["heel_impact"]
    assert isinstance(obj["verdict"], str) and obj["verdict"]


def test_diagnose_over_several_files_prints_the_summary_and_verdict(walker, run_once):
    paths, _ = walker
    code, out, err = run_once(["diagnose", *paths])
    assert code == 0, err
    assert out.startswith(f"Model criticism over {WALKS} walks of one walker")
    assert "heel_impact" in out
    assert out.strip().splitlines()[-1].startswith("verdict: ")


def test_compare_over_several_files_gives_the_effects_size(walker, run_once):
    paths, _ = walker
    obj = pooled_json(run_once, ["compare", *paths, "--effects", "heel_impact"])
    assert obj["walks"] == [str(p) for p in paths]
    assert [r["model"] for r in obj["rows"]] == [
        "baseline per walk",
        "baseline per walk + heel_impact",
    ]
    assert all(r["walk_heldout_rmse_n"] > 0 for r in obj["rows"])
    size = obj["effects"]["heel_impact"]
    assert size["force_rms_n"] > 0
    assert size["force_rms_se_n"] >= 0
    assert len(size["coefficients"]) == len(size["standard_errors"]) > 0


def test_compare_over_several_files_prints_the_scoreboard(walker, run_once):
    paths, _ = walker
    code, out, err = run_once(["compare", *paths, "--effects", "heel_impact"])
    assert code == 0, err
    assert out.startswith(f"Scoreboard over {WALKS} walks of one walker")
    assert "heel_impact (shared): force" in out


@pytest.mark.parametrize(
    "argv", [["diagnose"], ["compare", "--effects", "heel_impact"]], ids=["diagnose", "compare"]
)
def test_manifest_rows_of_the_subject_give_the_files_result(walker, run_once, argv):
    paths, manifest = walker
    command, *extra = argv
    from_files = pooled_json(run_once, [command, *paths, *extra])
    from_manifest = pooled_json(
        run_once, [command, "--manifest", manifest, "--subject", "ann", *extra]
    )
    assert from_manifest == from_files


def test_manifest_mass_and_pacing_win_over_the_flags(walker, tmp_path, capsys, monkeypatch):
    paths, _ = walker
    seen = []

    def stop(records, **_):
        seen.extend(records)
        raise UsageError("stopped after loading")

    monkeypatch.setattr("workbench.diagnostics.walker.prepare_walks", stop)
    manifest = paths[0].parent / "masses.csv"
    manifest.write_text("path,mass_kg,pacing_hz\nwalk0.csv,80,\nwalk1.csv,,2.0\n")
    argv = ["diagnose", "--manifest", manifest, "--mass", "60", "--pacing", "1.9"]
    assert "stopped after loading" in refused(argv, capsys)
    assert [r.mass_kg for r in seen] == [80.0, 60.0]
    assert [r.pacing_hz for r in seen] == [1.9, 2.0]


# -- one record keeps the one-record form ------------------------------------------------------
def test_one_record_keeps_the_one_record_compare(walker, capsys):
    paths, _ = walker
    code, out, err = run_cli(["compare", paths[0], "--effects", "heel_impact", "--json"], capsys)
    assert code == 0, err
    assert set(json.loads(out)) == {"rows"}


def test_one_record_keeps_the_one_record_diagnose(walker, capsys):
    paths, _ = walker
    code, out, err = run_cli(["diagnose", paths[0], "--no-one-step"], capsys)
    assert code == 0, err
    assert out.startswith(f"Model criticism of {paths[0]}")


# -- refusals, before any work -----------------------------------------------------------------
def test_manifest_of_several_subjects_needs_subject(walker, capsys, monkeypatch):
    _, manifest = walker
    monkeypatch.setattr("workbench.diagnostics.walker.diagnose_walker", never)
    err = refused(["diagnose", "--manifest", manifest], capsys)
    assert str(manifest) in err
    assert "several subjects (ann, bob)" in err
    assert "--subject NAME" in err


def test_subject_without_rows_is_refused(walker, capsys, monkeypatch):
    _, manifest = walker
    monkeypatch.setattr("workbench.diagnostics.walker.compare_walker", never)
    argv = ["compare", "--manifest", manifest, "--subject", "carl", "--effects", "heel_impact"]
    err = refused(argv, capsys)
    assert str(manifest) in err
    assert "no rows of subject 'carl'" in err and "ann, bob" in err


def test_records_and_manifest_together_are_refused(walker, capsys):
    paths, manifest = walker
    err = refused(["diagnose", paths[0], "--manifest", manifest, "--subject", "ann"], capsys)
    assert "either as record files or as --manifest" in err and "not both" in err


def test_no_record_is_refused(capsys):
    err = refused(["compare", "--effects", "heel_impact"], capsys)
    assert "give a record file" in err and "--manifest FILE" in err


@pytest.mark.parametrize(
    ("argv", "computation"),
    [
        (["diagnose"], "workbench.diagnostics.walker.diagnose_walker"),
        (["compare", "--effects", "heel_impact"], "workbench.diagnostics.walker.compare_walker"),
    ],
    ids=["diagnose", "compare"],
)
def test_a_missing_file_among_several_is_named(
    walker, tmp_path, capsys, monkeypatch, argv, computation
):
    paths, _ = walker
    monkeypatch.setattr(computation, never)
    missing = tmp_path / "walk9.csv"
    command, *extra = argv
    err = refused([command, paths[0], missing, paths[1], *extra, "--json"], capsys)
    assert str(missing) in err and "does not exist" in err


def test_a_missing_manifest_row_is_named(walker, capsys, monkeypatch):
    paths, _ = walker
    monkeypatch.setattr("workbench.diagnostics.walker.diagnose_walker", never)
    manifest = paths[0].parent / "gap.csv"
    manifest.write_text("path,subject\nwalk0.csv,ann\ngone.csv,ann\n")
    err = refused(["diagnose", "--manifest", manifest], capsys)
    assert "gone.csv" in err and "does not exist" in err


def test_the_same_walk_twice_is_refused(walker, capsys):
    paths, _ = walker
    again = f"{paths[0].parent}/./{paths[0].name}"  # another spelling of the first walk
    err = refused(["compare", paths[0], paths[1], again, "--effects", "heel_impact"], capsys)
    assert "given again" in err and "give each walk once" in err


def test_report_of_several_walks_is_refused(walker, tmp_path, capsys, monkeypatch):
    paths, manifest = walker
    monkeypatch.setattr("workbench.diagnostics.walker.prepare_walks", never)
    out = tmp_path / "report"
    for walks in ([*paths], ["--manifest", manifest, "--subject", "ann"]):
        err = refused(["diagnose", *walks, "--out", out], capsys)
        assert "the report is written for one record" in err
        assert "run diagnose on one walk with --out" in err
    assert not out.exists()

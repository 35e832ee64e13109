"""crosscheck on a deck record checks the posterior identify reports: the transmissibility's.

identify reads C and K of a record with ``ground_acc`` from the deck's transmissibility
(a grid posterior); crosscheck without ``--surface`` samples that same likelihood with
emcee and compares, and its help names the surface model it actually uses by default.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

import workbench as wb
from workbench.cli import main
from workbench.cli.crosscheck import _route_text
from workbench.inference.crosscheck.surface import crosscheck_surface_route
from workbench.records.io import save_record
from workbench.synth import deck_walk

PARAMS = ("damping_ns_per_m", "stiffness_n_per_m")


@pytest.fixture(scope="module")
def deck_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("deck") / "deck.csv"
    save_record(deck_walk(2, duration_s=20.0).record, path)
    return path


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[dict, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out), err


@pytest.fixture(scope="module")
def default_run(deck_file: Path) -> tuple[dict, dict]:
    """crosscheck and identify on the deck record, both with their defaults (seed 0)."""
    import contextlib
    import io

    outputs = []
    for argv in (["crosscheck", deck_file, "--json"], ["identify", deck_file, "--json"]):
        buffer = io.StringIO()
        with contextlib.redirect_stdout(buffer):
            assert main([str(a) for a in argv]) == 0
        outputs.append(json.loads(buffer.getvalue()))
    return outputs[0], outputs[1]


def test_crosscheck_checks_the_posterior_identify_reports(default_run):
    check, ident = default_run
    assert ident["surface"]["c_and_k_from"] == "transmissibility"
    assert check["surface"] == "coupled"
    assert check["checks"] == "transmissibility route"
    assert "transmissibility" in check["checked"] and "identify" in check["checked"]
    route = check["route_check"]
    # Side by side: the grid's values are identify's own (same record, settings and seed;
    # the draws are the same, so the means agree to rounding).
    for p in PARAMS:
        assert route["grid_mean"][p] == pytest.approx(ident[p], rel=1e-9)
        assert route["grid_sd"][p] == pytest.approx(ident["posterior_sd"][p], rel=1e-9)
    # The MCMC converged on the same likelihood and agrees with the grid. 0.5 sd: the grid's
    # moments come from a few thousand draws and the MCMC's ESS is in the thousands, so
    # both Monte Carlo errors are a few hundredths of an sd; 0.5 leaves room for the grid's
    # quadrature without hiding a wrong target (a shifted grid is caught below).
    assert route["converged"] and route["agree"]
    for p in PARAMS:
        z = (route["grid_mean"][p] - route["mcmc_mean"][p]) / route["mcmc_sd"][p]
        assert route["z"][p] == pytest.approx(z, rel=1e-9)
        assert abs(z) < 0.5
        assert 0.8 < route["sd_ratio"][p] < 1.25
    assert check["verdict"].startswith("identify's grid posterior and the MCMC agree")


def test_the_route_check_catches_a_grid_posterior_that_is_off(deck_file):
    """A grid posterior moved by 5 sd in K is reported as disagreeing: the check looks."""
    record = wb.load_record(deck_file)
    ident = wb.identify(record, seed=0, force_check=False)
    sd_k = ident.posterior_sd["stiffness_n_per_m"]
    moved = ident.replace(draws=ident.draws + np.array([0.0, 5.0 * sd_k]))
    check = crosscheck_surface_route(ident.problem, moved, seed=1)
    assert check.converged
    assert check.agree is False
    assert check.z[1] == pytest.approx(5.0, abs=0.5)  # the MCMC sd is the grid's within 10 %
    assert abs(check.z[0]) < 0.5
    assert "disagree" in check.verdict()


def test_the_help_names_the_surface_model_used_by_default(default_run, capsys):
    with pytest.raises(SystemExit):
        main(["crosscheck", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    named = re.search(
        r"\{coupled,joint,rigid\}\s+how the record's ground_acc enters: (\w+) \(default", help_text
    )
    assert named is not None, help_text
    check, _ = default_run
    assert named.group(1) == check["surface"] == "coupled"


def test_the_route_text_is_rounded_and_worded(default_run, capsys):
    check, _ = default_run
    text = _route_text({**check, "record": "deck"})
    assert not re.search(r"\d\.\d{5,}", text), text
    assert "checks       identify read C and K from the deck's transmissibility" in text
    c_line = next(line for line in text.splitlines() if line.strip().startswith("C  identify"))
    assert f"{check['route_check']['grid_mean']['damping_ns_per_m']:.1f}" in c_line
    assert f"{check['route_check']['mcmc_mean']['damping_ns_per_m']:.1f}" in c_line


def test_filter_options_on_the_route_are_reported_as_unused(deck_file, tmp_path, capsys):
    out, err = _run(
        ["crosscheck", deck_file, "--particles", "64", "--json", "--out", tmp_path], capsys
    )
    assert "workbench: warning: --particles set the per-step filter check" in err
    assert out["warnings"] and "--surface joint" in out["warnings"][0]
    import arviz as az

    idata = az.from_netcdf(out["netcdf"])
    assert set(PARAMS) <= set(idata.posterior.data_vars)


@pytest.mark.parametrize(
    ("has_deck", "surface", "words"),
    [
        (True, "joint", ["joint time-history model", "transmissibility"]),
        (True, "rigid", ["rigid-floor model", "transmissibility"]),
        (True, "coupled", ["fell back to the joint time-history model"]),
        (False, "coupled", ["per-step posterior of the model identify uses"]),
    ],
)
def test_the_per_step_check_says_which_model_it_checks(has_deck, surface, words):
    """Every per-step check names its model; on a deck record, also where identify's C and K
    come from by default (the sentence of the JSON's "checked" and the text's "checks")."""
    from types import SimpleNamespace

    from workbench.cli.crosscheck import _what_is_checked

    record = SimpleNamespace(ground_acc_m_s2=np.zeros(3) if has_deck else None)
    sentence = _what_is_checked(record, surface)
    for word in words:
        assert word in sentence
    assert "transmissibility" not in sentence or has_deck

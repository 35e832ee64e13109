"""The real treadmill record's cross-check (``workbench crosscheck treadmill``): time split.

Usage: ``python analyses/benchmarks/crosscheck_record.py [--reference-rev 0474b1a]
[--reference-steps 30] [--no-reference] [--json]`` (main environment, one pinned core by
default, ``--cores N`` to change; run from a git checkout).

Each run is a fresh process doing what the command does: load the embedded treadmill
record, identify it with the command's settings (rbpf, 256 particles, n = 10), then
:func:`~workbench.inference.crosscheck.check.crosscheck` with the command's defaults (grid
history, surrogate steps, InferenceData built). CPU seconds of the pinned process (all its
threads), split by instrumenting the cross-check's parts in place:

``identification``
    :func:`~workbench.inference.pipeline.identification.identify` (the filter under test).
``grid``
    :meth:`~workbench.inference.crosscheck.history_grid.HistoryGrid.advance`: every step model on
    the grid's nodes, for each step and for the rebuilds from the record's start.
``sampling``
    :func:`~workbench.inference.crosscheck.mcmc.run_ensembles`: emcee and its convergence checks.
``surrogate check``
    :func:`~workbench.inference.crosscheck.step_target.surrogate_error`: every surrogate step's
    exact likelihood at 512 of its draws.
``posterior``
    :func:`~workbench.inference.crosscheck.posterior.completion` and
    :func:`~workbench.inference.crosscheck.posterior.build_inference_data`.
``other``
    The rest of the cross-check (comparison, fits, hand-overs between steps).

Runs: ``current`` (this checkout) over the whole record and over its first
``--reference-steps`` steps, and the named reference, ``workbench`` at git revision
``--reference-rev`` (default 0474b1a, the cross-check before the issue "study-scale speed"),
checked out into a temporary ``git worktree`` and run in its own process over the same
first steps (over the whole record it takes about ten minutes of CPU; ``--reference-steps
0`` runs it to the end). Printed: each run's split, the ratio reference / current of every
part on the common steps, and how far the current run's per-step MCMC means and sds lie from
the reference's there (Monte Carlo error: the samplers differ, the posterior does not).
"""

from __future__ import annotations

import sys

from _cores import affinity, pin_cores

_CORES = pin_cores(sys.argv)

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

PARTS = ("identification", "grid", "sampling", "surrogate check", "posterior", "other")
_ROOT = Path(__file__).resolve().parents[2]


def _child(steps: list[int | None]) -> dict[str, Any]:
    """Identify the treadmill record once, cross-check it for every entry of ``steps``."""
    import time

    import numpy as np

    import workbench.inference.crosscheck.check as cc
    from workbench.datasets import load
    from workbench.inference.crosscheck import history_grid, step_target
    from workbench.inference.pipeline.identification import identify
    from workbench.inference.pipeline.settings import IdentifySettings
    from workbench.records.inspection import inspect_record

    spent = dict.fromkeys(PARTS[1:-1], 0.0)
    depth = [0]

    def timed(part: str, fn: Any) -> Any:
        # Only the outermost timed call counts (a grid rebuild advances the grid inside).
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            depth[0] += 1
            start = time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                depth[0] -= 1
                if depth[0] == 0:
                    spent[part] += time.process_time() - start

        return wrapper

    history_grid.HistoryGrid.advance = timed("grid", history_grid.HistoryGrid.advance)
    cc.run_ensembles = timed("sampling", cc.run_ensembles)
    cc.surrogate_error = timed("surrogate check", step_target.surrogate_error)
    cc.completion = timed("posterior", cc.completion)
    cc.build_inference_data = timed("posterior", cc.build_inference_data)

    import arviz  # noqa: F401  (imported before the clocks start, as the command has it)

    record = load("treadmill")
    # The command's settings; a record with surface motion runs the joint surface model.
    moving = getattr(record, "ground_acc_m_s2", None) is not None
    settings = IdentifySettings().replace(
        method="rbpf", seed=0, force_check=False, surface="joint" if moving else None
    )
    insp = inspect_record(record, highpass_hz=settings.preprocessing.highpass_hz)
    c0 = time.process_time()
    ident = identify(insp, settings=settings, progress=False)
    ident_cpu = time.process_time() - c0
    runs = []
    for n in steps:
        for part in spent:
            spent[part] = 0.0
        c0 = time.process_time()
        res = cc.crosscheck(ident.problem, ident, seed=0, max_pieces=n)
        total = time.process_time() - c0
        split = dict(spent)
        split["other"] = total - sum(spent.values())
        runs.append(
            {
                "steps": len(res.steps),
                "cpu_seconds": total,
                "split": split,
                "agreement": res.agreement,
                "converged": sum(s.converged for s in res.steps),
                "tau_max": float(max(np.max(s.mcmc.tau) for s in res.steps)),
                "chain_steps_mean": float(np.mean([s.mcmc.n_steps for s in res.steps])),
                "mean": [s.mcmc_mean.tolist() for s in res.steps],
                "sd": [s.mcmc_sd.tolist() for s in res.steps],
            }
        )
    return {"identification": ident_cpu, "runs": runs}


def _spawn(root: Path, steps: list[int | None]) -> dict[str, Any]:
    """Run :func:`_child` in a fresh process importing ``workbench`` from ``root``."""
    env = dict(os.environ, PYTHONPATH=str(root))
    cmd = [sys.executable, __file__, "--child", json.dumps(steps), "--cores", str(_CORES)]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if out.returncode:
        raise SystemExit(f"the run from {root} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _reference(rev: str, steps: list[int | None]) -> dict[str, Any]:
    """Run :func:`_child` at git revision ``rev``, from a temporary worktree (removed after)."""
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "reference"
        subprocess.run(
            ["git", "-C", str(_ROOT), "worktree", "add", "--detach", str(tree), rev],
            check=True,
            capture_output=True,
        )
        try:
            return _spawn(tree, steps)
        finally:
            subprocess.run(
                ["git", "-C", str(_ROOT), "worktree", "remove", "--force", str(tree)],
                check=False,
                capture_output=True,
            )


def _row(name: str, ident: float, run: dict[str, Any]) -> str:
    split = run["split"]
    cells = " ".join(f"{split[p]:>9.1f}" for p in PARTS[1:])
    return (
        f"{name:<22} {run['steps']:>5} {ident:>9.1f} {cells} {run['cpu_seconds']:>9.1f} "
        f"{run['cpu_seconds'] / run['steps']:>7.3f} {run['agreement']:>6.3f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--reference-rev", default="0474b1a", help="named reference (0474b1a)")
    parser.add_argument(
        "--reference-steps", type=int, default=30, help="steps compared (30; 0: all)"
    )
    parser.add_argument("--no-reference", action="store_true", help="skip the reference")
    parser.add_argument("--cores", type=int, default=1, help="CPUs (pinned; default 1)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        print(json.dumps(_child(json.loads(args.child))))
        return

    common = args.reference_steps or None
    current = _spawn(_ROOT, [None] if common is None else [None, common])
    cur_all = current["runs"][0]
    cur_common = current["runs"][-1]
    reference = None if args.no_reference else _reference(args.reference_rev, [common])
    result: dict[str, Any] = {
        "benchmark": "crosscheck_record",
        "record": "treadmill",
        "reference": f"workbench at git revision {args.reference_rev}",
        "current": current,
        "reference_run": reference,
        "environment": {"cores_used": _CORES, "affinity": affinity()},
    }
    if reference is not None:
        ref = reference["runs"][0]
        ratio = {p: ref["split"][p] / max(cur_common["split"][p], 1e-9) for p in PARTS[1:]}
        ratio["identification"] = reference["identification"] / current["identification"]
        ratio["cross-check"] = ref["cpu_seconds"] / cur_common["cpu_seconds"]
        import numpy as np

        m_ref, s_ref = np.array(ref["mean"]), np.array(ref["sd"])
        m_cur, s_cur = np.array(cur_common["mean"]), np.array(cur_common["sd"])
        result["ratio_reference_over_current"] = ratio
        result["mean_diff_sd_max"] = float(np.max(np.abs(m_cur - m_ref) / s_ref))
        result["sd_rel_diff_max"] = float(np.max(np.abs(s_cur / s_ref - 1)))
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(
        f"treadmill record, workbench crosscheck defaults, {_CORES} core(s), CPU seconds; "
        f"target: the whole command under 120 s"
    )
    head = " ".join(f"{p[:9]:>9}" for p in PARTS)
    print(f"{'run':<22} {'steps':>5} {head} {'cc total':>9} {'s/step':>7} {'agree':>6}")
    print(_row("current", current["identification"], cur_all))
    total = current["identification"] + cur_all["cpu_seconds"]
    if common is not None:
        print(_row("current", current["identification"], cur_common))
    if reference is not None:
        print(_row(f"reference {args.reference_rev}", reference["identification"], ref))
        cells = " ".join(f"{result['ratio_reference_over_current'][p]:>9.1f}" for p in PARTS)
        print(
            f"{'ratio ref / current':<22} {'':>5} {cells} "
            f"{result['ratio_reference_over_current']['cross-check']:>9.1f}"
        )
        print(
            f"current vs reference per step: means within {result['mean_diff_sd_max']:.3f} "
            f"MCMC sd, sds within {100 * result['sd_rel_diff_max']:.1f} %"
        )
    print(f"whole command (identification + cross-check), current: {total:.1f} CPU s")


if __name__ == "__main__":
    main()

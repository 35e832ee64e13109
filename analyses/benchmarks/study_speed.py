"""Study-scale speed: one record with every check, a mixed batch, a sensitivity study.

The issue's must-show figures are one command each, and one script: each part needs its
own child process (pinned cores, a fresh interpreter for every worker count and for the
previous revision), its table and its JSON, and all parts share one measurement protocol.

Usage::

    python analyses/benchmarks/study_speed.py --record [--batch] [--sensitivity]
        [--reference-revision 0474b1a] [--json]

Every timing runs in a fresh child process of this script (``--child``), with the numerical
libraries' thread pools capped at one thread, so that the revision under test and the
previous revision are measured alike.

``--record``: ``workbench.identify(record)`` with its defaults (noise estimate, the exact
posterior, identifiability and force-model checks; a deck record takes the deck route) on the
embedded 30 s, 200 Hz walks ``seed_individual`` (rigid floor) and ``seed_individual_deck``
(deck), the child pinned to one core. Printed: the first call in a fresh process (``cold``:
compiled kernels loaded from numba's cache, first-use imports) and the best of ``--repeats``
further calls (``warm``), wall and CPU seconds; ``|z|``, the distance of the posterior mean of
C and K from the exact posterior mean (``method="exact"``, the grid's moments, not its draws)
in exact posterior sd. Named references of the same run: the Rao-Blackwellised filter
(``method="rbpf"``, the default before the exact posterior became cheap), the seed-faithful
particle filter (``method="pf"``; on the deck record on the joint time history,
``--pf-deck-surface``, because ``identify`` would otherwise route it through the deck like the
default) and the previous implementation (``--reference-revision``, checked out into a
temporary git worktree and run by the same child code).

``--batch``: ``--batch-records`` (default 64) realistic records (the recovery study's
simulated walkers, half on a vibrating deck, half on a rigid floor, 20-35 s, 100-200 Hz) are
written to a temporary folder with a manifest, and ``run_batch`` identifies them with default
settings once with one worker and once with two. Printed: wall time, whether ``results.csv``
and ``failures.csv`` are byte-identical, peak resident memory of the parent and of the
largest worker, and the projected wall time of the 1528-record study on two workers. The
projection fits each floor's per-record time (``timings.csv`` of the one-worker run) as a
straight line in the number of samples, averages it over the study's mix (duration uniform
on 20-35 s, rate uniform on 100-200 Hz, ``--deck-fraction`` on decks), and divides by the
measured speed-up of two workers. With a reference revision, the first
``--reference-batch-records`` records also run with it (one worker) for a per-record ratio.

``--sensitivity``: ``workbench sensitivity RECORD --out DIR --workers 2`` with the default
one-at-a-time design on a 30 s record, as a user would type it (not ``--json``, so the
progress bar is on); the child reads the command's stderr as it comes and reports when the
bar first appeared and how many distinct counts it showed.

Nothing here asserts a time: read the seconds with the load average printed beside them.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from _revision import Revision

HERE = Path(__file__).resolve()
REPO = HERE.parents[2]
STUDY_RECORDS = 1528
#: The study's mix of records (duration [s], sample rate [Hz]), each drawn uniformly.
STUDY_DURATION_S = (20.0, 35.0)
STUDY_RATE_HZ = (100.0, 200.0)
RECORDS = {"seed_individual": "rigid", "seed_individual_deck": "deck"}
#: The issue's targets, printed beside the measurements (never asserted).
TARGET_RECORD_S = 1.0
TARGET_Z = 0.2
TARGET_STUDY_MIN = 15.0
TARGET_SENSITIVITY_MIN = 3.0
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


# --------------------------------------------------------------------------- child processes


def _child_env(pythonpath: str | None) -> dict[str, str]:
    """Environment of a child: one thread per process pool; the workbench to import."""
    env = dict(os.environ)
    for var in _THREAD_VARS:
        env[var] = "1"
    env["PYTHONPATH"] = pythonpath if pythonpath is not None else str(REPO)
    return env


def _spawn(child_args: list[str], pythonpath: str | None = None) -> dict[str, Any]:
    """Run this script as a child (``--child ...``) and return the JSON it prints last."""
    proc = subprocess.run(
        [sys.executable, str(HERE), "--child", *child_args],
        env=_child_env(pythonpath),
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        raise SystemExit(f"child {' '.join(child_args)} failed:\n{proc.stderr[-3000:]}")
    return dict(json.loads(proc.stdout.strip().splitlines()[-1]))


def _pin(cores: int) -> list[int]:
    """Pin this process to its first ``cores`` allowed CPUs (Linux); return them."""
    if not hasattr(os, "sched_setaffinity"):
        return []
    allowed = sorted(os.sched_getaffinity(0))
    os.sched_setaffinity(0, set(allowed[:cores]))
    return sorted(os.sched_getaffinity(0))


def _moments(result: Any) -> dict[str, list[float]]:
    est, sd = result.estimates, result.posterior_sd
    keys = ("damping_ns_per_m", "stiffness_n_per_m")
    return {"mean": [float(est[k]) for k in keys], "sd": [float(sd[k]) for k in keys]}


def _child_record(args: argparse.Namespace) -> dict[str, Any]:
    """Time ``identify`` on one embedded record in this (pinned) process."""
    cpus = _pin(1)
    t0, c0 = time.perf_counter(), time.process_time()
    import workbench as wb

    record = wb.datasets.load(args.name)
    import_s = [time.perf_counter() - t0, time.process_time() - c0]
    deck = RECORDS.get(args.name) == "deck"
    runs: dict[str, dict[str, Any]] = {}
    calls: dict[str, Any] = {"default": lambda: wb.identify(record)}
    methods = set(args.methods.split(","))
    if "exact" in methods:
        calls["exact"] = lambda: wb.identify(record, method="exact")
    if "rbpf" in methods:
        calls["rbpf"] = lambda: wb.identify(record, method="rbpf")
    if "pf" in methods:
        # identify() sends a deck record through the transmissibility whatever the method:
        # the seed-faithful filter is only a reference on the time history.
        model = wb.SMDModel(surface=args.pf_deck_surface) if deck else None
        calls["pf"] = lambda: wb.identify(record, model, method="pf")
    for name, call in calls.items():
        walls, cpus_s = [], []
        result = None
        # The default's first call is the cold one (kernels loaded, caches filled).
        for _ in range(args.repeats + (1 if name == "default" else 0)):
            w0, p0 = time.perf_counter(), time.process_time()
            out = call()
            walls.append(time.perf_counter() - w0)
            cpus_s.append(time.process_time() - p0)
            result = result or out
        assert result is not None
        row: dict[str, Any] = {
            "method": result.method,
            "cold": name == "default",
            "wall_s": walls,
            "cpu_s": cpus_s,
            "route": result.route is not None and result.route.through_surface,
            "identifiability": result.identifiability.get("level"),
            "trustworthy": bool(result.trustworthy),
            "obs_fraction": result.noise.get("obs_fraction"),
            **_moments(result),
        }
        if name == "exact":
            assert result.grid_results is not None  # the exact grid
            grid = result.grid_results.to_json()
            row["grid_mean"] = [grid["damping_ns_per_m"], grid["stiffness_n_per_m"]]
            row["grid_sd"] = [
                grid["posterior_sd"]["damping_ns_per_m"],
                grid["posterior_sd"]["stiffness_n_per_m"],
            ]
        runs[name] = row
    return {
        "name": args.name,
        "floor": RECORDS.get(args.name, "?"),
        "n_samples": int(record.n_samples),
        "duration_s": float(record.duration_s),
        "rate_hz": round(float(record.sample_rate_hz), 3),
        "import_s": import_s,
        "cpus": cpus,
        "workbench": str(Path(wb.__file__).resolve().parents[1]),
        "runs": runs,
    }


def _child_batch(args: argparse.Namespace) -> dict[str, Any]:
    """Run one batch in this process; report time and the memory of parent and workers."""
    import resource

    cpus = _pin(args.workers)
    from workbench.inference.pipeline.settings import IdentifySettings
    from workbench.population.batch import run_batch

    w0, c0 = time.perf_counter(), time.process_time()
    summary = run_batch(args.manifest, args.out, settings=IdentifySettings(), workers=args.workers)
    wall = time.perf_counter() - w0
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return {
        "workers": args.workers,
        "cpus": cpus,
        "wall_s": wall,
        "cpu_s_self": time.process_time() - c0,
        "cpu_s_workers": kids.ru_utime + kids.ru_stime,
        # ru_maxrss is in KiB on Linux; for the children it is the largest one's.
        "peak_mb_parent": me.ru_maxrss / 1024,
        "peak_mb_largest_worker": kids.ru_maxrss / 1024 if args.workers > 1 else None,
        "done": summary.done,
        "failed": summary.failed,
        "failures": summary.failures,
    }


_BAR = re.compile(r"sensitivity:\s*\d+%.*?\|\s*(\d+)/(\d+)")


def _child_command(args: argparse.Namespace) -> dict[str, Any]:
    """Run a command, reading its stderr as it comes: when progress first shows, and how often."""
    import resource

    cpus = _pin(args.workers)
    w0 = time.perf_counter()
    proc = subprocess.Popen(args.cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    assert proc.stderr is not None
    text, first_bar_s, counts = "", None, set[int]()
    while chunk := os.read(proc.stderr.fileno(), 4096):
        text += chunk.decode(errors="replace")
        found = _BAR.findall(text[-8192:])
        if found and first_bar_s is None:
            first_bar_s = time.perf_counter() - w0
        counts.update(int(done) for done, _ in found)
    code = proc.wait()
    wall = time.perf_counter() - w0
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    total = _BAR.findall(text)
    return {
        "returncode": code,
        "cpus": cpus,
        "wall_s": wall,
        "cpu_s": kids.ru_utime + kids.ru_stime,
        "peak_mb_largest_process": kids.ru_maxrss / 1024,
        "progress_first_shown_s": first_bar_s,
        "progress_counts_shown": len(counts),
        "runs": int(total[-1][1]) if total else None,
        "stderr_tail": text[-600:] if code else "",
    }


# --------------------------------------------------------------------------- references


# --------------------------------------------------------------------------- part (a)


def _z(row: dict[str, Any], exact: dict[str, Any]) -> list[float]:
    pairs = zip(row["mean"], exact["grid_mean"], exact["grid_sd"], strict=True)
    return [abs(m - e) / s for m, e, s in pairs]


def part_record(args: argparse.Namespace, revision: Revision | None) -> dict[str, Any]:
    """Part (a), with the pf and the previous revision as references."""
    out: dict[str, Any] = {}
    for name in args.records:
        new = _spawn(
            [
                *("record", "--name", name, "--repeats", str(args.repeats)),
                *("--methods", "exact,rbpf,pf", "--pf-deck-surface", args.pf_deck_surface),
            ]
        )
        exact = new["runs"]["exact"]
        for row in new["runs"].values():
            row["abs_z"] = _z(row, exact)
        if revision is not None:
            old = _spawn(
                [
                    "record",
                    "--name",
                    name,
                    "--repeats",
                    str(args.reference_repeats),
                    "--methods",
                    "-",
                ],
                pythonpath=str(revision.path),
            )
            row = old["runs"]["default"]
            row["abs_z"] = _z(row, exact)
            new["runs"]["previous"] = row
            new["previous_workbench"] = old["workbench"]
        out[name] = new
    return out


def _best(row: dict[str, Any], key: str) -> float:
    """Best warm time: the default's first call is the cold one, left out when others ran."""
    values = row[key][1:] if row["cold"] and len(row[key]) > 1 else row[key]
    return float(min(values))


def _record_table(part: dict[str, Any], revision: str | None) -> list[str]:
    lines = [
        f"(a) one record, defaults with every check, one pinned core; warm = best of the "
        f"repeats after the first (cold) call; |z| vs the exact grid posterior; targets "
        f"< {TARGET_RECORD_S:g} s and |z| < {TARGET_Z:g}",
        f"{'record':<22}{'run':<12}{'method':<7}{'cold wall':>10}{'cold cpu':>9}{'warm wall':>10}"
        f"{'warm cpu':>9}{'C':>8}{'K':>8}{'|z| C':>7}{'|z| K':>7}  identifiability",
    ]
    for name, rec in part.items():
        runs = rec["runs"]
        for run, row in runs.items():
            cw = f"{row['wall_s'][0]:>10.2f}" if row["cold"] else f"{'-':>10}"
            cc = f"{row['cpu_s'][0]:>9.2f}" if row["cold"] else f"{'-':>9}"
            ww, wc = _best(row, "wall_s"), _best(row, "cpu_s")
            label = {"previous": f"@{revision}", "pf": "pf ref", "rbpf": "rbpf ref"}.get(run, run)
            if run == "pf" and rec["floor"] == "deck":
                label = "pf ref (jt)"
            lines.append(
                f"{name:<22}{label:<12}{row['method']:<7}{cw}{cc}{ww:>10.2f}{wc:>9.2f}"
                f"{row['mean'][0]:>8.0f}{row['mean'][1]:>8.0f}{row['abs_z'][0]:>7.2f}"
                f"{row['abs_z'][1]:>7.2f}  {row['identifiability']}"
            )
        d = runs["default"]
        wc = _best(d, "cpu_s")
        ratios = [f"x pf {wc / _best(runs['pf'], 'cpu_s'):.2f}"]
        if "rbpf" in runs:
            ratios.append(f"x rbpf {wc / _best(runs['rbpf'], 'cpu_s'):.2f}")
        if "previous" in runs:
            ratios.append(f"x {revision} {wc / _best(runs['previous'], 'cpu_s'):.3f}")
        met = wc < TARGET_RECORD_S and max(d["abs_z"]) < TARGET_Z
        lines.append(
            f"{'':<22}default warm CPU {wc:.2f} s: {', '.join(ratios)} (CPU ratios, new / "
            f"reference); {rec['n_samples']} samples; targets {'met' if met else 'NOT met'}"
        )
    return lines


# --------------------------------------------------------------------------- part (b)


def _write_batch(folder: Path, n: int, seed: int, deck_fraction: float) -> Any:
    """Simulate ``n`` realistic records (deck and rigid) and write them with a manifest."""
    import numpy as np
    import pandas as pd

    from workbench.population.recovery_design import (
        RecoveryDesign,
        recovery_plan,
        simulate_recovery_record,
    )
    from workbench.records.io import save_record

    n_deck = round(n * deck_fraction)
    plans = []
    for floor, count, salt in (("deck", n_deck, 0), ("rigid", n - n_deck, 1)):
        if count == 0:
            continue
        design = RecoveryDesign(
            floor=floor, n_records=max(count, 8), ranges={"duration_s": STUDY_DURATION_S}
        )
        # Another seed per floor: one seed would give both floors the same walkers.
        plan = recovery_plan(design, seed=seed + salt).head(count).copy()
        plan["floor"] = floor
        plans.append(plan)
    plan = pd.concat(plans, ignore_index=True)
    rng = np.random.default_rng([seed, 0xBA7C])
    plan["sample_rate_hz"] = np.round(rng.uniform(*STUDY_RATE_HZ, len(plan)))
    plan["record"] = [f"{f}{i:03d}" for i, f in enumerate(plan["floor"])]
    plan["path"] = [f"records/{r}.csv" for r in plan["record"]]
    (folder / "records").mkdir(parents=True, exist_ok=True)
    for row in plan.to_dict(orient="records"):
        rec = simulate_recovery_record(row, float(row["sample_rate_hz"]))
        save_record(rec.replace(subject=str(row["record"])), folder / row["path"])
    plan["n_samples"] = np.round(plan["duration_s"] * plan["sample_rate_hz"]).astype(int)
    plan[["path", "mass_kg"]].to_csv(folder / "manifest.csv", index=False, float_format="%.10g")
    return plan


def _projection(plan: Any, timings: Any, deck_fraction: float) -> dict[str, Any]:
    """Mean seconds per record over the study's mix, from a line in samples per floor."""
    import numpy as np

    merged = plan.merge(timings[timings["status"] == "done"], on="path")
    mean_samples = np.mean(STUDY_DURATION_S) * np.mean(STUDY_RATE_HZ)
    fits: dict[str, Any] = {}
    per_record = 0.0
    for floor, weight in (("deck", deck_fraction), ("rigid", 1.0 - deck_fraction)):
        sub = merged[merged["floor"] == floor]
        if weight == 0:
            continue
        if len(sub) < 3:
            raise SystemExit(f"too few {floor} records identified to fit their time")
        x, y = sub["n_samples"].to_numpy(float), sub["elapsed_s"].to_numpy(float)
        slope, intercept = np.polyfit(x, y, 1)
        r2 = 1 - np.sum((y - (intercept + slope * x)) ** 2) / np.sum((y - y.mean()) ** 2)
        at_mean = intercept + slope * mean_samples
        fits[floor] = {
            "records": len(sub),
            "intercept_s": float(intercept),
            "s_per_1000_samples": float(1000 * slope),
            "r2": float(r2),
            "mean_s": float(y.mean()),
            "at_study_mean_s": float(at_mean),
        }
        per_record += weight * at_mean
    return {"study_mean_samples": float(mean_samples), "fits": fits, "s_per_record": per_record}


def part_batch(args: argparse.Namespace, revision: Revision | None) -> dict[str, Any]:
    """Part (b): one and two workers on the same mixed manifest; the study projection."""
    import pandas as pd

    tmp = Path(tempfile.mkdtemp(prefix="workbench-batch-"))
    try:
        t0 = time.perf_counter()
        plan = _write_batch(tmp, args.batch_records, args.seed, args.deck_fraction)
        simulate_s = time.perf_counter() - t0
        runs = {}
        for workers in (1, 2):
            runs[workers] = _spawn(
                [
                    *("batch", "--manifest", str(tmp / "manifest.csv")),
                    *("--out", str(tmp / f"out{workers}"), "--workers", str(workers)),
                ]
            )
        same = {
            f: (tmp / "out1" / f).read_bytes() == (tmp / "out2" / f).read_bytes()
            for f in ("results.csv", "failures.csv")
        }
        diff: dict[str, Any] | None = None
        if not same["results.csv"]:
            a = pd.read_csv(tmp / "out1" / "results.csv")
            b = pd.read_csv(tmp / "out2" / "results.csv")
            diff = {"rows": [len(a), len(b)]}
            if a.shape == b.shape:
                num = a.select_dtypes("number").columns
                rel = ((a[num] - b[num]).abs() / b[num].abs().clip(lower=1e-300)).max()
                diff["max_rel_diff"] = {k: float(v) for k, v in rel.items() if v > 0}
        timings = pd.read_csv(tmp / "out1" / "timings.csv")
        projection = _projection(plan, timings, args.deck_fraction)
        speedup = runs[1]["wall_s"] / runs[2]["wall_s"]
        projection["speedup_2_workers"] = speedup
        projection["study_min_2_workers"] = (
            STUDY_RECORDS * projection["s_per_record"] / speedup / 60
        )
        projection["study_min_2_workers_naive"] = runs[2]["wall_s"] * STUDY_RECORDS / len(plan) / 60
        # On a shared machine the wall times carry other users' load; CPU seconds do not. The
        # same projection from CPU time, two workers given two whole cores (their own CPU
        # overhead, e.g. loading the compiled kernels in each process, kept in).
        cpu_share = runs[1]["cpu_s_self"] / runs[1]["wall_s"]
        overhead = runs[2]["cpu_s_workers"] / runs[1]["cpu_s_self"]
        projection["cpu_share_1_worker"] = cpu_share
        projection["cpu_overhead_2_workers"] = overhead
        projection["study_min_2_idle_cores"] = (
            STUDY_RECORDS * projection["s_per_record"] * cpu_share * overhead / 2 / 60
        )
        reference = None
        if revision is not None and args.reference_batch_records > 0:
            sub = pd.concat(
                [
                    plan[plan["floor"] == f].head(args.reference_batch_records // 2)
                    for f in ("deck", "rigid")
                ]
            )
            sub[["path", "mass_kg"]].to_csv(tmp / "manifest_ref.csv", index=False)
            ref = _spawn(
                [
                    *("batch", "--manifest", str(tmp / "manifest_ref.csv")),
                    *("--out", str(tmp / "out_ref"), "--workers", "1"),
                ],
                pythonpath=str(revision.path),
            )
            old = pd.read_csv(tmp / "out_ref" / "timings.csv").set_index("path")["elapsed_s"]
            new = timings.set_index("path")["elapsed_s"].reindex(old.index)
            reference = {
                "records": len(old),
                "previous_s": float(old.sum()),
                "new_s": float(new.sum()),
                "ratio": float(new.sum() / old.sum()),
                "failed": ref["failed"],
            }
        per_record = timings.merge(plan[["path", "floor", "duration_s", "sample_rate_hz"]])
        return {
            "records": len(plan),
            "deck_records": int((plan["floor"] == "deck").sum()),
            "duration_s": [float(plan["duration_s"].min()), float(plan["duration_s"].max())],
            "rate_hz": [float(plan["sample_rate_hz"].min()), float(plan["sample_rate_hz"].max())],
            "simulate_s": simulate_s,
            "runs": {str(k): v for k, v in runs.items()},
            "identical": same,
            "difference": diff,
            "projection": projection,
            "reference": reference,
            "per_record": per_record.to_dict(orient="records"),
        }
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _batch_table(part: dict[str, Any], revision: str | None) -> list[str]:
    p = part["projection"]
    lines = [
        f"(b) batch of {part['records']} records ({part['deck_records']} deck), "
        f"{part['duration_s'][0]:.1f}-{part['duration_s'][1]:.1f} s, "
        f"{part['rate_hz'][0]:.0f}-{part['rate_hz'][1]:.0f} Hz, default settings "
        f"(simulated in {part['simulate_s']:.0f} s)",
        f"{'workers':>8}{'wall s':>9}{'s/record':>10}{'cpu s workers':>14}{'done':>6}"
        f"{'failed':>7}{'peak MB parent':>15}{'peak MB worker':>15}",
    ]
    for w, r in part["runs"].items():
        worker = r["peak_mb_largest_worker"] or r["peak_mb_parent"]
        cpu = r["cpu_s_workers"] if int(w) > 1 else r["cpu_s_self"]
        lines.append(
            f"{w:>8}{r['wall_s']:>9.1f}{r['wall_s'] / part['records']:>10.2f}{cpu:>14.1f}"
            f"{r['done']:>6}{r['failed']:>7}{r['peak_mb_parent']:>15.0f}{worker:>15.0f}"
        )
    lines.append(
        f"results.csv identical 1 vs 2 workers: {part['identical']['results.csv']}; "
        f"failures.csv: {part['identical']['failures.csv']}"
        + (f"; difference {part['difference']}" if part["difference"] else "")
    )
    for floor, f in p["fits"].items():
        lines.append(
            f"  {floor}: {f['records']} records, {f['intercept_s']:.2f} s + "
            f"{f['s_per_1000_samples']:.3f} s per 1000 samples (R^2 {f['r2']:.2f}); "
            f"{f['at_study_mean_s']:.2f} s at the study's mean {p['study_mean_samples']:.0f}"
        )
    lines.append(
        f"projected {STUDY_RECORDS} records on 2 workers: {p['study_min_2_workers']:.1f} min "
        f"({p['s_per_record']:.2f} s per record on one worker, 2-worker speed-up "
        f"{p['speedup_2_workers']:.2f}; this batch's mix scaled: "
        f"{p['study_min_2_workers_naive']:.1f} min); target < {TARGET_STUDY_MIN:g} min"
    )
    lines.append(
        f"  from CPU time, two idle cores: {p['study_min_2_idle_cores']:.1f} min (the one-worker "
        f"run got {100 * p['cpu_share_1_worker']:.0f} % of its core; two workers spent "
        f"{p['cpu_overhead_2_workers']:.2f} x its CPU)"
    )
    ref = part.get("reference")
    if ref:
        lines.append(
            f"previous implementation @{revision}, {ref['records']} of these records on one "
            f"worker: {ref['previous_s']:.1f} s, new {ref['new_s']:.1f} s: x {ref['ratio']:.3f}"
        )
    return lines


# --------------------------------------------------------------------------- part (c)


def part_sensitivity(args: argparse.Namespace) -> dict[str, Any]:
    """Part (c): the sensitivity command as typed, two workers, progress bar on."""
    tmp = Path(tempfile.mkdtemp(prefix="workbench-sens-"))
    try:
        record = args.sensitivity_record
        if not Path(record).exists():
            # The sensitivity command takes a file or a manifest, not an embedded name.
            import workbench as wb
            from workbench.records.io import save_record

            record = str(save_record(wb.datasets.load(record), tmp / f"{record}.csv")[0])
        cmd = [sys.executable, "-m", "workbench", "sensitivity", record]
        cmd += ["--out", str(tmp / "out"), "--workers", "2"]
        out = _spawn(["command", "--workers", "2", "--", *cmd])
        out["command"] = f"workbench sensitivity {args.sensitivity_record} --out DIR --workers 2"
        return out
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _sensitivity_table(part: dict[str, Any]) -> list[str]:
    shown = part["progress_first_shown_s"]
    return [
        f"(c) {part['command']} (default design); target < {TARGET_SENSITIVITY_MIN:g} min",
        f"    exit {part['returncode']}, {part['runs']} runs, wall {part['wall_s'] / 60:.2f} min, "
        f"CPU {part['cpu_s'] / 60:.2f} min, largest process {part['peak_mb_largest_process']:.0f}"
        f" MB; progress bar first shown after "
        + (f"{shown:.1f} s, {part['progress_counts_shown']} counts" if shown else "never")
        + (f"\n    stderr: {part['stderr_tail']}" if part["stderr_tail"] else ""),
    ]


# --------------------------------------------------------------------------- main


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    p.add_argument("--record", action="store_true", help="part (a): one record, all checks")
    p.add_argument("--batch", action="store_true", help="part (b): mixed batch, 1 vs 2 workers")
    p.add_argument("--sensitivity", action="store_true", help="part (c): sensitivity command")
    p.add_argument(
        "--reference-revision",
        metavar="REV",
        help="previous implementation to measure alike (git revision; e.g. 0474b1a)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--save", metavar="FILE", help="also write the JSON object to FILE")
    p.add_argument("--records", nargs="+", default=list(RECORDS), metavar="NAME")
    p.add_argument("--repeats", type=int, default=3, help="warm calls per method (part a)")
    p.add_argument("--reference-repeats", type=int, default=1, help="warm calls, previous rev.")
    p.add_argument("--pf-deck-surface", default="joint", choices=["joint", "rigid"])
    p.add_argument("--batch-records", type=int, default=64)
    p.add_argument("--reference-batch-records", type=int, default=4)
    p.add_argument("--deck-fraction", type=float, default=0.5, help="of the batch and study")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--sensitivity-record", default="seed_individual", metavar="NAME_OR_FILE")
    # The child processes: this script re-run with one job each.
    p.add_argument("--child", choices=["record", "batch", "command"], help=argparse.SUPPRESS)
    p.add_argument("--name", help=argparse.SUPPRESS)
    p.add_argument("--methods", default="exact,rbpf,pf", help=argparse.SUPPRESS)
    p.add_argument("--manifest", help=argparse.SUPPRESS)
    p.add_argument("--out", help=argparse.SUPPRESS)
    p.add_argument("--workers", type=int, default=1, help=argparse.SUPPRESS)
    p.add_argument("cmd", nargs="*", help=argparse.SUPPRESS)
    return p


def _environment() -> dict[str, Any]:
    head = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
        capture_output=True,
        text=True,
        check=False,
    ).stdout.strip()
    return {
        "revision": head,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "load_average": list(os.getloadavg()),
        "date": time.strftime("%Y-%m-%d %H:%M"),
    }


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the chosen parts and print their tables (or one JSON object)."""
    args = _parser().parse_args(argv)
    if args.child:
        child = {"record": _child_record, "batch": _child_batch, "command": _child_command}
        done = child[args.child](args)
        print(json.dumps(done))
        return done
    if not (args.record or args.batch or args.sensitivity):
        raise SystemExit("choose at least one part: --record, --batch, --sensitivity")
    result: dict[str, Any] = {
        "benchmark": "study_speed",
        "references": {
            "record": ["pf", args.reference_revision],
            "batch": ["1 worker", args.reference_revision],
        },
        "environment_before": _environment(),
    }
    revision = Revision(args.reference_revision) if args.reference_revision else None
    try:
        if revision is not None:
            revision.__enter__()
        if args.record:
            result["record"] = part_record(args, revision)
        if args.batch:
            result["batch"] = part_batch(args, revision)
        if args.sensitivity:
            result["sensitivity"] = part_sensitivity(args)
    finally:
        if revision is not None:
            revision.__exit__(None, None, None)
    result["environment_after"] = _environment()
    if args.save:
        Path(args.save).write_text(json.dumps(result, indent=2, default=str) + "\n")
    if args.json:
        print(json.dumps(result, indent=2, default=str))
        return result
    env, after = result["environment_before"], result["environment_after"]
    lines = [
        f"study_speed at {env['revision']}, Python {env['python']}, {env['cpu_count']} CPUs, "
        f"load average {env['load_average'][0]:.2f} before, {after['load_average'][0]:.2f} after"
    ]
    if "record" in result:
        lines += ["", *_record_table(result["record"], args.reference_revision)]
    if "batch" in result:
        lines += ["", *_batch_table(result["batch"], args.reference_revision)]
    if "sensitivity" in result:
        lines += ["", *_sensitivity_table(result["sensitivity"])]
    print("\n".join(lines))
    return result


if __name__ == "__main__":
    main()

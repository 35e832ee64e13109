r"""Check that the working tree's code gives the same command results as a pinned revision.

A refactor that promises "no change of behaviour" (issue 32) is checked by running the same
commands, with the same seeds, on the same records, with the code of a pinned revision and
with the code of the working tree, and comparing their JSON (and the batch's CSV and JSON
files) tree by tree.

Usage::

    python analyses/behaviour_check.py --against main
    python analyses/behaviour_check.py --against 2fc45e5 --records seed_individual \\
        --commands identify,diagnose --out behaviour-check/
    python analyses/behaviour_check.py --list        # the records and commands it knows

How it works:

1. ``git worktree add --detach TMP REV`` materialises REV in a temporary folder (removed at
   the end, also on an error or Ctrl-C). Each command runs as ``python -m workbench ...``
   with the same interpreter as this script, once with ``PYTHONPATH`` and the current
   folder set to that worktree ("before") and once to this repository's root ("after").
2. The records: the embedded synthetic records (rigid floor, deck, the seed's numerical
   example), a model with an effect, and the two real records cut to a short stretch
   (written to a temporary folder both sides read, with the body mass on the command line).
3. The outputs are compared as trees: same keys and structure; strings equal (after the
   temporary folders are replaced by placeholders); numbers equal to a relative tolerance
   with an absolute floor. Keys that legitimately differ are listed in ``IGNORED_KEYS``.
4. Each record x command is reported as ``identical``, ``equal to rounding``, ``DIFFERENT``
   or ``not comparable`` (a command or flag that REV lacks: it fails on both sides with a
   usage error). A command that fails on one side only is a difference; its stderr is
   quoted. The exit status is 0 only if everything compared is identical or equal to
   rounding.

Running every default case (26) takes 10-15 minutes on two cores (the first command on each
side also compiles the numba kernels of that tree).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

# --- What legitimately differs between two runs of the same behaviour -------------------

#: Keys (at any depth) left out of the comparison, with the reason. Everything else must
#: agree.
IGNORED_KEYS: dict[str, str] = {
    "elapsed_s": "wall time of a run, different from run to run",
    "wall_s": "wall time",
    "seconds": "wall time of crosscheck's MCMC (all steps, or one step's ensembles)",
    "seconds_per_step": "wall time of crosscheck's MCMC per step",
    "timings": "wall times",
    "version": "the package version may be bumped by the change under test",
    "workbench_version": "the package version may be bumped by the change under test",
    "revision": "the git revision is what differs by construction",
    "git_revision": "the git revision is what differs by construction",
    "created": "time stamp of the run",
    "created_utc": "time stamp of the run",
}

#: Batch output files left out, with the reason (paths relative to the batch's --out).
IGNORED_FILES: dict[str, str] = {
    "timings.csv": "wall times, the one batch output that differs from run to run (contracts)",
    "timings": "each record's wall time (contracts)",
}

# --- Tolerances --------------------------------------------------------------------------

#: Relative tolerance on numbers. A refactor that only moves code may still reorder
#: floating-point operations (a sum split in two, a product regrouped), which changes a
#: result by a few units in the last place, amplified at most modestly by the filters and
#: optimisers; 1e-6 relative is far above that and far below any change of a model, a
#: prior, a default or a formula (those move results by 1e-3 or more).
DEFAULT_RTOL = 1e-6
#: Absolute floor: a value that should be zero (a mean residual, a correlation of
#: independent terms, a coefficient of a harmonic the record lacks) comes out as rounding
#: noise of order 1e-16 times the size of the terms that cancelled (forces of 1e3 N,
#: stiffnesses of 1e4 N/m), whose relative difference means nothing. 1e-9 is well above
#: that noise and well below the smallest quantity the workbench reports (BLF posterior sds
#: of about 1e-5).
DEFAULT_ATOL = 1e-9
#: A number printed rounded (in a sentence, or a JSON number with few digits) may flip its
#: last digit when the value sits on a rounding boundary. One unit in the last printed place
#: is accepted when the number has at least this many significant digits (so it is a
#: rounded output, not a round constant such as a prior bound of 0.05 or 400).
MIN_DIGITS_FOR_PRINT_ROUNDING = 4

# --- Records and commands ----------------------------------------------------------------

DEFAULT_TIMEOUT_S = 600.0
SLICE_SECONDS = 20.0


@dataclass(frozen=True)
class RecordSpec:
    """A record the check runs commands on: its argument, extra flags and what it covers."""

    label: str
    record: str  # an embedded name, or a file name in the shared data folder ({data}/...)
    kind: str
    args: tuple[str, ...] = ()


RECORDS: dict[str, RecordSpec] = {
    r.label: r
    for r in (
        RecordSpec("seed_individual", "seed_individual", "rigid floor, synthetic"),
        RecordSpec("cubic_stiffness", "cubic_stiffness", "rigid floor, hidden effect"),
        RecordSpec("population_typical", "population_typical", "rigid floor, synthetic"),
        RecordSpec("seed_individual_deck", "seed_individual_deck", "vibrating deck"),
        RecordSpec(
            "treadmill_20s", "{data}/treadmill_20s.mot", "real, treadmill", ("--mass", "77.3")
        ),
        RecordSpec("insole_20s", "{data}/insole_20s.txt", "real, insoles", ("--mass", "83")),
        RecordSpec("seed_numerical_example", "seed_numerical_example", "numerical example"),
        RecordSpec(
            "cubic_stiffness+effect",
            "cubic_stiffness",
            "with an effect in the model",
            ("--effects", "cubic_stiffness"),
        ),
    )
}

#: Effects `compare` adds in turn (its --effects is required).
COMPARE_EFFECTS = "gait_asymmetry,cubic_stiffness"
#: crosscheck costs 10-45 s per record and side: by default on a few steps of one rigid-floor
#: record and of the deck record (whose check takes the transmissibility route's own path).
DEFAULT_CROSSCHECK_RECORDS = ("seed_individual", "seed_individual_deck")
CROSSCHECK_ARGS = ("--max-steps", "4")
#: The batch's manifest: short records, as files in the shared data folder.
DEFAULT_BATCH_RECORDS = ("seed_individual", "seed_individual_deck", "insole_20s")
COMMANDS = ("identify", "diagnose", "compare", "crosscheck", "batch")
#: Commands that take no --effects flag of their own (compare's is its list of effects).
_NO_MODEL_EFFECTS = ("crosscheck",)


@dataclass(frozen=True)
class Case:
    """One command to run on both sides."""

    record: str
    command: str
    argv: tuple[str, ...]
    out_dir: bool = False  # the command writes into {out}; compare that folder


@dataclass
class Outcome:
    """The result of comparing one case."""

    record: str
    command: str
    status: str  # identical | rounding | different | not comparable
    detail: str = ""
    seconds: tuple[float, float] = (0.0, 0.0)


@dataclass
class Comparison:
    """What differs between two trees."""

    differences: list[str] = field(default_factory=list)
    max_rel: float = 0.0
    max_rel_key: str = ""
    printed: list[str] = field(default_factory=list)  # last printed digit flips accepted
    floored: list[str] = field(default_factory=list)  # near zero, under the absolute floor
    exact: bool = True
    leaves: int = 0  # numbers, strings and nulls compared

    @property
    def status(self) -> str:
        """``identical``, ``rounding`` or ``different``."""
        if self.differences:
            return "different"
        return "identical" if self.exact else "rounding"


# --- Comparing trees ---------------------------------------------------------------------

_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


class _Printed(float):
    """A float that remembers how it was printed (to know its last printed place)."""

    text: str

    def __new__(cls, text: str) -> _Printed:
        obj = super().__new__(cls, text)
        obj.text = text
        return obj


def load_json(text: str) -> Any:
    """Parse JSON keeping each number's printed text (for its last printed place)."""
    return json.loads(text, parse_float=_Printed, parse_int=_Printed)


def _last_place(text: str) -> tuple[float, int]:
    """One unit in the last printed place of a number's text, and its significant digits."""
    mantissa, _, exponent = text.lower().partition("e")
    digits = mantissa.lstrip("+-")
    decimals = len(digits.partition(".")[2])
    significant = len(digits.replace(".", "").lstrip("0")) or 1
    return 10.0 ** (int(exponent or 0) - decimals), significant


def _within_print(a: Any, b: Any) -> bool:
    """Tell whether two printed numbers differ by one unit in the last place of a rounded one."""
    ta, tb = getattr(a, "text", None), getattr(b, "text", None)
    if ta is None or tb is None:
        return False
    (ua, sa), (ub, sb) = _last_place(ta), _last_place(tb)
    if min(sa, sb) < MIN_DIGITS_FOR_PRINT_ROUNDING:
        return False
    return abs(float(a) - float(b)) <= max(ua, ub) * (1 + 1e-9)


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _compare_numbers(a: float, b: float, key: str, out: Comparison, rtol: float, atol: float):
    fa, fb = float(a), float(b)
    if fa == fb or (math.isnan(fa) and math.isnan(fb)):
        return
    out.exact = False
    diff = abs(fa - fb)
    scale = max(abs(fa), abs(fb))
    rel = diff / scale if scale > 0 and math.isfinite(scale) else math.inf
    if diff <= rtol * scale:
        if rel > out.max_rel or not out.max_rel_key:
            out.max_rel, out.max_rel_key = rel, key
    elif diff <= atol:  # its relative difference means nothing: not the largest one
        out.floored.append(key)
    elif _within_print(a, b):
        out.printed.append(key)
    else:
        out.differences.append(f"{key}: {a!r} -> {b!r}")


def _compare_strings(a: str, b: str, key: str, out: Comparison, rtol: float, atol: float):
    if a == b:
        return
    na, nb = _NUMBER.findall(a), _NUMBER.findall(b)
    if _NUMBER.split(a) == _NUMBER.split(b) and len(na) == len(nb):
        sub = Comparison()
        for i, (x, y) in enumerate(zip(na, nb, strict=True)):
            _compare_numbers(_Printed(x), _Printed(y), f"{key}#{i}", sub, rtol, atol)
        if not sub.differences:
            out.exact = False
            out.printed.extend(sub.printed)
            out.floored.extend(sub.floored)
            if sub.max_rel > out.max_rel:
                out.max_rel, out.max_rel_key = sub.max_rel, sub.max_rel_key
            return
    out.differences.append(f"{key}: {_short(a)!r} -> {_short(b)!r}")


def _short(s: str, n: int = 80) -> str:
    return s if len(s) <= n else s[: n - 3] + "..."


def compare_trees(
    before: Any,
    after: Any,
    *,
    rtol: float = DEFAULT_RTOL,
    atol: float = DEFAULT_ATOL,
    ignored: Sequence[str] = tuple(IGNORED_KEYS),
    key: str = "",
    out: Comparison | None = None,
) -> Comparison:
    """Compare two JSON-like trees (dicts, lists, strings, numbers, None).

    Parameters
    ----------
    before, after
        The trees (from :func:`load_json`, or plain Python objects).
    rtol, atol
        Two numbers agree when ``|a - b| <= max(rtol * max(|a|, |b|), atol)``.
    ignored
        Dict keys skipped wherever they appear.

    Returns
    -------
    Comparison
        ``status`` is ``identical`` (every leaf equal), ``rounding`` (numbers within the
        tolerance or one last printed digit apart) or ``different`` (``differences`` lists
        each differing key path, in tree order).
    """
    out = Comparison() if out is None else out
    if not isinstance(before, (dict, list)):
        out.leaves += 1
    if isinstance(before, dict) and isinstance(after, dict):
        only_b = sorted(set(before) - set(after) - set(ignored))
        only_a = sorted(set(after) - set(before) - set(ignored))
        if only_b or only_a:
            out.differences.append(
                f"{key or '<root>'}: keys only before {only_b}, only after {only_a}"
            )
        for k in before:
            if k in after and k not in ignored:
                path = f"{key}.{k}" if key else str(k)
                compare_trees(
                    before[k], after[k], rtol=rtol, atol=atol, ignored=ignored, key=path, out=out
                )
    elif isinstance(before, list) and isinstance(after, list):
        if len(before) != len(after):
            out.differences.append(f"{key}: length {len(before)} -> {len(after)}")
        for i, (x, y) in enumerate(zip(before, after, strict=False)):
            compare_trees(x, y, rtol=rtol, atol=atol, ignored=ignored, key=f"{key}[{i}]", out=out)
    elif _is_number(before) and _is_number(after):
        _compare_numbers(before, after, key, out, rtol, atol)
    elif isinstance(before, str) and isinstance(after, str):
        _compare_strings(before, after, key, out, rtol, atol)
    elif before != after or type(before) is not type(after):
        out.differences.append(
            f"{key}: {type(before).__name__} {_short(repr(before))} -> "
            f"{type(after).__name__} {_short(repr(after))}"
        )
    return out


def describe(comparison: Comparison, limit: int = 3) -> str:
    """One line for the report: the status with its largest difference or first keys."""
    if comparison.status == "identical":
        return f"identical ({comparison.leaves} values)"
    if comparison.status == "rounding":
        parts = []
        if comparison.max_rel_key:
            parts.append(f"max rel diff {comparison.max_rel:.1e} at {comparison.max_rel_key}")
        if comparison.floored:
            parts.append(f"under the absolute floor at {', '.join(comparison.floored[:limit])}")
        if comparison.printed:
            parts.append(f"last printed digit at {', '.join(comparison.printed[:limit])}")
        return f"equal to rounding ({'; '.join(parts)}; {comparison.leaves} values)"
    more = len(comparison.differences) - limit
    keys = "; ".join(comparison.differences[:limit]) + (f"; +{more} more" if more > 0 else "")
    return f"DIFFERENT ({keys})"


# --- Reading a batch folder as one tree --------------------------------------------------


def _csv_tree(path: Path) -> list[dict[str, Any]]:
    """Read a CSV file as a list of rows, numbers parsed (keeping their printed text)."""
    with path.open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    return [{k: _cell(v) for k, v in row.items()} for row in rows]


def _cell(value: str | None) -> Any:
    if value is None:
        return None
    try:
        return _Printed(value) if _NUMBER.fullmatch(value.strip()) else value
    except ValueError:
        return value


def folder_tree(folder: Path, placeholders: dict[str, str]) -> dict[str, Any]:
    """Every JSON and CSV file under ``folder`` (except ``IGNORED_FILES``) as one tree."""
    tree: dict[str, Any] = {}
    if not folder.exists():
        return tree
    for path in sorted(folder.rglob("*")):
        rel = path.relative_to(folder)
        if not path.is_file() or rel.parts[0] in IGNORED_FILES or rel.name.startswith("."):
            continue
        if path.suffix == ".json":
            tree[rel.as_posix()] = load_json(
                _neutral(path.read_text(encoding="utf-8"), placeholders)
            )
        elif path.suffix == ".csv":
            tree[rel.as_posix()] = _csv_tree(path)
    return tree


def _neutral(text: str, placeholders: dict[str, str]) -> str:
    """Replace temporary folders (different on each side) by fixed placeholders."""
    for real, name in sorted(placeholders.items(), key=lambda kv: -len(kv[0])):
        text = text.replace(real, name)
    return text


# --- Preparing the shared data -----------------------------------------------------------


def repo_root() -> Path:
    """Find the root of the git repository this script belongs to."""
    here = Path(__file__).resolve().parent
    out = subprocess.run(
        ["git", "rev-parse", "--show-toplevel"], cwd=here, capture_output=True, text=True
    )
    if out.returncode != 0:
        sys.exit(f"behaviour_check: not in a git repository ({out.stderr.strip()})")
    return Path(out.stdout.strip())


def _slice_mot(src: Path, dst: Path, seconds: float) -> None:
    """Write the first ``seconds`` of an OpenSim .mot file, its header's nRows updated."""
    lines = src.read_text(encoding="utf-8").splitlines()
    end = next(i for i, line in enumerate(lines) if line.strip() == "endheader")
    header, columns, rows = lines[: end + 1], lines[end + 1], lines[end + 2 :]
    kept = [r for r in rows if r.strip() and float(r.split()[0]) <= seconds]
    header = [f"nRows={len(kept)}" if h.startswith("nRows=") else h for h in header]
    dst.write_text("\n".join([*header, columns, *kept]) + "\n", encoding="utf-8")


def _slice_lines(src: Path, dst: Path, seconds: float) -> None:
    """Write the first ``seconds`` of a headerless table whose first column is time [s]."""
    rows = src.read_text(encoding="utf-8").splitlines()
    kept = [r for r in rows if r.strip() and float(r.split()[0]) < seconds]
    dst.write_text("\n".join(kept) + "\n", encoding="utf-8")


def prepare_data(root: Path, data: Path, batch_records: Sequence[str]) -> None:
    """Write the short real records and the batch's manifest into ``data``.

    Both sides read these same files, cut from this repository's embedded records.
    """
    datasets = root / "workbench" / "datasets"
    _slice_mot(
        datasets / "real" / "treadmill_01_01_grf.mot", data / "treadmill_20s.mot", SLICE_SECONDS
    )
    _slice_lines(datasets / "real" / "GaCo01_01.txt", data / "insole_20s.txt", SLICE_SECONDS)
    batch = data / "batch"
    batch.mkdir()
    rows = []
    for label in batch_records:
        spec = RECORDS[label]
        if spec.record.startswith("{data}/"):
            name = spec.record.removeprefix("{data}/")
            shutil.copy(data / name, batch / name)
            mass = spec.args[spec.args.index("--mass") + 1] if "--mass" in spec.args else ""
        else:
            src = next(datasets.glob(f"*/{spec.record}.csv"))
            name = src.name
            shutil.copy(src, batch / name)
            shutil.copy(src.with_suffix(".json"), batch / src.with_suffix(".json").name)
            mass = ""
        rows.append({"path": name, "mass_kg": mass})
    with (batch / "manifest.csv").open("w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=["path", "mass_kg"])
        writer.writeheader()
        writer.writerows(rows)


# --- The cases ---------------------------------------------------------------------------


def build_cases(
    records: Sequence[str],
    commands: Sequence[str],
    crosscheck_records: Sequence[str],
) -> list[Case]:
    """List the record x command cases to run, in report order."""
    cases: list[Case] = []
    for label in records:
        spec = RECORDS[label]
        for command in commands:
            if command == "batch":
                continue
            if command == "crosscheck" and label not in crosscheck_records:
                continue
            args = spec.args
            if command in _NO_MODEL_EFFECTS and "--effects" in args:
                continue
            if command == "compare":
                if "--effects" in args:  # compare's --effects is the list it adds
                    continue
                args = (*args, "--effects", COMPARE_EFFECTS)
            if command == "crosscheck":
                args = (*args, *CROSSCHECK_ARGS)
            cases.append(Case(label, command, (command, spec.record, *args, "--json")))
    if "batch" in commands:
        cases.append(
            Case(
                "manifest",
                "batch",
                ("batch", "{data}/batch/manifest.csv", "--out", "{out}", "--json"),
                out_dir=True,
            )
        )
    return cases


# --- Running -----------------------------------------------------------------------------


@dataclass
class Run:
    """One side's run of a case."""

    returncode: int | None  # None: timed out
    stdout: str
    stderr: str
    seconds: float
    out: Path | None


def run_side(case: Case, code: Path, data: Path, scratch: Path, timeout: float) -> Run:
    """Run ``python -m workbench ...`` with the code of ``code`` (cwd and PYTHONPATH)."""
    out = None
    if case.out_dir:
        out = Path(tempfile.mkdtemp(dir=scratch)) / "out"
    argv = [a.replace("{data}", str(data)).replace("{out}", str(out)) for a in case.argv]
    env = {**os.environ, "PYTHONPATH": str(code), "PYTHONHASHSEED": "0"}
    start = time.perf_counter()
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "workbench", *argv],
            cwd=code,
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
        )
    except subprocess.TimeoutExpired as exc:
        err = exc.stderr.decode() if isinstance(exc.stderr, bytes) else (exc.stderr or "")
        return Run(None, "", err, time.perf_counter() - start, out)
    return Run(proc.returncode, proc.stdout, proc.stderr, time.perf_counter() - start, out)


def _usage_error(run: Run) -> bool:
    """Tell whether the command or a flag does not exist (argparse's exit status 2)."""
    return run.returncode == 2 and (
        "invalid choice" in run.stderr or "unrecognized arguments" in run.stderr
    )


def _tail(text: str, n: int = 300) -> str:
    text = " ".join(text.strip().splitlines()[-3:])
    return text[-n:]


def judge(case: Case, before: Run, after: Run, placeholders: dict[str, str], rtol, atol):
    """Compare both sides' runs of a case into an :class:`Outcome`."""
    seconds = (before.seconds, after.seconds)

    def outcome(status: str, detail: str = "") -> Outcome:
        return Outcome(case.record, case.command, status, detail, seconds)

    if _usage_error(before):
        return outcome("not comparable", f"the revision lacks it: {_tail(before.stderr)}")
    if before.returncode is None or after.returncode is None:
        side = "before" if before.returncode is None else "after"
        return outcome("different", f"timed out ({side})")
    if before.returncode != after.returncode:
        failed = before if before.returncode else after
        return outcome(
            "different",
            f"exit {before.returncode} -> {after.returncode}: {_tail(failed.stderr)}",
        )
    names = {**placeholders}
    if before.out and after.out:
        names.update({str(before.out): "<out>", str(after.out): "<out>"})
    try:
        tree_b = load_json(_neutral(before.stdout, names) or "null")
        tree_a = load_json(_neutral(after.stdout, names) or "null")
    except json.JSONDecodeError as exc:
        return outcome("different", f"stdout is not JSON ({exc})")
    if before.out and after.out:  # key paths: stdout.KEY and files.NAME.KEY
        tree_b = {"stdout": tree_b, "files": folder_tree(before.out, names)}
        tree_a = {"stdout": tree_a, "files": folder_tree(after.out, names)}
    result = compare_trees(tree_b, tree_a, rtol=rtol, atol=atol)
    detail = describe(result)
    status = result.status
    if before.returncode != 0:
        detail = f"both exit {before.returncode}; {detail}"
    return outcome(status, detail)


@contextlib.contextmanager
def pinned_worktree(root: Path, rev: str) -> Iterator[Path]:
    """Check out ``rev`` in a detached git worktree, removed on leaving (even on Ctrl-C)."""
    parent = Path(tempfile.mkdtemp(prefix="behaviour-check-"))
    path = parent / "rev"
    add = subprocess.run(
        ["git", "worktree", "add", "--detach", str(path), rev],
        cwd=root,
        capture_output=True,
        text=True,
    )
    if add.returncode != 0:
        shutil.rmtree(parent, ignore_errors=True)
        sys.exit(f"behaviour_check: cannot check out {rev!r}: {add.stderr.strip()}")
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        yield path
    finally:
        signal.signal(signal.SIGTERM, previous)
        subprocess.run(
            ["git", "worktree", "remove", "--force", str(path)],
            cwd=root,
            capture_output=True,
        )
        shutil.rmtree(parent, ignore_errors=True)
        subprocess.run(["git", "worktree", "prune"], cwd=root, capture_output=True)


def check_imports(code: Path) -> None:
    """Stop unless ``python -m workbench`` run as :func:`run_side` does imports ``code``'s."""
    env = {**os.environ, "PYTHONPATH": str(code)}
    probe = "import workbench, pathlib; print(pathlib.Path(workbench.__file__).resolve())"
    out = subprocess.run(
        [sys.executable, "-c", probe], cwd=code, env=env, capture_output=True, text=True
    )
    found = Path(out.stdout.strip() or "?")
    if not found.is_relative_to(code.resolve()):
        sys.exit(f"behaviour_check: the code of {code} is not the one imported ({found})")


def _raise_interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


# --- Report ------------------------------------------------------------------------------

_LABELS = {
    "identical": "identical",
    "rounding": "equal to rounding",
    "different": "DIFFERENT",
    "not comparable": "not comparable",
}


def table(outcomes: Sequence[Outcome], rev: str, commit: str) -> str:
    """Write the outcomes as a Markdown table, with a heading line naming the revisions."""
    lines = [
        f"Behaviour check: working tree against {rev} ({commit[:12]})",
        "",
        "| record | command | result | s (before / after) |",
        "|---|---|---|---|",
    ]
    for o in outcomes:
        detail = o.detail or _LABELS[o.status]
        if o.status == "not comparable":
            detail = f"not comparable ({o.detail})"
        detail = detail.replace("|", "\\|")
        lines.append(
            f"| {o.record} | {o.command} | {detail} | {o.seconds[0]:.0f} / {o.seconds[1]:.0f} |"
        )
    counts = {s: sum(o.status == s for o in outcomes) for s in _LABELS}
    lines += ["", ", ".join(f"{n} {_LABELS[s]}" for s, n in counts.items() if n)]
    return "\n".join(lines)


# --- Command line ------------------------------------------------------------------------


def _names(text: str, allowed: Sequence[str], what: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in allowed]
    if unknown:
        raise argparse.ArgumentTypeError(
            f"unknown {what} {', '.join(unknown)}; choose from {', '.join(allowed)}"
        )
    return names


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Parse the command line (see the module docstring)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--against", metavar="REV", help="pinned revision to compare with")
    p.add_argument(
        "--records",
        type=lambda s: _names(s, list(RECORDS), "record"),
        default=list(RECORDS),
        help=f"comma-separated records (default all: {','.join(RECORDS)})",
    )
    p.add_argument(
        "--commands",
        type=lambda s: _names(s, COMMANDS, "command"),
        default=list(COMMANDS),
        help=f"comma-separated commands (default all: {','.join(COMMANDS)})",
    )
    p.add_argument(
        "--crosscheck-records",
        type=lambda s: _names(s, list(RECORDS), "record"),
        default=list(DEFAULT_CROSSCHECK_RECORDS),
        help="records crosscheck runs on (slow; default %(default)s)",
    )
    p.add_argument(
        "--batch-records",
        type=lambda s: _names(s, list(RECORDS), "record"),
        default=list(DEFAULT_BATCH_RECORDS),
        help="records of the batch's manifest (default %(default)s)",
    )
    p.add_argument("--rtol", type=float, default=DEFAULT_RTOL, help="relative tolerance")
    p.add_argument("--atol", type=float, default=DEFAULT_ATOL, help="absolute floor")
    p.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT_S, help="per command [s]")
    p.add_argument("--out", type=Path, help="also write the table to DIR/behaviour_check.md")
    p.add_argument("--list", action="store_true", help="list records and commands, then exit")
    args = p.parse_args(argv)
    if not args.list and not args.against:
        p.error("--against REV is required")
    return args


def _list() -> None:
    for spec in RECORDS.values():
        print(f"{spec.label:24s} {spec.kind:28s} {spec.record} {' '.join(spec.args)}")
    print(f"commands: {', '.join(COMMANDS)}")
    print(
        f"ignored keys: {', '.join(IGNORED_KEYS)}; ignored batch files: {', '.join(IGNORED_FILES)}"
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Run the check; 0 when everything compared is identical or equal to rounding."""
    args = parse_args(argv)
    if args.list:
        _list()
        return 0
    root = repo_root()
    commit = subprocess.run(
        ["git", "rev-parse", "--verify", f"{args.against}^{{commit}}"],
        cwd=root,
        capture_output=True,
        text=True,
    ).stdout.strip()
    if not commit:
        sys.exit(f"behaviour_check: unknown revision {args.against!r}")
    cases = build_cases(args.records, args.commands, args.crosscheck_records)
    outcomes: list[Outcome] = []
    with tempfile.TemporaryDirectory(prefix="behaviour-data-") as tmp:
        data, scratch = Path(tmp) / "data", Path(tmp) / "scratch"
        data.mkdir()
        scratch.mkdir()
        prepare_data(root, data, args.batch_records)
        with pinned_worktree(root, commit) as pinned:
            check_imports(pinned)
            check_imports(root)
            placeholders = {str(data): "<data>", str(pinned): "<code>", str(root): "<code>"}
            for case in cases:
                print(f"{case.record} {' '.join(case.argv)} ...", file=sys.stderr, flush=True)
                before = run_side(case, pinned, data, scratch, args.timeout)
                after = run_side(case, root, data, scratch, args.timeout)
                outcome = judge(case, before, after, placeholders, args.rtol, args.atol)
                print(f"  {outcome.status}: {outcome.detail}", file=sys.stderr, flush=True)
                outcomes.append(outcome)
    report = table(outcomes, args.against, commit)
    print(report)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "behaviour_check.md").write_text(report + "\n", encoding="utf-8")
    failed = any(o.status == "different" for o in outcomes)
    return 1 if failed else 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM, after the temporary worktree was removed
        sys.exit("behaviour_check: interrupted; the temporary worktree was removed")

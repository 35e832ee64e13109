"""The package's shape: no import cycles, families that import one way, docs that match the code.

The import graph counts every import statement in ``workbench/``, those inside functions
(lazy) and under ``if TYPE_CHECKING:`` included: a cycle that only closes at run time in a
rarely used branch is still a cycle in the design.

Module size is not checked here: a module holds one idea and is split at its interfaces,
not at a line count; long modules and functions are a question for review (docs/design.md,
"Module size").
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import pytest

from tests.graphs import cycles, package_modules, resolve_module

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "workbench"


def import_graph() -> dict[str, set[str]]:
    """Edges module -> imported workbench module (a package's own parents excluded)."""
    mods = package_modules()
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for mod, path in mods.items():
        base = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                origin = node.module or ""
                if node.level:
                    b = base
                    for _ in range(node.level - 1):
                        b = b.rpartition(".")[0]
                    origin = f"{b}.{node.module}" if node.module else b
                targets = [f"{origin}.{a.name}" for a in node.names] + [origin]
            for target in targets:
                if not target.startswith("workbench"):
                    continue
                resolved = resolve_module(target, mods)
                # Importing one's own parent package runs nothing new: it is already running.
                if resolved and resolved != mod and not mod.startswith(resolved + "."):
                    if resolved != "workbench":
                        edges[mod].add(resolved)
    return edges


def test_the_cycle_finder_finds_a_cycle() -> None:
    """The checker itself: a lazy import back is a cycle, a one-way chain is not."""
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycle_in_the_package() -> None:
    edges = import_graph()
    assert len(edges) > 50  # the walk saw the package
    assert "workbench.inference.methods" in edges["workbench.inference.pipeline.identification"]
    assert cycles(edges) == []


def test_inference_families_import_one_way() -> None:
    """The subpackages of ``inference`` form no cycle among themselves.

    Importing ``workbench.inference.kalman.filter`` first runs ``workbench.inference.kalman``
    (its public face, which imports the family's modules): a cycle between two families
    would be a cycle at import time even when no two modules import each other.
    """
    family_of = {
        m: ".".join(m.split(".")[:3])
        for m in import_graph()
        if m.startswith("workbench.inference.") and m.count(".") >= 2
    }
    families: dict[str, set[str]] = {f: set() for f in family_of.values()}
    for mod, targets in import_graph().items():
        if mod in family_of:
            for t in targets:
                if t in family_of and family_of[t] != family_of[mod]:
                    families[family_of[mod]].add(family_of[t])
    assert len(families) >= 5
    assert cycles(families) == []
    assert "workbench.inference.core" not in families or not families["workbench.inference.core"]


def test_each_inference_family_has_a_public_face() -> None:
    """Every subpackage of ``inference`` says what it is and exports what others may use."""
    import importlib

    for init in sorted((PACKAGE / "inference").glob("*/__init__.py")):
        name = f"workbench.inference.{init.parent.name}"
        module = importlib.import_module(name)
        assert module.__doc__ and len(module.__doc__) > 80, name
        exported = getattr(module, "__all__", None)
        assert exported, f"{name} has no __all__"
        assert all(hasattr(module, n) and not n.startswith("_") for n in exported), name


def test_models_and_records_import_no_algorithm() -> None:
    """Models are descriptions (as in ``particles``): they never import the algorithms."""
    edges = import_graph()
    for mod, targets in edges.items():
        if mod.startswith(("workbench.models", "workbench.records")):
            bad = [t for t in targets if t.startswith(("workbench.inference", "workbench.cli"))]
            assert not bad, f"{mod} imports {bad}"


def test_nothing_cites_a_file_outside_the_repository() -> None:
    pattern = re.compile(r"DESIGN\.md|\.\./shared")
    offenders = []
    for folder in ("workbench", "tests", "analyses", "docs"):
        for path in (ROOT / folder).rglob("*"):
            if path.suffix in (".py", ".md", ".toml", ".yml") and path.name != Path(__file__).name:
                if pattern.search(path.read_text(encoding="utf-8")):
                    offenders.append(str(path.relative_to(ROOT)))
    assert not offenders


def _readme_session() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    match = re.search(r"## Notebook session\s+(?:<!--.*?-->\s*)?```python\n(.*?)```", text, re.S)
    assert match, "README.md has no notebook session block"
    return match.group(1)


def test_readme_is_a_front_page() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert readme.count("\n") <= 250
    lines = readme.splitlines()
    start = lines.index("```bash", next(i for i, x in enumerate(lines) if "Quick start" in x))
    end = lines.index("```", start + 1)
    commands = lines[start + 1 : end]
    assert len(commands) == 2 and "workbench demo" in commands[0]
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert commands[1] in ci  # CI runs the README's test command


def test_the_session_is_the_same_everywhere() -> None:
    session = _readme_session()
    assert (ROOT / "docs" / "examples" / "notebook_session.py").read_text(
        encoding="utf-8"
    ) == session
    assert session in (ROOT / "docs" / "notebook.md").read_text(encoding="utf-8")


@pytest.mark.slow
def test_the_notebook_session_runs_and_its_page_shows_a_fresh_run() -> None:
    """The session, run as a notebook would (bare expressions displayed), is the docs' page.

    CI also runs ``python docs/examples/run_session.py --check docs/notebook.md``; this is
    the same comparison from the test suite.
    """
    sys.path.insert(0, str(ROOT / "docs" / "examples"))
    try:
        from run_session import page_block, session_run
    finally:
        sys.path.pop(0)
    out, namespace = session_run()
    page = (ROOT / "docs" / "notebook.md").read_text(encoding="utf-8")
    assert page_block(page) == out, "docs/notebook.md is stale: run_session.py --write it"
    assert str(ROOT) not in out  # no machine paths

    # The deck record identifies C and K, and the intervals hold the simulated values.
    res, rec, rigid, d = (namespace[k] for k in ("res", "rec", "rigid", "d"))
    truth = rec.metadata["truth"]  # type: ignore[attr-defined]
    params = res.params  # type: ignore[attr-defined]
    ci = res.conf_int()  # type: ignore[attr-defined]
    assert res.not_identified == []  # type: ignore[attr-defined]
    assert params.notna().all() and set(params.index) == set(ci.index)
    assert (ci["lower"] <= params).all() and (params <= ci["upper"]).all()
    for key in ("stiffness_n_per_m", "damping_ns_per_m"):
        assert ci.loc[key, "lower"] <= float(truth[key]) <= ci.loc[key, "upper"], key
    assert "natural_frequency_hz" in out and "lower" in out and "upper" in out
    # The rigid stretch is graded not identified and prints no estimate for C and K.
    assert {"stiffness_n_per_m", "damping_ns_per_m"} <= set(rigid.not_identified)  # type: ignore[attr-defined]
    assert rigid.params[rigid.not_identified].isna().all()  # type: ignore[attr-defined]
    assert "K [N/m]                           not identified" in out
    assert d.to_json()["verdict"] in out  # type: ignore[attr-defined]

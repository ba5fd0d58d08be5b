"""The house rules of docs/architecture.md, checked on the source tree.

Every ``import`` statement is read from the source (module level and inside functions;
imports under ``if TYPE_CHECKING:`` are types only and do not count), so a cycle hidden
by a function-level import is still a cycle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Source folder -> the package it installs as (pyproject.toml's package-dir).
PACKAGES = {
    "core": "demtrack.core",
    "server": "demtrack.server",
    "bench": "demtrack.bench",
    "demtrack": "demtrack",
}
MAX_LINES = 800


def _modules() -> dict[str, Path]:
    mods = {}
    for folder, pkg in PACKAGES.items():
        for path in (ROOT / folder).rglob("*.py"):
            if "__pycache__" in path.parts:
                continue
            parts = path.relative_to(ROOT / folder).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join([pkg, *parts])] = path
    return mods


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    tree = ast.parse(path.read_text())
    type_only = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            type_only.update(id(n) for n in ast.walk(node))
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    for node in ast.walk(tree):
        if id(node) in type_only:
            continue
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                found.add(sub if sub in known else target)
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return {t for t in found if t in known and t != name}


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    mods = _modules()
    known = set(mods)
    return {name: _imports(name, path, known) for name, path in mods.items()}


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one member (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for root in edges:
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(edges.get(w, ())))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_the_graph_sees_function_level_imports(graph):
    # demtrack.core.terrain.dem's import of the caster or any lazily imported edge must be
    # seen; a known function-level import in the CLI proves the reader walks function bodies.
    assert any(t.startswith("demtrack.commands") for t in graph["demtrack.cli"])


def test_no_import_cycles(graph):
    assert _cycles(graph) == []


def test_server_core_and_bench_never_import_the_cli_or_the_generator(graph):
    bad = []
    for name, targets in graph.items():
        for t in targets:
            upward_cli = t.startswith(("demtrack.commands", "demtrack.cli"))
            generator = t.startswith("demtrack.samplesite")
            if name.startswith(("demtrack.server", "demtrack.core")) and (upward_cli or generator):
                bad.append((name, t))
            elif name.startswith("demtrack.bench") and upward_cli:
                bad.append((name, t))
    assert bad == []


def test_core_never_imports_the_server(graph):
    bad = [
        (n, t)
        for n, ts in graph.items()
        if n.startswith("demtrack.core")
        for t in ts
        if t.startswith("demtrack.server")
    ]
    assert bad == []


def test_no_source_file_is_over_800_lines():
    files = [p for folder in PACKAGES for p in (ROOT / folder).rglob("*.py")]
    files += list((ROOT / "web" / "console").glob("*.mjs"))
    long = {
        str(p.relative_to(ROOT)): n
        for p in files
        if "__pycache__" not in p.parts and (n := len(p.read_text().splitlines())) > MAX_LINES
    }
    assert long == {}

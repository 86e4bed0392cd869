"""The one-way architecture (docs/architecture.md), checked from the code's own imports.

Every ``import`` and ``from ... import`` in lowerbase counts, wherever it stands: at the top,
inside a function (deferred) or under ``if TYPE_CHECKING``. The layer table of
docs/architecture.md is the contract: a package may import its own modules and the packages
in the rows above it, never a row below; and no module may reach itself through its imports.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Iterable, Mapping
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "lowerbase"
DOC = ROOT / "docs" / "architecture.md"

Graph = dict[str, set[str]]


def modules(package: Path) -> dict[str, Path]:
    """Dotted module name -> file, for every .py under ``package``."""
    found = {}
    for path in sorted(package.rglob("*.py")):
        parts = path.relative_to(package.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


def imports(name: str, path: Path, known: Mapping[str, Path]) -> set[str]:
    """The package's modules that ``name`` imports (the deepest known module of each)."""
    is_package = path.name == "__init__.py"
    targets: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            targets += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                here = name.split(".") if is_package else name.split(".")[:-1]
                here = here[: len(here) - node.level + 1]
                base = ".".join([*here, base] if base else here)
            targets += [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base
                        for a in node.names]
    found = set()
    for target in targets:
        while target and target not in known:
            target = target.rpartition(".")[0]
        if target and target != name:
            found.add(target)
    return found


def import_graph(package: Path) -> Graph:
    known = modules(package)
    return {name: imports(name, path, known) for name, path in known.items()}


def doc_layers(text: str) -> list[str]:
    """The packages of the layer table, ground first."""
    return re.findall(r"^\|[^|\n]*\| `([a-z0-9_.]+)` \|", text, re.MULTILINE)


def owner(module: str, packages: Iterable[str]) -> str | None:
    """The longest listed package that ``module`` is or is inside (the top package, listed for
    its ``__init__``, owns only itself: a new subpackage must get a row of its own)."""
    best = None
    for p in packages:
        inside = "." in p and module.startswith(p + ".")
        if (module == p or inside) and (best is None or len(p) > len(best)):
            best = p
    return best


def upward(graph: Graph, order: list[str]) -> list[str]:
    """Imports from a package to one listed below it."""
    rank = {p: i for i, p in enumerate(order)}
    bad = []
    for a, targets in sorted(graph.items()):
        pa = owner(a, order)
        for b in sorted(targets):
            pb = owner(b, order)
            if pa is not None and pb is not None and pa != pb and rank[pb] > rank[pa]:
                bad.append(f"{a} -> {b} ({pa} is above {pb} in docs/architecture.md)")
    return bad


def circles(graph: Graph) -> list[frozenset[str]]:
    """Strongly connected sets of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[frozenset[str]] = []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph.get(start, ()))))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    component = set()
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        component.add(w)
                        if w == v:
                            break
                    if len(component) > 1:
                        found.append(frozenset(component))
    return found


# -- the checker on made-up packages (so that it can fail) -------------------------------------


def _tree(tmp_path: Path, files: Mapping[str, str]) -> Path:
    for rel, text in files.items():
        path = tmp_path / "pkg" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return tmp_path / "pkg"


def test_the_checker_finds_an_upward_import_even_deferred_or_type_only(tmp_path: Path) -> None:
    pkg = _tree(tmp_path, {
        "__init__.py": "",
        "low/__init__.py": "",
        "low/a.py": "def f():\n    from pkg.high.b import g\n",
        "low/c.py": ("from typing import TYPE_CHECKING\n"
                     "if TYPE_CHECKING:\n    from ..high import b\n"),
        "high/__init__.py": "",
        "high/b.py": "from pkg.low import a\n",
    })
    graph = import_graph(pkg)
    assert graph["pkg.low.a"] == {"pkg.high.b"}
    assert graph["pkg.low.c"] == {"pkg.high.b"}
    bad = [b.split(" (")[0] for b in upward(graph, ["pkg.low", "pkg.high"])]
    assert bad == ["pkg.low.a -> pkg.high.b", "pkg.low.c -> pkg.high.b"]
    flipped = [b.split(" (")[0] for b in upward(graph, ["pkg.high", "pkg.low"])]
    assert flipped == ["pkg.high.b -> pkg.low.a"]


def test_the_checker_finds_a_circle_through_several_modules(tmp_path: Path) -> None:
    pkg = _tree(tmp_path, {
        "__init__.py": "",
        "a.py": "from pkg import b\n",
        "b.py": "import pkg.c\n",
        "c.py": "def f():\n    from .a import x\n",
        "d.py": "from pkg import a\n",
    })
    assert circles(import_graph(pkg)) == [frozenset({"pkg.a", "pkg.b", "pkg.c"})]


# -- lowerbase ---------------------------------------------------------------------------------


def test_the_layer_table_names_every_package() -> None:
    order = doc_layers(DOC.read_text(encoding="utf-8"))
    assert len(order) == len(set(order)), "a package is listed twice in docs/architecture.md"
    unlisted = sorted({m for m in modules(PACKAGE) if owner(m, order) is None})
    assert not unlisted, f"add these to docs/architecture.md's table: {unlisted}"
    listed_missing = [p for p in order
                      if not (ROOT / p.replace(".", "/")).is_dir() and p not in modules(PACKAGE)]
    assert not listed_missing, f"docs/architecture.md lists what is not there: {listed_missing}"


def test_no_import_runs_back_up() -> None:
    order = doc_layers(DOC.read_text(encoding="utf-8"))
    bad = upward(import_graph(PACKAGE), order)
    assert not bad, "imports against docs/architecture.md's layers:\n" + "\n".join(bad)


def test_no_import_circles() -> None:
    found = [sorted(c) for c in circles(import_graph(PACKAGE))]
    assert not found, f"import circles: {found}"

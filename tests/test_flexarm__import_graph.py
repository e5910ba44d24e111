"""The package's module import graph, read from the source by AST (nothing imported): no
import cycles between modules (issue #43), and every module ranked in the documented layer
order (docs/architecture.md), ``distributed`` included.

The graph: one node per module of ``src/flexarm`` (a package is its ``__init__``); an edge
a → b for every import of b in a: ``import`` and ``from ... import`` statements, absolute
and relative, at the top, inside functions or under ``if TYPE_CHECKING:`` (a lazy or a
typing-only import is still a dependency), and ``importlib.import_module("...")`` with a
constant name. ``from P import n`` is an import of the module ``P.n`` where that is a
module, else of the module P (a package's ``__init__``: ``from flexarm.design import
design`` imports the package module ``flexarm.design``; the parent packages a dotted import
runs are not counted, or every package would be a cycle with its modules). A cycle is a
strongly connected component of more than one module (Tarjan)."""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "flexarm"
DOC = SRC.parents[1] / "docs" / "architecture.md"

#: modules every layer may import, and the package's own front door (docs/architecture.md)
ROOT = {"units", "errors", "metrics", "fastmath", "layered", "version", "display"}
FRONT = {"flexarm", "flexarm.__main__"}


def _module(path: Path) -> str:
    parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module(p): p for p in sorted(SRC.rglob("*.py")) if "__pycache__" not in p.parts}


def _edges(tree: ast.AST, module: str, known: set[str], is_pkg: bool) -> dict[str, int]:
    """Imported flexarm module → the first line importing it (``known``: the modules)."""
    pkg = module.split(".") if is_pkg else module.split(".")[:-1]
    out: dict[str, int] = {}

    def add(name: str, line: int) -> None:
        parts = name.split(".")
        while parts and ".".join(parts) not in known:  # flexarm.x.y.Name → flexarm.x.y
            parts.pop()
        if parts and ".".join(parts) != module:
            out.setdefault(".".join(parts), line)

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "flexarm":
                    add(a.name, node.lineno)
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: against this module's package
                base = pkg[: len(pkg) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] != "flexarm":
                continue
            for a in node.names:  # a submodule by name, or a name of the module mod
                add(f"{mod}.{a.name}" if f"{mod}.{a.name}" in known else mod, node.lineno)
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and str(node.args[0].value).startswith("flexarm")
        ):
            add(str(node.args[0].value), node.lineno)
    return out


def graph(sources: dict[str, str] | None = None) -> dict[str, dict[str, int]]:
    """module → {imported module: line}; ``sources`` (module → text, a package's name
    ending in ``.__init__``) replaces the package's files (the scanner's own test)."""
    if sources is None:
        files = _modules()
        sources = {
            (m + ".__init__" if p.name == "__init__.py" else m): p.read_text(encoding="utf-8")
            for m, p in files.items()
        }
    mods = {k.removesuffix(".__init__"): (k.endswith(".__init__"), v) for k, v in sources.items()}
    known = set(mods)
    return {m: _edges(ast.parse(text), m, known, pkg) for m, (pkg, text) in mods.items()}


def cycles(g: dict[str, dict[str, int]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = 0
    for root in sorted(g):
        if root in index:
            continue
        work = [(root, iter(sorted(g[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in g:
                    continue
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(g[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def _cycle_edges(g) -> set[tuple[str, str]]:
    """Every edge inside a cycle (both ends in one strongly connected component)."""
    out = set()
    for comp in cycles(g):
        c = set(comp)
        out |= {(a, b) for a in comp for b in g[a] if b in c}
    return out


_TD = "flexarm.identification.time_domain."
#: The cycles still open, edge by edge (importer, imported), each in files this branch does
#: not own; the test fails on any other edge inside a cycle (a new cycle, or a module or an
#: edge added to one of these), and on a listed edge no longer inside a cycle (then remove it
#: here: the list only shrinks).
ALLOWED_CYCLE_EDGES: set[tuple[str, str]] = set()  # none left (io's checks: issue #43)


def _where(g, edges) -> str:
    return "\n".join(f"  {a}:{g[a][b]} imports {b}" for a, b in sorted(edges))


def test_no_import_cycles_but_the_listed_ones():
    g = graph()
    new = _cycle_edges(g) - ALLOWED_CYCLE_EDGES
    assert not new, (
        "imports inside a cycle (modules that import each other, directly or around a "
        "circle; the components: "
        f"{[c for c in cycles(g) if any(a in c for a, _ in new)]}):\n" + _where(g, new)
    )


def test_listed_cycles_are_still_there():
    """A cycle fixed leaves the allow-list (so the list only shrinks)."""
    gone = ALLOWED_CYCLE_EDGES - _cycle_edges(graph())
    assert not gone, "no longer in a cycle; remove from ALLOWED_CYCLE_EDGES:\n" + "\n".join(
        f"  {a} -> {b}" for a, b in sorted(gone)
    )


def test_nothing_below_distributed_imports_it():
    """``distributed`` is the orchestration layer: only the CLI (and the package's front
    door) may import it; the batches take an executor (sim/batch.py's protocol)."""
    g = graph()
    users = sorted(
        f"{a}:{e['flexarm.distributed']}"
        for a, e in g.items()
        if "flexarm.distributed" in e and not (a.startswith("flexarm.cli") or a in FRONT)
    )
    assert not users, "modules below distributed import it:\n" + "\n".join(users)


def _documented_order() -> list[str]:
    text = DOC.read_text(encoding="utf-8")
    order = text.split("Data flows one way:", 1)[1].split("**")[1]
    return [n for n in (w.strip("*,. \n") for w in order.replace("/", "→").split("→")) if n]


def test_every_module_is_ranked_in_the_documented_order():
    """Every module sits in a layer of docs/architecture.md's order (or is a root module or
    the front door); ``distributed`` is ranked, above design and identification, below the
    CLI; and every import of one ranked layer goes to its own layer or one to its left."""
    order = _documented_order()
    assert "distributed" in order
    rank = {n: i for i, n in enumerate(order)}
    rank["specs"] = rank["io"]  # io / specs: one rank
    assert rank["design"] < rank["distributed"] < rank["cli"]
    g = graph()
    unranked, against = [], []
    for a, edges in g.items():
        if a in FRONT:
            continue
        head = a.split(".")[1]
        if head in ROOT:
            continue
        if head not in rank:
            unranked.append(a)
            continue
        for b, line in edges.items():
            hb = b.split(".")[1] if b.count(".") else None
            if hb in rank and rank[hb] > rank[head]:
                against.append(f"{a}:{line} imports {b}")
    assert not unranked, f"modules in no layer of {DOC.name}'s order: {unranked}"
    assert not against, "imports against the documented order:\n" + "\n".join(against)


def test_the_scanner_finds_what_it_looks_for():
    """A made-up package: relative and function-level imports, an import of a package's
    ``__init__`` and a typing-only import are edges, and a three-module circle is found."""
    src = {
        "flexarm.__init__": "",
        "flexarm.p.__init__": "from .a import f\n",
        "flexarm.p.a": "def f():\n    from flexarm.p.b import g\n",
        "flexarm.p.b": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
        "    from ..q import h\n",
        "flexarm.q": "from flexarm.p import f\nimport flexarm.z\n",
        "flexarm.z": "import importlib\nimportlib.import_module('flexarm.q')\n",
        "flexarm.w": "from flexarm.p import a\nfrom flexarm.z import Name\n",
    }
    g = graph(src)
    assert set(g["flexarm.p"]) == {"flexarm.p.a"}  # relative, from the package
    assert set(g["flexarm.p.a"]) == {"flexarm.p.b"}  # inside a function
    assert set(g["flexarm.p.b"]) == {"flexarm.q"}  # relative two levels, typing only
    assert set(g["flexarm.q"]) == {"flexarm.p", "flexarm.z"}  # a package's __init__
    assert set(g["flexarm.z"]) == {"flexarm.q"}
    assert set(g["flexarm.w"]) == {"flexarm.p.a", "flexarm.z"}  # a submodule by name
    assert cycles(g) == [["flexarm.p", "flexarm.p.a", "flexarm.p.b", "flexarm.q", "flexarm.z"]]
    assert cycles({"a": {"b": 1}, "b": {}}) == []

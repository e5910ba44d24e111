"""The package's layering (docs/architecture.md), read from the source by AST; nothing is
imported or executed.

1. No module imports a private name (``_name``) of another flexarm module: ``from
   flexarm.x import _y`` and ``flexarm.x._y`` attribute use through an imported module are
   both found. A private name is private to its module.
2. Imports flow one way: io / specs → models → control → sim → identification → design →
   deploy → analysis → reproduce → distributed → cli. A module imports from its own layer or
   the layers to its left; the root modules ``units``, ``errors``, ``metrics``, ``fastmath``,
   ``layered`` are usable by all (and import only each other).

Imports inside functions count as much as those at the top (a lazy import is still a
dependency)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "flexarm"

#: docs/architecture.md, first line: the layers left to right.
ORDER = [
    "io",
    "specs",
    "models",
    "control",
    "sim",
    "identification",
    "design",
    "deploy",
    "analysis",
    "reproduce",
    "distributed",
    "cli",
]
RANK = {"io": 0, "specs": 0, **{name: i for i, name in enumerate(ORDER) if i >= 2}}
ROOT = {"units", "errors", "metrics", "fastmath", "layered"}
#: the package's own front door re-exports every layer
FRONT = {"__init__", "__main__"}


def _module(path: Path) -> str:
    rel = path.relative_to(SRC.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _layer(module: str) -> str | None:
    """``flexarm.sim.build`` → ``sim``; a root module → its name; the package → None."""
    parts = module.split(".")
    if len(parts) < 2:
        return None
    head = parts[1]
    if head in ("cli",) or head.startswith("cli"):
        return "cli"
    return head


def _imports(tree: ast.AST, module: str):
    """(line, imported module, imported names or None) of every flexarm import."""
    pkg = module.split(".")
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "flexarm":
                    yield node.lineno, a.name, None
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against this module's package
                base = pkg[: len(pkg) - node.level + (1 if _is_pkg(module) else 0)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] == "flexarm":
                yield node.lineno, mod, [a.name for a in node.names]


def _is_pkg(module: str) -> bool:
    return (SRC.parent / Path(*module.split(".")) / "__init__.py").exists()


def _sources():
    return sorted(p for p in SRC.rglob("*.py") if "__pycache__" not in p.parts)


def _private_uses(tree: ast.AST, module: str) -> list[str]:
    out = []
    # local name → flexarm module, from "import flexarm.x as y" / "from flexarm import x"
    aliases = {}
    for line, mod, names in _imports(tree, module):
        if names is None:
            continue
        for n in names:
            if n.startswith("_") and not n.startswith("__") and mod != module:
                if _is_module(f"{mod}.{n}"):
                    continue  # a private *module* of a package is its own layer's business
                out.append(f"{module}:{line}: from {mod} import {n}")
            elif _is_module(f"{mod}.{n}"):
                aliases[n] = f"{mod}.{n}"
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("flexarm"):
            for a in node.names:
                if a.asname and _is_module(f"{node.module}.{a.name}"):
                    aliases[a.asname] = f"{node.module}.{a.name}"
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("flexarm.") and a.asname:
                    aliases[a.asname] = a.name
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in aliases
            and node.attr.startswith("_")
            and not node.attr.startswith("__")
            and aliases[node.value.id] != module
        ):
            out.append(f"{module}:{node.lineno}: {aliases[node.value.id]}.{node.attr}")
    return out


def _is_module(dotted: str) -> bool:
    p = SRC.parent / Path(*dotted.split("."))
    return p.with_suffix(".py").exists() or (p / "__init__.py").exists()


def _layer_breaks(tree: ast.AST, module: str) -> list[str]:
    me = _layer(module)
    if me is None or module.split(".")[-1] in FRONT and module.count(".") == 1:
        return []
    out = []
    for line, mod, names in _imports(tree, module):
        targets = (
            [mod]
            if names is None
            else [f"{mod}.{n}" if _is_module(f"{mod}.{n}") else mod for n in names]
        )
        for t in set(targets):
            them = _layer(t)
            if them is None:  # "from flexarm import x": the front door
                if me in ROOT or RANK.get(me, 99) < RANK["cli"]:
                    out.append(
                        f"{module}:{line}: imports the package front door ({t}: "
                        f"{', '.join(names or [])})"
                    )
                continue
            if them in ROOT:
                continue
            if me in ROOT:
                out.append(f"{module}:{line}: root module imports {t}")
            elif them not in RANK:
                continue
            elif RANK[them] > RANK.get(me, 99):
                out.append(f"{module}:{line}: {me} imports {t} ({them} is to its right)")
    return out


def _scan(check) -> list[str]:
    found = []
    for path in _sources():
        module = _module(path)
        found += check(ast.parse(path.read_text(encoding="utf-8")), module)
    return found


#: Findings in files other helpers own (reported to the lead, fixed in their branches);
#: every entry must still be found (a fixed one is removed here), and nothing else may be.
KNOWN_PRIVATE = {
    "flexarm.analysis.summary: from flexarm.sim.result import _unit",
    "flexarm.control.outer_loop: from flexarm.control.trajectories import _deflection_signal",
    "flexarm.control.trajectories: from flexarm.control.wiener import _siso_polys",
    # needs a public sim.build.measured_names (ctrlblocks: Controller.measured_signals)
    "flexarm.design.plants: from flexarm.sim.build import _measured_names",
    "flexarm.identification.frequency_domain.coulomb: "
    "from flexarm.identification.frequency_domain.harmonics import _warn",
    "flexarm.identification.frequency_domain.identify: "
    "from flexarm.identification.frequency_domain.harmonics import _warn",
    # fitcore: the next three need public names in sim (sampled.scan/quantise,
    # build.measured_names)
    "flexarm.identification.time_domain.general: from flexarm.sim.build import _measured_names",
    "flexarm.identification.time_domain.general: from flexarm.sim.sampled import _quantise",
    "flexarm.identification.time_domain.general: from flexarm.sim.sampled import _scan",
    # fitcore: needs a public specs.scenario.format_errors
    "flexarm.io.logformat: from flexarm.specs.scenario import _format_errors",
    "flexarm.models.single_link: from flexarm.models.lumped_beam import _clean",
    "flexarm.sim.continuous: flexarm.sim.sampled._prepare_refs",
    "flexarm.sim.continuous: flexarm.sim.sampled._run_all",
}
KNOWN_LAYER: set[str] = set()


def test_no_module_imports_another_modules_private_name():
    found = sorted(set(_scan(_private_uses)))
    new = [f for f in found if _key(f) not in KNOWN_PRIVATE]
    assert not new, "private names imported across modules:\n" + "\n".join(new)


def test_known_findings_are_still_there():
    """A fixed finding leaves the known lists (so the lists only shrink)."""
    gone = sorted(
        (KNOWN_PRIVATE - {_key(f) for f in _scan(_private_uses)})
        | (KNOWN_LAYER - {_key(f) for f in _scan(_layer_breaks)})
    )
    assert not gone, "fixed; remove from KNOWN_PRIVATE / KNOWN_LAYER:\n" + "\n".join(gone)


def test_imports_follow_the_layer_order():
    found = sorted(set(_scan(_layer_breaks)))
    new = [f for f in found if _key(f) not in KNOWN_LAYER]
    assert not new, "imports against the layer order (docs/architecture.md):\n" + "\n".join(new)


#: Modules that one direction of imports joins (importer, imported): the reverse would be an
#: import circle. The log-format reader decodes ``.mat`` files through ``matfile``, which
#: decodes only (issue #23: one loader, no circle between the two).
ONE_WAY = [("flexarm.io.logformat", "flexarm.io.matfile")]


def _imported_modules(module: str) -> set[str]:
    """The flexarm modules ``module`` imports (at the top, in functions, or by name from a
    package), and the modules named in ``importlib.import_module("...")`` calls."""
    path = SRC.parent / Path(*module.split("."))
    path = path / "__init__.py" if _is_pkg(module) else path.with_suffix(".py")
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = set()
    for _, mod, names in _imports(tree, module):
        out.add(mod)
        out.update(f"{mod}.{n}" for n in names or [] if _is_module(f"{mod}.{n}"))
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
        ):
            out.add(str(node.args[0].value))
    return out


@pytest.mark.parametrize(("importer", "imported"), ONE_WAY)
def test_imports_between_these_modules_go_one_way(importer, imported):
    assert imported in _imported_modules(importer), f"{importer} no longer imports {imported}"
    assert importer not in _imported_modules(imported), (
        f"{imported} imports {importer}, which imports it: an import circle"
    )


def _key(finding: str) -> str:
    """A finding without its line number (lines move; the module and the name do not)."""
    mod, _, rest = finding.partition(":")
    _, _, what = rest.partition(": ")
    return f"{mod}: {what}"


def test_the_checks_find_what_they_look_for():
    """The scanner is not blind: a private import and a layer break in a made-up module."""
    tree = ast.parse(
        "from flexarm.sim.sampled import _scan\nimport flexarm.design.result\n"
        "from flexarm.sim import sampled as S\nx = S._run_all\n"
    )
    assert any("_scan" in f for f in _private_uses(tree, "flexarm.models.fake"))
    assert any("_run_all" in f for f in _private_uses(tree, "flexarm.models.fake"))
    assert any("design" in f for f in _layer_breaks(tree, "flexarm.models.fake"))
    assert not _layer_breaks(
        ast.parse("from flexarm.models.assembly import Arm"), "flexarm.sim.fake"
    )


@pytest.mark.parametrize("doc", ["docs/architecture.md"])
def test_the_documented_order_is_the_tested_one(doc):
    text = (SRC.parents[1] / doc).read_text(encoding="utf-8")
    order = text.split("Data flows one way:", 1)[1].split("**")[1]
    names = [w.strip("*,. \n") for w in order.replace("/", "→").split("→")]
    assert [n for n in names if n] == ORDER

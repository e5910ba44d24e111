"""Build-time helpers of the documentation site (mkdocs.yml: ``hooks`` and the mkdocstrings
griffe ``extensions``). Standard library only at import.

* ``<!-- scenario-reference -->`` in a page becomes the scenario-field reference that
  ``tools/scenario_reference.py`` generates from the pydantic specs (docs/scenarios.md; no
  copy of it is kept in the repository);
* ``<!-- api: flexarm.PKG -->`` becomes one ``::: module`` block per public module of the
  package (found in ``src/``, so a module that is added, moved or removed needs no page edit);
* ``<!-- include: FILE -->`` becomes the text of FILE (relative to the repository root);
* :class:`SphinxRoles`: the docstrings use Sphinx roles (``:func:`flexarm.fit```); they are
  shown as code (``flexarm.fit``), the tilde form by its last name.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"

_ROLE = re.compile(
    r":(?:py:)?(?:func|class|meth|mod|attr|data|exc|obj|const|ref|term):"
    r"`(~?)([^`<]+?)(?:\s*<([^>]+)>)?`"
)
_API = re.compile(r"<!-- api: ([\w.]+) -->")
_INCLUDE = re.compile(r"<!-- include: ([\w./-]+) -->")


def sphinx_roles_to_code(text: str) -> str:
    """``:func:`~a.b.c``` → ```c```, ``:class:`a.B``` → ```a.B```, ``:ref:`text <x>``` →
    ```text```."""

    def repl(m: re.Match) -> str:
        tilde, name = m.group(1), m.group(2).strip()
        return f"`{name.rsplit('.', 1)[-1] if tilde else name}`"

    return _ROLE.sub(repl, text)


def public_modules(package: str) -> list[str]:
    """Dotted names of the public modules of ``package`` (no ``_`` in any part), the
    package itself first, in file order."""
    base = SRC.joinpath(*package.split("."))
    if not base.is_dir():
        raise ValueError(f"<!-- api: {package} -->: no package at {base}")
    out = [package]
    for p in sorted(base.rglob("*.py")):
        rel = p.relative_to(SRC).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
            if parts == package.split("."):
                continue
        if any(x.startswith("_") for x in parts):
            continue
        out.append(".".join(parts))
    return out


def scenario_reference() -> str:
    """The text ``python tools/scenario_reference.py`` prints."""
    spec = importlib.util.spec_from_file_location(
        "_scenario_reference", ROOT / "tools" / "scenario_reference.py"
    )
    mod = importlib.util.module_from_spec(spec)
    if str(SRC) not in sys.path:
        sys.path.insert(0, str(SRC))
    spec.loader.exec_module(mod)
    return mod.reference()


def expand(markdown: str) -> str:
    """Apply the three markers of this module to a page's Markdown."""
    if "<!-- scenario-reference -->" in markdown:
        markdown = markdown.replace("<!-- scenario-reference -->", scenario_reference())
    markdown = _API.sub(
        lambda m: "\n\n".join(f"::: {name}" for name in public_modules(m.group(1))), markdown
    )
    return _INCLUDE.sub(lambda m: (ROOT / m.group(1)).read_text(), markdown)


def on_page_markdown(markdown, page, config, files):  # mkdocs hook
    return expand(markdown)


try:  # the griffe extension (only where mkdocstrings is installed)
    from griffe import Extension

    class SphinxRoles(Extension):
        """Sphinx roles in docstrings shown as code (mkdocstrings extension)."""

        def on_instance(self, *, obj, **kwargs) -> None:
            if obj.docstring is not None:
                obj.docstring.value = sphinx_roles_to_code(obj.docstring.value)
except ImportError:  # pragma: no cover
    pass

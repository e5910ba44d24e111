"""The README and the docs pages it points to: the scenario reference is generated into the
site (docs/scenarios.md) at build time, the README opens with the two commands, and the
Python blocks the pages show run."""

import importlib.util
import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import scenario_reference  # noqa: E402 - from tools/, put on sys.path above

SCENARIOS = sorted((ROOT / "src" / "flexarm" / "scenarios").glob("*.toml"))


def _hooks():
    spec = importlib.util.spec_from_file_location("_docs_hooks", ROOT / "docs" / "hooks.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_scenarios_page_is_generated_at_build_time():
    """docs/scenarios.md holds the marker that docs/hooks.py replaces with the reference
    (so no copy is kept to go stale), and the replacement is the generated text."""
    page = (ROOT / "docs" / "scenarios.md").read_text()
    assert scenario_reference.MARKER in page
    built = _hooks().expand(page)
    assert scenario_reference.MARKER not in built
    assert scenario_reference.reference() in built
    assert "scenario-reference:begin" not in (ROOT / "README.md").read_text()


def test_scenario_reference_covers_the_builtin_scenarios():
    """Every top-level table of a built-in scenario has a section in the reference (e.g.
    ``[arm]``, ``[controller]``, ``[sampling]``, ``[simulation]``, ``[sensors.<signal>]``),
    or is a free-form table listed as a top-level field."""
    ref = scenario_reference.reference()
    assert SCENARIOS
    missing = []
    for path in SCENARIOS:
        data = tomllib.loads(path.read_text())
        for key, value in data.items():
            if not isinstance(value, dict):
                continue
            heading = re.search(rf"^#### \[\[?{re.escape(key)}[\].]", ref, re.M)
            if heading is None and f"| `{key}` | table |" not in ref:
                missing.append(f"{path.name}: [{key}]")
    assert not missing, "tables of built-in scenarios not in the reference:\n" + "\n".join(missing)
    for table in ("[arm]", "[controller]", "[sampling]", "[simulation]"):
        assert f"#### {table}" in ref


def test_readme_opens_with_the_two_commands():
    """The README starts with exactly two commands, `make demo` and `make test` (the
    developers' guide); `make check` is named in the prose after them."""
    text = (ROOT / "README.md").read_text()
    lines = text.splitlines()
    block = lines[lines.index("```") + 1 : lines.index("```", lines.index("```") + 1)]
    assert [ln.split()[0:2] for ln in block] == [["make", "demo"], ["make", "test"]]
    assert "`make check`" in text


def test_readme_links_exist():
    """Every relative link of the README points to a file of the repository."""
    text = (ROOT / "README.md").read_text()
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    assert links
    missing = [x for x in links if "://" not in x and not (ROOT / x).exists()]
    assert not missing, missing


def test_readme_c_loop_is_the_design_pages():
    """The README's C target loop (compiled by tests/test_c_export.py) is the one
    docs/tasks/design-export.md shows."""

    def block(path):
        text = (ROOT / path).read_text()
        return text.split("## Deploying a controller in C")[1].split("```c\n")[1].split("```")[0]

    assert block("README.md") == block("docs/tasks/design-export.md")


def test_multilink_example_runs():
    """The multi-link Python block of docs/tasks/simulate.md runs as written (API drift
    breaks it)."""
    import matplotlib

    matplotlib.use("Agg")
    text = (ROOT / "docs" / "tasks" / "simulate.md").read_text()
    block = text.split("## Multi-link arms under gravity")[1].split("```python")[1].split("```")[0]
    env: dict = {}
    exec(compile(block, "docs/tasks/simulate.md", "exec"), env)
    sweep = env["sweep"]
    assert not sweep.diverged.any()
    peaks = abs(sweep.torque[:, 0]).max(axis=1)
    assert peaks[0] < peaks[1] < peaks[2]  # larger gains, larger initial torques (DLS)

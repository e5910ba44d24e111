"""The README's scenario reference is generated from the specs: it must be current."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import scenario_reference  # noqa: E402


def test_readme_scenario_reference_is_current():
    text = (ROOT / "README.md").read_text()
    a = text.index(scenario_reference.BEGIN) + len(scenario_reference.BEGIN)
    b = text.index(scenario_reference.END)
    assert text[a:b] == "\n" + scenario_reference.reference(), (
        "README.md's scenario reference is stale: run `python tools/scenario_reference.py --write`")


def test_readme_opens_with_the_two_commands():
    lines = (ROOT / "README.md").read_text().splitlines()
    block = lines[lines.index("```") + 1: lines.index("```", lines.index("```") + 1)]
    assert [ln.split()[0:2] for ln in block] == [["make", "demo"], ["make", "test"]]


def test_readme_multilink_example_runs():
    """The README's multi-link Python block runs as written (API drift breaks it)."""
    import matplotlib

    matplotlib.use("Agg")
    text = (ROOT / "README.md").read_text()
    block = text.split("Multi-link arms under gravity")[1].split("```python")[1].split("```")[0]
    env: dict = {}
    exec(compile(block, "README.md", "exec"), env)
    sweep = env["sweep"]
    assert not sweep.diverged.any()
    peaks = abs(sweep.torque[:, 0]).max(axis=1)
    assert peaks[0] < peaks[1] < peaks[2]       # larger gains, larger initial torques (DLS)

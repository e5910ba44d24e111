"""`fit --help` groups its options (issue #46 item 4): data sheet, log, search, outputs,
each option under its panel, the route each panel is for in its title."""

from __future__ import annotations

from typer.testing import CliRunner

from flexarm.cli import app

runner = CliRunner()


def _sections(text: str) -> dict[str, str]:
    """Section title → its body (a title is an unindented line ending with ':')."""
    out, title = {}, None
    for line in text.splitlines():
        if line and not line[0].isspace() and line.endswith(":"):
            title = line[:-1]
            out[title] = ""
        elif title is not None:
            out[title] += line + "\n"
    return out


def test_fit_help_lists_its_options_in_panels():
    r = runner.invoke(app, ["fit", "--help"], terminal_width=100)
    assert r.exit_code == 0, r.output
    s = _sections(r.stdout)
    titles = [t.split(" (")[0] for t in s]
    assert titles == ["Arguments", "Data sheet", "Log", "Search", "Outputs", "Other options"]
    body = {t.split(" (")[0]: b for t, b in s.items()}
    for panel, opts in {
        "Data sheet": ["--gear-ratio", "--motor-constant", "--link-length", "--voltage-limit"],
        "Log": ["--log-format", "--window", "--validate-window", "--column"],
        "Search": ["--global-starts", "--free", "--prior", "--segment", "--tip-after-hub"],
        "Outputs": ["--json", "--scenario-out", "--report", "--overwrite"],
    }.items():
        missing = [o for o in opts if o not in body[panel]]
        assert not missing, (panel, missing)
    # what no panel claims lands in "Other options" (--help, options added later)
    assert "--help" in body["Other options"]
    data_sheet = next(t for t in s if t.startswith("Data sheet"))
    assert "--motor-constant" in data_sheet and "--armature-resistance" in data_sheet


def test_validate_help_uses_the_same_panels():
    r = runner.invoke(app, ["validate", "--help"], terminal_width=100)
    assert r.exit_code == 0, r.output
    titles = [t.split(" (")[0] for t in _sections(r.stdout)]
    assert titles == ["Arguments", "Log", "Search", "Outputs", "Other options"]

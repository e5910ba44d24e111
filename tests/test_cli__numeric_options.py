"""Issue #45 item 4 and 6: every numeric option of every command is checked at parse time.

The options are found by walking the command line itself (typer → click), so an option
added later is covered without editing this file.  Classes and counts (derandomised):

* non-finite floats (``nan``, ``inf``, ``-inf``) for every float option and ±1e30 for
  every integer option: refused before any work, one ``error:`` line naming the option
  (3 values × each float option, 2 × each integer option: 53 options, 31 of them
  float, 137 runs on 2026-12-05);
* any float (NaN, ±inf, subnormal, ±1e308) or any integer (±2⁷⁰) for a random numeric
  option of the 45 outside ``excite`` (hypothesis, 80 examples): exit 2 with one line,
  never "internal error" (the command's input is missing, so a value the parser takes
  ends in the line that names the missing file, and a value it refuses in the line that
  names the option).

Before: 18 options took any value (``--seed -1`` reached numpy: "error: expected
non-negative integer", no option named; ``--kp nan``, ``--global-seconds inf``,
``--max-nfev -1e30``, ``--poles 1e30`` ... ran on), and ``excite`` into a missing folder
ended in "internal error: FileNotFoundError".
"""

from __future__ import annotations

import math

import pytest
from typer.main import get_command
from typer.testing import CliRunner

from flexarm.cli import app

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402 - optional: after importorskip
from hypothesis import strategies as st  # noqa: E402 - optional: after importorskip

runner = CliRunner()

#: each command's arguments with a missing input, so that its body ends at once in one
#: line naming that input ({t}: a temporary folder; {f}: a file there)
BASE = {
    "design": ["design", "{t}/nope.toml", "--out", "{t}/d"],
    "experiment": ["experiment", "{t}/nope.toml", "--out", "{t}/e"],
    "fit": ["fit", "{t}/nope.csv"],
    "validate": ["validate", "rotary-flexible-link", "{t}/nope.csv"],
    "excite": ["excite", "{t}/none/e.csv", "--fs", "1000", "--period", "64"]
    + ["--f-min", "10", "--f-max", "200"],
    "tfest": ["tfest", "{t}/nope.json", "--json", "{t}/t.json"],
    "friction": ["friction", "{t}/nope.json", "{t}/nope2.json", "--json", "{t}/t.json"],
    "fit-many": ["fit-many", "{t}/nope.csv", "--out", "{t}/fm"],
    "example-logs": ["example-logs", "{f}"],
}


def numeric_options() -> list[tuple[str, str, str]]:
    """(command, option, "float" | "int") for every numeric option of the command line."""
    out = []
    for name, cmd in get_command(app).commands.items():  # pyright: ignore[reportAttributeAccessIssue]
        for p in cmd.params:
            if p.param_type_name != "option":
                continue
            kind = str(p.bare_type())
            if kind in ("float", "int"):
                out.append((name, p.opts[0], kind))
    return out


OPTIONS = numeric_options()
NON_FINITE = ("nan", "inf", "-inf")
HUGE = (str(10**30), str(-(10**30)))
CASES = [(c, o, v) for c, o, k in OPTIONS for v in (NON_FINITE if k == "float" else HUGE)]


def _argv(command, option, value, tmp):
    f = tmp / "a-file"
    f.write_text("x")
    base = [a.replace("{t}", str(tmp)).replace("{f}", str(f)) for a in BASE[command]]
    return [*base, option, value]


def _one_line(r) -> str:
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.exit_code == 2, (r.exit_code, r.output)
    assert len(lines) == 1 and lines[0].startswith("error:"), r.stderr
    assert "internal error" not in r.output
    return lines[0]


def test_the_walk_finds_the_numeric_options_and_every_command_has_a_base():
    assert len(OPTIONS) >= 50
    assert {c for c, _, _ in OPTIONS} <= set(BASE)
    assert ("design", "--plants", "int") in OPTIONS and ("excite", "--rms", "float") in OPTIONS


@pytest.mark.parametrize("command, option, value", CASES, ids=[" ".join(c) for c in CASES])
def test_a_non_finite_or_absurd_value_is_refused_naming_the_option(
    tmp_path, command, option, value
):
    line = _one_line(runner.invoke(app, _argv(command, option, value, tmp_path)))
    assert option in line, line
    assert not (tmp_path / "d").exists() and not (tmp_path / "t.json").exists()


FUZZED = [(c, o, k) for c, o, k in OPTIONS if c != "excite"]  # excite has no input: it runs


@settings(
    max_examples=80,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    which=st.integers(0, len(FUZZED) - 1),
    x=st.floats(allow_nan=True, allow_infinity=True),
    n=st.integers(-(2**70), 2**70),
)
def test_any_value_of_any_numeric_option_is_one_line_never_an_internal_error(tmp_path, which, x, n):
    command, option, kind = FUZZED[which]
    value = repr(x) if kind == "float" else str(n)
    line = _one_line(runner.invoke(app, _argv(command, option, value, tmp_path)))
    if kind == "float" and not math.isfinite(x):
        assert option in line, line  # refused by the parser, before the input is read
    if option not in line:  # taken: the body ends at the missing input
        assert "nope" in line or "a-file" in line, line


def test_an_output_in_a_missing_folder_is_one_line_not_an_internal_error(tmp_path):
    """`excite` into a folder that does not exist: the writer's refusal is a project
    error now (io.write.OutputFolderError), exit 2."""
    argv = _argv("excite", "--rms", "1", tmp_path)
    line = _one_line(runner.invoke(app, argv))
    assert f"the folder {tmp_path / 'none'} does not exist; create the folder first" in line

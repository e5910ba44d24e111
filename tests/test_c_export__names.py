"""export-c with names that are data (issue #45): a scenario's ``name`` (and a channel's)
reaches the generated C only through the one comment escaper (``c_comment``), ``--name``
only as a checked C identifier; with any name the generated files compile, define exactly
the macros of a plain export (no injected ``#define``), and lie inside ``--out``.

Fuzz classes (hypothesis, derandomized): scenario names of any Unicode text including
``*/``, ``/*``, newlines, NUL, ``??/`` trigraphs and backslashes (40 examples); ``--name``
strings of any text (60 examples)."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from flexarm.deploy import ExportError, export_c, generate_c
from flexarm.deploy.c_export import c_comment, c_string
from flexarm.specs import load_scenario

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import example, given, settings  # noqa: E402 - optional: after importorskip
from hypothesis import strategies as st  # noqa: E402 - optional: after importorskip

CC = next((c for c in ("cc", "gcc", "clang") if shutil.which(c)), None)
INJECTION = "rig */\n#define rig_step(s, m, r, u) injected_step(s, m, r, u)\n/*"
BASE = load_scenario("rotary-flexible-link")


def _macros(cc: str, header, folder) -> set[str]:
    """The macro names the header defines (``cc -dM -E``), less the compiler's own."""
    own = subprocess.run(
        [cc, "-std=c99", "-dM", "-E", "-x", "c", "/dev/null"], capture_output=True, text=True
    ).stdout
    got = subprocess.run(
        [cc, "-std=c99", "-dM", "-E", "-x", "c", str(header)],
        capture_output=True,
        text=True,
        cwd=folder,
    )
    assert got.returncode == 0, got.stderr
    return set(got.stdout.splitlines()) - set(own.splitlines())


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    d = tmp_path_factory.mktemp("plain")
    code = generate_c(BASE, name="rig")
    (d / "rig.h").write_text(code.header)
    return d, code


def test_the_escaper_leaves_no_comment_end_no_control_character_and_no_trigraph():
    for text in (INJECTION, "a*/b/*c", "??/\n", "x\\", "a\x00b\rc", "*" * 3 + "/" * 3):
        s = c_comment(text)
        assert "*/" not in s and "/*" not in s and "??" not in s
        assert not any(ord(ch) < 32 for ch in s) and not s.endswith("\\")
    assert c_comment("x" * 500).endswith("...") and len(c_comment("x" * 500)) == 203
    assert '"' not in c_string('say "hi" \\') and "\\" not in c_string('say "hi" \\')


@settings(max_examples=40, deadline=None)
@given(name=st.text(min_size=0, max_size=80))
@example(name=INJECTION)
@example(name="")
@example(name="a\x00b")
@example(name="x" * 300)
@example(name="??/\n#error broken")
def test_any_scenario_name_compiles_to_the_same_macros(plain, tmp_path_factory, name):
    if CC is None:
        pytest.skip("no C compiler (cc, gcc or clang) on this machine")
    folder, base = plain
    sc = BASE.model_copy(update={"name": name})
    code = generate_c(sc, name="rig", source=f"{name}.toml")
    d = tmp_path_factory.mktemp("fuzz")
    (d / "rig.h").write_text(code.header)
    (d / "rig.c").write_text(code.source)
    p = subprocess.run(
        [CC, "-std=c99", "-fsyntax-only", "-Wall", "-Werror", "rig.c"],
        capture_output=True,
        text=True,
        cwd=d,
    )
    assert p.returncode == 0, p.stderr
    assert _macros(CC, d / "rig.h", d) == _macros(CC, folder / "rig.h", folder)
    # the code itself (outside comments) is the plain export's
    strip = [ln for ln in code.source.splitlines() if not ln.lstrip().startswith(("*", "/*"))]
    want = [ln for ln in base.source.splitlines() if not ln.lstrip().startswith(("*", "/*"))]
    assert strip == want


@settings(max_examples=60, deadline=None)
@given(name=st.text(min_size=0, max_size=90))
@example(name="../victim")
@example(name="/tmp/abs")
@example(name="int")
@example(name="a" * 65)
def test_any_name_option_is_a_c_identifier_inside_out_or_refused_in_one_line(
    tmp_path_factory, name
):
    out = tmp_path_factory.mktemp("out")
    try:
        code = generate_c(BASE, name=name)
    except ExportError as exc:
        msg = str(exc)
        assert "--name" in msg and "\n" not in msg and len(msg) < 400
        return
    assert name.isidentifier() and name.isascii() and len(name) <= 64
    paths = code.write(out)
    assert all(p.resolve().parent == out.resolve() for p in paths)


def test_the_issues_injection_through_the_cli_renames_nothing(tmp_path):
    import tomli_w
    from typer.testing import CliRunner

    from flexarm.cli import app

    d = BASE.model_dump(mode="json", exclude_none=True)
    d["name"] = INJECTION
    src = tmp_path / "inj.toml"
    src.write_text(tomli_w.dumps(d))
    r = CliRunner().invoke(
        app, ["export-c", str(src), "--out", str(tmp_path / "c"), "--name", "rig"]
    )
    assert r.exit_code == 0, r.output
    header = (tmp_path / "c" / "rig.h").read_text()
    lines = header.splitlines()
    assert not any(ln.lstrip().startswith("#define rig_step") for ln in lines)
    assert sum(ln.startswith("#define") for ln in lines) == 5  # guard, 3 sizes, period
    if CC is not None:
        assert not any(
            m.startswith("#define rig_step")
            for m in _macros(CC, tmp_path / "c" / "rig.h", tmp_path / "c")
        )
    _, paths = export_c(src, tmp_path / "c2", name="rig")
    assert [p.name for p in paths] == ["rig.h", "rig.c"]

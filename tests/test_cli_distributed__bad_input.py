"""Issue #45: ``fit-many`` on a UTF-16 manifest names the manifest (before: "an input file
is not UTF-8 text", no file named), exit 2, nothing written."""

from __future__ import annotations

from typer.testing import CliRunner

from flexarm.cli import app


def test_a_utf16_manifest_is_one_line_naming_it(tmp_path):
    m = tmp_path / "manifest.csv"
    m.write_text("id,logs\nr1,log.csv\n", encoding="utf-16")
    r = CliRunner().invoke(app, ["fit-many", str(m), "--out", str(tmp_path / "fm")])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"error: {m}: not UTF-8 text (invalid start byte at byte 0)")
    assert "save the manifest as UTF-8" in lines[0]
    assert not (tmp_path / "fm" / "summary.csv").exists()

"""export-c: the gate on every export (issue #45): a scenario or design whose sampled loop
the nominal check finds unstable, or a design whose stored verdict is not "stable"
(whichever of its files is given), is refused (exit 2, one line) unless
--accept-unstable, which writes the reason into the header as a #warning."""

from __future__ import annotations

import json
import shutil
import subprocess

import pytest
import tomli_w
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.deploy import export_c
from flexarm.errors import FlexarmError, UnstableDesignError
from flexarm.specs import load_scenario

runner = CliRunner()
CC = next((c for c in ("cc", "gcc", "clang") if shutil.which(c)), None)


def _scenario_file(tmp_path, name="pos", **controller):
    d = load_scenario("rotary-flexible-link").model_dump(mode="json", exclude_none=True)
    d["controller"].update(controller)
    p = tmp_path / f"{name}.toml"
    p.write_text(tomli_w.dumps(d))
    return p


def test_a_scenario_with_positive_hub_feedback_is_refused_unless_accepted(tmp_path):
    src = _scenario_file(tmp_path, k1=-6.0)
    out = tmp_path / "c"
    with pytest.raises(UnstableDesignError, match="unstable on the nominal plant") as e:
        export_c(src, out, name="rig")
    assert isinstance(e.value, FlexarmError) and "--accept-unstable" in str(e.value)
    assert not out.exists()
    r = runner.invoke(app, ["export-c", str(src), "--out", str(out), "--name", "rig"])
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.exit_code == 2 and len(lines) == 1, r.output
    assert "pos.toml" in lines[0] and "|z| = 1.00571 > 1" in lines[0]
    assert "--accept-unstable" in lines[0] and "internal error" not in lines[0]
    assert not (out / "rig.h").exists()
    r = runner.invoke(
        app, ["export-c", str(src), "--out", str(out), "--name", "rig", "--accept-unstable"]
    )
    assert r.exit_code == 0, r.output
    header = (out / "rig.h").read_text()
    guard = header.index("#define RIG_H\n")
    warn = header.index('#warning "flexarm: pos.toml: unstable on the nominal plant')
    assert guard < warn < header.index("#endif")
    if CC is not None:  # every build says it
        p = subprocess.run(
            [CC, "-std=gnu99", "-c", str(out / "rig.c"), "-o", str(tmp_path / "rig.o")],
            capture_output=True,
            text=True,
        )
        assert p.returncode == 0 and "unstable on the nominal plant" in p.stderr


def test_a_stable_scenario_exports_without_a_warning(tmp_path):
    src = _scenario_file(tmp_path, name="ok")
    _, paths = export_c(src, tmp_path / "c", name="rig")
    assert "#warning" not in paths[0].read_text()


@pytest.mark.parametrize("given", ["folder", "design.toml", "design.json"])
def test_a_designs_stored_verdict_is_honoured_whichever_file_is_given(tmp_path, given):
    """The side door of issue #45: `export-c d/design.toml` exported a refused design."""
    d = tmp_path / "d"
    d.mkdir()
    sc = load_scenario("rotary-flexible-link").model_dump(mode="json", exclude_none=True)
    (d / "design.toml").write_text(tomli_w.dumps(sc))  # a loop the nominal check passes
    verdict = "unstable on 7 of 50 drawn plants (14 % > 1 %)"
    (d / "design.json").write_text(json.dumps({"method": "place", "verdict": verdict}))
    src = d if given == "folder" else d / given
    out = tmp_path / "c"
    with pytest.raises(UnstableDesignError, match="verdict is not stable") as e:
        export_c(src, out, name="rig")
    assert verdict in str(e.value)
    r = runner.invoke(app, ["export-c", str(src), "--out", str(out)])
    assert r.exit_code == 2 and verdict in r.stderr and not out.exists(), r.output
    _, paths = export_c(src, out, name="rig", accept_unstable=True)
    assert f'#warning "flexarm: d/design.toml: design verdict: {verdict}' in paths[0].read_text()

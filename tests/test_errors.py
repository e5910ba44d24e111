"""One error base (issue #25): every project error is a FlexarmError that keeps its
standard second base; one_line formats any error as the one line the CLI prints;
internal_error_report writes a traceback to a log file it names."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

from flexarm import errors
from flexarm.errors import FlexarmError, internal_error_report, one_line

SRC = Path(__file__).resolve().parents[1] / "src" / "flexarm"


def _error_classes():
    """Every class in src/flexarm whose name ends in Error, Diverged or Interrupted
    (found by parsing, so a new one cannot be forgotten), as (module, name)."""
    out = []
    for f in sorted(SRC.rglob("*.py")):
        tree = ast.parse(f.read_text(encoding="utf-8"))
        mod = ".".join(f.relative_to(SRC.parent).with_suffix("").parts).removesuffix(".__init__")
        for node in tree.body:
            if isinstance(node, ast.ClassDef) and node.name.endswith(
                ("Error", "Diverged", "Interrupted")
            ):
                out.append((mod, node.name))
    return out


def test_every_project_error_is_a_flexarm_error_and_keeps_its_second_base():
    classes = _error_classes()
    # the ones the issue lists are among them (the scan found the tree)
    names = {n for _, n in classes}
    assert {
        "ScenarioError",
        "LogError",
        "FitInputError",
        "ExportError",
        "UnitError",
        "TFEstError",
        "MatFileError",
        "LogFormatError",
    } <= names, names
    for mod, name in classes:
        cls = getattr(importlib.import_module(mod), name)
        if name == "Interrupted":  # a signal, deliberately not an error (errors.py)
            assert issubclass(cls, KeyboardInterrupt) and not issubclass(cls, Exception)
            continue
        assert issubclass(cls, FlexarmError), f"{mod}.{name}"
    # the second bases callers catch are kept
    from flexarm.deploy.c_export import ExportError
    from flexarm.identification.time_domain import FitInputError
    from flexarm.io.logs import LogError, LogExistsError
    from flexarm.specs import ScenarioError
    from flexarm.units import UnitError

    for cls in (ExportError, FitInputError, LogError, ScenarioError, UnitError):
        assert issubclass(cls, ValueError), cls
    assert issubclass(LogExistsError, FileExistsError) and issubclass(LogExistsError, LogError)
    assert issubclass(errors.OutputExistsError, FileExistsError)
    assert issubclass(errors.SimulationDiverged, RuntimeError)


def test_one_line_adds_file_field_value_and_fix_once():
    e = FlexarmError(
        "must be > 0",
        file="rig.toml",
        field="arm.motor.inertia",
        value=-1.0,
        fix="give the data-sheet value",
    )
    assert one_line(e) == (
        "rig.toml: arm.motor.inertia = -1.0: must be > 0; give the data-sheet value"
    )
    # parts the message already shows are not repeated
    e = FlexarmError(
        "rig.toml: arm.motor.inertia = -1 must be > 0",
        file="rig.toml",
        field="arm.motor.inertia",
        value=-1,
    )
    assert one_line(e) == "rig.toml: arm.motor.inertia = -1 must be > 0"
    # several lines (a scenario's list of problems) become one
    from flexarm.specs import ScenarioError

    e = ScenarioError("rig.toml: 2 problem(s) in the scenario\n  a: bad\n  b: worse")
    line = one_line(e)
    assert "\n" not in line and line == "rig.toml: 2 problem(s) in the scenario; a: bad; b: worse"
    # a plain message stays as it is
    assert one_line(FlexarmError("x")) == "x"


def test_other_exceptions_are_internal_errors_with_their_report(tmp_path):
    try:
        {}["missing"]
    except KeyError as exc:
        log = internal_error_report(exc, tmp_path / "logs")
        line = one_line(exc, log=log)
    assert log.parent == tmp_path / "logs" and log.name.startswith("flexarm-error-")
    text = log.read_text()
    assert "Traceback" in text and "KeyError: 'missing'" in text and "command:" in text
    assert line == f"internal error: KeyError: 'missing' (traceback in {log})"
    assert "\n" not in line


def test_internal_error_report_falls_back_to_the_temporary_folder(tmp_path, monkeypatch):
    import tempfile

    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    log = internal_error_report(RuntimeError("boom"), blocker / "sub")
    assert log.parent == tmp_path / "tmp" and "RuntimeError: boom" in log.read_text()


def test_unit_error_from_a_bad_quantity_is_one_line():
    from flexarm.units import UnitError, to_si

    with pytest.raises(UnitError) as info:
        to_si("7 in", "kg*m**2", field="arm.motor.inertia")
    assert isinstance(info.value, FlexarmError) and "\n" not in one_line(info.value)

"""The one atomic writer (flexarm.io.write): complete file or none, never a partial one;
no silent overwrite; no temporary file left behind, Ctrl-C included."""

import json
import os
import stat

import pytest

from flexarm.errors import OutputExistsError
from flexarm.io.write import (atomic_open, save_figure, write_bytes, write_json, write_text,
                           write_toml)


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_text_json_toml_round_trip_and_refuse_to_overwrite(tmp_path):
    import tomllib

    p = write_json(tmp_path / "a.json", {"x": 1.5, "nan": float("nan")})
    d = json.loads(p.read_text())
    assert d["x"] == 1.5 and d["nan"] != d["nan"]  # NaN written as json does
    t = write_toml(tmp_path / "a.toml", {"arm": {"length": 0.42}})
    assert tomllib.loads(t.read_text()) == {"arm": {"length": 0.42}}
    with pytest.raises(OutputExistsError, match="a.json: exists already"):
        write_text(tmp_path / "a.json", "other")
    assert json.loads(p.read_text())["x"] == 1.5
    write_bytes(tmp_path / "a.json", b"{}", overwrite=True)
    assert p.read_text() == "{}"
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("exc", [RuntimeError, KeyboardInterrupt])
def test_an_exception_mid_write_keeps_the_old_file_and_no_temp(tmp_path, exc):
    p = tmp_path / "log.csv"
    p.write_text("old\n")
    with pytest.raises(exc):
        with atomic_open(p, overwrite=True) as f:
            f.write("half of the new")
            raise exc()
    assert p.read_text() == "old\n"
    assert _leftovers(tmp_path) == []
    with pytest.raises(exc):
        with atomic_open(tmp_path / "new.csv") as f:
            f.write("half")
            raise exc()
    assert not (tmp_path / "new.csv").exists() and _leftovers(tmp_path) == []


def test_unserialisable_json_leaves_no_file(tmp_path):
    with pytest.raises(TypeError):
        write_json(tmp_path / "a.json", {"x": object()})
    assert list(tmp_path.iterdir()) == []


def test_a_folder_target_and_a_missing_folder_are_named(tmp_path):
    with pytest.raises(IsADirectoryError, match="is a folder"):
        write_text(tmp_path, "x", overwrite=True)
    with pytest.raises(FileNotFoundError, match="folder .*nope does not exist"):
        write_text(tmp_path / "nope" / "a.txt", "x")


def test_permissions_are_those_of_a_plain_open(tmp_path):
    """mkstemp makes 0600 files; the result must get what open(..., 'w') gives."""
    plain = tmp_path / "plain"
    plain.write_text("x")
    p = write_text(tmp_path / "atomic", "x")
    assert stat.S_IMODE(p.stat().st_mode) == stat.S_IMODE(plain.stat().st_mode)


def test_figure_format_follows_the_extension(tmp_path):
    from matplotlib.figure import Figure

    fig = Figure()
    fig.subplots().plot([0, 1], [0, 1])
    png = save_figure(fig, tmp_path / "f.png")
    pdf = save_figure(fig, tmp_path / "f.pdf")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert pdf.read_bytes()[:5] == b"%PDF-"
    with pytest.raises(OutputExistsError):
        save_figure(fig, png)
    assert _leftovers(tmp_path) == []


def test_write_log_keeps_its_error_and_is_atomic(tmp_path):
    """write_log goes through the writer: LogExistsError (a LogError and a FileExistsError)
    as before, and no temporary file beside the log."""
    import numpy as np

    from flexarm.io.logs import LogError, LogExistsError, write_log

    sig = {k: np.zeros(3) for k in ("reference", "current", "motor_angle", "tip_angle")}
    p = write_log(tmp_path / "a.csv", [0, 1, 2], sig)
    with pytest.raises(LogExistsError) as e:
        write_log(p, [0, 1, 2], sig)
    assert isinstance(e.value, LogError) and isinstance(e.value, FileExistsError)
    assert os.path.getsize(p) > 0
    assert _leftovers(tmp_path) == []

"""The one atomic writer (flexarm.io.write): complete file or none, never a partial one;
no silent overwrite; no temporary file left behind, Ctrl-C included."""

import json
import os
import stat

import pytest

from flexarm.errors import OutputExistsError
from flexarm.io.write import (
    atomic_open,
    save_figure,
    write_bytes,
    write_json,
    write_text,
    write_toml,
)


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


# ------------------------------------------------------------- the output policy (#25)
def test_an_input_is_never_written_over_even_with_overwrite(tmp_path):
    """A file declared an input of the run (write.inputs) is refused by every writer, by
    its own path, another path to it (a symlink, ..) or a hard link; a file inside an
    input folder too; outside the block the file is an ordinary output again."""
    import os

    from flexarm.errors import FlexarmError, InputOverwriteError
    from flexarm.io import write

    log = tmp_path / "data" / "trial1.csv"
    log.parent.mkdir()
    log.write_text("time,x\n0,1\n")
    before = log.read_bytes()
    (tmp_path / "link.csv").symlink_to(log)
    os.link(log, tmp_path / "hard.csv")
    with write.inputs([log, None]):
        for target in (
            log,
            tmp_path / "data" / ".." / "data" / "trial1.csv",
            tmp_path / "link.csv",
            tmp_path / "hard.csv",
        ):
            for w in (
                lambda p: write.write_text(p, "x", overwrite=True),
                lambda p: write.write_json(p, {"a": 1}, overwrite=True),
                lambda p: write.write_bytes(p, b"x", overwrite=True),
            ):
                with pytest.raises(InputOverwriteError, match="is an input of this run") as e:
                    w(target)
                assert isinstance(e.value, FlexarmError)
        assert write.is_input(tmp_path / "other.csv") is None
    assert log.read_bytes() == before
    with write.inputs([log.parent]):  # a folder of inputs: nothing written inside it
        with pytest.raises(InputOverwriteError):
            write.write_text(log.parent / "new.json", "{}")
        with pytest.raises(InputOverwriteError):
            write.output_folder(log.parent / "plots")
    write.write_text(tmp_path / "hard.csv", "now an output", overwrite=True)


def test_output_folder_is_not_written_into_without_overwrite(tmp_path):
    from flexarm.errors import OutputExistsError
    from flexarm.io import write

    d = write.output_folder(tmp_path / "plots" / "fit")  # created with its parents
    assert d.is_dir()
    assert write.output_folder(d) == d  # empty: fine
    write.write_text(d / "a.png", "old")
    with pytest.raises(OutputExistsError, match="holds files already"):
        write.output_folder(d)
    assert write.output_folder(d, overwrite=True) == d
    with pytest.raises(OutputExistsError, match="is a file"):
        write.output_folder(d / "a.png", overwrite=True)


def test_unique_keys_names_then_relative_paths_then_numbers(tmp_path):
    from flexarm.io.write import unique_keys

    a, b = tmp_path / "a" / "trial1.csv", tmp_path / "b" / "trial1.csv"
    assert unique_keys([a, tmp_path / "a" / "trial2.csv"]) == ["trial1.csv", "trial2.csv"]
    assert unique_keys([a, b]) == ["a/trial1.csv", "b/trial1.csv"]
    assert unique_keys([a, b, a]) == ["a/trial1.csv", "b/trial1.csv", "a/trial1.csv#2"]
    assert unique_keys(["rig", "rig"]) == ["rig", "rig#2"]  # names, e.g. two scenarios
    assert unique_keys([a, a]) == ["trial1.csv", "trial1.csv#2"]  # one file given twice
    keys = unique_keys([a, b, tmp_path / "c" / "d" / "trial1.csv"])
    assert len(set(keys)) == 3 and keys[2] == "c/d/trial1.csv"


def test_a_failed_final_write_is_saved_next_to_it_and_says_where(tmp_path):
    import json

    from flexarm.io.write import save_or_rescue

    ok = save_or_rescue(tmp_path / "fit.json", {"a": 1})
    assert not ok.rescued and json.loads((tmp_path / "fit.json").read_text()) == {"a": 1}
    # the requested file appeared meanwhile (no overwrite): saved beside it, old one kept
    s = save_or_rescue(tmp_path / "fit.json", {"a": 2})
    assert s.rescued and s.path.parent == tmp_path and s.path.name.startswith("fit.rescued-")
    assert s.path.suffix == ".json" and json.loads(s.path.read_text()) == {"a": 2}
    assert json.loads((tmp_path / "fit.json").read_text()) == {"a": 1}
    assert "exists already" in s.reason and str(s.path) in s.message("fit result")
    # the folder vanished: saved in the current folder
    import os

    cwd = tmp_path / "cwd"
    cwd.mkdir()
    old = os.getcwd()
    os.chdir(cwd)
    try:
        s = save_or_rescue(tmp_path / "gone" / "fit.toml", {"x": {"y": 1.5}})
    finally:
        os.chdir(old)
    assert s.rescued and s.path.parent == cwd and "y = 1.5" in s.path.read_text()
    # a data error is not an I/O error: raised, nothing written
    with pytest.raises(TypeError):
        save_or_rescue(tmp_path / "bad.json", {"a": object()})
    assert not (tmp_path / "bad.json").exists()


def test_sigterm_and_a_second_ctrl_c_inside_interruptible(tmp_path):
    """SIGTERM raises Interrupted (a KeyboardInterrupt, so a fit keeps its best result),
    a second SIGINT or SIGTERM while the result is saved raises nothing, and the old
    handlers come back when the block ends."""
    import os
    import signal

    from flexarm.errors import Interrupted
    from flexarm.io.write import interruptible

    before = signal.getsignal(signal.SIGTERM)
    repeats = []
    with pytest.raises(Interrupted) as info:
        with interruptible(on_repeat=repeats.append) as run:
            try:
                os.kill(os.getpid(), signal.SIGTERM)
                for _ in range(1000):  # the handler runs between byte codes
                    pass
            except KeyboardInterrupt:
                # "saving the best result": further signals do not break it
                os.kill(os.getpid(), signal.SIGTERM)
                if signal.getsignal(signal.SIGINT) not in (signal.SIG_IGN,):
                    os.kill(os.getpid(), signal.SIGINT)
                for _ in range(1000):
                    pass
                saved = True
                raise
    assert saved and info.value.signal == "SIGTERM" and info.value.number == signal.SIGTERM
    assert run.signal == "SIGTERM" and run.count >= 2 and "SIGTERM" in repeats
    assert signal.getsignal(signal.SIGTERM) == before

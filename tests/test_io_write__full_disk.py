"""Issue #45: a write that fails at the end (a full disk) keeps what it was to write.

The full disk is simulated: the atomic writer's final step onto a target (``os.replace``,
``os.link``) in the "full" folder raises ``OSError(ENOSPC)``.  Every writer of
:mod:`flexarm.io.write` (text, JSON, TOML, bytes, figures, CSV logs through
``atomic_open``) then saves the content under a fresh name beside the target, else in the
current folder, else in the system's temporary folder, and raises ``WriteFailedError``
naming the copy; the command line ends in one ``error:`` line naming it, exit 2.  Where
no copy can be made, the text is printed on stdout.  Before this, the writer raised a
plain ``OSError``: the content was lost ("internal error" for ``frf --json``, a bare
"cannot write" line for ``excite``, ``design`` and ``fit --json``, the issue's lost fit).
"""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.errors import FlexarmError
from flexarm.io import write

runner = CliRunner()
EXCITE = ["--fs", "1000", "--period", "64", "--f-min", "10", "--f-max", "200"]


@pytest.fixture
def full(tmp_path, monkeypatch):
    """``tmp_path/full`` is a full disk; ``tmp_path/cwd`` is the current folder. Returns a
    function that makes the current folder and the temporary folder full too."""
    disk = tmp_path / "full"
    disk.mkdir()
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    gone = [str(disk)]
    real_link, real_replace = os.link, os.replace

    def refuse(dst):
        if any(str(dst).startswith(g) for g in gone):
            raise OSError(errno.ENOSPC, "No space left on device", str(dst))

    def link(src, dst, *a, **k):
        refuse(dst)
        return real_link(src, dst, *a, **k)

    def replace(src, dst, *a, **k):
        refuse(dst)
        return real_replace(src, dst, *a, **k)

    monkeypatch.setattr(os, "link", link)
    monkeypatch.setattr(os, "replace", replace)

    def everywhere():
        tmp = tmp_path / "systemp"
        tmp.mkdir()
        monkeypatch.setattr("tempfile.tempdir", str(tmp))
        gone.extend([str(cwd), str(tmp)])

    return disk, cwd, everywhere


def _no_temporaries(folder: Path) -> None:
    assert [p.name for p in folder.iterdir() if p.name.startswith(".")] == []


def test_every_writer_keeps_its_content_when_the_disk_is_full(full):
    from matplotlib.figure import Figure

    from flexarm.io.logs import read_log, write_log

    disk, cwd, _ = full
    fig = Figure()
    fig.subplots().plot([0, 1], [0, 1])
    t = np.arange(20) * 1e-3
    sig = {k: np.full(20, 0.5) for k in ("reference", "current", "motor_angle", "tip_angle")}
    cases = [
        (lambda p: write.write_text(p, "hello\n"), "a.txt", lambda q: q.read_text() == "hello\n"),
        (
            lambda p: write.write_json(p, {"K": [1.5, 2.0]}),
            "fit.json",
            lambda q: json.loads(q.read_text()) == {"K": [1.5, 2.0]},
        ),
        (
            lambda p: write.write_toml(p, {"arm": {"length": 0.42}}),
            "s.toml",
            lambda q: "length = 0.42" in q.read_text(),
        ),
        (
            lambda p: write.write_bytes(p, b"\x00\x01"),
            "b.bin",
            lambda q: q.read_bytes() == b"\x00\x01",
        ),
        (lambda p: write.save_figure(fig, p), "f.png", lambda q: q.read_bytes()[:4] == b"\x89PNG"),
        (
            lambda p: write_log(p, t, sig),
            "log.csv",
            lambda q: np.allclose(read_log(q).signals["motor_angle"], 0.5),
        ),
    ]
    for w, name, same in cases:
        target = disk / name
        with pytest.raises(write.WriteFailedError) as e:
            w(target)
        exc = e.value
        assert isinstance(exc, FlexarmError) and isinstance(exc, OSError)
        assert exc.errno == errno.ENOSPC and "No space left on device" in exc.reason
        # beside the target is the full disk too: the copy is in the current folder
        assert exc.rescued is not None and exc.rescued.parent == cwd, exc
        assert exc.rescued.name.startswith(Path(name).stem + ".rescued-")
        assert exc.rescued.suffix == Path(name).suffix and same(exc.rescued), name
        assert str(exc.rescued) in str(exc) and "\n" not in str(exc)
        assert not target.exists()
    _no_temporaries(disk)
    assert len(list(cwd.iterdir())) == len(cases)


def test_a_result_no_folder_can_take_is_printed_on_stdout(full):
    """`excite` with every folder full: exit 2, one error line, the CSV on stdout."""
    disk, _, everywhere = full
    everywhere()
    r = runner.invoke(app, ["excite", str(disk / "e.csv"), *EXCITE])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert "nor a copy anywhere else" in lines[0] and "follows on stdout" in lines[0]
    rows = [ln for ln in r.stdout.splitlines() if ln and not ln.startswith("#")]
    assert len(rows) >= 64 * 2  # the header and two periods of 64 samples
    assert not list(disk.iterdir())


@pytest.mark.parametrize("cmd", ["excite", "frf"])
def test_the_command_line_names_the_saved_copy_and_exits_2(full, tmp_path, cmd):
    disk, cwd, _ = full
    if cmd == "excite":
        argv = ["excite", str(disk / "e.csv"), *EXCITE]
    else:  # a two-period multisine log, its FRF JSON onto the full disk
        n = 64
        tt = np.arange(4 * n) / 1000.0
        u = sum(np.cos(2 * np.pi * k * tt * 1000 / n + k) for k in (1, 3, 5, 7))
        y = np.roll(u, 1) * 0.5
        body = "\n".join(f"{a:.4f},{b:.9g},{c:.9g}" for a, b, c in zip(tt, u, y, strict=True))
        (tmp_path / "ms.csv").write_text("time,current,motor_angle\n" + body + "\n")
        argv = ["frf", str(tmp_path / "ms.csv"), "--json", str(disk / "f.json")]
    r = runner.invoke(app, argv)
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip() and not ln.startswith("warning")]
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert "internal error" not in r.output
    saved = [p for p in cwd.iterdir() if ".rescued-" in p.name]
    assert len(saved) == 1 and str(saved[0]) in lines[0]
    if cmd == "frf":
        assert json.loads(saved[0].read_text())["frequency_hz"]
    else:
        assert len(saved[0].read_text().splitlines()) > 64


def test_a_fit_whose_json_meets_a_full_disk_is_kept_and_named(full, tmp_path):
    """The issue's case: `flexarm fit --json` onto a full disk lost the fit. A 1 s
    simulated run of the rotary rig, fitted with its data sheet: exit 2, one error line
    naming the copy in the current folder, which holds the whole fit document; the
    `--scenario-out` on another disk is written all the same."""
    import tomli_w

    from flexarm.specs import load_scenario

    disk, cwd, _ = full
    d = load_scenario("rotary-flexible-link").model_dump(mode="json", exclude_none=True)
    d["simulation"]["duration"] = 1.0
    (tmp_path / "rig.toml").write_text(tomli_w.dumps(d))
    r = runner.invoke(app, ["simulate", str(tmp_path / "rig.toml"), "--out", str(tmp_path / "s")])
    assert r.exit_code == 0, r.output
    log = tmp_path / "s" / "rotary-flexible-link.csv"
    ds = ["--gear-ratio", "70", "--motor-constant", "7.68e-3", "--armature-resistance", "2.6"]
    ds += ["--link-length", "0.42", "--gear-efficiency", "0.9", "--motor-efficiency", "0.69"]
    ds += ["--controller", "state_feedback K1=6 K2=-40 K3=0.15 K4=0", "--seconds", "2"]
    out = ["--json", str(disk / "fit.json"), "--scenario-out", str(tmp_path / "fitted.toml")]
    r = runner.invoke(app, ["fit", str(log), *ds, *out])
    assert r.exit_code == 2, r.output
    # the scenario, on a disk with room, is written although the JSON before it failed
    assert load_scenario(tmp_path / "fitted.toml").arm is not None
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith(("error", "internal"))]
    assert len(errors) == 1 and "No space left on device" in errors[0], r.stderr
    saved = [p for p in cwd.iterdir() if p.name.startswith("fit.rescued-")]
    assert len(saved) == 1 and str(saved[0]) in errors[0]
    doc = json.loads(saved[0].read_text())
    assert doc["fit_percent"] and not (disk / "fit.json").exists()


def test_write_each_tries_every_write_and_raises_the_first_failure(tmp_path):
    """``io.write.write_each``: a design's ``design.toml`` meeting a full disk does not stop
    its ``design.json`` (and a fit's ``--json`` not its ``--scenario-out``)."""
    from flexarm.io.write import WriteFailedError, write_each, write_text

    def full():
        raise WriteFailedError(
            "error: a.toml: No space left on device", path=tmp_path / "a.toml",
            reason="No space left on device", rescued=tmp_path / "a.rescued.toml",
        )  # fmt: skip

    with pytest.raises(WriteFailedError, match="a.toml") as info:
        write_each(full, lambda: write_text(tmp_path / "b.json", "{}"), full)
    assert (tmp_path / "b.json").read_text() == "{}" and info.value.path.name == "a.toml"
    assert write_each(lambda: 1, lambda: 2) == [1, 2]

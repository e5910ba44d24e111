"""Issue #45: ``flexarm design`` with a drive it cannot work with ends in one line, exit 2.

Before: a Coulomb friction of 1e4 N·m (a unit slip: the drive's peak torque is ~1 N·m)
or a 1e300 A amplifier limit ended in "internal error: ControlArgument: QN must be a
symmetric matrix" (the Kalman weights overflowed).  Now ``design.linear.check_drive``
refuses both while the design model is built, naming the field, its value and the fix."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.design.linear import MAX_LIMIT, check_drive

BASE = (
    Path(__file__).resolve().parents[1] / "src/flexarm/scenarios/feliu-single-mass.toml"
).read_text()


def test_check_drive_refuses_by_field_and_passes_a_real_drive():
    check_drive("rig", [4.12], [0.2468], [0.0326])  # Feliu's arm: 0.13 A of 4.12 A
    check_drive("rig", [MAX_LIMIT], [0.2468], [0.0])
    with pytest.raises(ValueError, match=r"command limit 1e\+300 \(V or A\) of joint 1"):
        check_drive("rig", [1e300], [0.2468], [0.0326])
    with pytest.raises(ValueError, match=r"joint 2's Coulomb friction 1 .*needs 10 of command"):
        check_drive("rig", [5.0, 5.0], [1.0, 0.1], [0.0, 1.0])
    with pytest.raises(ValueError, match=r"needs 5 of command to overcome, at or beyond"):
        check_drive("rig", [5.0], [1.0], [5.0])  # exactly the limit: never moves either


@pytest.mark.parametrize(
    "old, new, words",
    [
        (
            'coulomb = "0.288288 lbf*in"           # 0.132 A x K, the paper\'s estimate\n'
            'static = "0.288288 lbf*in"',
            'coulomb = "1e4 N*m"\nstatic = "1e4 N*m"',
            "Coulomb friction 10000 (N*m",
        ),
        ('current_limit = "4.12 A"', 'current_limit = "1e300 A"', "command limit 1e+300"),
    ],
    ids=["coulomb-1e4", "limit-1e300"],
)
def test_design_refuses_an_impossible_drive_in_one_line(tmp_path, old, new, words):
    assert old in BASE
    sc = tmp_path / "rig.toml"
    sc.write_text(BASE.replace(old, new))
    r = CliRunner().invoke(app, ["design", str(sc), "--out", str(tmp_path / "d")])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith(("error", "internal"))]
    assert len(lines) == 1 and lines[0].startswith("error: ") and words in lines[0], r.stderr
    assert not (tmp_path / "d" / "design.toml").exists()

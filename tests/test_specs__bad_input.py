"""Issue #45: a ragged controller matrix is one line naming the file and the field.

Before: ``D = [[1, 2], [3]]`` in a scenario's ``[controller]`` passed the schema; ``info``
exited 0 and ``export-c`` ended in numpy's "setting an array element with a sequence".
Now the schema refuses it (``specs.experiment.LTIControllerSpec``): the file, the field
``controller`` and which matrix, with the row lengths and the fix."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.specs import ScenarioError, load_scenario

BASE = (
    Path(__file__).resolve().parents[1] / "src/flexarm/scenarios/feliu-single-mass.toml"
).read_text()
HEAD = BASE.split("[controller]")[0]
LTI = (
    'type = "lti"\ninputs = ["motor_angle", "tip_angle"]\nsetpoints = ["reference", 0]\n'
    'outputs = ["current"]\n'
)


@pytest.mark.parametrize(
    "matrices, bad, lengths",
    [
        ("D = [[1.0, 2.0], [3.0]]", "D", "2, 1"),
        (
            "A = [[0.5, 0.0], [0.1]]\nB = [[1.0, 0.0], [0.0, 1.0]]\n"
            "C = [[1.0, 0.0]]\nD = [[0.0, 0.0]]",
            "A",
            "2, 1",
        ),
        ("A = [[0.5]]\nB = [[1.0, 0.0]]\nC = [[1.0], [2.0, 3.0]]\nD = [[0.0, 0.0]]", "C", "1, 2"),
    ],
)
def test_a_ragged_matrix_in_a_scenario_is_named(tmp_path, matrices, bad, lengths):
    p = tmp_path / "rig.toml"
    p.write_text(HEAD + "[controller]\n" + LTI + matrices + "\n")
    with pytest.raises(ScenarioError) as e:
        load_scenario(p)
    msg = " ".join(str(e.value).split())
    assert str(p) in msg and f"controller: {bad} is ragged: its rows have {lengths} entries" in msg


def test_a_rectangular_matrix_is_read():
    from flexarm.specs.experiment import LTIControllerSpec

    spec = LTIControllerSpec.model_validate(
        {
            "type": "lti",
            "inputs": ["motor_angle", "tip_angle"],
            "outputs": ["current"],
            "D": [[1.5, -2.0]],
        }
    )
    assert spec.D == [[1.5, -2.0]]


@pytest.mark.parametrize("cmd", ["info", "export-c", "controller-file"])
def test_the_commands_refuse_a_ragged_d_in_one_line(tmp_path, cmd):
    block = "[controller]\n" + LTI + "D = [[1.0, 2.0], [3.0]]\n"
    if cmd == "controller-file":
        (tmp_path / "k.toml").write_text(block)
        p = tmp_path / "k.toml"
        argv = [
            "simulate",
            "feliu-single-mass",
            "--out",
            str(tmp_path / "s"),
            "--controller",
            str(p),
        ]
        argv += ["--log", str(tmp_path / "nope.csv")]
    else:
        p = tmp_path / "rig.toml"
        p.write_text(HEAD + block)
        argv = [cmd, str(p)] + (["--out", str(tmp_path / "c")] if cmd == "export-c" else [])
    r = CliRunner().invoke(app, argv)
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert str(p) in lines[0] and "D is ragged" in lines[0], lines[0]  # before the log

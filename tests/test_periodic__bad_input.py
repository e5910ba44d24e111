"""Issue #45: a channel that does not change gives no FRF (``periodic_frf``, ``lpm_frf``,
``flexarm frf``).  Before: an all-zero input channel ended in "internal error" (an
IndexError in the period search), a dead (constant) output channel gave an FRF of 0 with
NaN distortion judged "no distortion", exit 0.  Now one ``IdentificationError`` line
naming the channel and its value (exit 2 on the command line)."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.identification.frequency_domain.harmonics import IdentificationError
from flexarm.identification.frequency_domain.periodic import lpm_frf, periodic_frf

FS, N = 1000.0, 200


def _record(periods=4):
    t = np.arange(N * periods) / FS
    u = sum(np.cos(2 * np.pi * k * FS / N * t + k) for k in (1, 3, 5, 7, 9))
    y = 0.5 * np.roll(u, 2)
    return t, u, y


@pytest.mark.parametrize("which", ["input", "output"])
@pytest.mark.parametrize("value", [0.0, 0.25, -3e5])
def test_a_constant_channel_is_refused_by_name(which, value):
    _, u, y = _record()
    if which == "input":
        u = np.full_like(u, value)
    else:
        y = np.full_like(y, value)
    for run in (
        lambda: periodic_frf(u, {"motor_angle": y}, FS, input_name="current", source="r.mat"),
        lambda: lpm_frf(u, {"motor_angle": y}, FS, input_name="current", source="r.mat"),
    ):
        with pytest.raises(IdentificationError) as e:
            run()
        msg = str(e.value)
        name = "current" if which == "input" else "motor_angle"
        assert msg.startswith(f"r.mat: the {which} {name!r} is constant (all {N * 4} samples")
        assert f"{value:.6g}" in msg and "\n" not in msg


def test_a_live_record_still_gives_its_frf():
    """The check does not touch a record that changes: G = 0.5 e^{-2jωT} at the lines,
    to 1e-9 (noise-free, periodic)."""
    _, u, y = _record()
    res = periodic_frf(u, {"y": y}, FS, period=N)
    w = 2 * np.pi * res.frequency_hz / FS
    assert np.allclose(res.response[0], 0.5 * np.exp(-2j * w), atol=1e-9)


@pytest.mark.parametrize("dead", ["current", "motor_angle"])
def test_frf_command_refuses_a_dead_channel_in_one_line(tmp_path, dead):
    t, u, y = _record()
    cols = {"current": u, "motor_angle": y}
    cols[dead] = np.zeros_like(cols[dead])
    rows = "\n".join(
        f"{a:.4f},{b:.9g},{c:.9g}"
        for a, b, c in zip(t, cols["current"], cols["motor_angle"], strict=True)
    )
    (tmp_path / "r.csv").write_text("time,current,motor_angle\n" + rows + "\n")
    r = CliRunner().invoke(
        app, ["frf", str(tmp_path / "r.csv"), "--json", str(tmp_path / "f.json")]
    )
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert (
        len(lines) == 1 and lines[0].startswith("error: ") and f"{dead!r} is constant" in lines[0]
    )
    assert not (tmp_path / "f.json").exists()


def test_a_constant_reference_of_the_indirect_lpm_is_named_the_reference():
    _, u, y = _record()
    with pytest.raises(IdentificationError, match=r"r.mat: the reference 'reference' is constant"):
        lpm_frf(u, {"y": y}, FS, source="r.mat", reference=np.zeros_like(u))

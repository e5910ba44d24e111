"""Issue #17: the real two-link flexible arm (``../shared/data/two-link-rig``): its two file
layouts read with the log-format files in ``examples/`` through the one reader, the loader's
check against the swapped elbow variables, the built-in scenario ``quanser-two-link``, the
sensors' digital filters and the discrete LTI controller in the loop.

Real-data tests skip when ``../shared`` is absent; synthetic ones always run.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io as sio

from flexarm.io.logformat import LogFormatError, load_log_format, log_format_from_dict
from flexarm.io.logs import LogError
from flexarm.io.matfile import MatFileError

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "two-link-rig"
RUN = DATA / "lqr_full_10deg.mat"
STAIR = DATA / "lqr-stair"
WORKSPACE = ROOT / "examples" / "two-link-workspace.toml"
SCOPE = ROOT / "examples" / "two-link-scope.toml"
STAIRCASE = ROOT / "examples" / "two-link-staircase.toml"
KE_D1, KE_D2 = 2 * np.pi / 409600, 2 * np.pi / 204800

needs_data = pytest.mark.skipif(
    not RUN.is_file(), reason=f"real two-link rig data not found at {DATA} (../shared is "
                              "absent in a user's clone; CI has it)")

CHANNELS = {"theta_1", "alpha_f_1", "theta_dot_f_1", "alpha_dot_f_1", "theta_ref_1",
            "theta_2", "alpha_f_2", "theta_dot_f_2", "alpha_dot_f_2", "theta_ref_2"}


@pytest.fixture(scope="module")
def run_log():
    if not RUN.is_file():
        pytest.skip(f"real two-link rig data not found at {DATA}")
    return load_log_format(WORKSPACE).read(RUN)


@pytest.fixture(scope="module")
def raw():
    if not RUN.is_file():
        pytest.skip(f"real two-link rig data not found at {DATA}")
    return sio.loadmat(RUN, squeeze_me=True, struct_as_record=False)


# ------------------------------------------------------------------ 1. log formats
@needs_data
def test_workspace_layout_loads_with_the_shipped_format(run_log, raw):
    log = run_log
    assert set(log.signals) == CHANNELS
    # README: 102 s at 2 ms, N = 51 087 samples
    assert len(log) == 51087
    np.testing.assert_allclose(np.diff(log.time), 2e-3, rtol=1e-8)
    # values exactly as in the file (no conversion: SI already); the elbow's measured state is
    # the variable named "_sim"
    np.testing.assert_array_equal(log["theta_2"], raw["stage2_X2_sim"].signals.values[:, 0])
    np.testing.assert_array_equal(log["theta_ref_2"], raw["stage2_X2_meas"].signals.values[:, 0])
    np.testing.assert_array_equal(log["alpha_dot_f_1"],
                                  raw["stage1_X1_meas"].signals.values[:, 3])
    # the setpoints are the README's square waves: ±25° and ±10° (exact in the file, to the
    # last bit of the deg → rad conversion)
    assert np.abs(log["theta_ref_1"]).max() == pytest.approx(np.deg2rad(25), rel=1e-12)
    assert np.abs(log["theta_ref_2"]).max() == pytest.approx(np.deg2rad(10), rel=1e-12)


@needs_data
def test_scope_captures_are_a_second_log_of_the_same_samples(run_log):
    scope = load_log_format(SCOPE).read(RUN)
    assert len(scope) == 10000  # README: the last 20 s at 2 ms
    w = run_log.window(scope.time[0], scope.time[-1])
    np.testing.assert_array_equal(w.time, scope.time)
    # the scope's degrees are the workspace's radians (converted by [units]); the file
    # holds rad·180/π rounded to double: agreement to 1e-12 relative of the range
    for k in ("theta_1", "alpha_f_1", "theta_2", "alpha_f_2", "theta_ref_1", "theta_ref_2"):
        span = np.ptp(w[k]) or 1.0
        assert np.abs(scope[k] - w[k]).max() <= 1e-12 * span, k
    # commanded currents stay within the README's limits 0.94 A and 1.2 A
    assert np.abs(scope["current_1"]).max() <= 0.94 + 1e-12
    assert np.abs(scope["current_2"]).max() <= 1.2 + 1e-12


@needs_data
def test_staircase_layout_loads_every_file():
    fmt = load_log_format(STAIRCASE)
    files = sorted(STAIR.glob("*.mat"))
    assert len(files) == 10
    for f in files:
        log = fmt.read(f)
        assert set(log.signals) == CHANNELS and len(log) == 2000, f.name
        np.testing.assert_allclose(np.diff(log.time), 2e-3, rtol=1e-8)
        assert np.all(log["theta_ref_2"] == 0.0)  # the elbow held at 0
    # the 5° step file's setpoint ends at its target
    log = fmt.read(STAIR / "lqr_step_5deg_run01.mat")
    assert log["theta_ref_1"][-1] == pytest.approx(np.deg2rad(5), rel=1e-9)


@needs_data
def test_loader_catches_the_swapped_elbow_variables():
    """A format that takes the variable names at their word (elbow measured = "_meas") maps
    the setpoint as the measured angle: it is off the encoder grid, and reading stops with a
    message naming the channel, the variable and the fix."""
    data = load_log_format(WORKSPACE).model_dump()
    for k in ("theta_2", "alpha_f_2", "theta_dot_f_2", "alpha_dot_f_2"):
        data["columns"][k] = data["columns"][k].replace("X2_sim", "X2_meas")
    data["columns"]["theta_ref_2"] = "stage2_X2_sim[0]"
    fmt = log_format_from_dict(data, "naive.toml")
    with pytest.raises(LogFormatError) as e:
        fmt.read(RUN)
    msg = str(e.value)
    for w in ("lqr_full_10deg.mat", "theta_2", "stage2_X2_meas[0]", "not an encoder reading",
              "naive.toml", "setpoint"):
        assert w in msg, w
    # the rate columns of the setpoint are zero: a check of the right mapping passes, of the
    # swapped one fails
    cols = {"time": "stage1_X1_meas.time", "theta_dot_f_2": "stage2_X2_meas[2]"}
    ok = log_format_from_dict({"columns": cols, "checks": {"zero": ["theta_dot_f_2"]}}, "z.toml")
    assert np.all(ok.read(RUN)["theta_dot_f_2"] == 0.0)
    cols["theta_dot_f_2"] = "stage2_X2_sim[2]"
    bad = log_format_from_dict({"columns": cols, "checks": {"zero": ["theta_dot_f_2"]}}, "z.toml")
    with pytest.raises(LogFormatError, match="theta_dot_f_2.*must be all zeros"):
        bad.read(RUN)


def test_mat_log_format_synthetic(tmp_path):
    """The one reader on a synthetic workspace: struct values, sign, [units], window, checks,
    and the errors naming file and field (a struct without signals.values)."""
    n = 50
    q = 1e-3
    t = np.arange(n) * 2e-3
    th = np.round(np.sin(t * 20) / q) * q
    p = tmp_path / "ws.mat"
    sio.savemat(p, {"X": {"time": t, "signals": {"values": np.column_stack([th, 2 * th])}},
                    "S": {"time": t, "blockName": "scope"}, "deg": np.rad2deg(th),
                    "Q": q})
    fmt = log_format_from_dict({"columns": {"time": "X.time", "theta_1": "X[0]",
                                            "alpha_f_1": "-X[1]", "theta_2": "deg"},
                                "units": {"theta_2": "deg"},
                                "checks": {"quantum": {"theta_1": "Q", "theta_2": q}}}, "f.toml")
    log = fmt.read(p)
    np.testing.assert_array_equal(log["alpha_f_1"], -2 * th)
    np.testing.assert_allclose(log["theta_2"], th, rtol=1e-14, atol=1e-17)  # deg → rad
    w = log.window(0.01, 0.02)
    np.testing.assert_allclose(w.time, t[5:11], rtol=0, atol=1e-15)  # both ends included
    with pytest.raises(LogError, match="holds 0 sample"):
        log.window(5.0, 6.0)
    # a struct without signals.values: the error names the file, the channel and the struct
    bad = log_format_from_dict({"columns": {"time": "X.time", "theta_1": "S"}}, "g.toml")
    with pytest.raises(MatFileError) as e:
        bad.read(p)
    for w in ("ws.mat", "theta_1", "'S'", "struct without signals.values", "time, blockName"):
        assert w in str(e.value), w
    # a name flexarm does not know is refused by the format, naming it and the known ones
    with pytest.raises(LogFormatError, match="'thet_1' is not one of flexarm's column names"):
        log_format_from_dict({"columns": {"thet_1": "X[0]"}}, "h.toml")
    # a check on a channel the format does not map
    with pytest.raises(LogFormatError, match="theta_9"):
        log_format_from_dict({"columns": {"time": "X.time", "theta_1": "X[0]"},
                              "checks": {"quantum": {"theta_9": 1e-3}}}, "i.toml")
    # the time column is required
    with pytest.raises(LogFormatError, match="maps no time"):
        log_format_from_dict({"columns": {"theta_1": "X[0]"}}, "j.toml").read(p)

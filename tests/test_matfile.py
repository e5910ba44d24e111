"""MATLAB .mat reader (flexarm.io.matfile): v5 and v7.3, Simulink structs, signs, units,
opaque objects skipped, and the errors that name the file and the field."""

from pathlib import Path

import numpy as np
import pytest
import scipy.io as sio

from flexarm.io.logformat import load_log_format
from flexarm.io.matfile import MatFileError, read_mat

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "motor-bench.toml"
DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "motor-bench"


@pytest.fixture
def v5(tmp_path):
    n = 40
    t = np.arange(n) * 400  # microseconds
    log = {
        "time": np.arange(n) * 4e-4,
        "signals": {"values": np.column_stack([np.arange(n), -np.arange(n)]).astype(float)},
    }
    p = tmp_path / "rec.mat"
    sio.savemat(
        p,
        {
            "time": t[:, None].astype(np.int32),
            "iq": np.sin(t)[:, None],
            "th": np.cos(t)[None, :],
            "logsout": log,
            "short": np.ones(5),
            "bad": np.r_[np.ones(10), np.nan, np.ones(n - 11)],
        },
    )
    return p, t


def test_v5_variables_structs_sign_units(v5):
    p, t = v5
    r = read_mat(
        p,
        {
            "time": "time",
            "current": "iq",
            "motor_angle": "-th",
            "a": "logsout[1]",
            "b": "logsout.signals.values[0]",
            "tt": "logsout.time",
        },
        {"time": "us", "motor_angle": "deg"},
    )
    # exact: unit factors are exact decimal/π ratios, reading is a copy
    np.testing.assert_allclose(r.time, t * 1e-6, rtol=1e-15)
    np.testing.assert_allclose(r["current"], np.sin(t), rtol=0)
    np.testing.assert_allclose(r["motor_angle"], -np.cos(t) * np.pi / 180, rtol=1e-15)
    np.testing.assert_array_equal(r["a"], -np.arange(40.0))
    np.testing.assert_array_equal(r["b"], np.arange(40.0))


@pytest.mark.parametrize(
    "cols, words",
    [
        ({"current": "nothere"}, ["rec.mat", "current", "no variable 'nothere'", "iq 40x1"]),
        ({"current": "iq[2]"}, ["rec.mat", "column 2 does not exist", "1 column"]),
        ({"current": "-iq[1]"}, ["column 1 does not exist"]),
        ({"current": "logsout.nope"}, ["no field 'nope'", "signals"]),
        ({"current": "logsout.signals"}, ["struct without signals.values"]),
        ({"current": "iq", "x": "short"}, ["different lengths", "current 40", "x 5"]),
        ({"current": "bad"}, ["NaN", "sample 10", "current"]),
        ({"current": "logsout"}, ["2 columns"]),
        ({"current": "1abc"}, ["cannot read the variable spec"]),
    ],
)
def test_v5_errors_name_file_and_field(v5, cols, words):
    with pytest.raises(MatFileError) as e:
        read_mat(v5[0], cols)
    for w in words:
        assert w in str(e.value)


def test_unit_for_unmapped_name_is_an_error(v5):
    with pytest.raises(MatFileError, match="load_angle"):
        read_mat(v5[0], {"current": "iq"}, {"load_angle": "deg"})


def test_v73_through_h5py(tmp_path):
    h5py = pytest.importorskip("h5py")
    p = tmp_path / "rec73.mat"
    x = np.arange(12.0)
    with h5py.File(p, "w") as f:
        f.create_dataset("iq", data=x[None, :])  # MATLAB 12x1 is stored 1x12
        f["iq"].attrs["MATLAB_class"] = np.bytes_("double")
        g = f.create_group("logsout")
        g.create_dataset("time", data=(x * 0.1)[None, :])
        s = g.create_group("signals")
        s.create_dataset("values", data=np.vstack([x, 2 * x]))  # MATLAB 12x2
        o = f.create_dataset("sys", data=np.zeros((1, 6), np.uint32))
        o.attrs["MATLAB_class"] = np.bytes_("tf")
        o.attrs["MATLAB_object_decode"] = 3
    r = read_mat(p, {"time": "logsout.time", "current": "-iq", "y": "logsout[1]"})
    np.testing.assert_array_equal(r["current"], -x)
    np.testing.assert_array_equal(r["y"], 2 * x)
    np.testing.assert_array_equal(r.time, 0.1 * x)
    assert "sys" in r.skipped
    with pytest.raises(MatFileError, match="opaque MATLAB object"):
        read_mat(p, {"current": "sys"})


def test_motor_bench_example_format():
    if not (DATA / "MultisineTypeB.mat").is_file():
        pytest.skip(f"real recording absent: {DATA} (the shared data folder beside the repo)")
    fmt = load_log_format(EXAMPLE)  # the one log-format reader serves .mat files too
    with pytest.warns(UserWarning, match="irregular trailing row"):
        r = fmt.read(DATA / "MultisineTypeB.mat")
    raw = sio.loadmat(DATA / "MultisineTypeB.mat")
    assert len(r) == 49999 and r.skipped  # the tf object is skipped, not fatal
    np.testing.assert_allclose(np.diff(r.time), 4e-4, rtol=1e-9)  # 2.5 kHz, µs → s
    np.testing.assert_array_equal(r["load_angle"], -raw["theta_my"].ravel()[:-1])


def test_irregular_trailing_row_dropped_with_warning(tmp_path):
    p = tmp_path / "c.mat"
    sio.savemat(p, {"msr": np.r_[2:12, 11][:, None], "x": np.arange(11.0)[:, None]})
    with pytest.warns(UserWarning, match="1 irregular trailing row"):
        r = read_mat(p, {"sample_counter": "msr", "current": "x"})
    np.testing.assert_array_equal(r["current"], np.arange(10.0))
    assert "sample_counter" not in r.signals
    sio.savemat(p, {"msr": np.r_[2:6, 8:15][:, None], "x": np.arange(11.0)[:, None]})
    with pytest.raises(MatFileError, match="jumps at row 4"):
        read_mat(p, {"sample_counter": "msr", "current": "x"})

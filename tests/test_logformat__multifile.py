"""Issue #24, item 6: one run saved as several files (one scope capture per signal) read as one
log: ``[columns] theta_1 = { file = "{stem}_th11.mat", column = "data_th11[2]" }``. The
multi-file log equals the single-file one; files with different time bases are an error
naming both files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io as sio

from flexarm.io.logformat import LogFormatError, load_log_format, log_format_from_dict

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "two-link-rig"
RUN = DATA / "lqr_full_10deg.mat"


def _split_format(names: dict[str, str], time_file: str, own_time: bool = True) -> dict:
    """The scope format with each column in its own file {stem}_<var>.mat."""
    cols = {}
    for k, spec in names.items():
        var = spec.split("[")[0]
        entry = {"file": f"{{stem}}_{var}.mat", "column": spec}
        if own_time and k != "time":
            entry["time"] = f"{var}[0]"
        cols[k] = entry
    cols["time"] = {"file": f"{{stem}}_{time_file}.mat", "column": f"{time_file}[0]"}
    return cols


def test_multifile_log_equals_the_single_file_log(tmp_path):
    """Three captures [t, setpoint, measured] written once together and once one per file:
    the same log (time and every channel bit for bit, units applied); {stem} is the path
    given without its suffix; the time may come from any file."""
    N = 300
    t = 7.0 + np.arange(N) * 2e-3
    rng = np.random.default_rng(0)
    data = {
        v: np.column_stack([t, rng.normal(size=N), rng.normal(size=N)])
        for v in ("data_th11", "data_th12", "data_Im1")
    }
    sio.savemat(tmp_path / "run.mat", data)
    for v, a in data.items():
        sio.savemat(tmp_path / f"run_{v}.mat", {v: a})
    names = {
        "theta_ref_1": "data_th11[1]",
        "theta_1": "data_th11[2]",
        "alpha_f_1": "data_th12[2]",
        "current_1": "data_Im1[1]",
    }
    units = {"theta_ref_1": "deg", "theta_1": "deg", "alpha_f_1": "deg"}
    single = log_format_from_dict({"columns": {"time": "data_Im1[0]", **names}, "units": units})
    one = single.read(tmp_path / "run.mat")
    for tf in ("data_th11", "data_Im1"):
        multi = log_format_from_dict({"columns": _split_format(names, tf), "units": units})
        for given in (tmp_path / "run", tmp_path / "run.mat"):
            many = multi.read(given)
            np.testing.assert_array_equal(many.time, one.time)
            assert set(many.signals) == set(one.signals)
            for k in one.signals:
                np.testing.assert_array_equal(many[k], one[k], err_msg=k)
    # a relative file without {stem} is taken in the given path's folder; plain entries
    # come from the given file itself
    mixed = log_format_from_dict(
        {
            "columns": {
                "time": "data_th11[0]",
                "theta_1": "data_th11[2]",
                "alpha_f_1": {"file": "run_data_th12.mat", "column": "data_th12[2]"},
            }
        }
    )
    got = mixed.read(tmp_path / "run_data_th11.mat")
    np.testing.assert_array_equal(got["alpha_f_1"], data["data_th12"][:, 2])


def test_multifile_bad_input_names_both_files(tmp_path):
    N = 100
    t = np.arange(N) * 2e-3
    a = np.column_stack([t, t, t])
    fmt = log_format_from_dict(
        {"columns": _split_format({"theta_1": "a[2]", "alpha_f_1": "b[2]"}, "a")}
    )
    # another time base in one file: both files named, the sample and the two times
    sio.savemat(tmp_path / "x_a.mat", {"a": a})
    sio.savemat(tmp_path / "x_b.mat", {"b": np.column_stack([t + 0.5, t, t])})
    with pytest.raises(
        LogFormatError,
        match=r"x_b\.mat: its time .*differs from the log's "
        r"time in .*x_a\.mat at sample 0: 0\.5 s vs 0 s",
    ):
        fmt.read(tmp_path / "x")
    # another length
    sio.savemat(tmp_path / "y_a.mat", {"a": a})
    sio.savemat(tmp_path / "y_b.mat", {"b": a[:60]})
    with pytest.raises(LogFormatError, match=r"y_b\.mat: 60 samples, but .*y_a\.mat .*has 100"):
        fmt.read(tmp_path / "y")
    # a missing file: named, with {stem} and the fix
    with pytest.raises(LogFormatError, match=r"z_a\.mat: no such file .*\{stem\} = '.*z'"):
        fmt.read(tmp_path / "z")
    # a bad entry in the format
    with pytest.raises(LogFormatError, match="column"):
        log_format_from_dict({"columns": {"theta_1": {"file": "{stem}_a.mat"}}})


@pytest.mark.skipif(not RUN.is_file(), reason=f"real two-link rig data not found at {DATA}")
def test_the_rigs_scope_captures_as_one_file_per_signal(tmp_path):
    """The workspace's scope captures, saved one variable per file as a scope block would,
    read with the split format equal examples/two-link-scope.toml on the workspace."""
    raw = sio.loadmat(RUN)
    fmt = load_log_format(ROOT / "examples" / "two-link-scope.toml")
    cols = {k: v for k, v in fmt.columns.items()}
    for v in {c.split("[")[0] for c in cols.values()}:
        sio.savemat(tmp_path / f"cap_{v}.mat", {v: raw[v]})
    split = fmt.model_dump()
    split["columns"] = _split_format(
        {k: v for k, v in cols.items() if k != "time"}, cols["time"].split("[")[0]
    )
    split["checks"] = {"quantum": {"theta_1": 2 * np.pi / 409600, "theta_2": 2 * np.pi / 204800}}
    many = log_format_from_dict(split).read(tmp_path / "cap")
    one = fmt.read(RUN)
    np.testing.assert_array_equal(many.time, one.time)
    for k in one.signals:
        np.testing.assert_array_equal(many[k], one[k], err_msg=k)

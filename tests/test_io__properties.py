"""Property-based fuzzing of the readers issue #25 names: the ``.mat`` reader (v5 and v7.3),
log-format files, controller files (``[controller] file``: JSON / ``.npz`` / ``.mat``) and
the FRF JSON that ``flexarm frf`` writes.  Each input either gives a valid result or one
clear error of the project's own (a :class:`flexarm.errors.FlexarmError`) naming the file,
never another exception.  Valid ``.mat`` logs that pass keep the checks' promises
(flexarm.io.checks): time strictly increasing and not constant, every value within its
signal's physical range.  Bounded: derandomised, 30-60 examples a property.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flexarm.errors import FlexarmError
from flexarm.io.checks import signal_range
from flexarm.io.logformat import LogFormat, load_log_format, log_format_from_dict

sio = pytest.importorskip("scipy.io")

FUZZ = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
_DIR = Path(tempfile.mkdtemp(prefix="flexarm-fuzz-readers-"))
FMT = log_format_from_dict(
    {"columns": {"time": "t", "motor_angle": "th", "voltage": "u", "sample_counter": "n"}},
    source="fuzz format",
)


def _named(exc: BaseException, path) -> None:
    """One clear error: a FlexarmError whose one line names the file."""
    from flexarm.errors import one_line

    assert isinstance(exc, FlexarmError), f"{type(exc).__name__}: {exc}"
    line = one_line(exc)
    assert str(path) in line or Path(path).name in line, line


def _read_or_named(read, path):
    try:
        return read(path)
    except Exception as exc:  # the property: only FlexarmError is allowed
        _named(exc, path)
        return None


def _valid_log_promises(log) -> None:
    t = np.asarray(log.time)
    assert np.all(np.diff(t) > 0) and t[0] != t[-1]
    for name, x in log.signals.items():
        assert np.all(np.abs(x) <= signal_range(name)), name


# ------------------------------------------------------------------ .mat, v5
#: time stamps as a logger might get them wrong, and values a corrupt file may hold
TIMES = st.sampled_from(["ok", "zeros", "repeat", "swap", "decrease", "jitter", "huge"])
VALUES = st.one_of(st.floats(-10, 10), st.sampled_from([1e308, -1e308, 2e3, 1e6, 1e16]))


@st.composite
def mat_signals(draw):
    n = draw(st.integers(2, 30))
    t = np.arange(n) * 1e-3
    kind = draw(TIMES)
    k = draw(st.integers(0, n - 2))
    if kind == "zeros":
        t = np.zeros(n)
    elif kind == "repeat":
        t[k + 1] = t[k]
    elif kind == "swap":
        t[[k, k + 1]] = t[[k + 1, k]]
    elif kind == "decrease":
        t[k + 1 :] -= 0.5
    elif kind == "jitter":
        t[k + 1 :] += 3e-4
    elif kind == "huge":
        t = t + 1e300
    th = np.array(draw(st.lists(VALUES, min_size=n, max_size=n)))
    u = np.array(draw(st.lists(VALUES, min_size=n, max_size=n)))
    start = draw(st.integers(0, 65535))
    c = (start + np.arange(n)) % 65536  # a 16-bit counter: may wrap
    if draw(st.booleans()):
        c[-1] = c[0]  # an irregular row
    return {"t": t[:, None], "th": th[:, None], "u": u[:, None], "n": c[:, None].astype(np.uint16)}


@FUZZ
@given(mat_signals())
def test_v5_mat_logs_are_valid_or_one_clear_error(sig):
    p = _DIR / "fuzz5.mat"
    sio.savemat(p, sig)
    log = _read_or_named(FMT.read, p)
    if log is not None:
        _valid_log_promises(log)


def test_wrapping_16_bit_counter_is_unwrapped_not_lost_samples(tmp_path):
    n = 50
    c = (65520 + np.arange(n)) % 65536
    p = tmp_path / "wrap.mat"
    sio.savemat(
        p,
        {
            "t": np.arange(n)[:, None] * 1e-3,
            "th": np.zeros((n, 1)),
            "u": np.zeros((n, 1)),
            "n": c[:, None].astype(np.uint16),
        },
    )
    log = FMT.read(p)
    assert len(log) == n  # no row dropped, no "samples were lost"
    # and a .mat file's time stamps are checked as a text log's are
    sio.savemat(
        p,
        {
            "t": np.zeros((n, 1)),
            "th": np.zeros((n, 1)),
            "u": np.zeros((n, 1)),
            "n": c[:, None].astype(np.uint16),
        },
    )
    with pytest.raises(FlexarmError, match="all 50 time stamps are 0"):
        FMT.read(p)
    t = np.arange(n) * 1e-3
    t[[10, 11]] = t[[11, 10]]
    sio.savemat(
        p,
        {
            "t": t[:, None],
            "th": np.zeros((n, 1)),
            "u": np.zeros((n, 1)),
            "n": c[:, None].astype(np.uint16),
        },
    )
    with pytest.raises(
        FlexarmError,
        match=r"time decreases at sample 11 .*sample 10 and "
        r"sample 11 are swapped",
    ):
        FMT.read(p)
    th = np.zeros(n)
    th[7] = 1e308
    sio.savemat(
        p,
        {
            "t": np.arange(n)[:, None] * 1e-3,
            "th": th[:, None],
            "u": np.zeros((n, 1)),
            "n": c[:, None].astype(np.uint16),
        },
    )
    with pytest.raises(
        FlexarmError,
        match=r"column motor_angle \('th'\), sample 7: 1e\+308 "
        r"is beyond the physical range",
    ):
        FMT.read(p)


@FUZZ
@given(st.data())
def test_damaged_v5_mat_files_are_one_clear_error(data):
    p = _DIR / "damaged5.mat"
    n = 20
    sio.savemat(
        p,
        {
            "t": np.arange(n)[:, None] * 1e-3,
            "th": np.zeros((n, 1)),
            "u": np.ones((n, 1)),
            "n": np.arange(n)[:, None],
        },
    )
    raw = bytearray(p.read_bytes())
    cut = data.draw(st.integers(0, len(raw)))
    flips = data.draw(
        st.lists(st.tuples(st.integers(0, len(raw) - 1), st.integers(0, 255)), max_size=6)
    )
    for i, b in flips:
        raw[i] = b
    p.write_bytes(bytes(raw[:cut]) if data.draw(st.booleans()) else bytes(raw))
    log = _read_or_named(FMT.read, p)
    if log is not None:
        _valid_log_promises(log)


# ------------------------------------------------------------------ .mat, v7.3 (HDF5)
def _v73(path: Path, n: int = 20) -> None:
    h5py = pytest.importorskip("h5py")
    with h5py.File(path, "w") as f:
        for name, x in (
            ("t", np.arange(n) * 1e-3),
            ("th", np.linspace(0, 1, n)),
            ("u", np.ones(n)),
            ("n", np.arange(n, dtype=float)),
        ):
            f.create_dataset(name, data=x[None, :])
            f[name].attrs["MATLAB_class"] = np.bytes_("double")


@FUZZ
@given(st.data())
def test_damaged_v73_mat_files_are_one_clear_error(data):
    p = _DIR / "damaged73.mat"
    _v73(p)
    raw = bytearray(p.read_bytes())
    if data.draw(st.booleans()):
        raw = raw[: data.draw(st.integers(9, len(raw) - 1))]  # cut short (keeps the signature)
    for i, b in data.draw(
        st.lists(st.tuples(st.integers(8, len(raw) - 1), st.integers(0, 255)), max_size=8)
    ):
        raw[i] = b
    p.write_bytes(bytes(raw))
    log = _read_or_named(FMT.read, p)
    if log is not None:
        _valid_log_promises(log)


def test_a_truncated_v73_file_names_the_file(tmp_path):
    p = tmp_path / "cut.mat"
    _v73(p)
    p.write_bytes(p.read_bytes()[:600])
    with pytest.raises(FlexarmError) as info:
        FMT.read(p)
    assert str(p) in str(info.value) and "damaged or cut short" in str(info.value)


# ------------------------------------------------------------------ log-format files
FORMAT_VALUES = st.one_of(
    st.integers(-3, 20),
    st.text(max_size=8),
    st.floats(allow_nan=True),
    st.booleans(),
    st.lists(st.integers(0, 5), max_size=3),
    st.dictionaries(st.sampled_from(["K1", "x", "time"]), st.integers(0, 9), max_size=2),
)


@FUZZ
@given(
    st.dictionaries(
        st.sampled_from(
            [
                "columns",
                "units",
                "controller",
                "checks",
                "delimiter",
                "comment",
                "skip_rows",
                "description",
                "nonsense",
            ]
        ),
        st.one_of(
            FORMAT_VALUES,
            st.dictionaries(
                st.sampled_from(
                    [
                        "time",
                        "motor_angle",
                        "voltage",
                        "kind",
                        "gain_columns",
                        "limit",
                        "rate",
                        "quantum",
                        "zero",
                        "K1",
                        "bogus",
                    ]
                ),
                FORMAT_VALUES,
                max_size=4,
            ),
        ),
        max_size=5,
    )
)
def test_log_format_files_are_valid_or_one_clear_error(d):
    import tomli_w

    p = _DIR / "fuzz-format.toml"
    try:
        p.write_text(tomli_w.dumps(d))
    except (TypeError, ValueError):  # nan or mixed arrays tomli_w cannot write: as text
        p.write_text(repr(d))
    fmt = _read_or_named(load_log_format, p)
    assert fmt is None or isinstance(fmt, LogFormat)


@FUZZ
@given(st.binary(max_size=200) | st.text(max_size=200))
def test_log_format_files_of_any_content(data):
    p = _DIR / "fuzz-any.toml"
    try:
        p.write_bytes(data if isinstance(data, bytes) else data.encode("utf-8"))
    except UnicodeEncodeError:
        return
    _read_or_named(load_log_format, p)


# ------------------------------------------------------------------ controller files
MATRIX = st.one_of(
    st.lists(st.lists(st.floats(-5, 5), min_size=1, max_size=3), min_size=1, max_size=3),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=4),
    st.none(),
    st.lists(st.integers(), max_size=2),
    st.dictionaries(st.text(max_size=2), st.integers(), max_size=2),
)


@FUZZ
@given(st.dictionaries(st.sampled_from(["A", "B", "C", "D", "dt", "x"]), MATRIX, max_size=5))
def test_controller_files_are_valid_or_one_clear_error(d):
    """A JSON controller file read and made into the controller (its matrices' shapes
    checked against the inputs and outputs it names)."""
    from flexarm.control.lti import lti_controller, read_lti_file

    p = _DIR / "ctrl.json"
    p.write_text(json.dumps(d))

    def read(path):
        m = read_lti_file(path, where=f"[controller] file {str(path)!r}")
        return lti_controller(
            **{k: v for k, v in m.items() if k in "ABCD"},
            inputs=["motor_angle"],
            outputs=["voltage"],
            dt=m.get("dt"),
            input_names=("voltage",),
            base_dt=1e-3,
            where=f"[controller] file {str(path)!r}",
        )

    _read_or_named(read, p)


# ------------------------------------------------------------------ the FRF JSON
def _frf_json() -> dict:
    f = [1.0, 2.0, 4.0]
    out = {"re": [1.0, 0.5, 0.1], "im": [-0.1, -0.4, -0.2], "noise_std": [0.01] * 3}
    return {
        "input": "current",
        "frequency_hz": f,
        "lines": [1, 2, 4],
        "period_samples": 100,
        "fs_hz": 100.0,
        "periods_used": 4,
        "transient_periods": 1,
        "outputs": {"motor_angle": out},
        "warnings": [],
    }


@FUZZ
@given(st.data())
def test_frf_json_is_valid_or_one_clear_error(data):
    from flexarm.identification.frequency_domain.periodic import PeriodicFRF

    d = _frf_json()
    for _ in range(data.draw(st.integers(1, 3))):
        path = data.draw(
            st.sampled_from(
                [
                    ("input",),
                    ("frequency_hz",),
                    ("lines",),
                    ("period_samples",),
                    ("fs_hz",),
                    ("outputs",),
                    ("outputs", "motor_angle"),
                    ("outputs", "motor_angle", "re"),
                    ("outputs", "motor_angle", "noise_std"),
                    ("periods_used",),
                ]
            )
        )
        value = data.draw(
            st.one_of(
                st.none(),
                st.text(max_size=3),
                st.floats(allow_nan=True, allow_infinity=True),
                st.lists(st.floats(allow_nan=True), max_size=4),
                st.just({}),
                st.just("drop"),
            )
        )
        node = d
        for k in path[:-1]:
            node = node.get(k) if isinstance(node, dict) else None
        if isinstance(node, dict):
            if value == "drop":
                node.pop(path[-1], None)
            else:
                node[path[-1]] = value
    src = "fuzz-frf.json"
    try:
        PeriodicFRF.from_json(d, src)
    except Exception as exc:
        _named(exc, src)

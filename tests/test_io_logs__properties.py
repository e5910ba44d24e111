"""Property-based fuzzing of the log readers (issue #12): random text, random bytes, random
CSV shapes, delimiters and numbers either load (and then give back exactly what was written)
or raise the project's own error naming the file (and the line, where a line is at fault);
never another exception, never a silently wrong array. Bounded: derandomised, a few hundred
examples in all, about 8 s.

Found against the reader before the logger-format work (input, symptom, fix):
- a comment line holding a form feed, \x1e or U+2028: the header was found by splitting on
  "\n" but rows were numbered by str.splitlines(), so the error blamed the header ("'time'
  is not a number", line 3) instead of the bad value on line 4; fix: one line split
  (line ends normalised, then "\n" only) for finding, parsing and numbering.
- a UTF-8 byte-order mark: "missing column 'time'" for a file whose header starts with
  time; fix: decode as utf-8-sig.
- (guard) Python's float() reads "1_000" as 1000 although no logger writes digit
  grouping; the reader refuses underscores rather than guess.
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flexarm.identification.time_domain.logs import FitInputError, load_rig_log
from flexarm.io.logs import LogError, read_log
from test_logformat import EXAMPLE

FUZZ = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)
_DIR = Path(tempfile.mkdtemp(prefix="flexarm-fuzz-"))


def _file(data: bytes | str, name="fuzz.log") -> Path:
    p = _DIR / name
    p.write_bytes(data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data)
    return p


def _loads_or_names_file(read, p: Path):
    """``read(p)`` returns, or raises LogError / FitInputError whose message names ``p``."""
    try:
        return read(p)
    except (LogError, FitInputError) as exc:
        assert str(p) in str(exc), str(exc)
        return None


def _read(p):
    return read_log(p, required=("time",), min_samples=2)


def _read_rig_no_format(p):
    return load_rig_log(p, min_samples=2)


def _read_rig(p):
    return load_rig_log(p, log_format=EXAMPLE, min_samples=2)


LOG_CHARS = st.sampled_from(list("0123456789.,;\t -+eE#%\r\nabcxyz_:\x0b\x0c\u2028\x85\ufeff"))


@FUZZ
@given(st.text(LOG_CHARS, max_size=300) | st.text(max_size=200))
def test_random_text(text):
    try:
        p = _file(text)
    except UnicodeEncodeError:  # lone surrogates cannot be written as UTF-8
        return
    for read in (_read, _read_rig_no_format, _read_rig):
        _loads_or_names_file(read, p)


@FUZZ
@given(st.binary(max_size=300))
def test_random_bytes(data):
    p = _file(data)
    for read in (_read, _read_rig_no_format, _read_rig):
        _loads_or_names_file(read, p)


#: finite numbers within the tightest physical range a mapped column gets (a voltage:
#: |x| <= 1e5 V, flexarm.io.checks.RANGES); beyond it a reader refuses the value
NUMBERS = st.floats(min_value=-1e5, max_value=1e5, allow_nan=False, allow_infinity=False, width=64)


@st.composite
def csv_logs(draw):
    """A valid log: header, uniform time, random finite numbers written with repr (exact
    round trip), a random delimiter and line end, comment lines, maybe a BOM."""
    ncol = draw(st.integers(1, 5))
    n = draw(st.integers(2, 40))
    delim = draw(st.sampled_from([",", ";", "\t", " ", "  "]))
    nl = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    names = ["time"] + [f"c{j}" for j in range(ncol)]
    t0 = draw(st.integers(-(10**6), 10**6))
    # steps exact in binary (t0 + k step is exact) and a rig's rate whether the numbers
    # are read as s (4-64 Hz) or as ms (4-64 kHz): io.checks.RATE_RANGE (issue #45)
    step = draw(st.sampled_from([1 / 64, 1 / 16, 1 / 8, 1 / 4]))
    time = t0 + step * np.arange(n, dtype=float)
    vals = np.array(
        draw(st.lists(st.lists(NUMBERS, min_size=ncol, max_size=ncol), min_size=n, max_size=n)),
        float,
    ).reshape(n, ncol)
    comments = draw(
        st.lists(
            st.sampled_from(
                ["# note: x", "% logger 1", "#", "% a;b,c", "# form\x0cfeed\x1e\u2028"]
            ),
            max_size=3,
        )
    )
    lines = comments + [delim.join(names)]
    lines += [delim.join(repr(float(v)) for v in (time[k], *vals[k])) for k in range(n)]
    bom = draw(st.sampled_from(["", "\ufeff"]))
    return bom + nl.join(lines) + draw(st.sampled_from(["", nl])), time, vals, names


@FUZZ
@given(csv_logs())
def test_valid_logs_give_back_exactly_what_was_written(case):
    text, time, vals, names = case
    p = _file(text, "valid.csv")
    log = read_log(p, required=("time",), min_samples=2, max_jitter=1e-9)
    np.testing.assert_array_equal(log.time, time)
    for j, name in enumerate(names[1:]):
        np.testing.assert_array_equal(log[name], vals[:, j])
    # by column number, with the sign flipped, and the time in ms
    log = read_log(
        p,
        {"time": 1, "voltage": f"-{len(names)}"},
        {"time": "ms"},
        required=("time",),
        min_samples=2,
        max_jitter=1e-6,  # x 1e-3 rounds each stamp (<= 1e3 s) by ~1e-13 s; steps >= 1.5e-5 s
    )
    np.testing.assert_allclose(log.time, time * 1e-3, rtol=1e-15)
    np.testing.assert_array_equal(log["voltage"], -vals[:, -1])


@FUZZ
@given(csv_logs(), st.data())
def test_damaged_logs_fail_naming_file_and_line(case, data):
    """Cut mid-line, text in a number, a duplicated row: an error naming file and line (or,
    for a cut that leaves whole rows, a log equal to the rows kept)."""
    text, time, vals, names = case
    lines = text.replace("\r\n", "\n").replace("\r", "\n").rstrip("\n").split("\n")
    first = next(k for k, s in enumerate(lines) if s.lstrip("\ufeff").startswith("time"))
    k = data.draw(st.integers(first + 1, len(lines) - 1))
    how = data.draw(st.sampled_from(["cut", "text", "dup"]))
    row = k - first - 1
    if how == "cut":
        body = "\n".join(lines[:k]) + "\n" + lines[k][: data.draw(st.integers(0, len(lines[k])))]
    elif how == "text":
        body = "\n".join(lines[:k] + [lines[k] + "x"] + lines[k + 1 :])
    else:
        body = "\n".join(lines[: k + 1] + [lines[k]] + lines[k + 1 :])
    p = _file(body, "damaged.csv")
    try:
        log = read_log(p, required=("time",), min_samples=2, max_jitter=1e-9)
    except LogError as exc:
        msg = str(exc)
        assert str(p) in msg
        if "too few samples" not in msg:
            assert re.search(r"line \d+", msg), msg
        if how == "text":  # the damaged line, 1-based, is named
            assert f"(line {k + 1})" in msg, (msg, k)
        if how == "dup":  # the copy (line k + 2) repeats the time of line k + 1
            assert f"(line {k + 2}," in msg, (msg, k)
        return
    # it loaded: only possible for a cut that left a valid prefix (a whole last row, or a
    # last number cut to a shorter number); every other row must be as written
    assert how == "cut", (how, body)
    np.testing.assert_array_equal(log.time[:row], time[:row])
    for j, name in enumerate(names[1:]):
        np.testing.assert_array_equal(log[name][:row], vals[:row, j])

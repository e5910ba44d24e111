"""Issue #45 item 6: fuzzing the readers with the inputs the issue names.

Classes (hypothesis, derandomised; counts as run on 2026-12-05):

* **nested TOML / JSON** (60 examples): arrays or tables nested 1 to 5000 deep in a
  scenario TOML, a controller TOML (``--controller``), a log-format TOML, a controller's
  JSON matrices file and an FRF JSON (``flexarm tfest``): a result or one project error
  naming the file, never a ``RecursionError`` (before: the scenario and the controller
  JSON raised it, and the command line said "an input file is nested too deeply" without
  naming the file);
* **``.mat`` shapes and time units** (80 examples): the time and signal variables as
  (n,), (n, 1), (1, n), (n, 2), (0,), (0, 0) or (1, 0); the clock's numbers stepping
  1 ns to 1000 (s, ms, µs, ns, or no unit stated): a ``Log`` or one project error
  naming the file; a log read with a stated unit has a rig's sampling rate
  (``io.checks.RATE_RANGE``), and numbers whose stated unit gives another rate are
  refused (before: a .mat time in s said ``us`` was read as a 1 GHz clock).
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from flexarm.errors import FlexarmError, one_line
from flexarm.io.checks import RATE_RANGE

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402 - optional: after importorskip
from hypothesis import strategies as st  # noqa: E402 - optional: after importorskip

sio = pytest.importorskip("scipy.io")

FUZZ = dict(
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
_DIR = Path(tempfile.mkdtemp(prefix="flexarm-fuzz-45-"))


def _named(exc: BaseException, path: Path) -> str:
    assert isinstance(exc, FlexarmError), f"{type(exc).__name__}: {exc}"
    line = one_line(exc)
    assert str(path) in line or path.name in line, line
    assert "\n" not in line
    return line


# ------------------------------------------------------------------ nested documents
def _toml(depth: int, kind: str) -> str:
    if kind == "array":
        return "a = " + "[" * depth + "]" * depth + "\n"
    return "a = " + "{ b = " * depth + "1" + " }" * depth + "\n"


def _json(depth: int, kind: str) -> str:
    if kind == "array":
        return "[" * depth + "]" * depth
    return '{"a": ' * depth + "1" + "}" * depth


def _read_scenario(p):
    from flexarm.specs import load_scenario

    return load_scenario(p)


def _read_controllers(p):
    from flexarm.specs.scenario import load_controllers

    return load_controllers(p)


def _read_format(p):
    from flexarm.io.logformat import load_log_format

    return load_log_format(p)


def _read_lti_json(p):
    from flexarm.control.lti import read_lti_file

    return read_lti_file(p, where=f"[controller] file {str(p)!r}")


READERS = {
    "scenario.toml": (_toml, _read_scenario),
    "controller.toml": (_toml, _read_controllers),
    "format.toml": (_toml, _read_format),
    "matrices.json": (_json, _read_lti_json),
}


@settings(max_examples=60, **FUZZ)
@given(
    depth=st.one_of(st.integers(1, 50), st.integers(50, 5000)),
    kind=st.sampled_from(["array", "table"]),
    reader=st.sampled_from([*READERS, "frf.json"]),
)
def test_nested_documents_are_read_or_one_line_naming_the_file(depth, kind, reader):
    p = _DIR / reader
    if reader == "frf.json":  # through the command line: tfest reads the FRF JSON
        from flexarm.cli import app

        p.write_text(_json(depth, kind))
        r = CliRunner().invoke(app, ["tfest", str(p), "--json", str(_DIR / "t.json")])
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert r.exit_code == 2 and len(lines) == 1, r.output
        assert lines[0].startswith("error: ") and str(p) in lines[0], lines[0]
        return
    write, read = READERS[reader]
    p.write_text(write(depth, kind))
    with pytest.raises(Exception) as e:  # none of these documents is a valid input
        read(p)
    line = _named(e.value, p)
    if depth > 2000:
        assert "nested too deeply" in line or "recursion" in line, line


# ------------------------------------------------------------------ .mat shapes and time units
SHAPES = ["n", "n1", "1n", "n2", "0", "00", "10"]
PER_UNIT = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}


def _shaped(x: np.ndarray, shape: str) -> np.ndarray:
    n = len(x)
    return (
        {
            "n": x,
            "n1": x[:, None],
            "1n": x[None, :],
            "n2": np.column_stack([x, x]),
            "0": np.zeros(0),
            "00": np.zeros((0, 0)),
            "10": np.zeros((1, 0)),
        }[shape]
        if n
        else np.zeros(0)
    )


@settings(max_examples=80, **FUZZ)
@given(
    n=st.integers(0, 40),
    time_shape=st.sampled_from(SHAPES),
    signal_shape=st.sampled_from(SHAPES),
    step=st.sampled_from([1e-9, 1e-6, 1e-4, 1e-3, 0.01, 1.0, 1000.0]),
    unit=st.sampled_from([None, *PER_UNIT]),
)
def test_mat_shapes_and_time_units_are_a_log_or_one_line(n, time_shape, signal_shape, step, unit):
    from flexarm.io.logformat import log_format_from_dict

    t = np.arange(n) * step
    rng = np.random.default_rng(n)
    p = _DIR / "shapes.mat"
    sio.savemat(
        p,
        {
            "t": _shaped(t, time_shape),
            "i": _shaped(rng.normal(size=n), signal_shape),
            "th": _shaped(rng.normal(size=n), "n1"),
        },
    )
    d = {"columns": {"time": "t", "current": "i", "motor_angle": "th"}}
    if unit is not None:
        d["units"] = {"time": unit}
    fmt = log_format_from_dict(d, source="fuzz format")
    try:
        log = fmt.read(p)
    except Exception as exc:  # the property: only a project error naming the file
        _named(exc, p)
        return
    assert log.time is not None and len(log.time) == n > 0
    if unit is not None and n >= 2:
        fs = 1.0 / float(np.median(np.diff(log.time)))
        assert RATE_RANGE[0] <= fs <= RATE_RANGE[1], (fs, unit, step)
        assert fs == pytest.approx(1.0 / (step * PER_UNIT[unit]), rel=1e-6)


@pytest.mark.parametrize("step, unit", [(1e-3, "us"), (1e-3, "ns"), (1.0, "s"), (1e-3, "ms")])
def test_a_mat_clock_said_in_the_wrong_unit_is_always_refused(tmp_path, step, unit):
    """The deterministic half of the property above: 1 kHz numbers read in a unit that
    makes the rate no rig's (1 GHz, 1 THz, 1 Hz, 1 MHz) are refused, whatever the shape."""
    from flexarm.io.logformat import log_format_from_dict
    from flexarm.io.logs import LogError

    t = np.arange(50) * step
    for shape in ("n", "n1", "1n"):
        p = tmp_path / f"{shape}.mat"
        sio.savemat(p, {"t": _shaped(t, shape), "i": np.sin(t), "th": np.cos(t)})
        fmt = log_format_from_dict(
            {
                "columns": {"time": "t", "current": "i", "motor_angle": "th"},
                "units": {"time": unit},
            },
            source="f.toml",
        )
        with pytest.raises(LogError, match="the time unit is wrong"):
            fmt.read(p)


def test_the_fuzzed_json_writer_round_trips():
    """The strategies' documents are what they say: depth 3 is three arrays deep."""
    assert json.loads(_json(3, "array")) == [[[]]]
    assert json.loads(_json(2, "table")) == {"a": {"a": 1}}

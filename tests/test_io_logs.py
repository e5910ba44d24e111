"""The CSV exchange format of identification experiments (flexarm.io.logs)."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from flexarm.io.logs import LogError, read_log, write_log

HEADER = "time,reference,current,motor_angle,tip_angle"


def _rows(n=50, dt=1e-3, w=5.0):
    t = np.arange(n) * dt
    return t, {
        "reference": 0.1 * np.sin(w * t),
        "current": 0.5 * np.cos(w * t),
        "motor_angle": 0.1 * np.sin(w * t - 0.1),
        "tip_angle": 0.05 * np.sin(w * t),
    }


def _csv(path, header=HEADER, rows=None, comments=(), n=50):
    t, s = _rows(n)
    lines = [f"# {c}" for c in comments] + [header]
    if rows is None:
        rows = [
            ",".join(f"{v:.9g}" for v in r)
            for r in np.column_stack(
                [t, s["reference"], s["current"], s["motor_angle"], s["tip_angle"]]
            )
        ]
    path.write_text("\n".join(lines + list(rows)) + "\n")
    return path


def _sha(p):
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_round_trip_with_comments_meta_and_extra_columns(tmp_path):
    t, s = _rows()
    s["voltage"] = 2.0 * np.ones_like(t)
    s["motor_velocity"] = np.cos(t)
    p = write_log(tmp_path / "a.csv", t, s, comments={"omega": 5.0, "rig": "air table"})
    log = read_log(p)
    assert log.meta == {"omega": "5.0", "rig": "air table"}
    assert log.comments == ["omega: 5.0", "rig: air table"]
    assert list(log.signals) == [
        "reference",
        "current",
        "motor_angle",
        "tip_angle",
        "voltage",
        "motor_velocity",
    ]
    for k, v in s.items():
        np.testing.assert_allclose(log[k], v, rtol=1e-11, atol=1e-14)
    assert log.dt == pytest.approx(1e-3, rel=1e-9)
    assert len(log) == 50


def test_write_refuses_to_overwrite(tmp_path):
    t, s = _rows()
    p = write_log(tmp_path / "a.csv", t, s)
    before = _sha(p)
    with pytest.raises(LogError, match=r"a\.csv.*exists.*overwrite=True"):
        write_log(p, t, {k: 2 * v for k, v in s.items()})
    assert _sha(p) == before
    write_log(p, t, {k: 2 * v for k, v in s.items()}, overwrite=True)
    assert _sha(p) != before


def test_column_and_unit_mapping(tmp_path):
    t, s = _rows()
    p = tmp_path / "mapped.csv"
    rows = [
        f"{1e3 * ti:.9g},{r:.9g},{1e3 * i:.9g},{m:.9g},{tt:.9g}"
        for ti, r, i, m, tt in zip(
            t, s["reference"], s["current"], s["motor_angle"], s["tip_angle"], strict=True
        )
    ]
    _csv(p, header="t_ms,reference,i_m,motor_angle,tip_angle", rows=rows)
    before = _sha(p)
    log = read_log(
        p, columns={"current": "i_m", "time": "t_ms"}, units={"current": "mA", "time": "ms"}
    )
    np.testing.assert_allclose(log["current"], s["current"], rtol=1e-8)
    np.testing.assert_allclose(log.time, t, atol=1e-12)
    assert _sha(p) == before  # never modified
    with pytest.raises(
        LogError, match=r"mapped\.csv: cannot convert column 'current' from 'kg' to A"
    ):
        read_log(p, columns={"current": "i_m", "time": "t_ms"}, units={"current": "kg"})
    # encoder counts: a scaled unit (4096 counts per turn), 1 count = 2π/4096 rad
    counts = tmp_path / "counts.csv"
    rows = [
        f"{ti:.9g},{r:.9g},{i:.9g},{m * 4096 / (2 * np.pi):.12g},{tt:.9g}"
        for ti, r, i, m, tt in zip(
            t, s["reference"], s["current"], s["motor_angle"], s["tip_angle"], strict=True
        )
    ]
    _csv(counts, header="time,reference,current,motor_angle,tip_angle", rows=rows)
    log = read_log(counts, units={"motor_angle": "turn/4096"})
    np.testing.assert_allclose(log["motor_angle"], s["motor_angle"], rtol=1e-10, atol=1e-15)


def test_missing_column_lists_found_expected_and_mapping(tmp_path):
    p = _csv(tmp_path / "bad_cols.csv", header="time,reference,i_m,motor_angle,tip_angle")
    with pytest.raises(LogError) as e:
        read_log(p)
    msg = str(e.value)
    assert str(p) in msg and "'current'" in msg
    assert "found:    time, reference, i_m" in msg
    assert "expected: time, reference, current, motor_angle, tip_angle" in msg
    assert "--column current=" in msg


@pytest.mark.parametrize(
    "bad, what",
    [
        ("abc", "'abc' is not a number"),
        ("", "an empty field is not a number"),
        ("nan", "value is NaN"),
    ],
)
def test_bad_value_names_column_and_row(tmp_path, bad, what):
    p = tmp_path / "bad_value.csv"
    _csv(p, comments=["omega: 5"])
    lines = p.read_text().splitlines()
    f = lines[1 + 7].split(",")  # data row 7
    f[2] = bad
    lines[1 + 7] = ",".join(f)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(LogError) as e:
        read_log(p)
    msg = str(e.value)
    assert str(p) in msg and "column 'current'" in msg and "data row 7 (line 9)" in msg
    assert what in msg


def test_ragged_row(tmp_path):
    p = _csv(tmp_path / "ragged.csv")
    lines = p.read_text().splitlines()
    lines[5] = lines[5] + ",1.0"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(LogError, match=r"ragged\.csv: data row 5 \(line 6\) has 6 field"):
        read_log(p)


def test_time_not_increasing(tmp_path):
    t, s = _rows()
    t2 = t.copy()
    t2[10] = t2[9]
    p = write_log(tmp_path / "dup.csv", t2, s)
    with pytest.raises(LogError, match=r"dup\.csv: time repeats at data row 11"):
        read_log(p)
    t3 = t.copy()
    t3[20], t3[21] = t3[21], t3[20]
    p = write_log(tmp_path / "unsorted.csv", t3, s)
    with pytest.raises(LogError, match=r"unsorted\.csv: time decreases at data row 22"):
        read_log(p)


def test_non_uniform_sampling_names_worst_step(tmp_path):
    t, s = _rows()
    t2 = t.copy()
    t2[30:] += 5e-6  # one step 0.5 % long
    p = write_log(tmp_path / "jitter.csv", t2, s)
    with pytest.raises(LogError) as e:
        read_log(p)
    msg = str(e.value)
    assert str(p) in msg and "non-uniform sampling" in msg
    assert "from data row 30 to 31" in msg and "0.001005" in msg
    # small jitter (1e-4 relative) is accepted
    t4 = t + 1e-7 * np.sin(np.arange(len(t)))
    read_log(write_log(tmp_path / "ok.csv", t4, s))


def test_too_few_samples_and_no_header(tmp_path):
    p = _csv(tmp_path / "short.csv", n=5)
    with pytest.raises(LogError, match=r"short\.csv: too few samples: 5 data row"):
        read_log(p)
    q = tmp_path / "empty.csv"
    q.write_text("# only a comment\n")
    with pytest.raises(LogError, match=r"empty\.csv: no header row"):
        read_log(q)
    with pytest.raises(LogError, match=r"nothere\.csv: no such file"):
        read_log(tmp_path / "nothere.csv")

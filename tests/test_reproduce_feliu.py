"""Acceptance: the whole FRB reproduction (Figs. 11-19) runs once, writes its figures and
its paper-vs-ours table, and the table meets the paper's claims."""

import csv
import math

import pytest

from flexarm.reproduce.feliu import CHOICES, run


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    out = tmp_path_factory.mktemp("feliu")
    calls = []
    res = run(out, progress=lambda i, n, what: calls.append((i, n, what)))
    res["calls"] = calls
    res["out"] = out
    return res


@pytest.fixture(scope="module")
def table(result):
    return {r["key"]: r for r in result["table"]}


def test_files_and_progress(result):
    out = result["out"]
    names = sorted(p.name for p in out.glob("fig*.png"))
    assert [n[:5] for n in names] == [f"fig{k}" for k in range(11, 20)]
    assert all(p.stat().st_size > 10_000 for p in result["figures"])
    rows = list(csv.DictReader((out / "feliu_table.csv").open()))
    assert [r["key"] for r in rows] == [r["key"] for r in result["table"]]
    assert set(rows[0]) == {"key", "quantity", "unit", "paper", "ours", "ratio", "note"}
    md = (out / "feliu_table.md").read_text()
    assert md.count("\n|") == len(rows) + 2
    assert result["calls"][0][:2] == (0, 6) and result["calls"][-1][0] == 5
    assert result["choices"]["two_mass_distance"] == CHOICES.two_mass_distance


def test_inner_loop_rows(table):
    assert table["gcm1_dc"]["ours"] == pytest.approx(15.0, abs=1e-6)
    assert table["gcm2_dc"]["ours"] == pytest.approx(1.0, abs=1e-9)
    assert table["peak_400"]["ours"] == pytest.approx(6.0, rel=2e-3)
    assert table["inner_settle_design"]["ours"] <= 40.0  # ms, paper 33
    assert table["inner_settle_sim"]["ours"] <= 40.0
    assert abs(table["ess_all"]["ours"]) <= 1.0  # A/D counts
    assert table["ess_no_friction"]["ours"] > 1.0
    assert table["ess_no_coupling"]["ours"] > 1.0
    for k in ("rise90_no_friction", "rise90_no_coupling"):
        assert table[k]["ours"] == pytest.approx(1.0, abs=0.15)
    assert table["two_mass_inner_settle"]["ours"] <= 80.0  # ms, paper ~60 (5 %)
    assert abs(table["ess_two_mass"]["ours"]) < 1.0
    assert table["ess_two_mass_no_coupling"]["ours"] > abs(table["ess_two_mass"]["ours"]) + 0.5


def test_outer_loop_rows(table):
    for k in ("n_w2", "n_2zw", "accel_single"):
        assert table[k]["ratio"] == pytest.approx(1.0, abs=0.03)  # physical wire vs fit
    for k in ("n2_a2", "n2_a0", "n2_b1", "n2_b2", "n2_pole", "n2_gain"):
        assert table[k]["ratio"] == pytest.approx(1.0, abs=1e-3), k
    assert table["tip_settle_single"]["ours"] <= 0.3  # s, paper 0.22
    assert table["defl_single"]["ours"] <= 0.4
    assert table["tip_settle_two_mass"]["ours"] <= 0.4  # s, paper 0.3
    assert table["ripple_two_mass"]["ours"] < 3.0  # % of the step
    assert table["mode1_two_mass"]["ours"] < 1.0
    assert table["defl_two_mass"]["ours"] <= 0.4
    # the paper's snap bends the ideal linear loop past the limit; ours finds the snap
    assert table["defl_two_mass_linear"]["ours"] > 0.4
    assert 0.6 < table["snap_for_limit"]["ratio"] < 0.9
    for r in table.values():
        if isinstance(r["paper"], float) and r["paper"] and math.isfinite(r["ours"]):
            assert r["ratio"] == pytest.approx(r["ours"] / r["paper"])

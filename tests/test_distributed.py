"""flexarm.distributed: chunked plant batches and many fits on a Dask LocalCluster of 2
spawned workers on the loopback only (no network beyond 127.0.0.1, no dashboard).

What is checked, and why the tolerances:
* chunked batches: the same chunks run the same compiled code, so in-process, 1 worker and
  2 workers give bit-identical per-rollout reductions (exact equality); against the
  unchunked batch (a vmap over all rollouts at once) the arithmetic per rollout is the same
  but vectorised at another width: 1e-12 relative;
* fit_many: a real servo-rig fit of a short synthetic log per good row; a row whose log is
  not a log fails and is reported without stopping the others; a worker killed under its
  task (the task kills its own process) is replaced and the task rerun; a rerun skips the
  finished rows and retries the failed one.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import flexarm
from flexarm import distributed as fd

#: the tests that start workers; the in-process paths run without Dask
needs_dask = pytest.mark.skipif(
    not fd.have_dask(),
    reason="dask.distributed is not installed (pip install 'flexarm[distributed]')",
)

SPREAD = {
    "arm.friction.coulomb": (0.03, 0.006),
    "arm.motor.inertia": (2.08e-3, 2e-4),
    "arm.beam.damping_ratio": (0.03, 0.01),
    "sensors.tip_deflection.gain": (1.0, 0.05),
}
#: the synthetic rig of tests/test_time_domain_fit.py (its data sheet, delays known)
RIG = dict(
    drive="voltage",
    gear_ratio=70,
    motor_constant=7.68e-3,
    armature_resistance=2.6,
    link_length=0.42,
)
FAST = (
    "gear_efficiency=0.9;motor_efficiency=0.69;angle_delay=0;tip_delay=0;max_delay=3;"
    "estimates=false;popsize=4;maxiter=1;global_seconds=0.5;local_nfev=3;polish_iter=0;"
    "delay_nfev=1"
)


@pytest.fixture(scope="module")
def client():
    import cloudpickle

    # the spawned workers cannot import this test module: its functions travel by value
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    c = fd.client_for(workers=2)
    yield c
    fd.close(c)
    cloudpickle.unregister_pickle_by_value(sys.modules[__name__])


def test_client_for_defaults_and_bad_input(monkeypatch):
    assert fd.client_for() is None  # in-process: no Dask needed
    with pytest.raises(ValueError, match="give one"):
        fd.client_for(scheduler="tcp://h:8786", workers=2)
    with pytest.raises(ValueError, match="tcp://host:8786"):
        fd.client_for(scheduler="h:8786")
    monkeypatch.setattr(fd, "have_dask", lambda: False)
    with pytest.warns(RuntimeWarning, match="in-process"):
        assert fd.client_for(workers=2) is None
    env = fd.worker_environment()
    assert env["OMP_NUM_THREADS"] == "1" and "intra_op_parallelism_threads=1" in env["XLA_FLAGS"]
    assert env["FLEXARM_THREADS"] == "1"  # flexarm's own batches: one thread a worker too
    assert fd.chunk_bounds(7, 3) == [(0, 3), (3, 6), (6, 7)]
    assert fd.chunk_seed(0, 1) != fd.chunk_seed(0, 2) == fd.chunk_seed(0, 2)


def _batch():
    from flexarm.design import plants as pl

    sc = flexarm.load_scenario("rotary-flexible-link")
    b = pl.from_paths(sc, SPREAD, 5, seed=1).with_overrides({"simulation": {"duration": 0.4}})
    return b.loop()  # nominal + 5 plants: 6 rollouts, two chunks of 3


@needs_dask
def test_chunked_batch_is_bit_identical_in_process_1_and_2_workers(client):
    from flexarm.sim.sampled import simulate_batch

    bl = _batch()
    args = (bl.loop, bl.x0, bl.references, len(bl.time))
    plain = fd.rollout_summary(simulate_batch(*args, seed=3, check=False))
    opts = fd.ChunkOptions(chunk=3)
    here = simulate_batch(*args, seed=3, chunks=opts)
    workers = sorted(client.scheduler_info()["workers"])
    assert len(workers) == 2
    dask = fd.DaskExecutor(client)  # the batch's executor (sim.batch.BatchExecutor)
    one = simulate_batch(
        *args, seed=3, client=dask, chunks=fd.ChunkOptions(chunk=3, workers=(workers[0],))
    )
    two = simulate_batch(*args, seed=3, client=dask, chunks=opts)
    assert here.chunks == two.chunks == 2 and here.trajectories is None
    for k, v in here.per_rollout.items():
        assert v.shape[0] == 6
        assert np.array_equal(v, one.per_rollout[k], equal_nan=True), k
        assert np.array_equal(v, two.per_rollout[k], equal_nan=True), k
        if v.dtype != bool:
            np.testing.assert_allclose(v, plain[k], rtol=1e-12, atol=1e-15, err_msg=k)
    assert here.unstable == two.unstable == int(plain["diverged"].sum())
    med = np.median(here.per_rollout["peak_abs_signals"][~plain["diverged"]], axis=0)
    np.testing.assert_allclose(here.quantiles["peak_abs_signals"][0.5], med, rtol=1e-12)
    # trajectories only on request, then the same as the unchunked batch's
    full = simulate_batch(
        *args, seed=3, client=dask, chunks=fd.ChunkOptions(chunk=3, trajectories=True)
    )
    ref = simulate_batch(*args, seed=3, check=False)
    np.testing.assert_allclose(full.trajectories["signals"], ref["signals"], rtol=1e-12, atol=1e-15)


def test_compare_in_chunks_equals_one_batch():
    """compare over 4 drawn plants in chunks of 2 (in-process) against one batch: the same
    rows (nominal, median, worst, unstable) and per-plant metrics, 1e-12 relative."""
    from flexarm.design import plants as pl
    from flexarm.design.compare import compare

    sc = flexarm.load_scenario("rotary-flexible-link")
    b = pl.from_paths(sc, SPREAD, 4, seed=1)
    one = compare(b, duration=0.8, step=0.3)
    chunked = compare(b, duration=0.8, step=0.3, chunks=fd.ChunkOptions(chunk=2))
    name = "logged controller"
    assert chunked.settings["chunks"] == 2 and chunked.rows[name]["n_plants"] == 4
    for k, v in one.per_plant[name].items():
        np.testing.assert_allclose(
            np.asarray(chunked.per_plant[name][k], float),
            np.asarray(v, float),
            rtol=1e-12,
            err_msg=k,
        )
    assert chunked.rows[name]["unstable"] == one.rows[name]["unstable"]
    for s in ("nominal", "median", "worst"):
        for k, v in one.rows[name][s].items():
            assert chunked.rows[name][s][k] == pytest.approx(v, rel=1e-12, nan_ok=True), (s, k)


def test_tune_cost_in_chunks_equals_one_batch():
    """The tuning cost over 4 plants in chunks of 2 (in-process) against one batch: the same
    per-plant costs and quantile, 1e-12 relative."""
    from flexarm.design import plants as pl
    from flexarm.design.tune import TuneCost

    sc = flexarm.load_scenario("rotary-flexible-link")
    b = pl.from_paths(sc, SPREAD, 4, seed=1)
    kw = dict(
        step=0.3,
        start=0.1,
        duration=0.8,
        band=0.02,
        quantile=0.9,
        weights={},
        hub_error_max=1.0,
        count=None,
        seed=0,
    )
    paths = ["controller.k1", "controller.k3"]
    one = TuneCost(sc, b, paths, **kw)
    chunked = fd.ChunkedTuneCost(sc, b, paths, options=fd.ChunkOptions(chunk=2), **kw)
    p = [1.1 * sc.controller.k1, sc.controller.k3]
    J1, c1, _ = one.evaluate(p)
    J2, c2, _ = chunked.evaluate(p)
    assert chunked.base.size == one.base.size == 5
    np.testing.assert_allclose(c2, c1, rtol=1e-12)
    assert J2 == pytest.approx(J1, rel=1e-12)


# ------------------------------------------------------------------ many fits
def _manifest(tmp: Path) -> Path:
    from flexarm.identification.time_domain.synthetic import synthetic_log

    sc = flexarm.load_scenario("rotary-flexible-link")
    logs = tmp / "logs"
    logs.mkdir()
    synthetic_log(
        sc,
        (6, -40, 0.15, 0),
        logs / "a.csv",
        duration=1.5,
        period=1.0,
        amplitude=(0.5, 0.15),
        tip0=0.01,
        seed=0,
    )
    (logs / "broken.csv").write_text("this is not a log\n1,2\n")
    sheet = ",".join(
        str(RIG[k])
        for k in ("drive", "gear_ratio", "motor_constant", "armature_resistance", "link_length")
    )
    m = tmp / "manifest.csv"
    m.write_text(
        "# a small synthetic manifest\n"
        "id,preset,logs,drive,gear_ratio,motor_constant,armature_resistance,link_length,options\n"
        f"good,servo_rig,logs/a.csv,{sheet},{FAST}\n"
        f"bad,servo_rig,logs/broken.csv,{sheet},{FAST}\n"
        f"killer,servo_rig,logs/a.csv,{sheet},{FAST}\n"
    )
    return m


def _killing_fit(row):
    """The row 'killer' kills its own worker process the first time it runs (a marker file
    says it did), then fits as any row."""
    marker = Path(row.logs[0]).parent / "killed-once"
    if row.id == "killer" and not marker.exists():
        marker.write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)
    return fd.fit_row(row)


def _counting_fit(row):
    with open(Path(row.logs[0]).parent / "attempts.txt", "a") as fh:
        fh.write(row.id + "\n")
    return fd.fit_row(row)


def test_read_manifest_resolves_paths_and_names_bad_cells(tmp_path):
    m = _manifest(tmp_path)
    rows = fd.read_manifest(m)
    assert [r.id for r in rows] == ["good", "bad", "killer"]
    assert rows[0].logs == (str((tmp_path / "logs" / "a.csv").resolve()),)
    assert rows[0].data_sheet["gear_ratio"] == 70.0 and rows[0].options["popsize"] == 4
    assert rows[0].options["estimates"] is False
    general = tmp_path / "general.csv"
    general.write_text(
        "id,scenario,logs,free,window\n"
        "g,rotary-flexible-link,logs/a.csv,arm.friction.coulomb;arm.motor.inertia,0:1\n"
    )
    (g,) = fd.read_manifest(general)
    assert g.scenario == "rotary-flexible-link" and g.preset is None and g.window == (0.0, 1.0)
    assert g.free == ("arm.friction.coulomb", "arm.motor.inertia")
    bad = tmp_path / "bad.csv"
    bad.write_text("id,logs,gear_ratio\nx,logs/a.csv,seventy\n")
    with pytest.raises(fd.ManifestError, match=r"row 2, column 'gear_ratio' = 'seventy'"):
        fd.read_manifest(bad)
    bad.write_text("id,logs\nx,logs/missing.csv\n")
    with pytest.raises(fd.ManifestError, match="missing.csv is not a file"):
        fd.read_manifest(bad)
    bad.write_text("id,logs,colour\nx,logs/a.csv,red\n")
    with pytest.raises(fd.ManifestError, match="unknown column"):
        fd.read_manifest(bad)


@needs_dask
@pytest.mark.slow
def test_fit_many_killed_worker_failed_row_and_resume(client, tmp_path):
    m = _manifest(tmp_path)
    out = tmp_path / "fits"
    recs = fd.fit_many(m, client, out, options=fd.FitManyOptions(figures=False, fit=_killing_fit))
    st = {r["id"]: r for r in recs}
    assert (tmp_path / "logs" / "killed-once").exists()  # the worker was killed once
    assert st["good"]["status"] == "done" and st["killer"]["status"] == "done", st
    assert st["bad"]["status"] == "failed" and "broken.csv" in st["bad"]["error"], st["bad"]
    # the killed row's fit equals the other's (same log, same seed: deterministic fit)
    for k in ("arm.motor.inertia", "arm.friction.coulomb", "arm.beam.flexural_rigidity"):
        assert st["killer"][k] == pytest.approx(st["good"][k], rel=1e-9)
    d = json.loads((out / "good" / "fit.json").read_text())
    assert d["flexarm_fit_many"]["status"] == "done" and (out / "good" / "fitted.toml").is_file()
    flexarm.load_scenario(out / "good" / "fitted.toml")
    with open(out / "summary.csv") as fh:
        summary = list(csv.DictReader(fh))
    assert [r["id"] for r in summary] == ["good", "bad", "killer"]
    assert float(summary[0]["arm.motor.inertia"]) == pytest.approx(st["good"]["arm.motor.inertia"])
    assert any(k.startswith("fit%:a.csv:") for k in summary[0])
    # a rerun (in-process) skips the finished rows and tries the failed one again
    again = fd.fit_many(m, None, out, options=fd.FitManyOptions(figures=False, fit=_counting_fit))
    assert (tmp_path / "logs" / "attempts.txt").read_text().split() == ["bad"]
    assert [r["status"] for r in again] == [
        "skipped (finished before)",
        "failed",
        "skipped (finished before)",
    ]
    assert again[0]["arm.motor.inertia"] == st["good"]["arm.motor.inertia"]


def test_fit_many_in_process_without_dask(tmp_path, monkeypatch):
    """client_for says when Dask is missing and fit_many runs the rows in-process; here with
    a fit function that fails every row but one, to check the report without fitting."""
    m = _manifest(tmp_path)
    monkeypatch.setattr(fd, "have_dask", lambda: False)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        client = fd.client_for(workers=2)
    assert client is None and "not installed" in str(w[0].message)
    recs = fd.fit_many(
        m, client, tmp_path / "out", options=fd.FitManyOptions(figures=False, fit=_refuse)
    )
    assert [r["status"] for r in recs] == ["failed"] * 3
    assert recs[0]["error"] == "ValueError: refused good"
    assert (tmp_path / "out" / "good" / "error.txt").read_text().strip() == recs[0]["error"]


def _refuse(row):
    raise ValueError(f"refused {row.id}\nsecond line")


def test_cli_fit_many_reports_a_failed_row_and_exits_1(tmp_path):
    """``flexarm fit-many`` in-process: a row whose log is broken is reported as failed in
    the table and summary.csv (the command exits 1), without a traceback; both
    --scheduler and --workers is one line, exit 2."""
    import csv
    import subprocess
    import sys

    m = _manifest(tmp_path)
    lines = m.read_text().splitlines()
    m.write_text("\n".join([ln for ln in lines if not ln.startswith(("good,", "killer,"))]) + "\n")
    cmd = [
        sys.executable,
        "-m",
        "flexarm",
        "fit-many",
        str(m),
        "--out",
        str(tmp_path / "o"),
        "--no-figures",
    ]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 1, r.stderr
    assert "Traceback" not in r.stdout + r.stderr and "failed" in r.stdout
    rows = list(csv.DictReader(open(tmp_path / "o" / "summary.csv")))
    assert [(x["id"], x["status"]) for x in rows] == [("bad", "failed")]
    r2 = subprocess.run(
        cmd + ["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r2.returncode == 2 and len(r2.stderr.strip().splitlines()) == 1


@pytest.mark.slow  # ~19 s: two CLI designs; the 2-worker batch equality stays fast above
def test_cli_design_on_a_scheduler_equals_in_process(client, tmp_path):
    """`flexarm design ... --scheduler ADDRESS` (the module's LocalCluster of 2 workers):
    the comparison's rows equal those of the in-process run, 1e-12 relative (the plants
    run in chunks with per-chunk seeds: the result does not depend on where they ran);
    --scheduler with --workers is refused in one line."""
    import json

    from typer.testing import CliRunner

    from flexarm.cli import app

    base = [
        "design",
        "rotary-flexible-link",
        "--method",
        "lqr",
        "--spread",
        "arm.motor.inertia=10%,arm.friction.coulomb=20%",
        "--plants",
        "4",
        "--accept-unstable",
    ]
    rows = {}
    for tag, extra in (("local", []), ("dask", ["--scheduler", client.scheduler.address])):
        r = CliRunner().invoke(app, [*base, "--out", str(tmp_path / tag), *extra])
        assert r.exit_code == 0, r.output
        rows[tag] = json.loads((tmp_path / tag / "compare.json").read_text())["rows"]
    assert set(rows["dask"]) == set(rows["local"]) == {"scenario", "lqr"}
    for name, row in rows["local"].items():
        assert row["unstable"] == rows["dask"][name]["unstable"]
        for s in ("nominal", "median", "worst"):
            for k, v in row[s].items():
                assert rows["dask"][name][s][k] == pytest.approx(v, rel=1e-12, nan_ok=True), (
                    name,
                    s,
                    k,
                )
    r = CliRunner().invoke(
        app,
        [
            *base,
            "--out",
            str(tmp_path / "x"),
            "--scheduler",
            client.scheduler.address,
            "--workers",
            "2",
        ],
    )
    assert r.exit_code == 2 and "not both" in r.output

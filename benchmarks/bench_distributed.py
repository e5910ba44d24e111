"""Issue #27: many fits and a large plant batch on Dask, against in-process (not a test).

1. ``fit-many`` on the rotary development runs (examples/rotary-manifest.csv: 14 runs as
   6 fits, the servo-rig fit with the lab's data sheet), in-process and on a LocalCluster
   of 2 spawned workers: wall times side by side, the speed-up, and the largest relative
   difference of a fitted parameter between the two (the fit is deterministic: 0 expected).
2. ``compare`` over N plants (default 10^5) drawn from the fitted unit 6 (its first 5 s),
   chunk by chunk (``PlantSource.from_fit``, seeds per chunk), in-process and on
   LocalCluster(2): wall time, the client's peak memory (RSS above the start, sampled
   every 50 ms), and whether the per-plant metrics are bit-identical. Every process uses
   the persistent compilation cache (a second run loads what the first compiled).

Run: python benchmarks/bench_distributed.py [--rows K] [--plants N] [--chunk C]
     [--option key=value ...] [--skip-fits] [--skip-compare] [--out DIR]
(``--rows``/``--plants``/``--option seconds=2`` give a reduced run on a busy machine.)
"""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "examples" / "rotary-manifest.csv"
DATA = ROOT.parent / "shared" / "data" / "rotary-rig"


class PeakRSS:
    """The process's peak resident memory above its value at the start (psutil, sampled)."""

    def __init__(self, dt: float = 0.05):
        import psutil

        self.p, self.dt, self.peak = psutil.Process(), dt, 0
        self.base = self.p.memory_info().rss
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        while not self._stop.is_set():
            self.peak = max(self.peak, self.p.memory_info().rss - self.base)
            time.sleep(self.dt)

    def __enter__(self):
        self._t.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._t.join()
        self.peak = max(self.peak, self.p.memory_info().rss - self.base)


def bench_fits(rows, out: Path, workers: int) -> dict:
    from flexarm import distributed as fd

    res = {}
    for label, n in (("in-process", None), (f"{workers} workers", workers)):
        d = out / ("fits-" + label.replace(" ", "-"))
        shutil.rmtree(d, ignore_errors=True)
        t0 = time.perf_counter()
        with fd.session(workers=n) as client:
            t1 = time.perf_counter()
            recs = fd.fit_many(rows, client, d, options=fd.FitManyOptions(figures=False))
        res[label] = {"wall_s": time.perf_counter() - t0, "startup_s": t1 - t0, "records": recs}
        print(
            f"fit-many {label}: {res[label]['wall_s']:.1f} s wall "
            f"(cluster start {t1 - t0:.1f} s); "
            + ", ".join(f"{r['id']} {r['status']} {float(r['seconds'] or 0):.1f} s" for r in recs)
        )
    a, b = (res[k]["records"] for k in res)
    # Workers run XLA single-threaded (distributed.worker_environment), the client multi-threaded:
    # sums are ordered differently, and an ill-conditioned fit turns that rounding into a
    # parameter difference. The fit's own determinism is its std: the difference is
    # reported relative to the value and to the std (HAC) of the in-process fit.
    worst, worst_std = 0.0, 0.0
    for ra, rb in zip(a, b, strict=False):
        for k, v in ra.items():
            if k.endswith("_std") or not isinstance(v, float) or k in ("seconds",):
                continue
            w = rb.get(k)
            if isinstance(w, float) and np.isfinite(v) and v != 0:
                worst = max(worst, abs(w - v) / abs(v))
                s = ra.get(k + "_std")
                if isinstance(s, float) and np.isfinite(s) and s > 0:
                    worst_std = max(worst_std, abs(w - v) / s)
    ta, tb = (res[k]["wall_s"] for k in res)
    print(
        f"fit-many: in-process {ta:.1f} s, {workers} workers {tb:.1f} s, speed-up "
        f"{ta / tb:.2f}x; largest parameter difference {worst:.2e} relative, "
        f"{worst_std:.3f} of the fit's std"
    )
    return res


def bench_compare(n: int, chunk: int, workers: int, option: dict) -> dict:
    from flexarm import distributed as fd
    from flexarm.design.compare import compare
    from flexarm.identification.time_domain import load_rig_log
    from flexarm.identification.time_domain.fit import fit

    rows = fd.read_manifest(MANIFEST)
    row = next(r for r in rows if r.id == "unit6-flexible")
    g = load_rig_log(row.logs[0], log_format=row.log_format).window(*row.window)
    t = time.perf_counter()
    res = fit([g], **row.data_sheet, **option)
    print(f"unit 6 fitted in {time.perf_counter() - t:.1f} s")
    src = fd.PlantSource.from_fit(res, n, seed=0)
    opts = fd.ChunkOptions(chunk=chunk)
    out = {}
    for label, w in (("in-process", None), (f"LocalCluster({workers})", workers)):
        with fd.session(workers=w) as client:
            with PeakRSS() as mem:
                t = time.perf_counter()
                c = compare(src, duration=3.0, count=1e-3, client=fd.executor(client), chunks=opts)
                wall = time.perf_counter() - t
        out[label] = {"wall_s": wall, "peak_mb": mem.peak / 2**20, "cmp": c}
        row_ = c.rows["logged controller"]
        print(
            f"compare over {n} plants, chunks of {chunk}, {label}: {wall:.1f} s wall, "
            f"{n / wall:.0f} plants/s, client peak +{mem.peak / 2**20:.0f} MB; unstable "
            f"{row_['unstable']}, median settling {row_['median']['tip_settling_s']:.3g} s"
        )
    a, b = (v["cmp"].per_plant["logged controller"] for v in out.values())
    same = all(
        np.array_equal(np.asarray(a[k], float), np.asarray(b[k], float), equal_nan=True) for k in a
    )
    print(f"per-plant metrics bit-identical in-process vs LocalCluster({workers}): {same}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=None, help="only the first K manifest rows")
    ap.add_argument("--plants", type=int, default=100_000)
    ap.add_argument("--chunk", type=int, default=2000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--option",
        action="append",
        default=[],
        help="a fit keyword for every row, key=value (e.g. seconds=2)",
    )
    ap.add_argument("--skip-fits", action="store_true")
    ap.add_argument("--skip-compare", action="store_true")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    if not DATA.is_dir():
        print(f"skipped: {DATA} not found (../shared is absent)")
        return 0
    from flexarm import distributed as fd

    if not fd.have_dask():
        print(f"skipped: {fd.NO_DASK}")
        return 0
    # the client process uses the persistent compilation cache too (as the CLI does), so
    # in-process and the workers compile on the same terms
    fd.enable_compilation_cache()
    option = dict(x.split("=", 1) for x in a.option)
    option = {k: fd.option_value(v) for k, v in option.items()}
    out = a.out or Path(tempfile.mkdtemp(prefix="bench-distributed-"))
    if not a.skip_fits:
        rows = fd.read_manifest(MANIFEST)[: a.rows]
        rows = [dataclasses.replace(r, options={**r.options, **option}) for r in rows]
        bench_fits(rows, out, a.workers)
    if not a.skip_compare:
        bench_compare(a.plants, a.chunk, a.workers, option)
    return 0


if __name__ == "__main__":
    sys.exit(main())

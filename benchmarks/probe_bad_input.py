"""Issue #45 probe: every bad-input class of the issue through the command line.

Each class runs ``python -m flexarm ...`` in a fresh temporary folder on small synthetic
inputs (CSV, TOML, JSON, ``.mat`` written by scipy.io.savemat) and records the exit code
and the first line of stderr.  A class is

* ``ok``       exit 2 with one ``error:`` line (or, where the class allows it, exit 0 with a
               ``warning:`` line that names the problem);
* ``INTERNAL`` "internal error" (exit 1): the count the issue asks for;
* ``WRONG``    exit 0 without a word about the problem (a wrong answer presented as right),
               or any other outcome.

Run: ``PYTHONPATH=src python benchmarks/probe_bad_input.py [-k WORD] [-j 2]``; prints one
row per class and the counts.  The full disk is simulated by a wrapper that makes the
final rename of the atomic writer fail with ``OSError(ENOSPC)`` (``--full-disk``).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: the flexarm source the probe runs (--src: e.g. an older commit's, for a before/after)
SRC = [str(ROOT / "src")]
LAW = "state_feedback K1=6 K2=-40 K3=0.15 K4=0"
FS = 1000.0
N = 500  # samples per period

# the wrapper for the full-disk class: the writer's rename (and link) onto a target in the
# output folder (the run's out/, $PROBE_FULL) fails as a full disk would
FULL_DISK = r"""
import errno, os, sys
real_link, real_replace = os.link, os.replace
def link(src, dst, *a, **k):
    if str(dst).startswith(os.environ["PROBE_FULL"]):
        raise OSError(errno.ENOSPC, "No space left on device", str(dst))
    return real_link(src, dst, *a, **k)
def replace(src, dst, *a, **k):
    if str(dst).startswith(os.environ["PROBE_FULL"]):
        raise OSError(errno.ENOSPC, "No space left on device", str(dst))
    return real_replace(src, dst, *a, **k)
os.link, os.replace = link, replace
sys.argv = ["flexarm", *sys.argv[1:]]
from flexarm.cli import main
main()
"""


def multisine(n_periods=4, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(N * n_periods) / FS
    k = np.arange(1, 60, 2)
    ph = rng.uniform(0, 2 * np.pi, k.size)
    u = sum(np.cos(2 * np.pi * kk * FS / N * t + p) for kk, p in zip(k, ph, strict=True))
    u = u / np.std(u)
    # a first-order lag, 20 Hz, as the motor angle (periodic steady state: run it twice)
    a = np.exp(-2 * np.pi * 20 / FS)
    y = np.zeros_like(u)
    for _ in range(2):
        y0 = y[-1]
        for i in range(u.size):
            y0 = a * y0 + (1 - a) * u[i]
            y[i] = y0
    return t, u, y


def write_inputs(d: Path) -> None:
    import scipy.io as sio

    t, u, y = multisine()
    rows = "\n".join(f"{a:.6f},{b:.9g},{c:.9g}" for a, b, c in zip(t, u, y, strict=True))
    (d / "ms.csv").write_text("time,current,motor_angle\n" + rows + "\n")
    zero = "\n".join(f"{a:.6f},0,{c:.9g}" for a, c in zip(t, y, strict=True))
    (d / "zero_in.csv").write_text("time,current,motor_angle\n" + zero + "\n")
    dead = "\n".join(f"{a:.6f},{b:.9g},0.25" for a, b in zip(t, u, strict=True))
    (d / "dead_out.csv").write_text("time,current,motor_angle\n" + dead + "\n")
    (d / "big.csv").write_text("time,current,motor_angle\n0,0," + "1" * 5_000_000 + "\n")
    # .mat: time in s, the format says us (the MHz lines)
    sio.savemat(d / "rec_s.mat", {"t": t, "i": u, "th": y})
    sio.savemat(d / "rec_empty.mat", {"t": t, "i": np.zeros((0, 0)), "th": y})
    (d / "us.toml").write_text(
        '[columns]\ntime = "t"\ncurrent = "i"\nmotor_angle = "th"\n[units]\ntime = "us"\n'
    )
    (d / "ms.toml").write_text(
        '[columns]\ntime = "t"\ncurrent = "i"\nmotor_angle = "th"\n[units]\ntime = "ms"\n'
    )
    (d / "plain.toml").write_text('[columns]\ntime = "t"\ncurrent = "i"\nmotor_angle = "th"\n')
    (d / "deep.toml").write_text("a = " + "[" * 3000 + "]" * 3000 + "\n")
    (d / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    (d / "list.json").write_text("[1, 2, 3]")
    (d / "m16.csv").write_text("id,logs\nr1,ms.csv\n", encoding="utf-16")
    mf = "id,logs,motor_constant,armature_resistance\n..,ms.csv,0.01,2\n"
    (d / "dotdot.csv").write_text(mf)
    log = d / "rig.csv"
    log.write_text(f"# controller: {LAW}\ntime,voltage,motor_angle\n0,0,0\n0.001,0,0\n")
    base = (ROOT / "src/flexarm/scenarios/feliu-single-mass.toml").read_text()
    (d / "coulomb.toml").write_text(
        base.replace('coulomb = "0.288288 lbf*in"', 'coulomb = "1e4 N*m"').replace(
            'static = "0.288288 lbf*in"', 'static = "1e4 N*m"'
        )
    )
    (d / "vlimit.toml").write_text(
        base.replace('current_limit = "4.12 A"', 'current_limit = "1e300 A"')
    )
    ragged = base.split("[controller]")[0] + (
        '[controller]\ntype = "lti"\ninputs = ["motor_angle", "tip_angle"]\n'
        'setpoints = ["reference", 0]\noutputs = ["current"]\nD = [[1.0, 2.0], [3.0]]\n'
    )
    (d / "ragged.toml").write_text(ragged)
    (d / "ctl_ragged.toml").write_text(
        '[controller]\ntype = "lti"\ninputs = ["motor_angle", "tip_angle"]\n'
        'setpoints = ["reference", 0]\noutputs = ["current"]\nD = [[1.0, 2.0], [3.0]]\n'
    )
    for name, value in (
        ("name_up", '"../victim"'),
        ("name_abs", '"/tmp/flexarm-probe-victim"'),
        ("name_empty", '""'),
        ("name_long", '"' + "x" * 300 + '"'),
        ("name_nul", '"a\\u0000b"'),
    ):
        (d / f"{name}.toml").write_text(
            base.replace('name = "feliu-single-mass"', f"name = {value}")
        )
    frf = {
        "frequency_hz": [1.0, 2.0, 3.0],
        "input": "current",
        "outputs": {"motor_angle": {"re": [1, 0.5, 0.2], "im": [0, -0.5, -0.4]}},
    }
    (d / "frf_min.json").write_text(json.dumps(frf))


EX = ["--fs", "1000", "--period", "1000", "--f-min", "1", "--f-max", "10"]
DS = ["--motor-constant", "0.01", "--armature-resistance", "2"]
F = ["--log-format"]

# (class, argv, kind); kind: "refuse" (exit 2 wanted), "warn_or_refuse" (a warning with
# exit 0, or exit 2), "full" (the full-disk wrapper: exit 2 naming the rescued copy, which
# must exist), "safe" (exit 0 or 2, files only inside the output folder)
CASES = [
    ("5 MB field in a text log", ["frf", "{d}/big.csv", "--json", "{o}/f.json"], "refuse"),
    (
        "0x0 .mat variable",
        ["frf", "{d}/rec_empty.mat", *F, "{d}/plain.toml", "--json", "{o}/f.json"],
        "refuse",
    ),
    ("deeply nested TOML", ["simulate", "{d}/deep.toml", "--out", "{o}/s"], "refuse"),
    ("deeply nested JSON", ["tfest", "{d}/deep.json", "--json", "{o}/t.json"], "refuse"),
    ("all-zero input channel (frf)", ["frf", "{d}/zero_in.csv", "--json", "{o}/f.json"], "refuse"),
    ("frf --period 0", ["frf", "{d}/ms.csv", "--period", "0", "--json", "{o}/f.json"], "refuse"),
    ("excite --fs 0", ["excite", "{o}/e.csv", *EX, "--fs", "0"], "refuse"),
    (
        "fit --computation-delay -1",
        ["fit", "{d}/rig.csv", *DS, "--computation-delay", "-1"],
        "refuse",
    ),
    (
        "design 1e4 N m Coulomb friction",
        ["design", "{d}/coulomb.toml", "--out", "{o}/d", "--plants", "2"],
        "refuse",
    ),
    (
        "design 1e300 limit",
        ["design", "{d}/vlimit.toml", "--out", "{o}/d", "--plants", "2"],
        "refuse",
    ),
    ("ragged controller D (scenario)", ["info", "{d}/ragged.toml"], "refuse"),
    ("ragged controller D (export-c)", ["export-c", "{d}/ragged.toml", "--out", "{o}/c"], "refuse"),
    (
        "ragged controller D (controller file)",
        [
            "simulate",
            "feliu-single-mass",
            "--out",
            "{o}/s",
            "--log",
            "{d}/ms.csv",
            "--controller",
            "{d}/ctl_ragged.toml",
        ],
        "refuse",
    ),
    ("tfest on a JSON list", ["tfest", "{d}/list.json", "--json", "{o}/t.json"], "refuse"),
    ("UTF-16 manifest", ["fit-many", "{d}/m16.csv", "--out", "{o}/fm"], "refuse"),
    (
        "huge --plants",
        [
            "design",
            "feliu-single-mass",
            "--out",
            "{o}/d",
            "--spread",
            "arm.motor.inertia=10%",
            "--plants",
            "1000000000000",
        ],
        "refuse",
    ),
    ("huge --periods", ["excite", "{o}/e.csv", *EX, "--periods", "1000000000000"], "refuse"),
    (
        ".mat time in s, format says us",
        ["frf", "{d}/rec_s.mat", *F, "{d}/us.toml", "--json", "{o}/f.json"],
        "warn_or_refuse",
    ),
    (
        ".mat time in s, format says ms",
        ["frf", "{d}/rec_s.mat", *F, "{d}/ms.toml", "--json", "{o}/f.json"],
        "warn_or_refuse",
    ),
    ("dead output channel (frf)", ["frf", "{d}/dead_out.csv", "--json", "{o}/f.json"], "refuse"),
    ("excite --rms nan", ["excite", "{o}/e.csv", *EX, "--rms", "nan"], "refuse"),
    ("fit --encoder-counts 0", ["fit", "{d}/rig.csv", *DS, "--encoder-counts", "0"], "refuse"),
    (
        "design --encoder-counts 0",
        ["design", "feliu-single-mass", "--out", "{o}/d", "--encoder-counts", "0"],
        "refuse",
    ),
    (
        "design --plants 0",
        ["design", "feliu-single-mass", "--out", "{o}/d", "--plants", "0"],
        "refuse",
    ),
    ("fit --gear-ratio inf", ["fit", "{d}/rig.csv", *DS, "--gear-ratio", "inf"], "refuse"),
    ("/dev/zero as a log", ["frf", "/dev/zero", "--json", "{o}/f.json"], "refuse"),
    (
        "/dev/zero as a log format",
        ["frf", "{d}/ms.csv", *F, "/dev/zero", "--json", "{o}/f.json"],
        "refuse",
    ),
    ("scenario name ../victim", ["simulate", "{d}/name_up.toml", "--out", "{o}/s"], "safe"),
    ("scenario name absolute", ["simulate", "{d}/name_abs.toml", "--out", "{o}/s"], "safe"),
    ("scenario name empty", ["simulate", "{d}/name_empty.toml", "--out", "{o}/s"], "safe"),
    ("scenario name 300 chars", ["simulate", "{d}/name_long.toml", "--out", "{o}/s"], "safe"),
    ("scenario name NUL", ["simulate", "{d}/name_nul.toml", "--out", "{o}/s"], "safe"),
    ("fit-many id ..", ["fit-many", "{d}/dotdot.csv", "--out", "{o}/fm"], "refuse"),
    (
        "export-c --name injection",
        ["export-c", "feliu-single-mass", "--out", "{o}/c", "--name", "rig */\n#define x"],
        "safe",
    ),
    ("full disk at the final write (excite)", ["excite", "{o}/FULL.csv", *EX], "full"),
    (
        "full disk at the final write (frf --json)",
        ["frf", "{d}/ms.csv", "--json", "{o}/FULL.json"],
        "full",
    ),
    (
        "full disk at the final write (design)",
        ["design", "feliu-single-mass", "--out", "{o}/FULL", "--plants", "2"],
        "full",
    ),
]


def run_case(cls, argv, kind, timeout=600):
    with tempfile.TemporaryDirectory(prefix="probe45-") as tmp:
        d = Path(tmp) / "in"
        o = Path(tmp) / "out"
        d.mkdir()
        o.mkdir()
        write_inputs(d)
        args = [a.replace("{d}", str(d)).replace("{o}", str(o)) for a in argv]
        env = {
            **os.environ,
            "PYTHONPATH": SRC[0],
            "FLEXARM_LOG_DIR": str(Path(tmp) / "logs"),
            "PROBE_FULL": str(o),
        }
        cmd = (
            [sys.executable, "-c", FULL_DISK, *args]
            if kind == "full"
            else [sys.executable, "-m", "flexarm", *args]
        )
        t0 = time.perf_counter()
        try:
            p = subprocess.run(
                cmd, capture_output=True, text=True, env=env, timeout=timeout, cwd=tmp
            )
            rc, err = p.returncode, p.stderr
        except subprocess.TimeoutExpired:
            rc, err = "timeout", ""
        dt = time.perf_counter() - t0
        lines = [ln for ln in err.splitlines() if ln.strip()]
        first = next(
            (ln for ln in lines if ln.startswith(("error", "internal error", "warning"))),
            lines[-1] if lines else "",
        )
        escaped = [p for p in Path(tmp).iterdir() if p.name not in ("in", "out", "logs")]
        victim = Path("/tmp/flexarm-probe-victim")
        rescued = list(Path(tmp).rglob("*rescued*")) + list(
            Path(tempfile.gettempdir()).glob("flexarm-rescued/FULL*")
        )
        if "internal error" in err:
            verdict = "INTERNAL"
        elif kind == "refuse":
            verdict = "ok" if rc == 2 and first.startswith("error:") else "WRONG"
        elif kind == "warn_or_refuse":
            verdict = (
                "ok"
                if (rc == 2 and first.startswith("error:")) or "warning:" in err and "unit" in err
                else "WRONG"
            )
        elif kind == "safe":
            verdict = "ok" if rc in (0, 2) and not escaped and not victim.exists() else "WRONG"
        else:  # full
            verdict = (
                "ok"
                if rc == 2 and rescued and any(r.name in err.replace("\n", "") for r in rescued)
                else "WRONG"
            )
        return cls, rc, first[:150], verdict, dt


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("-k", default=None, help="only the classes whose name contains this")
    ap.add_argument("-j", type=int, default=2)
    ap.add_argument("--json", default=None, help="write the rows here")
    ap.add_argument("--src", default=None, help="the flexarm src folder to run (default ours)")
    a = ap.parse_args()
    if a.src:
        SRC[0] = str(Path(a.src).resolve())
    cases = [c for c in CASES if a.k is None or a.k.lower() in c[0].lower()]
    rows = []
    with cf.ThreadPoolExecutor(a.j) as ex:
        for r in ex.map(lambda c: run_case(*c), cases):
            rows.append(r)
            print(f"{r[3]:8s} rc={r[1]!s:7s} {r[4]:6.1f}s  {r[0]}: {r[2]}", flush=True)
    n_int = sum(r[3] == "INTERNAL" for r in rows)
    n_wrong = sum(r[3] == "WRONG" for r in rows)
    print(
        f"\n{len(rows)} classes: {n_int} internal error, {n_wrong} wrong/other, "
        f"{len(rows) - n_int - n_wrong} ok"
    )
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()

"""Write the notebooks of docs/notebooks/ (plain nbformat 4 JSON) from the cells below:
``python docs/make_notebooks.py`` writes them without outputs; ``--execute`` (``make
notebooks``) runs each in a fresh kernel from the repository root (nbclient, the real-log
cells where the logs are present) and writes it with its outputs, so that GitHub shows the
figures and tables (issue #46). tests/test_docs__notebooks.py executes every notebook and
fails when a notebook's cells differ from what this script writes (outputs aside).

Every notebook runs on the built-in scenarios with short durations; cells that need the
real lab logs run where ``FLEXARM_DATA`` (default ``../shared/data`` beside the repository)
exists and ``FLEXARM_NOTEBOOK_REAL`` is not ``0``, and otherwise print why they are skipped.
"""

from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).resolve().parent / "notebooks"

SETUP = '''\
%matplotlib inline
import os
from pathlib import Path

import numpy as np

import flexarm

# the repository root (the notebook may run from docs/notebooks/ or from the root)
ROOT = next(p for p in [Path.cwd(), *Path.cwd().parents] if (p / "mkdocs.yml").is_file())
DATA = Path(os.environ.get("FLEXARM_DATA", ROOT.parent / "shared" / "data"))
REAL = DATA.is_dir() and os.environ.get("FLEXARM_NOTEBOOK_REAL", "1") != "0"
print("real logs:", DATA if REAL else f"not used ({DATA} absent, or FLEXARM_NOTEBOOK_REAL=0)")


def shorter(scenario, seconds):
    """The scenario with a shorter simulation (seconds)."""
    sim = scenario.simulation.model_copy(update={"duration": seconds})
    return scenario.model_copy(update={"simulation": sim})'''

NOTEBOOKS: dict[str, list[tuple[str, str]]] = {}

NOTEBOOKS["simulate"] = [
    (
        "md",
        "# Simulate an arm\n\nA built-in scenario, its linear model, one closed-loop "
        "simulation and its figure. Every result prints as a short table.",
    ),
    ("code", SETUP),
    ("code", 'sc = shorter(flexarm.load_scenario("feliu-single-mass"), 0.6)\nsc'),
    (
        "md",
        "The linear model: $G_m(s) = \\theta_m / i$ (FRB eq. 12) and "
        "$G_b(s) = \\theta_t / \\theta_m$ (eq. 13), named python-control systems.",
    ),
    (
        "code",
        "model = flexarm.SingleLinkModel.from_spec(sc.arm)\n"
        "G_m, G_b = model.motor_tf(), model.beam_tf()\n"
        "print(G_m.name, G_m.input_labels, '->', G_m.output_labels)\n"
        "print(G_b.name, 'poles (rad/s):', np.round(G_b.poles(), 3))",
    ),
    ("code", "res = flexarm.simulate(sc)\nres"),
    ("code", "fig = res.plot_arm()\nfig"),
    ("md", "Named access to every signal, true and as the sensors read it:"),
    (
        "code",
        "print(f\"tip angle at the end: {res['tip_angle'][-1]:.4f} rad, motor angle read: \"\n"
        "      f\"{res.measured['motor_angle'][-1]:.4f} rad\")",
    ),
]

NOTEBOOKS["reproduce"] = [
    (
        "md",
        "# Reproduce the papers (a short subset)\n\n`flexarm reproduce feliu` and "
        "`flexarm reproduce deluca` run every experiment; here: FRB's Wiener feedforward "
        "and a parabolic move on the single-mass arm, and DLS's regulation under gravity "
        "(eq. 8) on the two-link arm.",
    ),
    ("code", SETUP),
    (
        "md",
        "FRB eq. (11): the ISE-optimal feedforward $N(s)$ for the beam $G_b$ and a "
        "parabolic reference (input $1/s^3$).",
    ),
    (
        "code",
        "import control\n\n"
        'arm = flexarm.load_scenario("feliu-single-mass").arm\n'
        "G_b = flexarm.SingleLinkModel.from_spec(arm).beam_tf()\n"
        's = control.tf("s")\n'
        "N = flexarm.wiener_feedforward(G_b, 1 / s**3)\nN",
    ),
    (
        "code",
        "from matplotlib.figure import Figure\n\n"
        "w = np.logspace(0, 2, 200)\n"
        'fig = Figure(figsize=(6, 3), layout="constrained")\n'
        "ax = fig.subplots()\n"
        'ax.semilogx(w, 20 * np.log10(np.abs(G_b(1j * w))), label="G_b")\n'
        'ax.semilogx(w, 20 * np.log10(np.abs(N(1j * w))), label="N (eq. 11)")\n'
        'ax.set_xlabel("ω (rad/s)")\n'
        'ax.set_ylabel("dB")\n'
        "ax.legend()\n"
        "ax.grid(alpha=0.3)\n"
        "fig",
    ),
    (
        "md",
        "DLS: the two-link arm under gravity, PD with constant gravity compensation "
        "(eq. 8), from hanging down to −45°; the equilibrium deflection (eq. 9) and the "
        "sufficient conditions (14)–(15).",
    ),
    (
        "code",
        "from flexarm.control import regulation as R\n"
        "from flexarm.sim.continuous import simulate_continuous\n"
        "from flexarm.specs.multilink import benchmark_arm\n\n"
        "model = flexarm.build_multilink(benchmark_arm())\n"
        "theta_d = np.radians([-45.0, 0.0])\n"
        "p = R.regulation_params(model, np.diag([18, 18]), np.diag([10, 2]), theta_d)\n"
        'print("δ_d =", np.round(np.asarray(p.delta_d), 5))\n'
        "print(R.stability_conditions(model, np.diag([18, 18]), 17.67).summary())",
    ),
    (
        "code",
        "run = simulate_continuous(model, R.law_pd_constant,\n"
        "                          model.state(theta=np.radians([-90, 0])), 1.0, 5e-3,\n"
        "                          params=p)\nrun",
    ),
    (
        "code",
        'fig = Figure(figsize=(6, 3), layout="constrained")\n'
        "ax = fig.subplots()\n"
        "ax.plot(run.time, np.degrees(run.theta))\n"
        'ax.axhline(-45, color="k", lw=0.5)\n'
        'ax.set_xlabel("time (s)")\n'
        'ax.set_ylabel("joint angle (deg)")\n'
        "ax.grid(alpha=0.3)\n"
        "fig",
    ),
]

NOTEBOOKS["fit-rotary-rig"] = [
    (
        "md",
        "# Fit a rotary rig\n\nA simulated run of the built-in rotary servo rig "
        "(`rotary-flexible-link`: sensor noise and quantisation, the sampled state "
        "feedback, the voltage limit) is fitted from a template whose friction and hub "
        "inertia are off by 30 %; then, where the lab's logs are present, the rig's own "
        "log with the data-sheet pipeline.\n\n"
        "Both go through the one fit, `flexarm.fit(scenario_or_preset, logs, free, "
        "options)`: the simulated run with a scenario template and a free list, the real "
        "rig with the servo-rig preset built from its data sheet "
        "(`presets.servo_rig(DataSheet(...))`).",
    ),
    ("code", SETUP),
    (
        "code",
        "from flexarm.identification.time_domain.general import scenario_with\n"
        "from flexarm.identification.time_domain.options import FitOptions, Local\n"
        "from flexarm.identification.time_domain.synthetic import scenario_log\n\n"
        'truth = shorter(flexarm.load_scenario("rotary-flexible-link"), 3.0)\n'
        "n = round(truth.simulation.duration / truth.sampling.period) + 1  # samples\n"
        "t = np.arange(n) * truth.sampling.period\n"
        "ref = 0.4 * np.sign(np.sin(2 * np.pi * 0.5 * t))       # ±0.4 rad steps\n"
        'log = scenario_log(truth, {"reference": ref}, seed=1)\n'
        'free = ["arm.friction.coulomb", "arm.motor.inertia"]\n'
        'true = {"arm.friction.coulomb": truth.arm.friction.coulomb,\n'
        '        "arm.motor.inertia": truth.arm.motor.inertia}\n'
        "template = scenario_with(truth, {k: 1.3 * v for k, v in true.items()})",
    ),
    (
        "code",
        "res = flexarm.fit(template, [log], free=free,\n"
        "                  options=FitOptions(local=Local(max_nfev=20)))\n"
        "for k, v in true.items():\n"
        '    print(f"{k}: fitted {res.params[k]:.4g} ± {res.std[k]:.2g}, true {v:.4g}")',
    ),
    ("md", "The fit's whole-run prediction of the log (`res.prediction`), with its fit %:"),
    (
        "code",
        "from matplotlib.figure import Figure\n\n"
        'tr = next(iter(res.prediction["trajectories"].values()))\n'
        "print(res.fit_percent)\n"
        'fig = Figure(figsize=(7, 4), layout="constrained")\n'
        'axes = fig.subplots(len(tr["simulated"]), 1, sharex=True, squeeze=False)[:, 0]\n'
        'for ax, (name, y) in zip(axes, tr["simulated"].items(), strict=True):\n'
        '    ax.plot(tr["time"], tr["measured"][name], ".", ms=1, label="log")\n'
        '    ax.plot(tr["time"], y, label="fitted model")\n'
        "    ax.set_ylabel(name)\n"
        "axes[0].legend()\n"
        'axes[-1].set_xlabel("time (s)")\n'
        "fig",
    ),
    ("md", "## The real rig (where the lab's logs are present)"),
    (
        "code",
        "if not REAL:\n"
        '    print("skipped: the real rotary-rig logs are not used here")\n'
        "else:\n"
        "    from flexarm.identification.time_domain.presets import DataSheet, servo_rig\n\n"
        '    real = flexarm.load_log(DATA / "rotary-rig" / "4PM_Group37_FlexArm_Unit6",\n'
        '                            ROOT / "examples" / "quanser-rotflex.toml")\n'
        '    rig = servo_rig(DataSheet(drive="voltage", gear_ratio=48.4, motor_constant=0.0107,\n'
        "                              armature_resistance=3.29, link_length=0.45))\n"
        "    fit = flexarm.fit(rig, [real.window(0, 5)])\n"
        "    print(fit)",
    ),
]

NOTEBOOKS["fit-two-link-rig"] = [
    (
        "md",
        "# Fit a two-link rig\n\nThe built-in `quanser-two-link` scenario (the rig's data "
        "sheet: torsional links, current drives, joint stiction, the lab's LQR) simulated "
        "for two seconds, then the shoulder's Coulomb friction fitted back from a template "
        "20 % off, on segments started from the logged state (multiple shooting). Where "
        "the lab's workspace is present, the same fit on its first 20 s.\n\n"
        "API: `flexarm.fit(scenario, logs, free, options)` (the one fit engine), "
        "`flexarm.validate`, `flexarm.load_log`, grouped options "
        "`FitOptions(shooting=Shooting(segment=...))`; `FitOptions(plots=folder)` draws "
        "the fit's prediction, `FitOptions(delay_search=DelaySearch())` searches the "
        "sensors' delays.",
    ),
    ("code", SETUP),
    (
        "code",
        "from flexarm.identification.time_domain.general import scenario_with\n"
        "from flexarm.identification.time_domain.options import FitOptions, Local, Shooting\n"
        "from flexarm.identification.time_domain.synthetic import scenario_log\n\n"
        'truth = shorter(flexarm.load_scenario("quanser-two-link"), 2.0)\n'
        "truth",
    ),
    (
        "code",
        "log = scenario_log(truth, seed=2)\n"
        'free = ["arm.joints[0].friction.coulomb"]\n'
        'true = {free[0]: truth.model_dump()["arm"]["joints"][0]["friction"]["coulomb"]}\n'
        "template = scenario_with(truth, {p: 1.2 * v for p, v in true.items()})\n"
        "res = flexarm.fit(template, [log], free=free,\n"
        "                  options=FitOptions(shooting=Shooting(segment=1.0),\n"
        "                                     local=Local(max_nfev=6)))\n"
        'print(f"{free[0]}: fitted {res.params[free[0]]:.4g} ± {res.std[free[0]]:.2g}, "\n'
        '      f"true {true[free[0]]:.4g}")',
    ),
    (
        "code",
        "from matplotlib.figure import Figure\n\n"
        'tr = next(iter(res.prediction["trajectories"].values()))\n'
        'names = [n for n in ("theta_1", "theta_2") if n in tr["simulated"]]\n'
        'fig = Figure(figsize=(7, 4), layout="constrained")\n'
        "axes = fig.subplots(len(names), 1, sharex=True, squeeze=False)[:, 0]\n"
        "for ax, name in zip(axes, names, strict=True):\n"
        '    ax.plot(tr["time"], tr["measured"][name], ".", ms=1, label="log")\n'
        '    ax.plot(tr["time"], tr["simulated"][name], label="fitted model")\n'
        '    ax.set_ylabel(f"{name} (rad)")\n'
        "axes[0].legend()\n"
        'axes[-1].set_xlabel("time (s)")\n'
        "fig",
    ),
    ("md", "## The real rig (where the lab's workspace is present)"),
    (
        "code",
        "if not REAL:\n"
        '    print("skipped: the real two-link logs are not used here")\n'
        "else:\n"
        '    real = flexarm.load_log(DATA / "two-link-rig" / "lqr_full_10deg.mat",\n'
        '                            ROOT / "examples" / "two-link-workspace.toml")\n'
        '    fit = flexarm.fit("quanser-two-link", [real.window(0.0, 20.0)],\n'
        '                      free=["arm.joints[*].friction.coulomb"],\n'
        "                      options=FitOptions(shooting=Shooting(segment=3.0),\n"
        "                                         local=Local(max_nfev=10)))\n"
        "    print(fit.params)\n"
        '    print(flexarm.validate(fit.scenario, [real.window(50.0, 70.0)])["fit_percent"])',
    ),
]

NOTEBOOKS["frequency-domain"] = [
    (
        "md",
        "# Frequency-domain identification\n\nA random-odd multisine through a known "
        "lightly damped system with output noise: the FRF with its noise level and "
        "distortion check, a transfer function fitted by maximum likelihood, and both as "
        "Bode figures (magnitude, phase, ±2σ band, fit). Where the lab's motor-bench "
        "recording is present, its FRF too.",
    ),
    ("code", SETUP),
    (
        "code",
        "from flexarm.identification.frequency_domain.excitation import multisine\n"
        "from flexarm.identification.frequency_domain.periodic import periodic_frf, plot_bode\n"
        "from flexarm.identification.frequency_domain.tfest import plot_fit, tfest\n\n"
        "FS, P = 1000.0, 500\n\n\n"
        "def G(f):\n"
        '    """A resonance at 60 Hz and an antiresonance at 40 Hz, unit static gain."""\n'
        "    s = 2j * np.pi * f\n"
        "    w1, w2 = 2 * np.pi * 40, 2 * np.pi * 60\n"
        "    num = (s**2 + 0.1 * w1 * s + w1**2) / w1**2\n"
        "    return num / (s**2 + 0.05 * w2 * s + w2**2) * w2**2\n\n\n"
        'e = multisine(P, FS, 10, 200, kind="random-odd", periods=8, seed=1)\n'
        "u = e.signal[0]\n"
        "U = np.fft.rfft(u[:P])\n"
        "f = np.arange(len(U)) * FS / P\n"
        "y = np.tile(np.fft.irfft(U * G(np.maximum(f, 1e-9)), P), len(u) // P)\n"
        "y = y + 0.01 * np.random.default_rng(0).standard_normal(len(y))\n"
        'frf = periodic_frf(u, {"y": y}, FS, period=P, lines=e.excited, input_name="u")\n'
        "frf",
    ),
    ("code", "plot_bode(frf)"),
    (
        "code",
        "import control\n\n"
        "fit = tfest(control.frd(frf.response[0], 2 * np.pi * frf.frequency_hz), 2, 2,\n"
        "            std=frf.noise_std[0])\nfit",
    ),
    ("code", 'plot_fit(fit, frf.frequency_hz, {"y": frf.response[0]}, {"y": frf.noise_std[0]})'),
    ("md", "## The motor bench (where the lab's recording is present)"),
    (
        "code",
        "if not REAL:\n"
        '    print("skipped: the motor-bench recording is not used here")\n'
        "else:\n"
        "    from flexarm.io.logformat import read_recording\n\n"
        '    sig, fs = read_recording(DATA / "motor-bench" / "MultisineTypeB.mat",\n'
        '                             ROOT / "examples" / "motor-bench.toml")\n'
        '    outs = {n: sig[n] for n in ("motor_angle", "load_angle")}\n'
        '    bench = periodic_frf(sig["current"], outs, fs, input_name="current",\n'
        '                         source="MultisineTypeB.mat")\n'
        "    display(bench)\n"
        "    display(plot_bode(bench))",
    ),
]

NOTEBOOKS["design-export"] = [
    (
        "md",
        "# Design and export a controller\n\nAn LQR state feedback with a Kalman "
        "predictor for the built-in rotary servo rig (its delays, friction, encoder and "
        "voltage limit in the design model), compared with the rig's own controller on a "
        "step, then written as C99.",
    ),
    ("code", SETUP),
    (
        "code",
        'd = flexarm.design("rotary-flexible-link", "lqr")\n'
        'print(type(d).__name__, "warnings:", d.warnings)',
    ),
    (
        "code",
        'rig = flexarm.load_scenario("rotary-flexible-link")\n'
        "ours = flexarm.simulate(shorter(d.scenario, 3.0))\n"
        "theirs = flexarm.simulate(shorter(rig, 3.0))\n"
        "from matplotlib.figure import Figure\n\n"
        'fig = Figure(figsize=(7, 3), layout="constrained")\n'
        "ax = fig.subplots()\n"
        'ax.plot(theirs.time, theirs["tip_angle"], label="the rig\'s state feedback")\n'
        'ax.plot(ours.time, ours["tip_angle"], label="lqr")\n'
        'ax.plot(ours.time, ours["reference"], "k--", lw=0.8, label="reference")\n'
        'ax.set_xlabel("time (s)")\n'
        'ax.set_ylabel("tip angle (rad)")\n'
        "ax.legend()\n"
        "fig",
    ),
    (
        "code",
        "import tempfile\n\n"
        "from flexarm.deploy import export_c\n\n"
        "target = Path(tempfile.mkdtemp())\n"
        'code, paths = export_c(d, target, name="rig")\n'
        "print([p.name for p in paths])\n"
        'print("\\n".join((target / "rig.h").read_text().splitlines()[:25]))',
    ),
]


def notebook(name: str, cells: list[tuple[str, str]]) -> dict:
    """nbformat 4.5 JSON without outputs; cell ids ``NAME-K``."""
    out = []
    for k, (kind, src) in enumerate(cells):
        lines = src.splitlines(keepends=True)
        cid = f"{name}-{k}"
        if kind == "md":
            out.append({"cell_type": "markdown", "id": cid, "metadata": {}, "source": lines})
        else:
            out.append(
                {
                    "cell_type": "code",
                    "execution_count": None,
                    "id": cid,
                    "metadata": {},
                    "outputs": [],
                    "source": lines,
                }
            )
    return {
        "cells": out,
        "metadata": {
            "kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"},
            "language_info": {"name": "python"},
        },
        "nbformat": 4,
        "nbformat_minor": 5,
    }


def text(name: str) -> str:
    return json.dumps(notebook(name, NOTEBOOKS[name]), indent=1, ensure_ascii=False) + "\n"


def stripped(text_: str) -> str:
    """A notebook's JSON text as :func:`text` writes it: outputs, execution counts, cell
    and notebook metadata dropped (what an executed notebook shares with its source)."""
    nb = json.loads(text_)
    cells = []
    for c in nb["cells"]:
        src = c["source"]
        lines = src.splitlines(keepends=True) if isinstance(src, str) else src
        cells.append(("code" if c["cell_type"] == "code" else "md", "".join(lines)))
    ids = [c.get("id", "") for c in nb["cells"]]
    out = notebook("", cells)
    for c, cid in zip(out["cells"], ids, strict=True):
        c["id"] = cid
    return json.dumps(out, indent=1, ensure_ascii=False) + "\n"


def _clean(nb: dict, root: Path) -> dict:
    """An executed notebook without what differs from machine to machine: the cells'
    execution timestamps, the kernel's version details, and the absolute paths in printed
    text: the repository's made relative to it (``/home/u/flexarm/src/...`` → ``src/...``),
    the folder above it's to ``..`` (``/home/u/shared/data`` → ``../shared/data``), and the
    kernel's file of a cell in a warning's location (``/tmp/ipykernel_20977/2474714312.py:9``)
    as ``<cell>:9``."""
    import re

    here, above = (str(p).rstrip("/") + "/" for p in (root, root.parent))

    def rel(t: str) -> str:
        t = re.sub(r"[^\s\"']*/ipykernel_\d+/\d+\.py", "<cell>", t)
        return t.replace(here, "").replace(above, "../")

    for c in nb["cells"]:
        c.get("metadata", {}).pop("execution", None)
        for o in c.get("outputs", []):
            if "text" in o:
                t = o["text"] if isinstance(o["text"], str) else "".join(o["text"])
                o["text"] = rel(t)
            for mime in ("text/plain", "text/html", "text/markdown"):
                d = o.get("data", {}).get(mime)
                if d is not None:
                    d = d if isinstance(d, str) else "".join(d)
                    o["data"][mime] = rel(d)
    nb["metadata"] = notebook("", [])["metadata"]
    return nb


def execute(name: str, *, real: bool = True, timeout: int = 900) -> tuple[str, float]:
    """Notebook ``name`` (from :data:`NOTEBOOKS`) run in a fresh ``python3`` kernel from the
    repository root, with ``src`` first on its path and the real-log cells on where
    ``real`` and the logs are present: (its JSON text with outputs, seconds)."""
    import os
    import time

    import nbclient
    import nbformat

    root = HERE.parent.parent
    nb = nbformat.reads(text(name), as_version=4)
    keep = {k: os.environ.get(k) for k in ("FLEXARM_NOTEBOOK_REAL", "PYTHONPATH")}
    os.environ["FLEXARM_NOTEBOOK_REAL"] = "1" if real else "0"
    os.environ["PYTHONPATH"] = os.pathsep.join(
        [str(root / "src"), *[p for p in (keep["PYTHONPATH"] or "").split(os.pathsep) if p]]
    )
    t0 = time.perf_counter()
    try:
        nbclient.NotebookClient(
            nb, timeout=timeout, kernel_name="python3", resources={"metadata": {"path": str(root)}}
        ).execute()
    finally:
        for k, v in keep.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    seconds = time.perf_counter() - t0
    return json.dumps(_clean(nb, root), indent=1, ensure_ascii=False) + "\n", seconds


def main(argv: list[str] | None = None) -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--execute", action="store_true", help="run each and keep its outputs")
    ap.add_argument("names", nargs="*", help="notebooks (default: all)")
    args = ap.parse_args(argv)
    HERE.mkdir(exist_ok=True)
    for name in args.names or list(NOTEBOOKS):
        if name not in NOTEBOOKS:
            ap.error(f"{name!r}: no such notebook; known: {', '.join(NOTEBOOKS)}")
        if not args.execute:
            (HERE / f"{name}.ipynb").write_text(text(name))
            continue
        out, seconds = execute(name)
        (HERE / f"{name}.ipynb").write_text(out)
        print(f"{name}: executed in {seconds:.0f} s, {len(out.encode()) / 1e6:.2f} MB")


if __name__ == "__main__":
    main()

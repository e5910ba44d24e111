"""The notebooks of docs/notebooks/: committed with the cells docs/make_notebooks.py writes
and the outputs of its ``--execute`` run (``make notebooks``: GitHub shows the figures, issue
#46), and executed here (nbclient), each drawing its figures. The fast run uses the
built-in scenarios only (FLEXARM_NOTEBOOK_REAL=0: the real-log cells print why they skip);
the slow ``rig`` run executes the real-log cells where FLEXARM_DATA is present."""

from __future__ import annotations

import importlib.util
import os
import time
from html.parser import HTMLParser

import numpy as np
import pytest

from conftest import DATA, ROOT

nbformat = pytest.importorskip("nbformat", reason="the docs extra is not installed")
nbclient = pytest.importorskip("nbclient", reason="the docs extra is not installed")

NB_DIR = ROOT / "docs" / "notebooks"
_spec = importlib.util.spec_from_file_location(
    "make_notebooks", ROOT / "docs" / "make_notebooks.py"
)
make_notebooks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_notebooks)
NAMES = sorted(make_notebooks.NOTEBOOKS)
#: notebooks with cells on the real logs
REAL = ["fit-rotary-rig", "fit-two-link-rig", "frequency-domain"]


def test_notebooks_are_generated_and_committed_with_outputs():
    assert sorted(p.stem for p in NB_DIR.glob("*.ipynb")) == NAMES
    for name in NAMES:
        text = (NB_DIR / f"{name}.ipynb").read_text()
        assert make_notebooks.stripped(text) == make_notebooks.text(name), (
            f"docs/notebooks/{name}.ipynb differs from what docs/make_notebooks.py writes; "
            "run make notebooks (python docs/make_notebooks.py --execute)"
        )
        nb = nbformat.reads(text, as_version=4)
        nbformat.validate(nb)
        # rendered where GitHub shows them: every code cell ran, in order, without an
        # error, at least one figure; no absolute path of the machine that ran it
        code = [c for c in nb.cells if c.cell_type == "code"]
        assert [c.execution_count for c in code] == list(range(1, len(code) + 1)), name
        assert not any(o.output_type == "error" for c in code for o in c.outputs), name
        assert outputs(nb, "image/png"), f"{name}: no figure committed"
        above = str(ROOT.parent).rstrip("/") + "/"
        assert str(ROOT) not in text and (above == "/" or above not in text), name
        assert len(text.encode()) < 1.5e6, f"{name}: {len(text.encode()) / 1e6:.2f} MB"


def test_cleaning_makes_printed_paths_machine_independent(tmp_path):
    """An executed notebook's printed paths, as ``make notebooks`` commits them: the
    repository's relative, the folder above it as ``..``, and the kernel's file of a cell
    in a warning's location (a temporary folder: ``/tmp/ipykernel_20977/2474714312.py:9``)
    as ``<cell>:9``, so that no clone's own folder shows in the committed outputs."""
    root = tmp_path / "flexarm"
    text = (
        f"{root}/src/flexarm/io/logs.py:3: W\n{tmp_path}/shared/data/x.mat\n"
        "/tmp/ipykernel_20977/2474714312.py:9: IdentificationWarning: w\n"
    )
    nb = {"cells": [{"metadata": {}, "outputs": [{"name": "stderr", "text": text}]}]}
    out = make_notebooks._clean(nb, root)["cells"][0]["outputs"][0]["text"]
    assert out == (
        "src/flexarm/io/logs.py:3: W\n../shared/data/x.mat\n<cell>:9: IdentificationWarning: w\n"
    )


def test_stripping_an_executed_notebook_gives_its_source():
    """What the comparison above relies on: outputs, counts and metadata are all that
    ``stripped`` drops; a changed source line is still a difference."""
    name = NAMES[0]
    src = make_notebooks.text(name)
    nb = nbformat.reads(src, as_version=4)
    code = next(c for c in nb.cells if c.cell_type == "code")
    code.execution_count = 1
    code.outputs = [nbformat.v4.new_output("stream", name="stdout", text="x\n")]
    code.metadata["execution"] = {"iopub.status.idle": "2026-01-01T00:00:00Z"}
    nb.metadata["language_info"]["version"] = "3.11.9"
    assert make_notebooks.stripped(nbformat.writes(nb)) == src
    code.source += "\n# changed"
    assert make_notebooks.stripped(nbformat.writes(nb)) != src


def execute(name: str, monkeypatch, real: bool):
    """Run the notebook in a fresh kernel from the repository root; (notebook, seconds)."""
    monkeypatch.setenv("FLEXARM_NOTEBOOK_REAL", "1" if real else "0")
    monkeypatch.setenv("FLEXARM_DATA", str(DATA))
    src = str(ROOT / "src")
    monkeypatch.setenv(
        "PYTHONPATH",
        os.pathsep.join(
            [src] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
        ),
    )
    nb = nbformat.read(NB_DIR / f"{name}.ipynb", as_version=4)
    t0 = time.perf_counter()
    nbclient.NotebookClient(
        nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(ROOT)}}
    ).execute()
    return nb, time.perf_counter() - t0


def outputs(nb, mime: str) -> list[str]:
    return [
        o["data"][mime]
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.outputs
        if mime in o.get("data", {})
    ]


def printed(nb) -> str:
    return "".join(
        o.get("text", "")
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.outputs
        if o.get("output_type") == "stream"
    )


class _Rows(HTMLParser):
    def __init__(self):
        super().__init__()
        self.rows, self._cell = [], None

    def handle_starttag(self, tag, attrs):
        if tag == "tr":
            self.rows.append([])
        elif tag in ("td", "th"):
            self._cell = ""

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.rows[-1].append(self._cell)
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data


#: the notebook whose built-in run is a whole two-link fit (about a minute on 2 cores): a
#: long end-to-end test, run by `make test` with the slow ones
LONG = {"fit-two-link-rig"}


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=pytest.mark.slow) if n in LONG else n for n in NAMES]
)
def test_notebook_runs(name, monkeypatch):
    nb, seconds = execute(name, monkeypatch, real=False)
    print(f"{name}: executed in {seconds:.1f} s")
    assert outputs(nb, "image/png"), f"{name} drew no figure"
    if name in REAL:
        assert "skipped:" in printed(nb)
    if name == "frequency-domain":
        # the fit result renders as one HTML table; its denominator is the system's,
        # s² + 0.05 ω₂ s + ω₂² with ω₂ = 2π·60 rad/s: a0 = ω₂², a1 = 0.05 ω₂ (the noise,
        # 1 % of the output's rms, moves them by less than 0.1 %, the tolerance 1 %)
        fit_html = [h for h in outputs(nb, "text/html") if "TFEstimate" in h]
        assert len(fit_html) == 1
        p = _Rows()
        p.feed(fit_html[0])
        rows = {r[0]: r[1:] for r in p.rows if r}
        assert rows["parameter"] == ["value", "std"]
        w2 = 2 * np.pi * 60
        assert float(rows["a0"][0]) == pytest.approx(w2**2, rel=0.01)
        assert float(rows["a1"][0]) == pytest.approx(0.05 * w2, rel=0.01)


@pytest.mark.slow
@pytest.mark.rig
@pytest.mark.parametrize("name", REAL)
def test_notebook_on_real_logs(name, monkeypatch):
    if not DATA.is_dir():
        pytest.skip(f"real lab logs not found at {DATA} (set FLEXARM_DATA)")
    nb, seconds = execute(name, monkeypatch, real=True)
    print(f"{name} on the real logs: executed in {seconds:.1f} s")
    assert "skipped:" not in printed(nb)
    assert outputs(nb, "image/png")

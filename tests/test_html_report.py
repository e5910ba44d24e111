"""The HTML report (analysis/html_report.py) of fit, validate and design results: one
self-contained file, its tables against the results' own numbers, ``--report`` on the CLI
(no overwrite without --overwrite), and the page rendered in a real headless Chromium:
every figure loaded and drawn, the page not blank.

The browser check (``_render``): a copy of the report with a probe script appended (the
report itself has no script) is loaded with ``--dump-dom``; the probe writes, for every
``<img>``, ``complete && naturalWidth > 0`` and its box on the page into the DOM. The
report itself (no script) is then screenshot at device scale 1 with the window as tall as
the page, and each figure's box is cut out of the screenshot. The "ink" of an image is
its fraction of non-white pixels (min channel < 235). Thresholds:

* the page: ink > 1 % (a blank page has 0 %; our reports measure 10-14 %);
* each figure: the ink of its box in the screenshot within 10 % of the ink of the PNG
  embedded in the page (decoded here in Python). A figure drawn at its natural size is
  the same pixels (measured: identical), and a one-pixel offset of the box from
  sub-pixel layout moves the ink fraction by about one border row or column out of
  600 (< 1 %); a broken image draws an icon of a few hundred pixels (ink < 1 % of a
  figure's 6 %) and an image not drawn draws nothing.
"""

from __future__ import annotations

import base64
import html
import io
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from flexarm.analysis.html_report import HtmlReport, design_report, figure_data_uri, fit_report
from flexarm.cli import app

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "rotary-rig"
runner = CliRunner()


# ----------------------------------------------------------------------------- browser
def _chromium() -> str | None:
    for name in (
        os.environ.get("FLEXARM_CHROMIUM"),
        "chromium",
        "chromium-browser",
        "google-chrome",
        "google-chrome-stable",
    ):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


needs_browser = pytest.mark.skipif(
    _chromium() is None,
    reason="no headless Chromium found (Debian/Ubuntu: apt-get install chromium; `make test` "
    "installs it when CI=true and it runs as root; or set FLEXARM_CHROMIUM to the "
    "browser's path)",
)

_PROBE = """<script>addEventListener('load', () => {
const r = [...document.images].map(i => {const b = i.getBoundingClientRect();
 return {id: i.id, ok: i.complete && i.naturalWidth > 0, w: i.naturalWidth, h: i.naturalHeight,
         x: b.left + scrollX, y: b.top + scrollY, bw: b.width, bh: b.height};});
const p = document.createElement('pre'); p.id = 'img-check';
p.textContent = JSON.stringify({images: r, height: document.documentElement.scrollHeight});
document.body.appendChild(p);});</script>"""


def _ink(img) -> float:
    a = np.asarray(img.convert("RGB"), dtype=int)
    return float(np.mean(a.min(axis=2) < 235))


def _render(page: Path, tmp: Path):
    """(probe result, screenshot as a PIL image) of ``page`` in headless Chromium."""
    from PIL import Image

    probe = tmp / "probe.html"
    probe.write_text(
        page.read_text(encoding="utf-8").replace("</body>", _PROBE + "</body>"), encoding="utf-8"
    )
    base = [
        _chromium(),
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--hide-scrollbars",
        "--force-device-scale-factor=1",
        f"--user-data-dir={tmp / 'profile'}",
    ]
    dom = subprocess.run(
        base
        + ["--virtual-time-budget=10000", "--window-size=1200,1000", "--dump-dom", probe.as_uri()],
        capture_output=True,
        text=True,
        timeout=120,
    )
    m = re.search(r'<pre id="img-check">(.*?)</pre>', dom.stdout, re.S)
    assert m, f"the probe did not run in Chromium: {dom.stderr[-2000:]}"
    info = json.loads(html.unescape(m.group(1)))
    shot = tmp / "shot.png"
    subprocess.run(
        base
        + [f"--window-size=1200,{info['height']}", f"--screenshot={shot}", page.resolve().as_uri()],
        capture_output=True,
        timeout=120,
    )
    assert shot.is_file(), f"Chromium wrote no screenshot of {page}"
    return info, Image.open(shot)


def _check_in_browser(page: Path, tmp: Path, n_figures: int) -> None:
    """Every embedded figure loaded and drawn where the page puts it; the page not blank."""
    from PIL import Image

    text = page.read_text(encoding="utf-8")
    srcs = re.findall(r'<img src="data:image/png;base64,([^"]+)"', text)
    assert len(srcs) == n_figures
    info, shot = _render(page, tmp)
    assert len(info["images"]) == n_figures
    assert _ink(shot) > 0.01, "the screenshot is blank"
    for s, im in zip(srcs, info["images"], strict=True):
        src = Image.open(io.BytesIO(base64.b64decode(s)))
        assert im["ok"] and (im["w"], im["h"]) == src.size, im
        x, y = round(im["x"]), round(im["y"])
        box = shot.crop((x, y, x + round(im["bw"]), y + round(im["bh"])))
        assert _ink(src) > 0.01  # the figure itself is drawn (curves, axes, text)
        assert _ink(box) == pytest.approx(_ink(src), rel=0.10), (im, _ink(box), _ink(src))


# ----------------------------------------------------------------------------- the builder
def _figure():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4, 3), dpi=80)
    ax.plot(np.linspace(0, 1, 50), np.sin(np.linspace(0, 6, 50)))
    return fig


def test_report_is_self_contained_escaped_and_its_tables_hold_the_numbers(tmp_path):
    fig = _figure()
    rep = HtmlReport(
        "t <1>",
        command="flexarm fit 'a b.csv'",
        inputs=["/x/a b.csv"],
        warnings=["<script>alert(1)</script> fit 12.0 % is low"],
    )
    rep.parameters(
        [("J", 2.0e-3, 1.0e-4, "kg*m**2"), ("c", 0.5, 0.4, "N*m"), ("d", 1.0, float("nan"), "")]
    )
    rep.fit_percent({"/x/a.csv": {"motor_angle": 97.34, "tip_deflection": 12.0}}, "fit")
    rep.figures([fig], ["overlay"])
    page = rep.write(tmp_path / "r.html")
    text = page.read_text()
    # nothing outside the file: every src/href is a data URI, no script, no style sheet link
    refs = re.findall(r'(?:src|href)="([^"]*)"', text)
    assert refs and all(r.startswith("data:image/png;base64,") for r in refs)
    assert "<script" not in text and "<link" not in text and "http" not in text
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in text and "t &lt;1&gt;" in text
    # the embedded figure is the Figure's PNG (base64 round trip, exact)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    assert base64.b64decode(refs[0].split(",", 1)[1]) == buf.getvalue()
    # value ± std, relative std 100 σ/|v| (5 % and 80 %: exact arithmetic, 3 digits shown);
    # 80 % > 50 % is marked as poorly determined, fit 12.0 < 80 % as low, NaN std as –
    rows = re.findall(r"<tr>(.*?)</tr>", text)
    cells = [re.findall(r"<td[^>]*>(.*?)</td>", r) for r in rows]
    j = next(c for c in cells if c and c[0] == "J")
    assert j[1:] == ["0.002", "0.0001", "kg*m**2", "5"]
    c = next(r for r in rows if "<td>c</td>" in r)
    assert '<td class="num low">80</td>' in c
    assert next(c for c in cells if c and c[0] == "d")[2] == "–"
    assert '<td class="num low">12.0</td>' in text and '<td class="num">97.3</td>' in text
    with pytest.raises(FileExistsError, match="r.html: exists already"):
        rep.write(page)
    assert rep.write(page, overwrite=True) == page


def test_figures_that_cannot_be_embedded_are_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.png: no such file"):
        figure_data_uri(tmp_path / "nope.png")
    (tmp_path / "f.pdf").write_bytes(b"%PDF")
    with pytest.raises(ValueError, match=r"f.pdf: a \.pdf file cannot be embedded"):
        figure_data_uri(tmp_path / "f.pdf")
    with pytest.raises(TypeError, match="cannot embed a dict"):
        figure_data_uri({})
    (tmp_path / "f.svg").write_text("<svg xmlns='http://www.w3.org/2000/svg'/>")
    assert figure_data_uri(tmp_path / "f.svg").startswith("data:image/svg+xml;base64,")


# ----------------------------------------------------------------------------- design
def test_design_report_shows_controller_poles_info_comparison_and_figures(tmp_path):
    import control

    from flexarm.design.result import Design
    from flexarm.specs import load_scenario

    sc = load_scenario("rotary-flexible-link")
    # a discrete system with known poles 0.5 and 0.9 (its state matrix is diagonal)
    lin = control.ss(np.diag([0.5, 0.9]), [[1.0], [1.0]], [[1.0, 2.0]], [[0.0]], dt=0.001)
    d = Design(
        "lqr",
        sc,
        lin,
        info={
            "gains": [6.0, -3.0, 0.213, 0.0],
            "cost": 1.25,
            "trace": {"iterations": list(range(20))},
        },
        warnings=["saturates in 3 of 200 plants"],
    )
    # the comparison as design/compare's Comparison.rows: controller -> nested metrics
    rows = {
        "logged": {"median": {"hub_error_counts": 7.0}, "unstable": 0},
        "lqr": {"median": {"hub_error_counts": 0.5}, "unstable": 2},
    }
    page = design_report(
        d, figures=[_figure()], command="flexarm design x --method lqr", comparison=rows
    ).write(tmp_path / "d.html")
    text = page.read_text()
    assert "flexarm design --method lqr: " + sc.name in text
    assert "|poles| (discrete; &lt; 1 stable): 0.5, 0.9" in text
    assert "[6, -3, 0.213, 0]" in text and '<td class="num">1.25</td>' in text
    assert "saturates in 3 of 200 plants" in text.split('class="warnings"')[1]
    assert "<th>median.hub_error_counts</th><th>unstable</th>" in text
    assert _cells(text, "lqr")[1:] == ["0.5", "2"] and _cells(text, "logged")[1:] == ["7", "0"]
    assert '"iterations"' in html.unescape(text)  # a long list: in the JSON block
    ctrl = sc.model_dump(mode="json", exclude_none=True)["controller"]
    assert f"<td>type</td><td>{ctrl['type']}</td>" in text
    if _chromium():
        _check_in_browser(page, tmp_path, 1)


# ----------------------------------------------------------------------------- CLI, synthetic
SYN = [
    "--gear-ratio",
    "70",
    "--motor-constant",
    "7.68e-3",
    "--armature-resistance",
    "2.6",
    "--link-length",
    "0.42",
    "--gear-efficiency",
    "0.9",
    "--motor-efficiency",
    "0.69",
]


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    """One synthetic log of the built-in rotary rig (stick-slip, ringing link), fitted and
    validated through the CLI with --report and --json (one fit for the module)."""
    from flexarm.identification.time_domain.synthetic import synthetic_log
    from flexarm.specs import load_scenario

    d = tmp_path_factory.mktemp("report")
    log = synthetic_log(
        load_scenario("rotary-flexible-link"),
        [6.0, -3.0, 0.213, 0.0],
        d / "b.csv",
        duration=4.0,
        amplitude=(0.5, 0.15),
        period=3.0,
    )
    r = runner.invoke(
        app,
        [
            "fit",
            str(log),
            *SYN,
            "--seconds",
            "2",
            "--json",
            str(d / "fit.json"),
            "--scenario-out",
            str(d / "fit.toml"),
            "--report",
            str(d / "fit.html"),
        ],
    )
    assert r.exit_code == 0, r.output
    r = runner.invoke(
        app,
        [
            "validate",
            str(d / "fit.toml"),
            str(log),
            "--json",
            str(d / "v.json"),
            "--report",
            str(d / "v.html"),
        ],
    )
    assert r.exit_code == 0, r.output
    return d, log


def _cells(text: str, first: str) -> list[str]:
    for row in re.findall(r"<tr>(.*?)</tr>", text):
        c = re.findall(r"<td[^>]*>(.*?)</td>", row)
        if c and c[0] == first:
            return c
    raise AssertionError(f"no table row {first!r}")


def test_fit_report_holds_the_fit_and_the_command(synthetic):
    d, log = synthetic
    text = (d / "fit.html").read_text()
    res = json.loads((d / "fit.json").read_text())
    # the tables carry the result's numbers: 5 significant digits for values, 2 for std
    for name, value in res["params"].items():
        c, std = _cells(text, name), res["std"][name]
        assert float(c[1]) == pytest.approx(value, rel=1e-4)
        assert float(c[2]) == pytest.approx(std, rel=0.06)  # '.2g': half a unit in 10
        assert float(c[4]) == pytest.approx(100 * std / abs(value), rel=1e-2)
    for sig, v in res["fit_percent"]["b.csv"].items():  # '.1f'
        assert float(
            _cells(text, "b.csv")[1 + list(res["fit_percent"]["b.csv"]).index(sig)]
        ) == pytest.approx(v, abs=0.051)
    # the true model fits its own noisy, quantised log (test_time_domain_fit: > 95 % both)
    assert min(res["fit_percent"]["b.csv"].values()) > 95
    cmd = re.search(r"<code>(flexarm fit .*?)</code>", text).group(1)
    assert html.unescape(cmd).split()[:3] == ["flexarm", "fit", str(log)]
    # given as --seconds (the alias), written under the option's name
    assert f"--report {d / 'fit.html'}" in html.unescape(cmd) and "--global-seconds 2.0" in cmd
    for w in res["warnings"]:
        assert html.escape(w) in text
    assert text.count("<img ") == 1 and "b_fit.png" in text
    assert not list(d.glob("flexarm-report-*"))  # the figures' temporary folder is gone


def test_validate_report_and_refused_overwrite(synthetic):
    d, log = synthetic
    text = (d / "v.html").read_text()
    fp = json.loads((d / "v.json").read_text())["fit_percent"]["b.csv"]
    c = _cells(text, "b.csv")
    assert [float(x) for x in c[1:]] == pytest.approx(
        [fp["motor_angle"], fp["tip_deflection"]], abs=0.051
    )
    assert json.loads((d / "v.json").read_text())["plots"] == []  # no --plots: none kept
    before = (d / "v.html").read_bytes()
    r = runner.invoke(
        app, ["validate", str(d / "fit.toml"), str(log), "--report", str(d / "v.html")]
    )
    assert r.exit_code == 2
    said = " ".join(r.output.split())
    assert f"--report {d / 'v.html'}: exists; pass --overwrite" in said
    assert (d / "v.html").read_bytes() == before
    r = runner.invoke(
        app,
        ["validate", str(d / "fit.toml"), str(log), "--report", str(d / "v.html"), "--overwrite"],
    )
    assert r.exit_code == 0 and (d / "v.html").read_bytes() != before
    r = runner.invoke(app, ["validate", str(d / "fit.toml"), str(log), "--report", str(d)])
    assert r.exit_code == 2 and "is a folder, not a file" in " ".join(r.output.split())


@needs_browser
def test_synthetic_fit_and_validate_reports_render_in_chromium(synthetic, tmp_path):
    d, _ = synthetic
    for name in ("fit.html", "v.html"):
        sub = tmp_path / name
        sub.mkdir()
        _check_in_browser(d / name, sub, 1)


@pytest.mark.slow  # two general fits (least squares on the one simulator): ~40-80 s
def test_general_fit_and_refit_validate_reports(tmp_path):
    """The general path (flexarm fit SCENARIO LOG --free ..., validate --refit friction)
    with --report, on test_time_domain_general's synthetic two-mode link: the report's fitted
    values, std and fit % are the JSON's, and the refitted friction table is there."""
    from flexarm.identification.time_domain.result import drop_none as _drop_none
    from flexarm.identification.time_domain.synthetic import scenario_log
    from flexarm.io.logs import write_log
    from flexarm.io.write import write_toml
    from test_time_domain_general import scenario_with, staircase, two_mode_link

    truth = two_mode_link()
    t = np.arange(1501) * 0.002
    short = truth.model_copy(
        update={"simulation": truth.simulation.model_copy(update={"duration": 3.0})}
    )
    log = scenario_log(short, {"reference": staircase(t, [0.0, 0.4, -0.1, 0.3], 0.75)}, seed=2)
    path = write_log(tmp_path / "run.csv", log.time, log.signals, required=("time",))
    sc_path = tmp_path / "template.toml"
    write_toml(
        sc_path,
        _drop_none(scenario_with(short, {"arm.joints[0].friction.coulomb": 0.026}).model_dump()),
    )
    coul = "arm.joints[0].friction.coulomb"
    r = runner.invoke(
        app,
        [
            "fit",
            str(sc_path),
            str(path),
            "--free",
            "arm.hubs[0].inertia",
            "--free",
            coul,
            "--json",
            str(tmp_path / "fit.json"),
            "--max-nfev",
            "20",
            "--report",
            str(tmp_path / "fit.html"),
        ],
    )
    assert r.exit_code == 0, r.output
    d = json.loads((tmp_path / "fit.json").read_text())
    text = (tmp_path / "fit.html").read_text()
    c = _cells(text, coul)
    assert [float(x) for x in c[1:4]] == pytest.approx(
        [d["template"][coul], d["params"][coul], d["std"][coul]], rel=0.05
    )  # '.2g' std
    fp = next(iter(d["fit_percent"].values()))
    row = _cells(text, "run.csv")
    assert [float(x) for x in row[1:]] == pytest.approx(list(fp.values()), abs=0.051)
    assert text.count("<img ") == len(d["fit_percent"]) >= 1
    r = runner.invoke(
        app,
        [
            "validate",
            str(sc_path),
            str(path),
            "--refit",
            "friction",
            "--refit-window",
            "0:3",
            "--json",
            str(tmp_path / "v.json"),
            "--report",
            str(tmp_path / "v.html"),
        ],
    )
    assert r.exit_code == 0, r.output
    v = json.loads((tmp_path / "v.json").read_text())
    text = (tmp_path / "v.html").read_text()
    assert "Friction refitted on [0.0, 3.0] s of run.csv" in text
    assert float(_cells(text, coul)[2]) == pytest.approx(v["refit"]["params"][coul], rel=1e-4)
    assert text.count("<img ") == 2  # the scenario as given and after the refit


@needs_browser
def test_the_browser_check_fails_on_a_broken_or_blank_figure(tmp_path):
    """The check can fail: a figure whose data is not an image does not load, and a blank
    figure has no ink."""
    from PIL import Image

    good = HtmlReport("t").figures([_figure()])
    broken = good.html().replace(
        "data:image/png;base64,", "data:image/png;base64," + base64.b64encode(b"no png").decode(), 1
    )
    (tmp_path / "b.html").write_text(broken)
    info, _ = _render(tmp_path / "b.html", tmp_path)
    assert [im["ok"] for im in info["images"]] == [False]
    buf = io.BytesIO()
    Image.new("RGB", (300, 200), "white").save(buf, format="PNG")
    (tmp_path / "w.html").write_text(HtmlReport("t").figures([buf.getvalue()]).html())
    with pytest.raises(AssertionError):
        _check_in_browser(tmp_path / "w.html", tmp_path, 1)


# ----------------------------------------------------------------------------- real data
@pytest.fixture(scope="module")
def unit6(tmp_path_factory, rotary_whole_fit):
    """The unit 6 rig fitted on its whole log (conftest's shared fit, the data sheet),
    its report written with its overlay figure."""
    d = tmp_path_factory.mktemp("unit6")
    path = DATA / "4PM_Group37_FlexArm_Unit6"
    res = rotary_whole_fit(path.name)
    page = fit_report(
        res,
        figures=res.plots(d),
        command="flexarm.identification.fit (tests/test_html_report.py)",
        inputs=[path],
    ).write(d / "unit6.html")
    return res, page


@pytest.mark.slow
def test_unit6_fit_report_shows_its_figures_in_chromium(unit6, tmp_path):
    res, page = unit6
    text = page.read_text()
    fp = res.fit_percent["4PM_Group37_FlexArm_Unit6"]
    print("unit 6 whole-log fit %:", fp)
    # the whole-log fit reaches the held-out levels of test_time_domain_fit__rotary_rig (>= 95 / 80)
    assert fp["motor_angle"] >= 95 and fp["tip_deflection"] >= 80
    c = _cells(text, "4PM_Group37_FlexArm_Unit6")
    assert float(c[1]) == pytest.approx(fp["motor_angle"], abs=0.051)
    # the report's table is the one result's, keyed by the scenario's paths (#43): J's path
    assert float(_cells(text, "arm.motor.inertia")[1]) == pytest.approx(
        res.params["hub_inertia"], rel=1e-4
    )
    if _chromium() is None:
        pytest.skip("no headless Chromium found (apt-get install chromium)")
    _check_in_browser(page, tmp_path, 1)


def test_fit_report_names_the_std_the_result_carries(synthetic):
    """A fit whose std came from the parametric bootstrap (``FitOptions.bootstrap``) is
    reported as such: the column says "std (bootstrap)" and the note is the result's own
    ``stages["std_source"]``; without it the column stays "std (HAC)"."""
    from flexarm.analysis.html_report import fit_report
    from flexarm.identification.time_domain.result import FitResult

    d, _ = synthetic
    doc = json.loads((d / "fit.json").read_text())
    res = FitResult.from_dict(doc)
    page = fit_report(res).html()
    assert "std (HAC)" in page and "std (bootstrap)" not in page
    res.stages["bootstrap"] = {"n": 8}
    res.stages["std_source"] = "parametric bootstrap: 8 of 8 refits"
    page = fit_report(res).html()
    assert "std (bootstrap)" in page and "std: parametric bootstrap: 8 of 8 refits." in page

"""Results that read well (flexarm.display): the text form of every result fits 80 columns
and cuts no number, the HTML form is one table holding the same numbers; named
python-control systems; Bode figures (magnitude and phase, data band, fit)."""

from html.parser import HTMLParser

import control
import numpy as np
import pytest

import flexarm
from flexarm.display import Table, fmt
from flexarm.identification.frequency_domain.excitation import multisine
from flexarm.identification.frequency_domain.periodic import periodic_frf, plot_bode
from flexarm.identification.frequency_domain.tfest import plot_fit, tfest
from flexarm.models.single_link import SingleLinkModel

FS, P = 1000.0, 500


class _Cells(HTMLParser):
    """The text of every <td>/<th> and the count of <table> tags."""

    def __init__(self):
        super().__init__()
        self.cells, self.tables, self._in = [], 0, False

    def handle_starttag(self, tag, attrs):
        self.tables += tag == "table"
        if tag in ("td", "th"):
            self._in = True
            self.cells.append("")

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self._in = False

    def handle_data(self, data):
        if self._in:
            self.cells[-1] += data


def cells(html: str) -> _Cells:
    p = _Cells()
    p.feed(html)
    return p


def check_text(text: str, numbers=()):
    assert all(len(line) <= 80 for line in text.splitlines()), text
    for x in numbers:  # every number appears whole (nothing cut at the edge)
        assert fmt(x) in text, (fmt(x), text)


def test_fmt_and_table_stack_instead_of_cut():
    assert fmt(1.23456789) == "1.235" and fmt(None) == "–" and fmt(float("nan")) == "–"
    assert fmt(1 - 2j) == "1-2j" and fmt([1.0, 2.5]) == "1, 2.5" and fmt(3) == "3"
    long = "x" * 70
    t = Table("t", [(long, 12345.678, long)], header=("a", "b", "c"))
    text = t.text()
    check_text(text, [12345.678])
    assert "b: 1.235e+04" in text  # stacked as name: value, the number whole
    h = cells(t.html())
    assert h.tables == 1 and h.cells == ["a", "b", "c", long, "1.235e+04", long]
    assert "<script>" not in Table("<script>", [("<b>", 1)]).html()  # escaped


@pytest.fixture(scope="module")
def sim():
    sc = flexarm.load_scenario("feliu-single-mass")
    sc = sc.model_copy(update={"simulation": sc.simulation.model_copy(update={"duration": 0.3})})
    return flexarm.simulate(sc)


def test_simulation_result_repr(sim):
    text = repr(sim)
    t = sim.time
    assert text.startswith(f"SimulationResult 'feliu-single-mass': {len(t)} samples")
    final = [sim[n][-1] for n in ("motor_angle", "tip_angle", "current")]
    check_text(text, final + [sim["motor_angle"].max()])
    h = cells(sim._repr_html_())
    assert h.tables == 1
    k = h.cells.index("motor_angle")
    assert h.cells[k : k + 5] == [
        "motor_angle",
        "rad",
        fmt(sim["motor_angle"][-1]),
        fmt(sim["motor_angle"].min()),
        fmt(sim["motor_angle"].max()),
    ]
    assert "coupling_torque" in text and "N*m" in h.cells[h.cells.index("coupling_torque") + 1]


def test_scenario_repr():
    for name in flexarm.builtin_scenarios():
        sc = flexarm.load_scenario(name)
        text = repr(sc)
        check_text(text)
        assert text.splitlines()[0] == f"Scenario {name!r}"
        h = cells(sc._repr_html_())
        assert h.tables == 1 and "arm" in h.cells
    sc = flexarm.load_scenario("feliu-single-mass")
    h = cells(sc._repr_html_())
    assert h.cells[h.cells.index("sampling") + 1] == f"period {sc.sampling.period:.4g} s"


def test_named_transfer_functions():
    m = SingleLinkModel.from_spec(flexarm.load_scenario("feliu-single-mass").arm)
    gm, gb, gt = m.motor_tf(), m.beam_tf(), m.tip_tf()
    assert (gm.name, gm.input_labels, gm.output_labels) == ("G_m", ["current"], ["motor_angle"])
    assert (gb.name, gb.input_labels, gb.output_labels) == ("G_b", ["motor_angle"], ["tip_angle"])
    assert (gt.name, gt.output_labels) == ("G_t", ["tip_angle"])
    assert "sys[" not in repr(gm)
    # G_t = G_m G_b at a frequency: the names change nothing in the numbers
    w = 7.0
    assert complex(gt(1j * w)) == pytest.approx(complex(gm(1j * w)) * complex(gb(1j * w)), rel=1e-9)


def _G(f):
    s = 2j * np.pi * f
    w1, w2 = 2 * np.pi * 40, 2 * np.pi * 60
    return (s**2 + 0.1 * w1 * s + w1**2) / (s**2 + 0.05 * w2 * s + w2**2) / w1**2 * w2**2


@pytest.fixture(scope="module")
def frf():
    e = multisine(P, FS, 10, 200, kind="random-odd", periods=8, seed=1)
    u = e.signal[0]
    U = np.fft.rfft(u[:P])
    f = np.arange(len(U)) * FS / P
    y = np.tile(np.fft.irfft(U * _G(np.maximum(f, 1e-9)), P), len(u) // P)
    y = y + 1e-3 * np.random.default_rng(0).standard_normal(len(y))
    return periodic_frf(u, {"y": y}, FS, period=P, lines=e.excited, input_name="u")


def test_frf_and_tfest_reprs(frf):
    text = repr(frf)
    check_text(text)
    assert text.startswith(f"PeriodicFRF u → y: {len(frf.lines)} lines")
    h = cells(frf._repr_html_())
    db = 20 * np.log10(np.abs(frf.response[0]))
    assert h.cells[h.cells.index("y") + 1] == f"{db.min():.1f} … {db.max():.1f}"
    fit = tfest(
        control.frd(frf.response[0], 2 * np.pi * frf.frequency_hz), 2, 2, std=frf.noise_std[0]
    )
    text = repr(fit)
    check_text(text)
    assert text.startswith("TFEstimate: 2 poles, 2 zeros")
    h = cells(fit._repr_html_())
    for name, v in fit.parameters.items():
        k = h.cells.index(name)
        assert h.cells[k + 1 : k + 3] == [fmt(v["value"]), fmt(v["std"])]


def test_bode_figures(frf, tmp_path):
    fig = plot_bode(frf, tmp_path / "frf.png")
    assert (tmp_path / "frf.png").stat().st_size > 10_000
    mag, ph = fig.axes[:2]
    assert "magnitude" in mag.get_ylabel() and "phase" in ph.get_ylabel()
    assert len(mag.collections) == 1  # the ±2σ band
    # the data points are 20 log10 |G| at the lines
    np.testing.assert_allclose(mag.lines[0].get_ydata(), 20 * np.log10(np.abs(frf.response[0])))
    fit = tfest(
        control.frd(frf.response[0], 2 * np.pi * frf.frequency_hz), 2, 2, std=frf.noise_std[0]
    )
    fig = plot_fit(
        fit,
        frf.frequency_hz,
        {"y": frf.response[0]},
        {"y": frf.noise_std[0]},
        path=tmp_path / "tfest.png",
    )
    mag, ph = fig.axes[:2]
    labels = [ln.get_label() for ln in mag.lines]
    assert labels == ["data", "fit", "|fit − data|", "2σ level"]
    # the error line lies below the 2σ level at most lines (the fit is accepted)
    assert np.mean(mag.lines[2].get_ydata() < mag.lines[3].get_ydata()) > 0.8
    # the fit line is the model's magnitude; the true system lies within 0.1 dB of it
    fg = mag.lines[1].get_xdata()
    np.testing.assert_allclose(mag.lines[1].get_ydata(), 20 * np.log10(np.abs(_G(fg))), atol=0.1)
    # tick labels of the frequency axis do not overlap (the old tfest.png's did)
    fig.canvas.draw()
    lo, hi = ph.get_xlim()
    boxes = sorted(
        (
            t.get_window_extent()
            for t, x in zip(ph.get_xticklabels(), ph.get_xticks(), strict=True)
            if t.get_text() and lo <= x <= hi
        ),
        key=lambda b: b.x0,
    )
    assert len(boxes) >= 3
    assert all(a.x1 < b.x0 for a, b in zip(boxes, boxes[1:], strict=False))


def test_design_repr():
    """A design reads as one table: method, rig, verdict, the controller's size."""
    des = flexarm.design(flexarm.load_scenario("rotary-flexible-link"), "lqr")
    text = repr(des)
    check_text(text)
    assert text.splitlines()[0] == "Design (lqr) of rotary-flexible-link"
    h = cells(des._repr_html_())
    assert h.tables == 1 and h.cells[h.cells.index("verdict") + 1] == "not checked"
    c = des.controller
    assert f"{c.ninputs} in, {c.noutputs} out, {c.nstates} states" in text

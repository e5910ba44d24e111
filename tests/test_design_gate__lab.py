"""The design gate judges what it says (issue #46 item 3): against the lab's controller, a
design is refused only for instability on the nominal plant, on more drawn plants than the
lab's controller, or for the limits it names; a design that beats the lab's controller on
every figure passes; a refusal names the figure, the threshold and the option."""

from __future__ import annotations

import numpy as np

from flexarm.design.gate import STABLE, GateOptions, assess, refusal


def _row(nominal_stable, n_unstable, n=200):
    return {"nominal_stable": nominal_stable, "n_plants": n, "unstable": n_unstable}


class _Cmp:
    """The parts of a Comparison that assess reads: a design "d" and the lab's "lab"."""

    def __init__(self, d, d_lim, lab, lab_lim, limit=5.0):
        self.rows = {"d": d, "lab": lab}
        self.per_plant = {
            "d": {"time_at_limit_s": np.asarray(d_lim, float)},
            "lab": {"time_at_limit_s": np.asarray(lab_lim, float)},
        }
        self.settings = {"limit_V": limit}


def _lim(nominal, k_drawn, n=200, t=0.01):
    a = np.zeros(n + 1)
    a[0] = nominal
    a[1 : 1 + k_drawn] = t
    return a


def test_a_design_that_beats_the_lab_on_every_figure_passes():
    """The issue's tune design on unit 6: 0/200 unstable against the lab's 38/200, at the
    5 V limit for 22 ms against the lab's 25 ms (and on fewer drawn plants): stable, though
    it touches the limit on the nominal plant and on 3 % of the drawn plants."""
    c = _Cmp(_row(True, 0), _lim(0.022, 6), _row(True, 38), _lim(0.025, 40))
    g = assess(c, "d", reference="lab")
    assert g["verdict"] == STABLE, g
    assert g["lab"]["unstable"] == 38 and g["lab"]["nominal_time_at_limit_s"] == 0.025
    # without the lab's row the same figures are refused (the old, stricter rule)
    assert assess(c, "d")["reasons"] == [
        "the command reaches the ±5 limit on the nominal plant",
        "the command reaches the ±5 limit on 6 of 200 drawn plants (3 % > 1 %)",
    ]


def test_more_unstable_plants_than_the_lab_is_refused_with_the_share_option():
    """The issue's nested design: 152/200 unstable against the lab's 38/200: refused for
    stability, naming both counts, the share and --max-unstable-share / --accept-unstable."""
    c = _Cmp(_row(True, 152), _lim(0.0, 0), _row(True, 38), _lim(0.025, 40))
    g = assess(_rename(c), "nested", reference="lab")
    assert g["reasons"] == [
        "unstable on 152 of 200 drawn plants (76 % > 1 %; the lab's controller: 38 of 200)"
    ]
    assert g["stability"] is True
    msg, fix = refusal("nested", g)
    assert msg.startswith("the nested design is not safe to run: unstable on 152 of 200")
    assert "--max-unstable-share (now 0.01)" in fix and "--accept-unstable" in fix
    # as many unstable plants as the lab's controller: not a reason
    c2 = _Cmp(_row(True, 38), _lim(0.0, 0), _row(True, 38), _lim(0.0, 0))
    assert assess(_rename(c2), "nested", reference="lab")["verdict"] == STABLE


def _rename(c, name="nested"):
    c.rows[name] = c.rows.pop("d")
    c.per_plant[name] = c.per_plant.pop("d")
    return c


def test_a_longer_time_at_the_limit_is_refused_without_accept_unstable():
    """An lqr design at the limit for 30 ms against the lab's 25 ms: refused for the limit,
    with both times, and the fix is the design's own option (--r), not --accept-unstable."""
    c = _rename(_Cmp(_row(True, 0), _lim(0.030, 0), _row(True, 0), _lim(0.025, 0)), "lqr")
    g = assess(c, "lqr", reference="lab")
    assert g["reasons"] == [
        "the command sits at the ±5 limit for 30 ms on the nominal plant, longer than the "
        "lab's controller (25 ms)"
    ]
    assert g["stability"] is False and g["nominal_time_at_limit_s"] == 0.03
    msg, fix = refusal("lqr", g)
    assert msg.startswith("the lqr design is refused by the gate: the command sits")
    assert "--r" in fix and "--accept-unstable" not in fix
    # the limit check off: passes
    assert assess(c, "lqr", GateOptions(check_limit=False), reference="lab")["verdict"] == STABLE


def test_the_nominal_plant_alone_is_judged_on_its_own():
    """Unstable on the nominal plant is refused whatever the lab's controller does (even
    if the lab's is unstable too); more drawn plants at the limit than the lab's and over
    the share is refused naming --max-unstable-share."""
    c = _Cmp(_row(False, 0), _lim(0.0, 0), _row(False, 100), _lim(0.0, 0))
    g = assess(c, "d", reference="lab")
    assert g["reasons"] == ["unstable on the nominal plant"] and g["stability"]
    c = _Cmp(_row(True, 0), _lim(0.0, 10), _row(True, 0), _lim(0.0, 4))
    g = assess(c, "d", reference="lab")
    assert g["reasons"] == [
        "the command reaches the ±5 limit on 10 of 200 drawn plants (5 % > 1 %; "
        "the lab's controller: 4 of 200)"
    ]
    assert g["fixes"] == ["--max-unstable-share (now 0.01) sets the share"]
    assert not g["stability"]

"""The controller check: the declared law regressed on the logged command (issue #11 item 2)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from flexarm.identification.time_domain.controller_check import check_controller
from flexarm.identification.time_domain.logs import FitInputError, load_rig_log
from flexarm.io.logformat import load_log_format, log_format_from_dict
from test_logformat import EXAMPLE, README_GAINS, RIG_FILES, needs_data


@needs_data
@pytest.mark.parametrize("path", RIG_FILES, ids=lambda p: p.name)
def test_every_rig_log_confirms_the_logged_law(path):
    """The logged command is the declared law with the gains as logged (K2 negative) to
    R² > 0.999 (the worst file measures 0.99970 at the best delay; the bound leaves that
    margin and still means less than 0.1 % of the command unexplained). Each identifiable
    gain within the check's own 10 % of the README's table (+0.01 for gains declared 0)."""
    log = load_rig_log(path, log_format=EXAMPLE)
    c = check_controller(log)
    print(
        f"\n{path.name}: R² {c.r2:.5f}, delay {c.delay}, by delay {c.r2_by_delay}, "
        f"saturation {c.saturation_limit}"
    )
    assert c.r2 > 0.999 and not c.disagreements
    assert c.rates == "logged"
    decl = np.array(README_GAINS[path.name], float)
    ok = np.isfinite(c.regressed[0])
    assert ok[0] and ok[2]  # K1, K3 are always identifiable (the hub moves)
    # a gain declared 0 may regress to a small value: 0.01 V per unit of its signal for the
    # hub terms (K1 V/rad, K3 V·s/rad); the tip terms K2, K4 multiply metres (|d| < 0.03 m
    # on these links), so 0.03 V/m there is under 1 mV of command (flexarm_K1_6: K2 -0.011)
    floor = np.array([0.01, 0.03, 0.01, 0.03])
    assert np.all(np.abs(c.regressed[0, ok] - decl[ok]) <= 0.1 * np.abs(decl[ok]) + floor[ok])
    # Saturation: the units that hit the amplifier show a plateau at 5 V (README: "saturates
    # at ±5 V on some units"); logged values are rounded to 1 mV.
    if c.saturation_limit is not None:
        assert c.saturation_limit == pytest.approx(5.0, abs=0.01)
    assert json.loads(c.to_json())["r2"] == pytest.approx(c.r2)


@needs_data
def test_saturation_detected_where_the_command_plateaus():
    by = {p.name: p for p in RIG_FILES}
    c = check_controller(load_rig_log(by["Unit5_Rigid_trial1.csv"], log_format=EXAMPLE))
    assert c.saturation_limit == pytest.approx(5.0, abs=0.01) and c.saturation_fraction > 0.005
    c = check_controller(load_rig_log(by["rigidarm_K1_6"], log_format=EXAMPLE))
    assert c.saturation_limit is None  # |u| < 1.2 V there


@needs_data
def test_wrong_k2_sign_is_rejected_naming_k2():
    by = {p.name: p for p in RIG_FILES}
    fmt = load_log_format(EXAMPLE).model_dump()
    fmt["controller"] = {
        "kind": "state_feedback",
        "gains": {"K1": 8, "K2": 8.5, "K3": 1.5, "K4": 1.5},
    }  # K2 sign flipped
    wrong = log_format_from_dict(fmt, "wrong-k2.toml")
    log = load_rig_log(by["4PM_Group37_FlexArm_Unit6"], log_format=wrong)
    with pytest.raises(FitInputError) as e:
        check_controller(log)
    msg = str(e.value)
    print("\n" + msg)
    assert "4PM_Group37_FlexArm_Unit6" in msg
    assert "K2: declared 8.5 V/m, regressed -8.5" in msg and "opposite sign" in msg
    assert "K1:" not in msg and "K3:" not in msg  # only the wrong term is named
    assert "--use-regressed-law" in msg
    c = check_controller(log, use_regressed=True)
    assert c.disagreements and c.disagreements[0].startswith("K2")
    fixed = c.apply(log)
    assert fixed.controller.k2 == pytest.approx(-8.5, abs=0.1)
    assert not check_controller(fixed).disagreements


@pytest.fixture(scope="module")
def synthetic_delay1(tmp_path_factory):
    from flexarm.identification.time_domain.synthetic import synthetic_log
    from flexarm.specs.scenario import load_scenario

    sc = load_scenario("rotary-flexible-link")
    sc = sc.model_copy(update={"sampling": sc.sampling.model_copy(update={"delay": 1})})
    return synthetic_log(
        sc,
        (6.0, -3.0, 0.2, 0.05),
        tmp_path_factory.mktemp("cc") / "d1.csv",
        duration=2.0,
        period=1.0,
        amplitude=0.3,
    )


def test_synthetic_log_gains_and_one_sample_delay_recovered(synthetic_delay1):
    """The simulator's law is exactly the regressed model at delay 1 (backward-difference
    rates, no glitch), so the gains come back to the file's 12 significant digits: rtol 1e-6
    leaves room for the written rounding; the other delays fit visibly worse."""
    c = check_controller(load_rig_log(synthetic_delay1))
    assert c.delay == 1 and c.rates == "backward"
    np.testing.assert_allclose(c.regressed[0], [6.0, -3.0, 0.2, 0.05], rtol=1e-6)
    assert c.r2 > 1 - 1e-9 and c.r2_by_delay[0] < 0.99 and c.r2_by_delay[2] < 0.99


def test_gain_segments_regressed_separately(synthetic_delay1, tmp_path):
    """A log whose K1 column switches half way: each segment is checked against its own
    declared gains; declaring the first segment's K1 for the whole log is caught in the
    second segment only."""
    log = load_rig_log(synthetic_delay1)
    g = log.gains.copy()
    g[1000:, 0] = 7.0  # a declaration that changes although the simulated law did not
    from dataclasses import replace

    with pytest.raises(
        FitInputError,
        match=r"K1 \(samples 1000-2001\): declared 7 V/rad, "
        r"regressed 6 ",
    ):
        check_controller(replace(log, gains=g))


def test_check_needs_voltage_and_gains(synthetic_delay1):
    log = load_rig_log(synthetic_delay1)
    from dataclasses import replace

    with pytest.raises(FitInputError, match=r"d1\.csv: field 'voltage'"):
        check_controller(
            replace(log, signals={k: v for k, v in log.columns.items() if k != "voltage"})
        )
    with pytest.raises(FitInputError, match=r"d1\.csv: field 'controller': no declared law"):
        check_controller(replace(log, controller=None, gains=None))


@needs_data
def test_cli_fit_checks_the_law_before_fitting(tmp_path):
    """`flexarm fit --log-format` reads the rig log and stops at the controller check, before
    any fitting, when the format's K2 has the wrong sign."""
    from typer.testing import CliRunner

    from flexarm.cli import app

    by = {p.name: p for p in RIG_FILES}
    wrong = tmp_path / "wrong.toml"
    wrong.write_text(
        EXAMPLE.read_text().replace(
            "gain_columns = { K1 = 8, K2 = 9, K3 = 10, K4 = 11 }",
            "gain_columns = { K1 = 8, K2 = -9, K3 = 10, K4 = 11 }",
        )
    )
    res = CliRunner().invoke(
        app,
        [
            str(x)
            for x in ["fit", by["Unit7_Flex_trial1.csv"], "--log-format", wrong, "--gear-ratio"]
            + [48.4, "--motor-constant", 0.0107, "--armature-resistance", 3.29]
            + ["--link-length", 0.45]
        ],
    )
    out = res.output + (res.stderr if res.stderr_bytes is not None else "")
    assert res.exit_code != 0
    assert "K2: declared 1 V/m, regressed -1" in " ".join(out.split())

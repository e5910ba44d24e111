"""Issue #43 item 2, "the scenario is the model": what ``flexarm fit`` reports is what
``flexarm validate`` of the scenario it wrote (``--scenario-out``) gives, on the fit's own
held-out windows and on its training windows, through the documented commands on the real
rotary-rig logs (``../shared/data/rotary-rig``).

Both figures come from one computation (:func:`flexarm.identification.time_domain.predict.
predict` of the written scenario, each window's start state estimated on the window as the
fit estimates it), so they agree to the TOML file's round trip: the tolerance, 0.1 point,
is the issue's. Before (the servo rig's loop for the fit, the scenario's replay from the
logged start state for ``validate``) unit 6 gave held-out tip 84.0 % in the fit and 73.5 %
through ``validate``. One CLI fit per unit and route (``--local servo``: the pipeline's own
local stage, about 10-20 s; ``--local general``: the general engine after its global
stage, 15-35 s, on 2 cores); marked slow.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "rotary-rig"
FORMAT = Path(__file__).resolve().parents[1] / "examples" / "quanser-rotflex.toml"
#: the README's data-sheet options (the lab's data sheet)
SHEET = [
    "--drive",
    "voltage",
    "--gear-ratio",
    "48.4",
    "--motor-constant",
    "0.0107",
    "--armature-resistance",
    "3.29",
    "--link-length",
    "0.45",
]
CLI = [sys.executable, "-m", "flexarm"]

pytestmark = [
    pytest.mark.slow,
    pytest.mark.rig,
    pytest.mark.skipif(
        not DATA.is_dir(),
        reason=f"real rig logs not found at {DATA} (../shared is absent in a "
        "user's clone; CI has it)",
    ),
]


def _run(args: list[str]) -> subprocess.CompletedProcess:
    r = subprocess.run([*CLI, *args], capture_output=True, text=True)
    assert r.returncode == 0 and "Traceback" not in r.stderr, (r.stdout[-2000:], r.stderr[-3000:])
    return r


def _validate(toml: Path, log: Path, window: str, out: Path) -> dict:
    _run(
        ["validate", str(toml), str(log), "--log-format", str(FORMAT), "--window", window]
        + ["--json", str(out)]
    )
    return json.loads(out.read_text())


@pytest.mark.parametrize(
    "name, floor, local",
    [
        # unit 6: the 97 / 84 (measured 97.5 / 84.0); unit 7: the 83 / 56
        # (measured 85.7 / 57.8 with its delays searched in order, hub 34 / tip 68 samples;
        # 82.4 / 63.2 when the order was left free and the hub came out 85 samples late)
        ("4PM_Group37_FlexArm_Unit6", (97.0, 83.5), "servo"),
        ("Unit7_Flex_trial1.csv", (83.0, 56.0), "servo"),
        # --local general: the servo's estimates and global stage, then the one general
        # engine (#43 item 1); the floors (measured 97.7 / 84.5 and 84.2 / 61.6; unit
        # 7's held-out hub is fragile: 82.5 with the breakaway's lower bound 1e-4 N*m lower)
        ("4PM_Group37_FlexArm_Unit6", (97.0, 84.0), "general"),
        ("Unit7_Flex_trial1.csv", (83.0, 56.0), "general"),
    ],
)
def test_fit_figures_are_validate_of_the_written_scenario(name, floor, local, tmp_path):
    log = DATA / name
    fit_json, toml = tmp_path / "fit.json", tmp_path / "rig.toml"
    figs = tmp_path / "figs"  # the general route's figures and report (the bench's options)
    figs.mkdir()
    extra = ["--plots", str(figs), "--report", str(figs / "fit.html")] if local == "general" else []
    _run(
        ["fit", str(log), "--log-format", str(FORMAT), *SHEET, "--local", local]
        + ["--window", "0:5", "--validate-window", "5:10"]
        + ["--scenario-out", str(toml), "--json", str(fit_json), *extra]
    )
    if extra:  # the fitted and held-out windows' overlays, and the report
        assert len(list(figs.glob("*.png"))) == 2 and (figs / "fit.html").stat().st_size > 0
    fit = json.loads(fit_json.read_text())
    held = _validate(toml, log, "5:10", tmp_path / "held.json")
    train = _validate(toml, log, "0:5", tmp_path / "train.json")
    print(name, "fit:", fit["fit_percent"], fit["held_out"]["fit_percent"])
    print(name, "validate:", train["fit_percent"], held["fit_percent"])
    for reported, validated in (
        (fit["held_out"]["fit_percent"], held["fit_percent"]),
        # the general engine keys a fitted window "LOG[0:5 s]"; validate --window "LOG"
        ({k.split("[")[0]: v for k, v in fit["fit_percent"].items()}, train["fit_percent"]),
    ):
        assert set(reported) == set(validated) == {name}
        for sig, v in reported[name].items():
            if v is None:
                assert validated[name].get(sig) is None, (sig, validated)
                continue
            assert validated[name][sig] == pytest.approx(v, abs=0.1), (sig, reported, validated)
    fp = held["fit_percent"][name]
    assert fp["motor_angle"] >= floor[0] and fp["tip_deflection"] >= floor[1], fp
    # validate says how it started each window
    assert any("refined by least squares" in n for n in held["notes"]), held["notes"]


@pytest.mark.parametrize("local", ["servo", "general"])
def test_the_hard_session_fit_is_validate_of_its_scenario(local, tmp_path):
    """The 4/27 session's two runs fitted together (whole logs, the README's data sheet,
    default options), then ``flexarm validate`` of the written scenario on the same two
    runs: the fit's figures to 0.1 point. Floors: hub 80 / tip 50 on each run (measured
    82.5 / 55.4 and 84.7 / 67.5; the rig loop's own figures, each log's start state
    estimated jointly with the parameters, were 83.1 / 54.8 and 84.1 / 67.6; issue #43
    asks 83 / 55: the K1 run's hub is 0.5 point short through the written scenario).
    ``--local general`` (the general engine after the servo's global stage, each log's
    start state estimated on that log alone in the prediction): measured 83.3 / 54.2 and
    81.6 / 65.7, the same floors."""
    logs = [DATA / "flexarm_K1_6", DATA / "flexarm_K1K2_6_-5"]
    fit_json, toml, out = tmp_path / "fit.json", tmp_path / "rig.toml", tmp_path / "v.json"
    _run(
        ["fit", *map(str, logs), "--log-format", str(FORMAT), *SHEET, "--local", local]
        + ["--scenario-out", str(toml), "--json", str(fit_json)]
    )
    fit = json.loads(fit_json.read_text())["fit_percent"]
    _run(["validate", str(toml), *map(str, logs), "--log-format", str(FORMAT), "--json", str(out)])
    val = json.loads(out.read_text())["fit_percent"]
    print("fit:", fit, "validate:", val)
    assert set(fit) == set(val) == {g.name for g in logs}
    for name, fp in fit.items():
        for sig, v in fp.items():
            assert val[name][sig] == pytest.approx(v, abs=0.1), (name, sig, fit, val)
        assert fp["motor_angle"] >= 80.0 and fp["tip_deflection"] >= 50.0, (name, fp)

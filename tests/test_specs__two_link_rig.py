"""Issue #17: the real two-link flexible arm (``../shared/data/two-link-rig``): its two file
layouts read with the log-format files in ``examples/`` through the one reader, the loader's
check against the swapped elbow variables, the built-in scenario ``quanser-two-link``, the
sensors' digital filters and the discrete LTI controller in the loop.

Real-data tests skip when ``../shared`` is absent; synthetic ones always run.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import scipy.io as sio

from flexarm.io.logformat import LogFormatError, load_log_format, log_format_from_dict
from flexarm.io.logs import LogError
from flexarm.io.matfile import MatFileError

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "two-link-rig"
RUN = DATA / "lqr_full_10deg.mat"
STAIR = DATA / "lqr-stair"
WORKSPACE = ROOT / "examples" / "two-link-workspace.toml"
SCOPE = ROOT / "examples" / "two-link-scope.toml"
STAIRCASE = ROOT / "examples" / "two-link-staircase.toml"
KE_D1, KE_D2 = 2 * np.pi / 409600, 2 * np.pi / 204800

needs_data = pytest.mark.skipif(
    not RUN.is_file(),
    reason=f"real two-link rig data not found at {DATA} (../shared is "
    "absent in a user's clone; CI has it)",
)

CHANNELS = {
    "theta_1",
    "alpha_f_1",
    "theta_dot_f_1",
    "alpha_dot_f_1",
    "theta_ref_1",
    "theta_2",
    "alpha_f_2",
    "theta_dot_f_2",
    "alpha_dot_f_2",
    "theta_ref_2",
}


@pytest.fixture(scope="module")
def run_log():
    if not RUN.is_file():
        pytest.skip(f"real two-link rig data not found at {DATA}")
    return load_log_format(WORKSPACE).read(RUN)


@pytest.fixture(scope="module")
def raw():
    if not RUN.is_file():
        pytest.skip(f"real two-link rig data not found at {DATA}")
    return sio.loadmat(RUN, squeeze_me=True, struct_as_record=False)


# ------------------------------------------------------------------ 1. log formats
@needs_data
def test_workspace_layout_loads_with_the_shipped_format(run_log, raw):
    log = run_log
    assert set(log.signals) == CHANNELS
    # README: 102 s at 2 ms, N = 51 087 samples
    assert len(log) == 51087
    np.testing.assert_allclose(np.diff(log.time), 2e-3, rtol=1e-8)
    # values exactly as in the file (no conversion: SI already); the elbow's measured state is
    # the variable named "_sim"
    np.testing.assert_array_equal(log["theta_2"], raw["stage2_X2_sim"].signals.values[:, 0])
    np.testing.assert_array_equal(log["theta_ref_2"], raw["stage2_X2_meas"].signals.values[:, 0])
    np.testing.assert_array_equal(log["alpha_dot_f_1"], raw["stage1_X1_meas"].signals.values[:, 3])
    # the setpoints are the README's square waves: ±25° and ±10° (exact in the file, to the
    # last bit of the deg → rad conversion)
    assert np.abs(log["theta_ref_1"]).max() == pytest.approx(np.deg2rad(25), rel=1e-12)
    assert np.abs(log["theta_ref_2"]).max() == pytest.approx(np.deg2rad(10), rel=1e-12)


@needs_data
def test_scope_captures_are_a_second_log_of_the_same_samples(run_log):
    scope = load_log_format(SCOPE).read(RUN)
    assert len(scope) == 10000  # README: the last 20 s at 2 ms
    w = run_log.window(
        scope.time[0] - run_log.time[0],  # [t0, t1) s from the first sample
        scope.time[-1] - run_log.time[0] + run_log.dt,
    )
    np.testing.assert_array_equal(w.time, scope.time)
    # the scope's degrees are the workspace's radians (converted by [units]); the file
    # holds rad·180/π rounded to double: agreement to 1e-12 relative of the range
    for k in ("theta_1", "alpha_f_1", "theta_2", "alpha_f_2", "theta_ref_1", "theta_ref_2"):
        span = np.ptp(w[k]) or 1.0
        assert np.abs(scope[k] - w[k]).max() <= 1e-12 * span, k
    # commanded currents stay within the README's limits 0.94 A and 1.2 A
    assert np.abs(scope["current_1"]).max() <= 0.94 + 1e-12
    assert np.abs(scope["current_2"]).max() <= 1.2 + 1e-12


@needs_data
def test_staircase_layout_loads_every_file():
    fmt = load_log_format(STAIRCASE)
    files = sorted(STAIR.glob("*.mat"))
    assert len(files) == 10
    for f in files:
        log = fmt.read(f)
        assert set(log.signals) == CHANNELS and len(log) == 2000, f.name
        np.testing.assert_allclose(np.diff(log.time), 2e-3, rtol=1e-8)
        assert np.all(log["theta_ref_2"] == 0.0)  # the elbow held at 0
    # the 5° step file's setpoint ends at its target
    log = fmt.read(STAIR / "lqr_step_5deg_run01.mat")
    assert log["theta_ref_1"][-1] == pytest.approx(np.deg2rad(5), rel=1e-9)


@needs_data
def test_loader_catches_the_swapped_elbow_variables():
    """A format that takes the variable names at their word (elbow measured = "_meas") maps
    the setpoint as the measured angle: it is off the encoder grid, and reading stops with a
    message naming the channel, the variable and the fix."""
    data = load_log_format(WORKSPACE).model_dump()
    for k in ("theta_2", "alpha_f_2", "theta_dot_f_2", "alpha_dot_f_2"):
        data["columns"][k] = data["columns"][k].replace("X2_sim", "X2_meas")
    data["columns"]["theta_ref_2"] = "stage2_X2_sim[0]"
    fmt = log_format_from_dict(data, "naive.toml")
    with pytest.raises(LogFormatError) as e:
        fmt.read(RUN)
    msg = str(e.value)
    for w in (
        "lqr_full_10deg.mat",
        "theta_2",
        "stage2_X2_meas[0]",
        "not an encoder reading",
        "naive.toml",
        "setpoint",
    ):
        assert w in msg, w
    # the rate columns of the setpoint are zero: a check of the right mapping passes, of the
    # swapped one fails
    cols = {"time": "stage1_X1_meas.time", "theta_dot_f_2": "stage2_X2_meas[2]"}
    ok = log_format_from_dict({"columns": cols, "checks": {"zero": ["theta_dot_f_2"]}}, "z.toml")
    assert np.all(ok.read(RUN)["theta_dot_f_2"] == 0.0)
    cols["theta_dot_f_2"] = "stage2_X2_sim[2]"
    bad = log_format_from_dict({"columns": cols, "checks": {"zero": ["theta_dot_f_2"]}}, "z.toml")
    with pytest.raises(LogFormatError, match="theta_dot_f_2.*must be all zeros"):
        bad.read(RUN)


def test_mat_log_format_synthetic(tmp_path):
    """The one reader on a synthetic workspace: struct values, sign, [units], window, checks,
    and the errors naming file and field (a struct without signals.values)."""
    n = 50
    q = 1e-3
    t = np.arange(n) * 2e-3
    th = np.round(np.sin(t * 20) / q) * q
    p = tmp_path / "ws.mat"
    sio.savemat(
        p,
        {
            "X": {"time": t, "signals": {"values": np.column_stack([th, 2 * th])}},
            "S": {"time": t, "blockName": "scope"},
            "deg": np.rad2deg(th),
            "Q": q,
        },
    )
    fmt = log_format_from_dict(
        {
            "columns": {
                "time": "X.time",
                "theta_1": "X[0]",
                "alpha_f_1": "-X[1]",
                "theta_2": "deg",
            },
            "units": {"theta_2": "deg"},
            "checks": {"quantum": {"theta_1": "Q", "theta_2": q}},
        },
        "f.toml",
    )
    log = fmt.read(p)
    np.testing.assert_array_equal(log["alpha_f_1"], -2 * th)
    np.testing.assert_allclose(log["theta_2"], th, rtol=1e-14, atol=1e-17)  # deg → rad
    w = log.window(0.01, 0.022)  # [t0, t1) s from the first sample
    np.testing.assert_allclose(w.time, t[5:11], rtol=0, atol=1e-15)
    with pytest.raises(LogError, match="lies outside the log"):
        log.window(5.0, 6.0)
    # a struct without signals.values: the error names the file, the channel and the struct
    bad = log_format_from_dict({"columns": {"time": "X.time", "theta_1": "S"}}, "g.toml")
    with pytest.raises(MatFileError) as e:
        bad.read(p)
    for w in ("ws.mat", "theta_1", "'S'", "struct without signals.values", "time, blockName"):
        assert w in str(e.value), w
    # a name flexarm does not know is refused by the format, naming it and the known ones
    with pytest.raises(LogFormatError, match="'thet_1' is not one of flexarm's column names"):
        log_format_from_dict({"columns": {"thet_1": "X[0]"}}, "h.toml")
    # a check on a channel the format does not map
    with pytest.raises(LogFormatError, match="theta_9"):
        log_format_from_dict(
            {
                "columns": {"time": "X.time", "theta_1": "X[0]"},
                "checks": {"quantum": {"theta_9": 1e-3}},
            },
            "i.toml",
        )
    # the time column is required
    with pytest.raises(LogFormatError, match="maps no time"):
        log_format_from_dict({"columns": {"theta_1": "X[0]"}}, "j.toml").read(p)


# ------------------------------------------------------------------ 2. the built-in scenario
#: the workspace's parameters (lqr_full_10deg.mat), for checks that need no data folder
SHEET = dict(
    J11=0.06353616,
    J12=0.170434272,
    J21=0.00301955,
    J22=0.006438700964166668,
    Ks1=39.957193021017844,
    Ks2=6.857750992455394,
    Ktg1=8.925,
    Ktg2=0.87,
    B11=4.0,
    B21=1.5,
    B12=0.0,
    B22=0.085608,
)


@pytest.fixture(scope="module")
def rig():
    from flexarm.sim.build import prepare
    from flexarm.specs import load_scenario

    return prepare(load_scenario("quanser-two-link"))


def _stage(rig, keep):
    """The linear model (A, B) of the coordinates ``keep`` of q = (θ1, θ2, α1, α2) with the
    others locked, at the straight arm, in the lab's state order [θ, α, θ̇, α̇]."""
    arm, model = rig.loop.plant, rig.model
    M = np.asarray(model.mass_matrix(np.zeros(model.n_q)))
    Kq = np.zeros((4, 4))
    Dq = np.zeros((4, 4))
    Kq[2:, 2:] = model.K
    Dq[2:, 2:] = model.D
    Dq[0, 0], Dq[1, 1] = np.asarray(arm.viscous)
    ku = np.zeros((4, 2))
    ku[0, 0], ku[1, 1] = np.asarray(arm.k_u)
    ix = np.ix_(keep, keep)
    Mi = np.linalg.inv(M[ix])
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [-Mi @ Kq[ix], -Mi @ Dq[ix]]])
    B = np.concatenate([np.zeros((2, 2)), Mi @ ku[keep]])
    return A, B, M


def _lab_stage(J1, J2, Ks, B1, B2, Kt):
    """The lab's decoupled stage model (A1/A2, B1/B2 of the workspace): J1 θ̈ = Kt i − B1 θ̇ +
    Ks α + B2 α̇, J2 (θ̈ + α̈) = −Ks α − B2 α̇."""
    A = np.zeros((4, 4))
    A[0, 2] = A[1, 3] = 1
    A[2, 1], A[2, 2], A[2, 3] = Ks / J1, -B1 / J1, B2 / J1
    A[3, 1], A[3, 2], A[3, 3] = -Ks * (1 / J1 + 1 / J2), B1 / J1, -B2 * (1 / J1 + 1 / J2)
    return A, np.array([0, 0, Kt / J1, -Kt / J1])


def test_scenario_is_listed_and_stages_are_the_lab_models(rig):
    """With the elbow (θ2, α2) locked the shoulder stage is the lab's A1, B1; with link 1
    (θ1, α1) locked the elbow stage is A2, B2 (the J12 split keeps the straight-arm inertia
    beyond the shoulder spring at J12). Tolerance 1e-12 relative: the same numbers through
    a matrix inverse."""
    from flexarm.specs import builtin_scenarios

    assert "quanser-two-link" in builtin_scenarios()
    s = SHEET
    A, B, M = _stage(rig, [0, 2])
    A1, B1 = _lab_stage(s["J11"], s["J12"], s["Ks1"], s["B11"], s["B12"], s["Ktg1"])
    np.testing.assert_allclose(A, A1, rtol=1e-12, atol=1e-12 * np.abs(A1).max())
    np.testing.assert_allclose(B[:, 0], B1, rtol=1e-12)
    # straight-arm inertia seen by joint 1 beyond its spring: J12; hub + all: J11 + J12
    assert M[2, 2] == pytest.approx(s["J12"], rel=1e-12)
    assert M[0, 0] == pytest.approx(s["J11"] + s["J12"], rel=1e-12)
    # joint 1 held too: link 1 rings at sqrt(Ks1 / J12) (rad/s)
    assert math.sqrt(s["Ks1"] / M[2, 2]) == pytest.approx(math.sqrt(s["Ks1"] / s["J12"]), rel=1e-12)
    A, B, M = _stage(rig, [1, 3])
    A2, B2 = _lab_stage(s["J21"], s["J22"], s["Ks2"], s["B21"], s["B22"], s["Ktg2"])
    np.testing.assert_allclose(A, A2, rtol=1e-12, atol=1e-12 * np.abs(A2).max())
    np.testing.assert_allclose(B[:, 1], B2, rtol=1e-12)
    # the stage eigenvalues (free hub: two-inertia oscillator) are the lab model's
    for Ast, Alab in ((_stage(rig, [0, 2])[0], A1), (A, A2)):
        e1 = np.sort_complex(np.linalg.eigvals(Ast))
        e2 = np.sort_complex(np.linalg.eigvals(Alab))
        np.testing.assert_allclose(e1, e2, rtol=1e-10, atol=1e-10)


@needs_data
def test_scenario_numbers_are_the_files(raw):
    """The scenario's stage models equal the workspace's own A1, B1, A2, B2 (to the file's
    printing: the TOML holds the file's values to 17 digits)."""
    from flexarm.sim.build import prepare
    from flexarm.specs import load_scenario

    rig = prepare(load_scenario("quanser-two-link"))
    A, B, _ = _stage(rig, [0, 2])
    np.testing.assert_allclose(A, raw["A1"], rtol=1e-12, atol=1e-12 * np.abs(raw["A1"]).max())
    np.testing.assert_allclose(B[:, 0], raw["B1"], rtol=1e-12)
    A, B, _ = _stage(rig, [1, 3])
    np.testing.assert_allclose(A, raw["A2"], rtol=1e-12, atol=1e-12 * np.abs(raw["A2"]).max())
    np.testing.assert_allclose(B[:, 1], raw["B2"], rtol=1e-12)
    ctrl = rig.loop.controller
    np.testing.assert_array_equal(np.asarray(ctrl.D)[0, :4], raw["K1"])
    np.testing.assert_array_equal(np.asarray(ctrl.D)[1, 4:], raw["K2"])
    q = np.asarray(rig.loop.sensors.quantum)
    names = rig.loop.sensors.names
    assert q[names.index("theta_1")] == raw["KE_D1"] and q[names.index("theta_2")] == raw["KE_D2"]


# ------------------------------------------------------------------ 3. digital sensor filters
FE = "forward_euler"


@needs_data
def test_derivative_filter_reproduces_the_logged_rate(run_log):
    """The lab's θ̇_f is the encoder angle through ω²s/(s² + 2ζωs + ω²), ω = 2π·40 Hz,
    ζ = 0.9, forward Euler at 2 ms, at rest on the first reading: the filter applied to the
    logged θ reproduces the logged θ̇_f to round-off (1e-12 of its range: 51 087 steps of
    a stable recursion in double precision)."""
    from flexarm.control.lti import digital_filter

    f = digital_filter({"kind": "derivative2", "cutoff": 40.0, "damping": 0.9}, 2e-3)
    for j in (1, 2):
        v, _ = f.run(run_log[f"theta_{j}"])
        ref = run_log[f"theta_dot_f_{j}"]
        assert np.abs(v - ref).max() <= 1e-12 * np.abs(ref).max(), j
    # the logged α̇_f is the rate state of the α low-pass: α_f⁺ = α_f + T α̇_f (forward
    # Euler), to round-off
    for j in (1, 2):
        a, ad = run_log[f"alpha_f_{j}"], run_log[f"alpha_dot_f_{j}"]
        assert np.abs((a[1:] - a[:-1]) / 2e-3 - ad[:-1]).max() <= 1e-9 * np.abs(ad).max()


def _ramp_loop(channels, dt=2e-3):
    import jax.numpy as jnp

    from flexarm.control import discrete
    from flexarm.models.plant import Plant
    from flexarm.sim.sampled import Actuator, SampledLoop, Sensors

    class Ramp(Plant):
        """ṗ = v0 = 0.3: its signal s(t) = 0.1 + 0.3 t."""

        def rhs(self, x, u):
            return jnp.full((1,), 0.3)

        def signals(self, x, u):
            return x[:1]

    plant = Ramp(("p",), ("s",), ("u",))
    sens = Sensors.make(plant, channels, dt)
    ctrl = discrete.from_transfer_function(([0.0], [1.0]), dt, measured=next(iter(channels)))
    return SampledLoop(
        plant, ctrl, sens, Actuator(jnp.asarray([1.0]), jnp.asarray([0.0])), jnp.asarray(dt), 2
    )


@pytest.mark.parametrize("how", ["forward_euler", "zoh", "tustin"])
def test_digital_filters_in_the_loop_match_an_independent_recursion(how):
    """Channels reading one signal (a ramp 0.1 + 0.3 t) through the three filter kinds, in
    the sampled loop, equal the same filters run in numpy on the quantised samples (1e-12:
    the same recursion, jit vs numpy), start at rest on the first reading, and settle on
    the ramp's rate (rate kinds: 0.3, to 1e-9 after 3 s, the slowest pole's decay) and its
    lagged value (lowpass2: 0.1 + 0.3 (t − 2ζ/ω), forward Euler's exact lag)."""
    from flexarm.control.lti import digital_filter
    from flexarm.sim.sampled import simulate_loop

    q = 1e-4
    f2 = {"kind": "lowpass2", "cutoff": 2.0, "damping": 0.9, "discretisation": how}
    chans = {
        "s": {"quantum": q},
        "lp": {"signal": "s", "quantum": q, "filter": f2},
        "lpr": {"signal": "s", "quantum": q, "filter": {**f2, "kind": "lowpass2_rate"}},
        "d": {
            "signal": "s",
            "quantum": q,
            "filter": {
                "kind": "derivative2",
                "cutoff": 40.0,
                "damping": 0.9,
                "discretisation": how,
            },
        },
        "tf": {"signal": "s", "filter": {"kind": "tf", "num": [0.5, 0.0], "den": [1.0, -0.5]}},
    }
    loop = _ramp_loop(chans)
    n = 2000
    out = simulate_loop(loop, np.array([0.1]), {}, n)
    meas = dict(zip(loop.sensors.names, out["measured"].T, strict=True))
    y = meas["s"]
    t = np.arange(n) * 2e-3
    np.testing.assert_allclose(y, np.round((0.1 + 0.3 * t) / q) * q, atol=1e-12)
    for name in ("lp", "lpr", "d", "tf"):
        v, _ = digital_filter(chans[name]["filter"], 2e-3).run(y if name != "tf" else 0.1 + 0.3 * t)
        np.testing.assert_allclose(meas[name], v, rtol=1e-12, atol=1e-12, err_msg=name)
    assert meas["lp"][0] == pytest.approx(0.1, abs=1e-15)  # at rest on the first reading
    assert abs(meas["lpr"][0]) < 1e-14 and abs(meas["d"][0]) < 1e-12  # round-off of the solve
    # settled: the rate kinds read the ramp's rate (forward Euler and Tustin map s = 0 to
    # z = 1 and see the samples of a ramp; zoh filters the held staircase, whose rate at
    # the sample instants is biased by the 40 Hz filter's phase within a period)
    if how != "zoh":
        assert abs(meas["lpr"][-1] - 0.3) < 1e-3
        assert abs(np.mean(meas["d"][-500:]) - 0.3) < 1e-3
    if how == "forward_euler":
        lag = 2 * 0.9 / (2 * np.pi * 2.0)
        assert meas["lp"][-1] == pytest.approx(0.1 + 0.3 * (t[-1] - lag), abs=2 * q)


def test_filter_state_settable_and_read_from_a_log():
    """A filter started from given states runs on from them: a log made by the loop itself
    restarted at sample k from filter_state_from_log(...) continues that log exactly
    (the states the rules read off its outputs are the loop's own, to round-off)."""
    from flexarm.io.logs import Log
    from flexarm.sim.filters import filter_state_from_log, with_filter_state
    from flexarm.sim.sampled import simulate_loop
    from flexarm.specs.experiment import Sensor

    f2 = {"kind": "lowpass2", "cutoff": 2.0, "damping": 0.9}
    specs = {
        "s": Sensor(),
        "lp": Sensor(signal="s", filter=f2),
        "lpr": Sensor(signal="s", filter={**f2, "kind": "lowpass2_rate"}),
        "d": Sensor(signal="s", filter={"kind": "derivative2", "cutoff": "40 Hz"}),
    }
    loop = _ramp_loop({k: v.model_dump() for k, v in specs.items()})
    n, k = 1500, 700
    out = simulate_loop(loop, np.array([0.1]), {}, n)
    log = Log(
        None, np.arange(n) * 2e-3, dict(zip(loop.sensors.names, out["measured"].T, strict=True))
    )
    states = filter_state_from_log(specs, log, k, 2e-3)
    assert set(states) == {"lp", "lpr", "d"}
    later = simulate_loop(with_filter_state(loop, states), out["states"][k], {}, n - k)
    for j, name in enumerate(loop.sensors.names):
        np.testing.assert_allclose(
            later["measured"][:, j], out["measured"][k:, j], rtol=1e-9, atol=1e-12, err_msg=name
        )
    # without its sibling, a lowpass2 state comes from the forward-Euler difference of its
    # own output (exact), a rate state from the filter run over the unfiltered reading
    alone = {n_: specs[n_] for n_ in ("s", "lp", "d")}
    st2 = filter_state_from_log(alone, log, k, 2e-3)
    np.testing.assert_allclose(st2["lp"], states["lp"], rtol=1e-9)
    np.testing.assert_allclose(st2["d"], states["d"], rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="'s' has no digital filter"):
        with_filter_state(loop, {"s": [0.0]})


def test_bad_filter_specs_are_named():
    from flexarm.control.lti import digital_filter
    from flexarm.specs.experiment import Sensor

    with pytest.raises(ValueError, match="needs cutoff"):
        Sensor(filter={"kind": "lowpass2"})
    with pytest.raises(ValueError, match="angular frequency"):
        Sensor(filter={"kind": "lowpass2", "cutoff": "12.57 rad/s"})
    with pytest.raises(ValueError, match="needs num and den"):
        Sensor(filter={"kind": "tf", "num": [1.0]})
    with pytest.raises(ValueError, match="quantum .* or bits"):
        Sensor(quantum=1e-3, bits=12)
    # forward Euler of a 200 Hz filter at 2 ms is unstable: named, with the remedy
    with pytest.raises(
        ValueError, match=r"sensor 'x': filter: the discrete filter is not stable.*tustin"
    ):
        digital_filter(
            {"kind": "lowpass2", "cutoff": 200.0, "damping": 0.9}, 2e-3, where="sensor 'x': filter"
        )


# ------------------------------------------------------------------ 4. LTI controller
def _ctrl(**kw):
    from flexarm.control.lti import lti_controller

    base = dict(
        inputs=["y1", "y2"],
        setpoints=["r", 0],
        outputs=["current_1"],
        input_names=("current_1", "current_2"),
        base_dt=1e-3,
    )
    return lti_controller(**{**base, **kw})


def _steps(ctrl, ys, rs):
    state = ctrl.init()
    us = []
    for y, r in zip(ys, rs, strict=True):
        state, u = ctrl.step(state, {"y1": y[0], "y2": y[1]}, {"r": r})
        us.append(np.asarray(u))
    return np.array(us)


def test_lti_controller_state_space_period_and_hold():
    """x⁺ = A x + B e, u = C x + D e on e = (r − y1, −y2), computed by hand in numpy;
    at dt = 3 T it updates every third sample and holds its output in between."""
    rng = np.random.default_rng(0)
    A = np.array([[0.5, 0.1], [0.0, 0.8]])
    B = np.array([[1.0, 0.0], [0.5, -1.0]])
    C = np.array([[0.3, -0.2]])
    D = np.array([[2.0, -1.0]])
    n = 12
    ys, rs = rng.normal(size=(n, 2)), rng.normal(size=n)
    for every in (1, 3):
        ctrl = _ctrl(A=A, B=B, C=C, D=D, dt=every * 1e-3, x0=[0.1, -0.1])
        us = _steps(ctrl, ys, rs)
        x = np.array([0.1, -0.1])
        want = np.zeros((n, 2))
        held = np.zeros(2)
        for k in range(n):
            if k % every == 0:
                e = np.array([rs[k] - ys[k, 0], -ys[k, 1]])
                held = np.array([(C @ x + D @ e)[0], 0.0])  # output 1 → current_1
                x = A @ x + B @ e
            want[k] = held
        np.testing.assert_allclose(us, want, rtol=1e-13, atol=1e-15)


def test_lti_controller_from_python_control_and_files(tmp_path):
    """The same controller from a python-control StateSpace (its dt the period), from .npz,
    JSON and .mat files, and SISO num/den: the same commands (1e-12: realisation
    round-off)."""
    import json

    import control

    from flexarm.control.lti import lti_from_spec
    from flexarm.specs.experiment import LTIControllerSpec

    A, B, C, D = [[0.9]], [[1.0, 0.0]], [[0.5]], [[1.0, 2.0]]
    ref = _ctrl(A=A, B=B, C=C, D=D, dt=2e-3)
    rng = np.random.default_rng(1)
    ys, rs = rng.normal(size=(10, 2)), rng.normal(size=10)
    want = _steps(ref, ys, rs)
    sys = control.ss(A, B, C, D, 2e-3)
    np.testing.assert_allclose(_steps(_ctrl(tf=sys), ys, rs), want, rtol=1e-12)
    assert _ctrl(tf=sys).every == 2
    np.savez(tmp_path / "c.npz", A=A, B=B, C=C, D=D, dt=2e-3)
    (tmp_path / "c.json").write_text(json.dumps({"A": A, "B": B, "C": C, "D": D, "dt": 2e-3}))
    sio.savemat(tmp_path / "c.mat", {"A": A, "B": B, "C": C, "D": D, "dt": 2e-3})
    for f in ("c.npz", "c.json", "c.mat"):
        spec = LTIControllerSpec(
            type="lti", file=str(tmp_path / f), inputs=["y1", "y2"], setpoints=["r", 0], outputs=[1]
        )
        c = lti_from_spec(spec, base_dt=1e-3, input_names=("current_1", "current_2"))
        assert c.every == 2
        np.testing.assert_allclose(_steps(c, ys, rs), want, rtol=1e-12, err_msg=f)
    # SISO num/den: C(z) = (z − 0.5)/(z − 0.9) on e = r − y1
    siso = _ctrl(inputs=["y1"], setpoints=["r"], tf=([1.0, -0.5], [1.0, -0.9]))
    u = _steps(siso, np.c_[ys[:, 0], 0 * ys[:, 0]], rs)[:, 0]
    e = rs - ys[:, 0]
    x, want1 = 0.0, []
    for ek in e:  # u = e + 0.4 x, x⁺ = 0.9 x + e
        want1.append(ek + 0.4 * x)
        x = 0.9 * x + ek
    np.testing.assert_allclose(u, want1, rtol=1e-12)


def test_lti_controller_bad_input():
    """Matrices that do not fit the named signals, a period that is not a multiple of the
    base period, an unstable controller (named eigenvalue; allowed on request)."""
    with pytest.raises(ValueError, match=r"D is 1 × 3.*2 input\(s\).*must be 1 × 2"):
        _ctrl(D=[[1.0, 2.0, 3.0]])
    with pytest.raises(ValueError, match=r"B is 1 × 3.*must be 1 × 2"):
        _ctrl(A=[[0.5]], B=[[1.0, 2.0, 3.0]], C=[[1.0]], D=[[0.0, 0.0]])
    with pytest.raises(
        ValueError,
        match=r"dt = 0.0025 s is not a whole multiple of the loop's "
        r"sampling period 0.001 s",
    ):
        _ctrl(D=[[1.0, 0.0]], dt=2.5e-3)
    with pytest.raises(ValueError, match=r"unstable: eigenvalue 1\.1.*allow_unstable"):
        _ctrl(A=[[1.1]], B=[[1.0, 0.0]], C=[[1.0]], D=[[0.0, 0.0]])
    c = _ctrl(A=[[1.1]], B=[[1.0, 0.0]], C=[[1.0]], D=[[0.0, 0.0]], allow_unstable=True)
    assert float(c.A[0, 0]) == 1.1
    _ctrl(A=[[1.0]], B=[[1.0, 0.0]], C=[[1.0]], D=[[0.0, 0.0]])  # an integrator is allowed
    with pytest.raises(ValueError, match="output 'current_3' is not an input of the plant"):
        _ctrl(D=[[1.0, 0.0]], outputs=["current_3"])
    with pytest.raises(ValueError, match="initial_state has 2 value"):
        _ctrl(A=[[0.5]], B=[[1.0, 0.0]], C=[[1.0]], D=[[0.0, 0.0]], x0=[0.0, 0.0])


def test_lti_bad_input_through_the_scenario():
    """The same errors from a scenario file, naming [controller] and the fix."""
    from _helpers import scenario_dict
    from flexarm.sim.build import prepare
    from flexarm.specs import ScenarioError, scenario_from_dict

    base = scenario_dict("quanser-two-link")
    bad = {
        **base,
        "controller": {**base["controller"], "D": [r[:7] for r in base["controller"]["D"]]},
    }
    with pytest.raises(ValueError, match=r"\[controller\]: D is 2 × 7.*8 input\(s\)"):
        prepare(scenario_from_dict(bad))
    bad = {**base, "controller": {**base["controller"], "dt": "3 ms"}}
    with pytest.raises(ValueError, match="not a whole multiple"):
        prepare(scenario_from_dict(bad))
    bad = {**base, "controller": {**base["controller"], "setpoints": ["theta_ref_9"] + [0] * 7}}
    with pytest.raises(ValueError, match="setpoint 'theta_ref_9' is not a reference channel"):
        prepare(scenario_from_dict(bad))
    bad = {**base, "controller": {**base["controller"], "num": [1.0], "den": [1.0]}}
    with pytest.raises(ScenarioError, match="one way"):
        scenario_from_dict(bad)


# ------------------------------------------------------------------ 5. controller check
@needs_data
def test_lab_law_reproduces_the_logged_current(run_log, rig):
    """The scenario's LTI controller (the lab's LQR, D = blockdiag(K1, K2)) applied to the
    logged states and setpoints reproduces the commanded currents of the scope window
    (82.174–102.172 s). Measured worst errors: 3.3e-16 A (shoulder, t = 85.486 s) and
    1.7e-16 A (elbow, t = 92.728 s): the same products in another order; asserted to 1e-12 A."""
    import jax

    scope = load_log_format(SCOPE).read(RUN)
    w = run_log.window(
        scope.time[0] - run_log.time[0],  # [t0, t1) s from the first sample
        scope.time[-1] - run_log.time[0] + run_log.dt,
    )
    ctrl = rig.loop.controller
    meas = {k: w[k] for k in ctrl.inputs}
    refs = {k: w[k] for k in ctrl.reference_signals}
    _, u = jax.vmap(lambda m, r: ctrl.step(ctrl.init(), m, r))(meas, refs)
    u = np.clip(
        np.asarray(u), -np.asarray(rig.loop.actuator.limit), np.asarray(rig.loop.actuator.limit)
    )
    for j in (0, 1):
        err = np.abs(u[:, j] - scope[f"current_{j + 1}"])
        assert err.max() <= 1e-12, (j, err.max(), w.time[np.argmax(err)])


# ------------------------------------------------------------------ 6. replay with the data sheet
@pytest.fixture(scope="module")
def synthetic_log(rig):
    """The scenario's own 3 s run from rest (the square-wave setpoints), its measured
    channels and setpoints as a log."""
    from flexarm.io.logs import Log
    from flexarm.sim.build import prepare, run_prepared
    from flexarm.specs import load_scenario

    sc = load_scenario("quanser-two-link")
    sc = sc.model_copy(update={"simulation": sc.simulation.model_copy(update={"duration": 3.0})})
    p = prepare(sc)
    res = run_prepared(p)
    sig = {
        **{k: np.asarray(v) for k, v in res.measured.items()},
        "theta_ref_1": p.references["theta_ref_1"],
        "theta_ref_2": p.references["theta_ref_2"],
    }
    return sc, Log(None, np.asarray(p.time), sig)


@pytest.mark.slow
def test_replay_of_the_scenarios_own_log_is_exact(synthetic_log):
    """Replaying a log the scenario made (from rest) on the same scenario: setpoints, initial
    state and filter states taken from the log give back every channel (fit 100 % to 1e-6
    points: the same jit-compiled loop, round-off only)."""
    from flexarm.analysis.replay import replay

    sc, log = synthetic_log
    rep = replay(sc, log)
    assert set(rep.fit_percent) == {
        "theta_1",
        "alpha_f_1",
        "theta_dot_f_1",
        "alpha_dot_f_1",
        "theta_2",
        "alpha_f_2",
        "theta_dot_f_2",
        "alpha_dot_f_2",
    }
    for k, v in rep.fit_percent.items():
        assert v == pytest.approx(100.0, abs=1e-6), k
    # drawn by the one overlay figure: a panel per compared channel, titled with its fit %,
    # the logged and the simulated trace the replay's own arrays
    from flexarm.analysis.replay import as_prediction
    from flexarm.identification.time_domain.predict import overlay_figure

    pred = as_prediction(rep, sc.name)
    fig = overlay_figure(pred, next(iter(pred.traces)))
    axes = fig.get_axes()
    assert [a.get_title() for a in axes] == [
        f"{k}: fit {v:.1f} %" for k, v in rep.fit_percent.items()
    ]
    line = axes[0].get_lines()
    np.testing.assert_array_equal(line[0].get_ydata(), log["theta_1"])
    np.testing.assert_array_equal(line[1].get_ydata(), rep.result.measured["theta_1"])
    # the log's step must be the scenario's sampling period
    from flexarm.io.logs import Log

    coarse = Log(None, log.time[::2], {k: v[::2] for k, v in log.signals.items()})
    with pytest.raises(ValueError, match=r"every 0.004 s.*period is 0.002 s.*period_tolerance"):
        replay(sc, coarse)


def test_cli_simulate_replays_a_mat_log(tmp_path, synthetic_log):
    """``flexarm simulate SCENARIO --log F.mat --log-format F.toml``: the table, replay.json
    with fit % per channel (the replay's own numbers) and an overlay figure."""
    import json

    from typer.testing import CliRunner

    from flexarm.cli import app

    sc, log = synthetic_log
    X1 = np.column_stack(
        [log[k] for k in ("theta_1", "alpha_f_1", "theta_dot_f_1", "alpha_dot_f_1")]
    )
    X2 = np.column_stack(
        [log[k] for k in ("theta_2", "alpha_f_2", "theta_dot_f_2", "alpha_dot_f_2")]
    )
    R1 = np.column_stack([log["theta_ref_1"]] + [0 * log.time] * 3)
    R2 = np.column_stack([log["theta_ref_2"]] + [0 * log.time] * 3)
    sio.savemat(
        tmp_path / "s.mat",
        {"time": log.time, "X1_meas": X1, "X1_ref": R1, "X2_sim": X2, "X2_meas": R2},
    )
    r = CliRunner().invoke(
        app,
        [
            "simulate",
            "quanser-two-link",
            "--out",
            str(tmp_path / "o"),
            "--log",
            str(tmp_path / "s.mat"),
            "--log-format",
            str(STAIRCASE),
            "--window",
            "0:2",
        ],
    )
    assert r.exit_code == 0, r.output
    got = json.loads((tmp_path / "o" / "replay.json").read_text())["fit_percent"]
    fp = got[str(tmp_path / "s.mat")]
    assert fp["theta_1"] == pytest.approx(100.0, abs=1e-4)  # rounded to 0.01 in the JSON
    assert (tmp_path / "o" / "replay-s.png").stat().st_size > 10_000
    # a log that is not there: exit 2, one line naming it
    r = CliRunner().invoke(
        app,
        [
            "simulate",
            "quanser-two-link",
            "--out",
            str(tmp_path / "p"),
            "--log",
            str(tmp_path / "nope.mat"),
            "--log-format",
            str(STAIRCASE),
        ],
    )
    assert r.exit_code == 2 and "nope.mat" in r.output


def test_cli_simulate_window_counts_from_the_logs_first_sample(tmp_path, synthetic_log):
    """``--window START:STOP`` is in s from the log's first sample (the one window rule of
    io.logs.Log.window, which replay applies): a log whose clock starts at 100 s replays
    its first 2 s as the log starting at 0 does (the CLI added the first time stamp
    again, and the window fell outside such a log)."""
    import json

    from typer.testing import CliRunner

    from flexarm.cli import app

    sc, log = synthetic_log
    X1 = np.column_stack(
        [log[k] for k in ("theta_1", "alpha_f_1", "theta_dot_f_1", "alpha_dot_f_1")]
    )
    X2 = np.column_stack(
        [log[k] for k in ("theta_2", "alpha_f_2", "theta_dot_f_2", "alpha_dot_f_2")]
    )
    R1 = np.column_stack([log["theta_ref_1"]] + [0 * log.time] * 3)
    R2 = np.column_stack([log["theta_ref_2"]] + [0 * log.time] * 3)
    fps = []
    for t0 in (0.0, 100.0):
        f = tmp_path / f"s{t0:g}.mat"
        sio.savemat(
            f, {"time": log.time + t0, "X1_meas": X1, "X1_ref": R1, "X2_sim": X2, "X2_meas": R2}
        )
        out = tmp_path / f"o{t0:g}"
        r = CliRunner().invoke(
            app,
            [
                "simulate",
                "quanser-two-link",
                "--out",
                str(out),
                "--log",
                str(f),
                "--log-format",
                str(STAIRCASE),
                "--window",
                "0:2",
            ],
        )
        assert r.exit_code == 0, r.output
        fps.append(json.loads((out / "replay.json").read_text())["fit_percent"][str(f)])
    assert fps[1] == fps[0]
    assert fps[1]["theta_1"] == pytest.approx(100.0, abs=1e-4)


@pytest.mark.slow
@needs_data
def test_data_sheet_replay_of_the_102_s_run(run_log):
    """The 102 s run replayed with the data sheet's values, no fit (logged setpoints, initial
    state and filter states from the log). Measured: theta_1 98.4 %, alpha_f_1 56.9 %,
    theta_2 84.1 %, alpha_f_2 36.3 % (rates 93.2 / 44.7 / 52.5 / 25.9). Asserted: the
    shoulder angle at least 95 % (the issue's held-out target for the fitted model: the
    sheet's shoulder stage already meets it) and every channel better than the mean (> 0 %);
    the deflections and the elbow need the fit (sheet stiffness, torque constants and the
    friction placeholders: docs/choices.md)."""
    from flexarm.analysis.replay import replay
    from flexarm.specs import load_scenario

    rep = replay(load_scenario("quanser-two-link"), run_log)
    assert rep.fit_percent["theta_1"] >= 95.0
    assert min(rep.fit_percent.values()) > 0.0


# ------------------------------------------------------------------ the scenario from a workspace
def _close(a, b, path=""):
    """Recursive comparison of validated specs (SI floats to 1e-12 relative)."""
    if isinstance(a, dict):
        assert set(a) == set(b), path
        for k in a:
            _close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _close(x, y, f"{path}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert a == pytest.approx(b, rel=1e-12, abs=1e-300), path
    else:
        assert a == b, path


@needs_data
def test_scenario_from_the_workspace_is_the_builtin(tmp_path):
    """``flexarm scenario-from-mat lqr_full_10deg.mat`` writes the built-in scenario's arm,
    sensors, controller and sampling (the built-in TOML holds the file's numbers to 17
    digits, so equal to 1e-12 relative), and names a missing variable."""
    from typer.testing import CliRunner

    from flexarm.cli import app
    from flexarm.specs import load_scenario

    r = CliRunner().invoke(app, ["scenario-from-mat", str(RUN), "--out", str(tmp_path / "s.toml")])
    assert r.exit_code == 0, r.output
    got, ref = load_scenario(tmp_path / "s.toml"), load_scenario("quanser-two-link")
    a, b = got.model_dump(), ref.model_dump()
    for sec in ("arm", "sensors", "controller", "sampling", "references"):
        _close(a[sec], b[sec], sec)
    sio.savemat(tmp_path / "w.mat", {"J11": 1.0})
    r = CliRunner().invoke(
        app, ["scenario-from-mat", str(tmp_path / "w.mat"), "--out", str(tmp_path / "t.toml")]
    )
    assert r.exit_code == 2 and "J12" in r.output and "w.mat" in r.output


def test_controller_state_from_the_log_before_a_window():
    """A dynamic controller's state at sample k, run over a log of its inputs, is the state
    its own stepping reached (1e-12: the same products)."""
    from flexarm.control.lti import state_from_log
    from flexarm.io.logs import Log

    rng = np.random.default_rng(2)
    ctrl = _ctrl(
        A=[[0.5, 0.1], [0.0, 0.8]],
        B=[[1.0, 0.0], [0.5, -1.0]],
        C=[[0.3, -0.2]],
        D=[[2.0, -1.0]],
        dt=2e-3,
        x0=[0.2, 0.0],
    )
    n, k = 40, 25
    ys, rs = rng.normal(size=(n, 2)), rng.normal(size=n)
    log = Log(None, np.arange(n) * 1e-3, {"y1": ys[:, 0], "y2": ys[:, 1], "r": rs})
    state = ctrl.init()
    for j in range(k):
        state, _ = ctrl.step(state, {"y1": ys[j, 0], "y2": ys[j, 1]}, {"r": rs[j]})
    np.testing.assert_allclose(state_from_log(ctrl, log, k), np.asarray(state[0]), rtol=1e-12)
    with pytest.raises(ValueError, match="has no r"):
        state_from_log(ctrl, Log(None, log.time, {"y1": ys[:, 0], "y2": ys[:, 1]}), k)

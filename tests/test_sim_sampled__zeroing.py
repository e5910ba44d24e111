"""Issue #24, item 7: the logger's zeroing (``[sensors.X] zeroing = "1 s"``): the channel reads
0 over the window, then its reading minus the reading's mean over the window, before the
channel's digital filter (the lab's filtered gauge leaves rest one sample after the window).
Checked against an analytic ramp, through a digital filter, on the real rig's log (its
shoulder gauge is held at 0 for exactly 500 samples = 1 s), and the bad inputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "two-link-rig"
RUN = DATA / "lqr_full_10deg.mat"
DT = 2e-3


def _ramp_loop(channels):
    """The signal s(t) = 0.1 + 0.3 t sampled every 2 ms."""
    import jax.numpy as jnp

    from flexarm.control import discrete
    from flexarm.models.plant import Plant
    from flexarm.sim.sampled import Actuator, SampledLoop, Sensors

    class Ramp(Plant):
        def rhs(self, x, u):
            return jnp.full((1,), 0.3)

        def signals(self, x, u):
            return x[:1]

    plant = Ramp(("p",), ("s",), ("u",))
    sens = Sensors.make(plant, channels, DT)
    ctrl = discrete.from_transfer_function(([0.0], [1.0]), DT, measured=next(iter(channels)))
    return SampledLoop(
        plant, ctrl, sens, Actuator(jnp.asarray([1.0]), jnp.asarray([0.0])), jnp.asarray(DT), 2
    )


def test_zeroing_of_a_ramp_is_analytic():
    """Window W = 0.1 s = 50 samples on s = 0.1 + 0.3 t: the reading is 0 for k < 50, then
    s(t_k) − mean_{i<50} s(t_i) = 0.3 (t_k − 49 T / 2) (1e-12: double round-off of t and
    the sum); a channel without zeroing reads s unchanged; a lowpass2 channel with the
    same zeroing equals the filter (numpy) run on that zeroed ramp (1e-12)."""
    from flexarm.control.lti import digital_filter
    from flexarm.sim.sampled import simulate_loop
    from flexarm.specs.experiment import Sensor

    f2 = {"kind": "lowpass2", "cutoff": "2 Hz", "damping": 0.9}
    specs = {
        "z": Sensor(signal="s", zeroing="100 ms"),
        "s": Sensor(),
        "zf": Sensor(signal="s", zeroing="0.1 s", filter=f2),
    }
    assert specs["z"].zeroing == pytest.approx(0.1)
    loop = _ramp_loop({k: v.model_dump() for k, v in specs.items()})
    assert loop.sensors.zeroed == (0, 2) and loop.sensors.zero_n == (50, 50)
    n = 400
    out = simulate_loop(loop, np.array([0.1]), {}, n)
    meas = dict(zip(loop.sensors.names, out["measured"].T, strict=True))
    t = np.arange(n) * DT
    want = np.where(np.arange(n) < 50, 0.0, 0.3 * (t - 49 * DT / 2))
    np.testing.assert_allclose(meas["z"], want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(meas["s"], 0.1 + 0.3 * t, rtol=0, atol=1e-12)
    v, _ = digital_filter(specs["zf"].filter.model_dump(), DT).run(want)
    np.testing.assert_allclose(meas["zf"], v, rtol=0, atol=1e-12)
    assert np.all(meas["zf"][:51] == 0.0)  # at rest on 0 until the first zeroed reading


def test_zeroing_bad_input_names_the_field():
    from flexarm.io.logs import Log
    from flexarm.sim.sampled import simulate_loop
    from flexarm.specs.experiment import Sensor

    loop = _ramp_loop({"z": Sensor(signal="s", zeroing="1 s").model_dump()})
    with pytest.raises(
        ValueError,
        match=r"sensors\.z\.zeroing = 1 s \(500 samples\) is not "
        r"shorter than the run \(300 samples.*set zeroing = 0",
    ):
        simulate_loop(loop, np.array([0.1]), {}, 300)
    with pytest.raises(
        ValueError,
        match=r"sensors\.z\.zeroing = 0\.0005 s is shorter than one "
        r"sample",
    ):
        _ramp_loop({"z": Sensor(signal="s", zeroing="0.5 ms").model_dump()})
    with pytest.raises(ValueError, match=r"(?s)zeroing.*must be >= 0 s"):
        Sensor(zeroing="-1 s")
    # through a log: the log file is named
    from flexarm.analysis.replay import replay
    from flexarm.specs import load_scenario

    sc = load_scenario("quanser-two-link")
    sens = dict(sc.sensors)
    sens["alpha_f_1"] = sens["alpha_f_1"].model_copy(update={"zeroing": 1.0})
    sc = sc.model_copy(update={"sensors": sens})
    n = 200
    log = Log(
        Path("piece07.mat"),
        np.arange(n) * DT,
        {
            k: np.zeros(n)
            for k in ("theta_1", "alpha_f_1", "theta_2", "alpha_f_2", "theta_ref_1", "theta_ref_2")
        },
    )
    with pytest.raises(
        ValueError,
        match=r"piece07\.mat: sensors\.alpha_f_1\.zeroing = 1 s "
        r"\(500 samples\) is not shorter than the log",
    ):
        replay(sc, log)


@pytest.mark.skipif(not RUN.is_file(), reason=f"real two-link rig data not found at {DATA}")
def test_the_rigs_gauges_are_zeroed_over_the_first_second():
    """The lab's shoulder gauge reading, recovered from the logged α_f, α̇_f by inverting the
    2 Hz low-pass (B u_k = ξ_{k+1} − A ξ_k), is exactly 0 for the first 500 samples (1 s)
    and jumps to 0.0177 rad at sample 500 (the arm moves from sample 20): the logger's
    zeroing, before the filter. The elbow gauge is held for 100 samples (0.2 s)."""
    from flexarm.control.lti import digital_filter
    from flexarm.io.logformat import load_log

    w = load_log(RUN, ROOT / "examples" / "two-link-workspace.toml")
    f = digital_filter({"kind": "lowpass2", "cutoff": 2.0, "damping": 0.9}, DT)
    for j, n in ((1, 500), (2, 100)):
        X = np.stack([w[f"alpha_f_{j}"], w[f"alpha_dot_f_{j}"]], 1)
        u = ((X[1:] - X[:-1] @ f.A.T) @ f.B) / (f.B @ f.B)
        assert np.all(u[:n] == 0.0), j
        assert abs(u[n]) > 5e-3, j
    assert np.nonzero(w["theta_1"])[0][0] == 20


@pytest.mark.slow
def test_replay_and_predict_apply_the_zeroing():
    """A 3 s run of the rig's scenario with its shoulder gauge zeroed over 0.5 s (the arm
    moves from the first sample: the window's mean is not 0), logged: replayed and predicted
    from the scenario's start with the zeroing, every channel is reproduced (fit ≥ 99.999 %:
    the same loop, numpy round-off); the same scenario without it misses the shoulder
    gauge (it reads the ringing in the window and keeps the offset)."""
    from flexarm.analysis.replay import replay
    from flexarm.identification.time_domain import predict_scenario
    from flexarm.identification.time_domain.options import FitOptions, Shooting
    from flexarm.io.logs import Log
    from flexarm.sim.build import prepare, to_result
    from flexarm.sim.sampled import simulate_loop
    from flexarm.specs import load_scenario

    sc = load_scenario("quanser-two-link")
    sens = dict(sc.sensors)
    for k in ("alpha_f_1", "alpha_dot_f_1"):
        sens[k] = sens[k].model_copy(update={"zeroing": 0.5})
    scz = sc.model_copy(
        update={"sensors": sens, "simulation": sc.simulation.model_copy(update={"duration": 3.0})}
    )
    p = prepare(scz)
    res = to_result(p, simulate_loop(p.loop, p.x0, p.references, p.n_samples))
    n = p.n_samples
    a = res.measured["alpha_f_1"]
    assert np.all(a[:251] == 0.0) and np.abs(a).max() > 1e-3
    log = Log(
        Path("zeroed.csv"),
        np.arange(n) * DT,
        {
            **{k: np.asarray(v) for k, v in res.measured.items()},
            **{k: np.asarray(p.references[k]) for k in ("theta_ref_1", "theta_ref_2")},
        },
    )
    rep = replay(scz, log)
    assert min(rep.fit_percent.values()) > 99.999, rep.fit_percent
    opts = FitOptions(shooting=Shooting(initial="scenario"))
    with_z = predict_scenario(scz, [log], opts)["fit_percent"]["zeroed.csv"]
    assert min(with_z.values()) > 99.999, with_z
    without = predict_scenario(sc.model_copy(update={"simulation": scz.simulation}), [log], opts)[
        "fit_percent"
    ]["zeroed.csv"]
    assert without["alpha_f_1"] < with_z["alpha_f_1"] - 5, without

"""Several controllers at several rates (issue #24, item 2): ``[[controllers]]`` run by the
one sampled loop, each block at its own multiple of the base period, holding its output
between updates and driving only its own commands."""

from __future__ import annotations

import numpy as np

from flexarm.sim.build import prepare, simulate
from flexarm.specs import load_scenario
from flexarm.specs.scenario import scenario_from_dict


def _scenario(duration=0.2):
    """quanser-two-link with a dynamic shoulder block at 10 ms (5 base periods) in the
    signals form and the lab's elbow LQR at 2 ms."""
    d = load_scenario("quanser-two-link").model_dump(mode="json", exclude_none=True)
    d["simulation"]["duration"] = duration
    for r in d["references"].values():  # both setpoints move inside the run, unsaturated
        r.update(period=0.1, start=0.0, amplitude=0.02, offset=-0.01)
    K = np.asarray(d.pop("controller")["D"])
    Dw = list(-K[0, :4]) + [K[0, 0], 0.0, 0.0, 0.0]
    d["controllers"] = [
        {
            "type": "lti",
            "name": "shoulder",
            "dt": "10 ms",
            "outputs": ["current_1"],
            "signals": [
                "theta_1",
                "alpha_f_1",
                "theta_dot_f_1",
                "alpha_dot_f_1",
                "theta_ref_1",
                0,
                0,
                0,
            ],
            "A": [[0.9, 0.05], [0.0, 0.8]],
            "B": [[0.02] * 8, [-0.01] * 8],
            "C": [[0.3, -0.2]],
            "D": [Dw],
        },
        {
            "type": "lti",
            "name": "elbow",
            "dt": "2 ms",
            "outputs": ["current_2"],
            "inputs": ["theta_2", "alpha_f_2", "theta_dot_f_2", "alpha_dot_f_2"],
            "setpoints": ["theta_ref_2", 0, 0, 0],
            "D": [list(K[1, 4:])],
        },
    ]
    return scenario_from_dict(d), K


def test_each_block_updates_at_its_own_period_and_holds_between():
    """The loop's commands against an independent recursion on the recorded measured and
    reference signals: the shoulder block updates at samples 0, 5, 10, ... and holds
    its output in between, the elbow's every sample; then the drives' limits (0.94 A,
    1.2 A). 1e-12 A: the same products (the simulator's matrix products against numpy's),
    a few ulps of the largest term (~10 A)."""
    sc, K = _scenario()
    res = simulate(sc)
    blocks = prepare(sc).loop.controller
    assert [b.every for b in blocks.parts] == [5, 1]
    m, r = res.measured, res.references
    A = np.array([[0.9, 0.05], [0.0, 0.8]])
    B = np.array([[0.02] * 8, [-0.01] * 8])
    C = np.array([[0.3, -0.2]])
    Dw = np.r_[-K[0, :4], K[0, 0], 0, 0, 0]
    x, held = np.zeros(2), 0.0
    want = np.zeros((len(res.time), 2))
    for k in range(len(res.time)):
        if k % 5 == 0:
            w = np.r_[
                m["theta_1"][k],
                m["alpha_f_1"][k],
                m["theta_dot_f_1"][k],
                m["alpha_dot_f_1"][k],
                r["theta_ref_1"][k],
                0,
                0,
                0,
            ]
            held = C @ x + Dw @ w
            x = A @ x + B @ w
        e2 = np.r_[
            r["theta_ref_2"][k] - m["theta_2"][k],
            -m["alpha_f_2"][k],
            -m["theta_dot_f_2"][k],
            -m["alpha_dot_f_2"][k],
        ]
        want[k] = [held[0], K[1, 4:] @ e2]
    assert np.abs(want[:, 0]).max() < 0.94  # the shoulder's holds are not hidden by saturation
    want = np.clip(want, [-0.94, -1.2], [0.94, 1.2])
    np.testing.assert_allclose(res.command, want, rtol=0, atol=1e-12)
    # the shoulder's command changes only at its own updates
    changes = np.nonzero(np.diff(res.command[:, 0]))[0] + 1
    assert len(changes) > 10 and np.all(changes % 5 == 0)
    assert np.count_nonzero(np.diff(res.command[:, 1])) > 50


def test_the_period_comes_from_the_file_when_dt_is_not_given(tmp_path):
    """A block whose period is the struct's Ts (10 ms) runs every 5 samples of 2 ms."""
    import scipy.io as sio

    sc, _ = _scenario()
    d = sc.model_dump(mode="json", exclude_none=True)
    sh = d["controllers"][0]
    sio.savemat(
        tmp_path / "sh.mat", {"K": {k: np.asarray(sh.pop(k)) for k in "ABCD"} | {"Ts": 0.01}}
    )
    sh.pop("dt")
    sh.update(file=str(tmp_path / "sh.mat"), variable="K")
    blocks = prepare(scenario_from_dict(d)).loop.controller
    assert [b.every for b in blocks.parts] == [5, 1]
    np.testing.assert_array_equal(np.asarray(blocks.parts[0].A), [[0.9, 0.05], [0.0, 0.8]])

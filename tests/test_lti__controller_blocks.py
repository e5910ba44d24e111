"""Controller blocks as exported (issue #24, item 1): the ``signals`` input vector, ``file`` +
``variable`` (a struct in a .mat v5 / v7.3, a key prefix in an .npz, an object in JSON), a
relative ``file`` read from the folder of the TOML that names it, controller files
(``load_controllers`` / ``Scenario.with_controllers``), and the bad-input messages."""

from __future__ import annotations

import json
from pathlib import Path

import jax
import numpy as np
import pytest
import scipy.io as sio

from flexarm.control.lti import lti_controller, lti_from_spec, read_lti_file
from flexarm.specs import ScenarioError, load_scenario
from flexarm.specs.experiment import LTIControllerSpec
from flexarm.specs.scenario import load_controllers, scenario_from_dict

INPUTS = ("current_1", "current_2")
RNG = np.random.default_rng(7)
A = np.array([[0.6, 0.2], [-0.1, 0.7]])
B4 = RNG.normal(size=(2, 4))
C = np.array([[0.4, -0.3]])
D4 = RNG.normal(size=(1, 4))


def _steps(ctrl, meas: dict, refs: dict) -> np.ndarray:
    """The controller stepped over the sequences (lax.scan, as the loop runs it)."""

    def body(state, inp):
        return ctrl.step(state, *inp)

    _, u = jax.lax.scan(body, ctrl.init(), (meas, refs))
    return np.asarray(u)


def _seq(n=30):
    names = ("y1", "y2", "y3", "y4")
    meas = {k: RNG.normal(size=n) for k in names}
    refs = {"r": RNG.normal(size=n)}
    return meas, refs


def test_signals_vector_is_the_error_form_reordered():
    """A block on w = (y1, y2, y3, y4, r, 0, 0, c) with B_w = B_e M, D_w = D_e M, M the map
    e = M w of the error form e = (r − y1, −y2, −y3, −y4), and a constant input c = 0.5
    in column 8 weighted by d8: u equals the error-form block's plus C-free d8·c, computed
    by hand (1e-12: the same products summed in another order)."""
    M = np.zeros((4, 8))
    M[0, 0], M[0, 4] = -1.0, 1.0
    M[1, 1] = M[2, 2] = M[3, 3] = -1.0
    d8 = 0.25
    Bw, Dw = B4 @ M, D4 @ M
    Dw[0, 7] = d8
    Bw[:, 7] = [0.1, -0.2]
    err = lti_controller(
        A,
        B4,
        C,
        D4,
        inputs=["y1", "y2", "y3", "y4"],
        setpoints=["r", 0, 0, 0],
        outputs=[1],
        input_names=INPUTS,
        base_dt=1e-3,
    )
    blk = lti_controller(
        A,
        Bw,
        C,
        Dw,
        signals=["y1", "y2", "y3", "y4", "r", 0, 0, 0.5],
        references={"r"},
        outputs=[1],
        input_names=INPUTS,
        base_dt=1e-3,
    )
    assert blk.measured_signals == ("y1", "y2", "y3", "y4")
    assert blk.reference_signals == ("r",)
    meas, refs = _seq()
    u_err, u_blk = _steps(err, meas, refs), _steps(blk, meas, refs)
    # by hand: the constant adds d8·c to the output and B[:, 7]·c to the state update
    x, want = np.zeros(2), []
    for k in range(30):
        w = np.r_[[meas[n][k] for n in ("y1", "y2", "y3", "y4")], refs["r"][k], 0, 0, 0.5]
        want.append((C @ x + Dw @ w)[0])
        x = A @ x + Bw @ w
    np.testing.assert_allclose(u_blk[:, 0], want, rtol=1e-12, atol=1e-13)
    np.testing.assert_array_equal(u_blk[:, 1], 0.0)
    # without the constant column the two forms are one controller
    blk0 = lti_controller(
        A,
        B4 @ M,
        C,
        D4 @ M,
        signals=["y1", "y2", "y3", "y4", "r", 0, 0, 0],
        references={"r"},
        outputs=[1],
        input_names=INPUTS,
        base_dt=1e-3,
    )
    np.testing.assert_allclose(_steps(blk0, meas, refs), u_err, rtol=1e-12, atol=1e-13)


def _write_all(folder: Path, Ts=0.01) -> dict[str, tuple[str, str | None]]:
    """The block (A, B4, C, D4, Ts) as a struct in a v5 .mat, a v7.3 .mat (HDF5, MATLAB's
    transposed layout), an .npz with a key prefix, a JSON object, and top-level variables
    of a v5 .mat: file name → (file, variable)."""
    import h5py

    st = {"A": A, "B": B4, "C": C, "D": D4, "Ts": Ts}
    sio.savemat(folder / "v5.mat", {"lqg_ss": st, "other": np.eye(2)})
    with h5py.File(folder / "v73.mat", "w") as f:
        g = f.create_group("lqg_ss")
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        for k, v in st.items():
            g.create_dataset(k, data=np.atleast_2d(np.asarray(v, float)).T)
    np.savez(folder / "blk.npz", **{f"lqg_ss.{k}": v for k, v in st.items()})
    (folder / "blk.json").write_text(
        json.dumps({"lqg_ss": {k: np.asarray(v).tolist() for k, v in st.items()}})
    )
    sio.savemat(folder / "top.mat", st)
    return {
        "v5": ("v5.mat", "lqg_ss"),
        "v73": ("v73.mat", "lqg_ss"),
        "npz": ("blk.npz", "lqg_ss"),
        "json": ("blk.json", "lqg_ss"),
        "top": ("top.mat", None),
    }


def test_file_and_variable_select_the_struct_in_every_format(tmp_path):
    """The same A, B, C, D and Ts from each format (exact: the files hold the doubles); the
    block built from them runs every 10 base periods of 1 ms."""
    for label, (f, var) in _write_all(tmp_path).items():
        got = read_lti_file(tmp_path / f, var)
        for k, want in (("A", A), ("B", B4), ("C", C), ("D", D4)):
            np.testing.assert_array_equal(np.atleast_2d(got[k]), want, err_msg=f"{label} {k}")
        assert got["dt"] == 0.01, label
        spec = LTIControllerSpec(
            type="lti",
            file=str(tmp_path / f),
            variable=var,
            signals=["y1", "y2", "y3", "y4"],
            outputs=["current_1"],
        )
        assert lti_from_spec(spec, base_dt=1e-3, input_names=INPUTS).every == 10


def test_relative_file_is_read_from_the_scenarios_folder(tmp_path, monkeypatch):
    """A scenario in sub/ naming file = "blk.npz" loads sub/blk.npz from any working
    directory, not the blk.npz of the working directory (a different controller)."""
    from flexarm.sim.build import prepare

    sub = tmp_path / "sub"
    sub.mkdir()
    np.savez(sub / "blk.npz", D=[[3.0]])
    np.savez(tmp_path / "blk.npz", D=[[-99.0]])  # the wrong one, where a cwd lookup finds it
    d = load_scenario("rotary-flexible-link").model_dump(mode="json", exclude_none=True)
    d["simulation"]["duration"] = 0.01
    d["controller"] = {
        "type": "lti",
        "file": "blk.npz",
        "inputs": ["motor_angle"],
        "setpoints": ["reference"],
        "outputs": ["voltage"],
    }
    import tomli_w

    (sub / "sc.toml").write_bytes(tomli_w.dumps(d).encode())
    for cwd in (tmp_path, sub, Path("/")):
        monkeypatch.chdir(cwd)
        ctrl = prepare(load_scenario(sub / "sc.toml")).loop.controller
        assert float(ctrl.D[0, 0]) == 3.0, cwd


def _two_link_dict() -> dict:
    d = load_scenario("quanser-two-link").model_dump(mode="json", exclude_none=True)
    d["simulation"]["duration"] = 0.1
    return d


def _blocks(K) -> list[dict]:
    K = np.asarray(K)
    return [
        {
            "type": "lti",
            "name": "shoulder",
            "dt": 0.01,
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
            "D": [list(-K[0, :4]) + [K[0, 0], 0, 0, 0]],
        },
        {
            "type": "lti",
            "name": "elbow",
            "dt": 0.002,
            "outputs": ["current_2"],
            "inputs": ["theta_2", "alpha_f_2", "theta_dot_f_2", "alpha_dot_f_2"],
            "setpoints": ["theta_ref_2", 0, 0, 0],
            "D": [list(K[1, 4:])],
        },
    ]


def test_controller_file_replaces_the_scenarios_controllers(tmp_path):
    """load_controllers reads [[controllers]] (relative file resolved against its folder)
    and with_controllers returns the scenario with them instead of its [controller]."""
    import tomli_w

    sc = load_scenario("quanser-two-link")
    K = np.asarray(sc.controller.D)
    blocks = _blocks(K)
    np.savez(tmp_path / "sh.npz", D=blocks[0].pop("D"))
    blocks[0]["file"] = "sh.npz"
    (tmp_path / "ctrl.toml").write_bytes(tomli_w.dumps({"controllers": blocks}).encode())
    cf = load_controllers(tmp_path / "ctrl.toml")
    assert Path(cf.controllers[0].file) == (tmp_path / "sh.npz").resolve()
    sc2 = sc.with_controllers(cf)
    assert sc2.controller is None and [c.name for c in sc2.controllers] == ["shoulder", "elbow"]
    assert sc2.controller_references() == {"theta_ref_1", "theta_ref_2"}
    # a single [controller] table too
    (tmp_path / "one.toml").write_bytes(
        tomli_w.dumps(
            {"controller": sc.controller.model_dump(mode="json", exclude_none=True)}
        ).encode()
    )
    sc3 = sc2.with_controllers(load_controllers(tmp_path / "one.toml"))
    assert sc3.controllers is None and sc3.controller == sc.controller


def _error(d: dict, tmp_path: Path, name="bad.toml") -> str:
    import tomli_w

    (tmp_path / name).write_bytes(tomli_w.dumps(d).encode())
    with pytest.raises(ScenarioError) as exc:
        load_scenario(tmp_path / name)
    return str(exc.value)


def test_bad_input_names_the_file_the_field_the_value_and_the_fix(tmp_path):
    """A signals entry that is neither a channel nor a number; a period that is not a
    multiple of the base period; two blocks driving one output; a struct without D (at
    build: the file and variable); a non-lti block in [[controllers]]; a controller file
    with neither table."""
    from flexarm.sim.build import prepare

    K = np.asarray(load_scenario("quanser-two-link").controller.D)
    d = _two_link_dict()
    d.pop("controller")
    d["controllers"] = _blocks(K)
    d["controllers"][0]["signals"][5] = "theta_ddot_1"
    msg = _error(d, tmp_path)
    assert "bad.toml" in msg
    assert "controllers[0].signals[5] = 'theta_ddot_1' is neither a channel nor a number" in msg
    assert "a number (a constant input)" in msg

    d["controllers"] = _blocks(K)
    d["controllers"][0]["dt"] = 0.005 + 1e-4
    msg = _error(d, tmp_path)
    assert (
        "controllers[0].dt = 0.0051 s is not a whole multiple of the sampling period 0.002 s" in msg
        and "bad.toml" in msg
        and "e.g. 0.006 s" in msg
    )

    d["controllers"] = _blocks(K)
    d["controllers"][1]["outputs"] = [1]
    msg = _error(d, tmp_path)
    assert (
        "controllers[1].outputs: 1 is driven by controllers[0] already; two controllers "
        "cannot drive one output" in msg
    )

    d["controllers"] = _blocks(K)
    d["controllers"][1] = {"type": "pd", "kp": 1.0}
    assert "type = 'pd' cannot run as one of several [[controllers]]" in _error(d, tmp_path)

    sio.savemat(tmp_path / "noD.mat", {"lqg_ss": {"A": A, "B": B4, "C": C, "Ts": 0.01}})
    d["controllers"] = _blocks(K)
    d["controllers"][0].pop("D")
    d["controllers"][0].update(file="noD.mat", variable="lqg_ss")
    import tomli_w

    (tmp_path / "noD.toml").write_bytes(tomli_w.dumps(d).encode())
    with pytest.raises(
        ScenarioError,
        match=r"\[\[controllers\]\]\[0\] \(shoulder\) file = "
        r"'.*noD.mat', variable = 'lqg_ss': no D \(the struct holds: A, B, C, "
        r"Ts\).*add the field D",
    ):
        prepare(load_scenario(tmp_path / "noD.toml"))
    d["controllers"][0]["variable"] = "lqr_ss"
    (tmp_path / "noD.toml").write_bytes(tomli_w.dumps(d).encode())
    with pytest.raises(ScenarioError, match=r"the file has no 'lqr_ss' \(it holds: lqg_ss\)"):
        prepare(load_scenario(tmp_path / "noD.toml"))

    (tmp_path / "empty.toml").write_text('[sampling]\nperiod = "1 ms"\n')
    with pytest.raises(
        ScenarioError,
        match=r"empty.toml: .*controller file.*\n.*sampling: "
        r"unknown key",
    ):
        load_controllers(tmp_path / "empty.toml")
    (tmp_path / "none.toml").write_text("")
    with pytest.raises(ScenarioError, match=r"none.toml(.|\n)*the file has neither"):
        load_controllers(tmp_path / "none.toml")


def test_one_block_in_controllers_is_the_single_controller():
    """[[controllers]] with the lab's one LQR block drives the loop exactly as [controller]
    (the same Blocks sum of one part: bit-identical commands)."""
    from flexarm.sim.build import simulate

    d = _two_link_dict()
    one = scenario_from_dict(d)
    d["controllers"] = [d.pop("controller")]
    many = scenario_from_dict(d)
    r1, r2 = simulate(one), simulate(many)
    np.testing.assert_array_equal(r1.command, r2.command)

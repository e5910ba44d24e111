"""A two-link flexible-arm scenario from the lab's MATLAB workspace (the Quanser-type "2-DOF
serial flexible link" setup script's variables), as plain data for
:func:`flexarm.specs.scenario_from_dict` (the built-in ``quanser-two-link`` is this for the
rig's ``lqr_full_10deg.mat``; ``flexarm scenario-from-mat`` writes it as TOML).

Read from the file (SI): hub inertias J11, J21; link-end inertias J12, J22; link springs Ks1,
Ks2; torque per ampere Ktg1, Ktg2; joint viscous B11, B21; link damping B12, B22; lengths
L1, L2; encoder quanta KE_D1, KE_D2; filter constants wcf, wcfa, zetaf; LQR gains K1, K2;
the logger's step from ``stage1_X1_meas.time`` when present. Not in the file: the current
limits and the joint friction levels (arguments). The lumped J12 is split as
docs/choices.md states: link 2 a uniform rod (m2 = 3 J22 / L2², centre at L2/2), hub 2 J21
without mass, link 1's own J_0 = J12 − (J21 + J22 + 2 L1 m2 L2/2 + m2 L1²).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from flexarm.io.matfile import MatFileError, load_mat, scalar

#: The workspace variables read (one number each, K1 and K2 four).
SCALARS = (
    "J11",
    "J12",
    "J21",
    "J22",
    "Ks1",
    "Ks2",
    "Ktg1",
    "Ktg2",
    "B11",
    "B21",
    "B12",
    "B22",
    "L1",
    "L2",
    "KE_D1",
    "KE_D2",
    "wcf",
    "wcfa",
    "zetaf",
)


def scenario_from_workspace(
    path: str | Path,
    *,
    current_limits: tuple[float, float] = (0.94, 1.2),
    coulomb: tuple[float, float] = (0.5, 0.025),
    static: tuple[float, float] = (1.0, 0.05),
    period: float | None = None,
    duration: float = 20.0,
    name: str | None = None,
) -> dict[str, Any]:
    """The scenario (a dict in SI numbers) of the rig a workspace file describes.

    ``current_limits`` (A) and the joint friction levels ``coulomb`` / ``static`` (N·m) per
    joint are not in the file (defaults: the README's limits, the built-in scenario's
    friction placeholders); ``period`` (s) defaults to the logger's step in the file, else
    2 ms. Raises :class:`flexarm.io.matfile.MatFileError` naming a missing variable."""
    path = Path(path)
    v = load_mat(path)
    p = {k: scalar(path, v, k, f"[workspace] {k}") for k in SCALARS}
    K = {}
    for k in ("K1", "K2"):
        if k not in v:
            raise MatFileError(
                f"{path}: the file has no variable {k!r} (the LQR gains of one stage, 4 numbers)"
            )
        K[k] = np.asarray(v[k], float).ravel()
        if K[k].size != 4:
            raise MatFileError(
                f"{path}: {k} holds {K[k].size} numbers; the stage law "
                "i = K (x_ref − x), x = [θ, α_f, θ̇_f, α̇_f], needs 4"
            )
    if period is None:  # the logger's step, rounded off its float noise; else 2 ms
        period = 2e-3
        if "stage1_X1_meas" in v:
            t = load_time(path, v)
            period = float(f"{np.median(np.diff(t)):.9g}")
    m2 = 3 * p["J22"] / p["L2"] ** 2
    J01 = p["J12"] - (p["J21"] + p["J22"] + 2 * p["L1"] * m2 * p["L2"] / 2 + m2 * p["L1"] ** 2)
    if not J01 > 0:
        raise MatFileError(
            f"{path}: J12 = {p['J12']:g} kg·m² is smaller than the elbow stage's "
            f"inertia about joint 1 ({p['J12'] - J01:g} kg·m² with link 2 a "
            "uniform rod): the split of docs/choices.md does not apply"
        )

    def link(L, m, J, K_, B):
        return {
            "model": "torsional",
            "length": L,
            "mass": m,
            "inertia": J,
            "torsional_stiffness": K_,
            "torsional_damping": B,
        }

    def joint(B, Kt, lim, fc, fs):
        return {
            "viscous": B,
            "drive": {"drive": "current", "torque_constant": Kt, "current_limit": lim},
            "friction": {"model": "coulomb", "coulomb": fc, "static": fs},
        }

    def filt(kind, w):
        return {
            "kind": kind,
            "cutoff": w / (2 * math.pi),
            "damping": p["zetaf"],
            "discretisation": "forward_euler",
        }

    sensors: dict[str, Any] = {}
    for j, q in ((1, p["KE_D1"]), (2, p["KE_D2"])):
        sensors[f"theta_{j}"] = {"quantum": q}
        sensors[f"alpha_f_{j}"] = {
            "signal": f"deflection_angle_{j}",
            "filter": filt("lowpass2", p["wcfa"]),
        }
        sensors[f"theta_dot_f_{j}"] = {
            "signal": f"theta_{j}",
            "quantum": q,
            "filter": filt("derivative2", p["wcf"]),
        }
        sensors[f"alpha_dot_f_{j}"] = {
            "signal": f"deflection_angle_{j}",
            "filter": filt("lowpass2_rate", p["wcfa"]),
        }
    D = np.zeros((2, 8))
    D[0, :4], D[1, 4:] = K["K1"], K["K2"]
    inputs = [
        f"{s}_{j}" for j in (1, 2) for s in ("theta", "alpha_f", "theta_dot_f", "alpha_dot_f")
    ]
    return {
        "name": name or path.stem,
        "description": f"two-link flexible arm from the lab workspace {path.name}",
        "arm": {
            "kind": "multi_link",
            "gravity": 0.0,
            "links": [
                link(p["L1"], 1.0, J01, p["Ks1"], p["B12"]),
                link(p["L2"], m2, p["J22"], p["Ks2"], p["B22"]),
            ],
            "hubs": [{"mass": 0.0, "inertia": p["J11"]}, {"mass": 0.0, "inertia": p["J21"]}],
            "joints": [
                joint(p["B11"], p["Ktg1"], current_limits[0], coulomb[0], static[0]),
                joint(p["B21"], p["Ktg2"], current_limits[1], coulomb[1], static[1]),
            ],
        },
        "sampling": {"period": period},
        "simulation": {"duration": duration, "substeps": 4},
        "sensors": sensors,
        "references": {
            "theta_ref_1": {
                "type": "square",
                "offset": -math.radians(25),
                "amplitude": math.radians(50),
                "period": 10.0,
            },
            "theta_ref_2": {
                "type": "square",
                "offset": -math.radians(10),
                "amplitude": math.radians(20),
                "period": 10.0,
                "start": 2.5,
            },
        },
        "controller": {
            "type": "lti",
            "dt": period,
            "inputs": inputs,
            "setpoints": ["theta_ref_1", 0, 0, 0, "theta_ref_2", 0, 0, 0],
            "outputs": ["current_1", "current_2"],
            "D": D.tolist(),
        },
    }


def load_time(path: Path, variables: dict) -> np.ndarray:
    """The logger's time vector ``stage1_X1_meas.time``."""
    from flexarm.io.matfile import VarSpec, resolve_variable

    return resolve_variable(path, variables, "time", VarSpec.parse("stage1_X1_meas.time"))

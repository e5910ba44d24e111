"""What ``flexarm info`` prints: the linear model of an arm as plain data.

Transfer functions as ``{"num": [...], "den": [...]}`` (descending powers of s), poles,
zeros, natural frequencies (rad/s and Hz) and damping ratios, static gains.
"""

from __future__ import annotations

import control
import numpy as np

from flexarm.models.single_link import SingleLinkModel


def tf_dict(g: control.TransferFunction) -> dict:
    """A SISO transfer function as plain data."""
    num = np.asarray(g.num[0][0], float)
    den = np.asarray(g.den[0][0], float)
    poles = np.roots(den) if len(den) > 1 else np.zeros(0)
    zeros = np.roots(num) if len(num) > 1 else np.zeros(0)
    n_int = int(np.sum(np.abs(poles) < 1e-9 * max(1.0, np.max(np.abs(poles), initial=1.0))))
    # static gain, integrators removed
    den_red = den[: len(den) - n_int] if n_int else den
    static = float(num[-1] / den_red[-1]) if den_red[-1] != 0 else float("inf")
    return {
        "num": num.tolist(),
        "den": den.tolist(),
        "poles": _cplx(poles),
        "zeros": _cplx(zeros),
        "integrators": n_int,
        "static_gain": static,
        "static_gain_note": "gain of s^k G(s) at s = 0 with k the integrators" if n_int else "G(0)",
        "natural_frequencies_rad_s": _wn(poles),
        "zero_frequencies_rad_s": _wn(zeros),
        "right_half_plane_zeros": _cplx(zeros[zeros.real > 1e-12]),
    }


def _cplx(r: np.ndarray) -> list:
    r = np.asarray(r, complex)
    r = r[np.lexsort((r.imag, r.real))]
    return [{"re": float(z.real), "im": float(z.imag)} for z in r]


def _wn(r: np.ndarray) -> list[dict]:
    out = []
    for z in np.asarray(r, complex):
        if z.imag > 1e-12 or (abs(z.imag) <= 1e-12 and abs(z) > 1e-12):
            wn = abs(z)
            out.append({"wn_rad_s": float(wn), "hz": float(wn / (2 * np.pi)),
                        "damping_ratio": float(-z.real / wn)})
    return sorted(out, key=lambda d: d["wn_rad_s"])


def single_link_info(model: SingleLinkModel) -> dict:
    """The linear model of a single-link arm (FRB eqs. 12-15)."""
    d = model.drive
    u = "A" if d.kind == "current" else "V"
    info = {
        "kind": "single_link",
        "drive": d.kind,
        "hub": {"inertia_kg_m2": model.J, "viscous_N_m_s_per_rad": model.V,
                "torque_per_command": float(d.k_u), "back_emf_damping_N_m_s_per_rad": float(d.k_omega),
                "command_limit": float(d.limit), "command_unit": u},
        "friction": {"model": model.friction.model, "coulomb_N_m": float(model.friction.coulomb),
                     "breakaway_N_m": float(model.friction.static),
                     "coulomb_command": float(model.friction.coulomb) / float(d.k_u)},
        "transfer_functions": {
            "motor": {"description": f"G_m(s) = motor angle [rad] / command [{u}] (FRB eq. 12)",
                      **tf_dict(model.motor_tf())},
            "beam": {"description": "G_b(s) = tip angle / motor angle (FRB eqs. 13, 14)",
                     **tf_dict(model.beam_tf())},
            "coupling": {"description": "C_t(s) / (motor angle - tip angle) [N*m/rad] (FRB eqs. 15, 16)",
                         **tf_dict(model.coupling_tf())},
            "tip": {"description": f"tip angle [rad] / command [{u}]", **tf_dict(model.tip_tf())},
        },
    }
    return info

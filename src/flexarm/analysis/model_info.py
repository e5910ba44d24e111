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
    r = r[np.lexsort((np.imag(r), np.real(r)))]
    return [{"re": float(z.real), "im": float(z.imag)} for z in r]


def _wn(r: np.ndarray) -> list[dict]:
    out = []
    for z in np.asarray(r, complex):
        if z.imag > 1e-12 or (abs(z.imag) <= 1e-12 and abs(z) > 1e-12):
            wn = abs(z)
            out.append(
                {
                    "wn_rad_s": float(wn),
                    "hz": float(wn / (2 * np.pi)),
                    "damping_ratio": float(-z.real / wn),
                }
            )
    return sorted(out, key=lambda d: d["wn_rad_s"])


def single_link_info(model: SingleLinkModel) -> dict:
    """The linear model of a single-link arm (FRB eqs. 12-15)."""
    d = model.drive
    u = "A" if d.kind == "current" else "V"
    if getattr(model.arm, "joint", "revolute") == "prismatic":
        return _linear_axis_info(model, u)
    info = {
        "kind": "single_link",
        "drive": d.kind,
        "hub": {
            "inertia_kg_m2": model.J,
            "viscous_N_m_s_per_rad": model.V,
            "torque_per_command": float(d.k_u),
            "back_emf_damping_N_m_s_per_rad": float(d.k_omega),
            "command_limit": float(d.limit),
            "command_unit": u,
        },
        "friction": {
            "model": model.friction.model,
            "coulomb_N_m": float(model.friction.coulomb),
            "breakaway_N_m": float(model.friction.static),
            "coulomb_command": float(model.friction.coulomb) / float(d.k_u),
        },
        "transfer_functions": {
            "motor": {
                "description": f"G_m(s) = motor angle [rad] / command [{u}] (FRB eq. 12)",
                **tf_dict(model.motor_tf()),
            },
            "beam": {
                "description": "G_b(s) = tip angle / motor angle (FRB eqs. 13, 14)",
                **tf_dict(model.beam_tf()),
            },
            "coupling": {
                "description": "C_t(s) / (motor angle - tip angle) [N*m/rad] (FRB eqs. 15, 16)"
                + (
                    "; a rigid link: 0 (tip angle = motor angle, its masses in the hub)"
                    if model.arm.beam.model == "rigid"
                    else ""
                ),
                **tf_dict(model.coupling_tf()),
            },
            "tip": {"description": f"tip angle [rad] / command [{u}]", **tf_dict(model.tip_tf())},
        },
    }
    return info


def _linear_axis_info(model: SingleLinkModel, u: str) -> dict:
    """A linear axis (a prismatic joint, rigid carriage): mass, forces, position / command."""
    d = model.drive
    return {
        "kind": "single_link",
        "joint": "prismatic",
        "drive": d.kind,
        "axis": {
            "mass_kg": model.J,
            "viscous_N_s_per_m": model.V,
            "force_per_command": float(d.k_u),
            "back_emf_damping_N_s_per_m": float(d.k_omega),
            "command_limit": float(d.limit),
            "command_unit": u,
        },
        "friction": {
            "model": model.friction.model,
            "coulomb_N": float(model.friction.coulomb),
            "breakaway_N": float(model.friction.static),
            "offset_force_N": float(model.friction.bias),
            "coulomb_command": float(model.friction.coulomb) / float(d.k_u),
        },
        "transfer_functions": {
            "motor": {
                "description": f"G_m(s) = position [m] / command [{u}] (mass m s² + (V + k_ω) s)",
                **tf_dict(model.motor_tf()),
            },
        },
    }


def multilink_info(scenario) -> dict:
    """Per link: mode frequencies (Hz), φ(ℓ), φ'(ℓ), k_ij; with a regulation target:
    δ_d (DLS eq. 9), α (eq. 6) over the box spanned by the initial and target angles,
    and the sufficient conditions (14)-(15) with their margins."""
    from flexarm.control.regulation import (
        alpha_bound,
        gravity_torque,
        residual_deflection,
        stability_conditions,
    )
    from flexarm.models.multilink import build_multilink

    model = build_multilink(scenario.arm)
    links = []
    for i, m in enumerate(model.modes):
        links.append(
            {
                "link": i + 1,
                "modes": len(m.omega),
                "mode_type": m.mode_type,
                "frequencies_hz": (np.asarray(m.omega) / (2 * np.pi)).tolist(),
                "beta_l": np.asarray(m.beta_l).tolist(),
                "phi_end": np.asarray(m.tip_value).tolist(),
                "phi_prime_end_per_m": np.asarray(m.tip_slope).tolist(),
                "stiffness_k_ij_N_per_m": np.asarray(m.K).tolist(),
                "tip_load": {"mass_kg": m.tip_mass, "inertia_kg_m2": m.tip_inertia},
            }
        )
    info = {"kind": "multi_link", "links": links, "gravity_m_s2": scenario.arm.gravity}
    reg = scenario.regulation
    if reg is not None:
        th_d = np.asarray(reg.target)
        th_0 = np.asarray(reg.initial)
        d_d = residual_deflection(model, th_d)
        lo, hi = np.minimum(th_0, th_d), np.maximum(th_0, th_d)
        dmax = np.maximum(2 * np.abs(d_d), 1e-3)
        a = alpha_bound(model, lo, hi, dmax)
        cond = stability_conditions(model, np.diag(reg.kp), a.alpha)
        info["target"] = {
            "theta_d_rad": th_d.tolist(),
            "delta_d_m": np.asarray(d_d).tolist(),
            "gravity_torque_at_target_N_m": np.asarray(gravity_torque(model, th_d, d_d)).tolist(),
            "alpha": {
                "value": a.alpha,
                "region": {
                    "theta_low": lo.tolist(),
                    "theta_high": hi.tolist(),
                    "delta_max": dmax.tolist(),
                },
                "note": "largest ||dg/dq||_2 found over the region (eq. 6)",
            },
            "conditions": {
                "14": {
                    "statement": "lambda_min(K) > alpha",
                    "lambda_min_K": cond.lambda_min_K,
                    "holds": cond.holds_14,
                    "margin": cond.margin_14,
                },
                "15": {
                    "statement": "lambda_min(K_P) > alpha",
                    "lambda_min_KP": cond.lambda_min_KP,
                    "holds": cond.holds_15,
                    "margin": cond.margin_15,
                },
            },
        }
    return info

"""The result of a bench fit: parameters with uncertainty, fit %, figures, scenario file."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from flexarm.errors import OutputExistsError
from flexarm.identification.time_domain.logs import FitInputError
from flexarm.identification.time_domain.params import DOCS, UNITS, derived
from flexarm.identification.time_domain.result import finite, session_key, session_path
from flexarm.io.logs import log_keys
from flexarm.io.write import write_json, write_text


def check_physical(params: dict[str, float], source: str = "fit") -> None:
    """Raise a clear error for non-physical values (inertia, stiffness, gain <= 0)."""
    for name, what in (
        ("hub_inertia", "hub inertia J"),
        ("link_inertia", "link inertia J_l"),
        ("link_stiffness", "link stiffness C"),
        ("link_frequency", "link frequency"),
        ("coulomb", "Coulomb friction"),
        ("viscous", "viscous friction"),
    ):
        v = params.get(name)
        if v is None:
            continue
        strict = name not in ("coulomb", "viscous")
        if not np.isfinite(v) or (v <= 0 if strict else v < 0):
            raise FitInputError(
                f"{source}: non-physical result: {what} ({name}) = {v:.4g} "
                f"{UNITS.get(name, 'N*m/rad')}; it must be {'> 0' if strict else '>= 0'}. "
                "The model cannot explain the logs with physical values: check the data-sheet "
                "values (gear ratio, motor constant, resistance, link length), the units of "
                "the log columns and the controller declaration, or give bounds="
            )


@dataclass
class FitResult:
    """Fitted parameters (SI) with standard errors, fit % per log and signal, and what is
    needed to plot and to write a scenario. ``converged`` is False when a stage stopped
    on its iteration budget; ``message`` says what happened, ``warnings`` what to check.

    ``std``: the reported standard errors, from the Newey–West (HAC) sandwich covariance
    (JᵀJ)⁻¹ Ŝ (JᵀJ)⁻¹ with Ŝ = Σ_logs Σ_|k|<=M w_k Σ_t g_t g_{t+k}ᵀ, g_t = Σ_channels J_tᵀ r_t
    and Bartlett weights w_k = 1 − |k|/(M+1), M = 10 residual correlation times per log
    (:mod:`flexarm.identification.time_domain.uncertainty`), mapped to physical units by |dp/du|.
    They are reported because the output-error residuals are strongly autocorrelated (model error,
    filtered sensors, encoder quantisation of a slow hub), which the textbook estimate
    ignores. ``std_iid``: that textbook s² (JᵀJ)⁻¹, s² = ‖r‖²/(m − n), kept for
    comparison (the previous AR(1)-inflated value is ``std_iid`` · √((1+ρ)/(1−ρ)) with
    ρ = ``stages['local']['rho']``). NaN where the Jacobian is singular or missing. Both
    are local linearisations: they ignore the jumps of stick-slip in the friction
    coordinates and any bias from a wrong model structure."""

    params: dict[str, float]
    std: dict[str, float]
    derived: dict[str, float]
    delays: dict[str, int]
    fit_percent: dict[str, dict[str, float | None]]  # None: not finite
    converged: bool
    message: str
    warnings: list[str]
    settings: dict[str, Any]
    stages: dict[str, Any]
    initial_states: dict[str, dict[str, float]]
    rig: Any = None
    logs: list = field(default_factory=list)
    traj: list = field(default_factory=list)
    seconds: float = 0.0
    std_iid: dict[str, float] = field(default_factory=dict)
    #: the search space and the fitted point in it (unit coordinates, discrete), so that
    #: the same model predicts other logs (:func:`flexarm.identification.time_domain.fit.predict`)
    space: Any = None
    unit: Any = None
    discrete: Any = None

    # ------------------------------------------------------------------ construction
    @classmethod
    def build(
        cls,
        *,
        logs,
        rig,
        space,
        U,
        D,
        offsets,
        std_u,
        fit_percent,
        diverged,
        traj,
        glob,
        local,
        info,
        settings,
        seconds,
        objective,
        std_iid_u=None,
    ) -> FitResult:
        params, std, std_iid = {}, {}, {}
        if std_iid_u is None:
            std_iid_u = np.full(len(space.defs), np.nan)
        for i, (name, d) in enumerate(zip(space.names, space.defs, strict=True)):
            params[name] = float(d.to_phys(U[i]))
            std[name] = float(abs(d.dphys_du(U[i])) * std_u[i])
            std_iid[name] = float(abs(d.dphys_du(U[i])) * std_iid_u[i])
        sign = int(2 * D[2] - 1)
        if "tip_gain" in params:
            params["tip_gain"] *= sign

        def first(n):
            return params.get(n, params.get(f"{n}[0]", 0.0))

        der = derived(
            {
                k: first(k)
                for k in ("hub_inertia", "link_frequency", "link_inertia")
                if k in params or f"{k}[0]" in params
            },
            rig.length,
        )
        if settings["friction"]:
            for s in range(space.n_sessions):
                sfx = "" if space.n_sessions == 1 else f"[{s}]"
                der["static" + sfx] = params["coulomb" + sfx] + params["static_excess" + sfx]
        check_physical({**params, **der})
        names = log_keys(logs)  # one key per log (same names in other folders apart)
        fp = {
            n: {"motor_angle": _r(fit_percent[i, 0]), "tip_deflection": _r(fit_percent[i, 1])}
            for i, n in enumerate(names)
        }
        d0, v0 = objective.tip_initial(np.asarray([D[1]]), offsets[None])
        th0, om0 = objective.hub_initial(1, offsets[None], np.asarray([D[0]]))
        ini = {
            n: {
                "motor_angle": float(th0[0, i]),
                "motor_velocity": float(om0[0, i]),
                "tip_deflection": float(d0[0, i] / params.get("tip_gain", 1.0)),
                "tip_velocity": float(v0[0, i] / params.get("tip_gain", 1.0)),
            }
            for i, n in enumerate(names)
        }
        warn = []
        converged = bool(local["success"])
        msg = []
        if not glob.success:
            msg.append(
                f"global stage stopped after {glob.nit} generations without meeting "
                f"its tolerance ({glob.message})"
            )
        if not local["success"]:
            msg.append(
                f"local stage did not converge in {local['nfev']} evaluations ({local['message']})"
            )
        if converged:
            msg.insert(0, "converged (local stage met its tolerance)")
        else:
            msg.insert(
                0,
                "NOT CONVERGED: the best parameters found are returned with their "
                "fit %; raise maxiter / local_nfev, or narrow the bounds",
            )
        for i in local["at_bounds"]:
            warn.append(
                f"{space.names[i]} = {params[space.names[i]]:.4g} lies at a bound of "
                f"[{space.defs[i].lo:.4g}, {space.defs[i].hi:.4g}]; widen it with "
                f"bounds={{'{space.defs[i].name}': (lo, hi)}}"
            )
        for i, n in enumerate(names):
            if diverged[i]:
                warn.append(f"{n}: the fitted loop diverges in simulation")
            for sig, v in fp[n].items():
                if v is not None and v < 80:
                    warn.append(f"{n}: fit {v:.1f} % on {sig} is low")
        dl = {"motor_angle": int(D[0]), "tip_deflection": int(D[1])}
        stages = {
            "global": {
                "cost": glob.cost,
                "nfev": glob.nfev,
                "generations": glob.nit,
                "success": glob.success,
                "message": glob.message,
                "seconds": glob.seconds,
            },
            "local": {
                k: local[k] for k in ("cost", "nfev", "success", "message", "seconds", "rho")
            },
            "guesses": info,
        }
        if "smooth_stage" in local:  # the continuation's first stage (unrounded loop)
            stages["local"]["smooth_stage"] = local["smooth_stage"]
        if local.get("cov_u") is not None:  # the HAC covariance of the unit coordinates
            # (space.names order): plants drawn from the fit (flexarm.design.plants)
            stages["local"]["covariance_unit"] = np.asarray(local["cov_u"]).tolist()
        stages["local"]["hac_bandwidth_samples"] = {
            n: m for n, m in zip(names, local.get("bandwidth", []), strict=False)
        }
        return cls(
            params,
            std,
            der,
            dl,
            fp,
            converged,
            "; ".join(msg),
            warn,
            settings,
            stages,
            ini,
            rig,
            list(logs),
            traj,
            seconds,
            std_iid,
            space,
            np.asarray(U),
            np.asarray(D),
        )

    # ------------------------------------------------------------------ outputs
    def result(self, **extras: Any):
        """The one result of every rig (:class:`~flexarm.identification.time_domain.result.
        FitResult`) holding this one (:func:`as_fit_result`; ``extras`` as there)."""
        return as_fit_result(self, **extras)

    def to_dict(self) -> dict:
        """The ``--json`` document: the one result's (:meth:`result`), the rig's own record
        under ``stages["servo_rig"]``."""
        return self.result().to_dict()

    def document(
        self,
        *,
        without_friction: FitResult | None = None,
        window: tuple[float, float] | None = None,
        held_out: Any = None,
        held_window: tuple[float, float] | None = None,
    ) -> dict:
        """The ``--json`` document ``flexarm fit LOG... --drive ...`` writes: :meth:`to_dict`
        plus, when given, the fit without joint friction, the fitted window and the
        held-out prediction (:func:`as_fit_result`)."""
        return self.result(
            without_friction=without_friction,
            window=window,
            held_out=held_out,
            held_window=held_window,
        ).to_dict()

    def to_json(self, path: str | Path) -> Path:
        path = Path(path)
        write_json(path, self.to_dict(), overwrite=True)
        return path

    def summary(self) -> str:
        lines = [
            f"flexarm fit ({self.settings['mode']}, friction "
            f"{'on' if self.settings['friction'] else 'off'}): {self.message}"
        ]
        lines.append(
            "  parameter              value ± std (HAC) [std if residuals were independent]"
        )
        for k, v in self.params.items():
            s = self.std.get(k, float("nan"))
            si = self.std_iid.get(k, float("nan"))
            rel = f" ({100 * s / abs(v):.1f} %)" if v else ""
            lines.append(
                f"  {k:22s} {v: .5g} ± {s:.2g}{rel} [{si:.2g}] {UNITS.get(k.split('[')[0], '')}"
            )
        for k, v in self.derived.items():
            lines.append(f"  {k:22s} {v: .5g}")
        lines.append(
            f"  delays (samples): hub angle {self.delays['motor_angle']}, "
            f"tip deflection {self.delays['tip_deflection']}"
        )
        lines.append("  fit %:")
        for n, d in self.fit_percent.items():
            lines.append(
                f"    {n}: "
                + ", ".join(f"{k} {v:.1f}" if v is not None else f"{k} -" for k, v in d.items())
            )
        for w in self.warnings:
            lines.append(f"  warning: {w}")
        lines.append(
            f"  time {self.seconds:.1f} s (global {self.stages['global']['seconds']:.1f}"
            f" s, {self.stages['global']['generations']} generations; local "
            f"{self.stages['local']['seconds']:.1f} s)"
        )
        return "\n".join(lines)

    def _table(self):
        from flexarm.display import Table, fit_percent_lines, parameter_rows

        state = "converged" if self.converged else "NOT converged"
        notes = [
            f"{state}: {self.message}",
            "delays (samples): " + ", ".join(f"{k} {v}" for k, v in self.delays.items()),
            *fit_percent_lines(self.fit_percent),
        ]
        notes += [f"warning: {w}" for w in self.warnings]
        units = {k: UNITS.get(k.split("[")[0], "") for k in self.params}
        return Table(
            f"FitResult of the servo rig ({self.settings.get('mode', 'fit')}): "
            f"{len(self.params)} parameters (SI)",
            parameter_rows(self.params, self.std, units),
            header=("parameter", "value", "std (HAC)", "std %", "unit"),
            notes=notes,
        )

    def __repr__(self) -> str:
        return self._table().text()

    def _repr_html_(self) -> str:
        return self._table().html()

    def scenario_dict(self) -> dict:
        """The fitted arm as a scenario dict (SI), for :func:`flexarm.specs.scenario_from_dict`."""
        return scenario_from_fit(self)[0]

    def scenario(self):
        from flexarm.specs import scenario_from_dict

        return scenario_from_dict(self.scenario_dict(), source="fitted scenario")

    def write_scenario(self, path: str | Path, overwrite: bool = False) -> Path:
        """Write the fitted scenario as commented TOML (SI units); refuses to overwrite."""
        path = Path(path)
        if path.exists() and not overwrite:  # before the work; the writer checks again
            raise OutputExistsError(
                f"{path}: exists already; not overwritten (pass overwrite=True)"
            )
        d, comments = scenario_from_fit(self)
        self.scenario()  # validates
        write_text(
            path,
            overwrite=overwrite,
            text=toml_with_comments(
                d,
                comments,
                header=[
                    "Fitted by flexarm.identification.time_domain from "
                    + ", ".join(g.name for g in self.logs),
                    self.message,
                    "fit %: "
                    + "; ".join(
                        f"{n}: " + ", ".join(f"{k} {v:.1f}" for k, v in d_.items() if v is not None)
                        for n, d_ in self.fit_percent.items()
                    ),
                ],
            ),
        )
        return path

    def plots(self, directory: str | Path) -> list[Path]:
        """One overlay figure per log (measured vs simulated hub angle, tip deflection,
        command) as PNG files in ``directory``."""
        return overlay_plots(directory, self.logs, self.traj, self.fit_percent, "fit")


def _r(v) -> float | None:
    return None if v is None or not np.isfinite(v) else round(float(v), 3)


#: what the servo rig's std mean (``stages["servo_rig"]["uncertainty_note"]``)
UNCERTAINTY_NOTE = (
    "std: Newey-West (HAC) sandwich (J^T J)^-1 S (J^T J)^-1 from the final Jacobian, S the "
    "Bartlett-weighted autocovariance of the residual x Jacobian-row products per log, "
    "bandwidth 10 residual correlation times (stages.local.hac_bandwidth_samples); "
    "std_iid: s^2 (J^T J)^-1 assuming independent residuals, too small when they are "
    "correlated. Both ignore the jumps of stick-slip and structural bias"
)


def as_fit_result(
    res: FitResult,
    *,
    without_friction: FitResult | None = None,
    window: tuple[float, float] | None = None,
    held_out: Any = None,
    held_window: tuple[float, float] | None = None,
    free_source: str = "preset rotary-servo",
):
    """The servo rig's result as the one :class:`~flexarm.identification.time_domain.
    result.FitResult` of every rig (what :func:`flexarm.fit` returns for the servo rig).

    ``free``/``params``/``std``/``correlation``: keyed by the scenario's paths (issue #43:
    the scenario is the model), the rig's fitted parameters mapped as the written scenario
    holds them (:func:`_path_values`; a session s > 0's own as ``sessions[s].PATH``) and
    their HAC covariance carried by the map's Jacobian (:func:`scenario_covariance`; the
    rig's correlation is that of its search coordinates, monotonic per parameter, so to
    first order the parameters', signed for a negative gauge gain); the rig's own names and
    std stay in ``stages["servo_rig"]["params"]`` / ``["std"]``, the paths' units in
    ``stages["units"]``; ``template``: the start point of the global stage
    (``stages["guesses"]["start"]``) on the same paths, NaN where an older result lacks it;
    ``nfev``: the global and local stages' evaluations; ``cost``: the local stage's;
    ``scenario``: the fitted scenario (:func:`scenario_from_fit`). The rig's own stages
    (``global``, ``local``, ``guesses``) are kept as they are, merged with
    ``stages["servo_rig"]``: ``derived``, ``delays_samples``, ``initial_states``,
    ``settings``, ``std_iid``, ``units``, ``docs`` and ``uncertainty_note``. ``res`` itself
    is the result's ``engine_result``.

    Extras (top-level keys of the document): ``without_friction`` (its fit %, parameters,
    message: ``flexarm fit --compare-no-friction``), ``window_s`` (the fitted window, s
    from each log's first sample) and ``held_out`` (the prediction ``held_out`` over
    ``held_window``: a :class:`~flexarm.identification.time_domain.predict.Prediction` or
    the rig's ``predict`` dict)."""
    from flexarm.identification.time_domain.result import FitResult as One

    nan = float("nan")
    free = list(res.params)  # the rig's own names (its search space)
    start = (res.stages.get("guesses") or {}).get("start") or {}
    loc, glob = res.stages.get("local") or {}, res.stages.get("global") or {}
    warnings = list(res.warnings)
    try:
        scenario = res.scenario()
    except Exception as exc:  # the fit stands without its scenario (e.g. interrupted early)
        scenario = None
        warnings.append(f"the fitted scenario could not be built: {exc}")
    stages = {
        **res.stages,
        "servo_rig": {
            "derived": res.derived,
            "delays_samples": res.delays,
            "initial_states": res.initial_states,
            "settings": res.settings,
            "std_iid": res.std_iid,
            "units": {k: UNITS.get(k.split("[")[0], "") for k in free},
            "docs": {k: DOCS.get(k.split("[")[0], "") for k in free},
            "uncertainty_note": UNCERTAINTY_NOTE,
            # the rig's own parameters (its search space), as the engine fitted them
            "params": dict(res.params),
            "std": dict(res.std),
        },
    }
    # the one result is keyed by scenario paths (the model the scenario file holds): the
    # rig's parameters mapped by scenario_from_fit's map, their covariance by its Jacobian
    corr = _correlation(res, free)
    paths, values, std, pcorr = scenario_covariance(res, free, dict(res.params), res.std, corr)
    tmpl = {k: float(start.get(k, nan)) for k in free}
    try:
        t_paths = _path_values(res, tmpl)
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        t_paths = {}
    stages["units"] = {p: PATH_UNITS.get(session_path(p), "") for p in paths}
    extras = fit_extras(
        without_friction=without_friction,
        window=window,
        held_out=held_out,
        held_window=held_window,
    )
    return One(
        free=paths,
        params=values,
        template={p: float(t_paths.get(p, nan)) for p in paths},
        std=std,
        correlation=pcorr,
        warnings=warnings,
        fit_percent=res.fit_percent,
        segment_fit_percent={},
        scenario=scenario,
        converged=res.converged,
        message=res.message,
        nfev=int(glob.get("nfev") or 0) + int(loc.get("nfev") or 0),
        cost=float(loc["cost"]) if loc.get("cost") is not None else nan,
        seconds=float(res.seconds),
        stages=finite(stages),
        free_source=free_source,
        extras=extras,
        engine_result=res,
    )


def fit_extras(
    *,
    without_friction: Any = None,
    window: tuple[float, float] | None = None,
    held_out: Any = None,
    held_window: tuple[float, float] | None = None,
) -> dict[str, Any]:
    """The servo rig's extras of the one result (:func:`as_fit_result`), JSON-ready:
    ``without_friction`` (a rig result or the one result holding it:
    :func:`without_friction_entry`), ``window_s`` and ``held_out`` (a
    :class:`~flexarm.identification.time_domain.predict.Prediction` or the rig's
    ``predict`` dict, over ``held_window``)."""
    extras: dict[str, Any] = {}
    if without_friction is not None:
        rig = getattr(without_friction, "engine_result", None) or without_friction
        extras["without_friction"] = without_friction_entry(rig)
    if window is not None:
        extras["window_s"] = list(window)
    if held_out is not None:
        extras["held_out"] = {
            "window_s": list(held_window) if held_window is not None else None,
            "fit_percent": held_out["fit_percent"],
            "diverged": held_out["diverged"],
            "initial_state": "estimated from each window's own data",
        }
    return finite(extras)


#: the scenario paths of the servo rig's parameters, their units (SI)
PATH_UNITS = {
    "arm.motor.inertia": "kg*m**2",
    "arm.motor.viscous": "N*m*s/rad",
    "arm.friction.coulomb": "N*m",
    "arm.friction.static": "N*m",
    "arm.friction.bias": "N*m",
    "arm.beam.flexural_rigidity": "N*m**2",
    "arm.beam.masses[0].mass": "kg",
    "arm.beam.damping_ratio": "",
    "sensors.tip_deflection.gain": "m/m",
}


def _path_values(res: FitResult, params: dict[str, float]) -> dict[str, float]:
    """Scenario path → value of the rig's ``params`` (names as the rig's, ``[s]`` per
    session), as :func:`scenario_from_fit` writes them: J, B, C_f, the breakaway C_f + excess,
    the bias, EI = ω_c² J_l L / 3 and the tip mass J_l / L² (:func:`derived`), ζ, the gauge
    gain (its sign per session where the gauge's differs: ``space.session_signs``). A
    session s > 0's own values are ``sessions[s].PATH`` (session 0's are the scenario's)."""
    L = res.rig.length
    signs = tuple(getattr(res.space, "session_signs", ()) or ())
    sessions = sorted(
        {int(k.split("[")[1].rstrip("]")) for k in params if "[" in k}
        | {0}
        | {s_ for s_, x in enumerate(signs) if x < 0}
    )
    out: dict[str, float] = {}
    for s_ in sessions:
        p = {k.split("[")[0]: v for k, v in params.items() if "[" not in k}
        p.update({k.split("[")[0]: v for k, v in params.items() if k.endswith(f"[{s_}]")})
        own = {k.split("[")[0] for k in params if k.endswith(f"[{s_}]")}
        d: dict[str, tuple[float, set]] = {}
        d["arm.motor.inertia"] = (p["hub_inertia"], {"hub_inertia"})
        d["arm.motor.viscous"] = (p["viscous"], {"viscous"})
        if "coulomb" in p:
            d["arm.friction.coulomb"] = (p["coulomb"], {"coulomb"})
            if "static_excess" in p:
                d["arm.friction.static"] = (
                    p["coulomb"] + p["static_excess"],
                    {"coulomb", "static_excess"},
                )
            if "bias" in p:
                d["arm.friction.bias"] = (p["bias"], {"bias"})
        if "link_frequency" in p:
            der = derived(p, L)
            d["arm.beam.flexural_rigidity"] = (
                der["flexural_rigidity"],
                {"link_frequency", "link_inertia"},
            )
            d["arm.beam.masses[0].mass"] = (der["tip_mass"], {"link_inertia"})
            d["arm.beam.damping_ratio"] = (p["link_damping"], {"link_damping"})
        flip = s_ < len(signs) and signs[s_] < 0  # this session's gauge reads the other way
        if "tip_gain" in p:
            d["sensors.tip_deflection.gain"] = (
                -p["tip_gain"] if flip else p["tip_gain"],
                {"tip_gain"},
            )
        for path, (v, uses) in d.items():
            if s_ == 0 or uses & own or (flip and path == "sensors.tip_deflection.gain"):
                out[session_key(s_, path)] = float(v)
    return out


def scenario_covariance(
    res: FitResult,
    free: list[str],
    params: dict[str, float],
    std: dict[str, float],
    corr: np.ndarray,
) -> tuple[list[str], dict[str, float], dict[str, float], np.ndarray]:
    """(paths, values, std, correlation) of the rig's parameters mapped onto the scenario's
    paths (:func:`_path_values`), the covariance carried by the map's Jacobian G (central
    differences, relative step 1e-6): Σ_paths = G Σ Gᵀ with Σ = D R D (D the rig's HAC std,
    R its correlation; R's NaN entries as 0 off the diagonal). A path that depends on an
    undetermined parameter (non-finite std) has an infinite std and a NaN row."""
    x = np.array([float(params[k]) for k in free])
    base = _path_values(res, dict(zip(free, x, strict=True)))
    paths = list(base)
    g0 = np.array([base[p] for p in paths])
    G = np.zeros((len(paths), len(free)))
    for i in range(len(free)):
        h = 1e-6 * max(abs(x[i]), 1e-12)
        up, dn = x.copy(), x.copy()
        up[i] += h
        dn[i] -= h
        a = _path_values(res, dict(zip(free, up, strict=True)))
        b = _path_values(res, dict(zip(free, dn, strict=True)))
        G[:, i] = [(a[p] - b[p]) / (2 * h) for p in paths]
    sd = np.array([float(std.get(k, np.nan)) for k in free])
    ok = np.isfinite(sd)
    R = np.where(np.isfinite(corr), corr, 0.0) if np.shape(corr) == (len(free),) * 2 else None
    R = np.eye(len(free)) if R is None else R.copy()
    np.fill_diagonal(R, 1.0)
    D = np.where(ok, sd, 0.0)
    cov = G @ (D[:, None] * R * D[None, :]) @ G.T
    bad = np.any((np.abs(G) > 0) & ~ok[None, :], axis=1)  # depends on an undetermined one
    s = np.sqrt(np.maximum(np.diag(cov), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        c = cov / np.outer(s, s)
    c[bad, :] = np.nan
    c[:, bad] = np.nan
    out_std = {p: (float("inf") if bad[j] else float(s[j])) for j, p in enumerate(paths)}
    return paths, dict(zip(paths, map(float, g0), strict=True)), out_std, c


def _correlation(res: FitResult, free: list[str]) -> np.ndarray:
    """The correlation matrix of the rig's HAC covariance (search coordinates; see
    :func:`as_fit_result`), NaN where it has none."""
    n = len(free)
    cov = (res.stages.get("local") or {}).get("covariance_unit")
    if cov is None or np.shape(cov) != (n, n):
        return np.full((n, n), np.nan)
    cov = np.asarray(cov, float)
    s = np.sqrt(np.maximum(np.diag(cov), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        c = cov / np.outer(s, s)
    sign = np.array([-1.0 if res.params[k] < 0 else 1.0 for k in free])  # a negative gauge
    return c * np.outer(sign, sign)


def without_friction_entry(res0) -> dict:
    """The ``without_friction`` entry of the document (``fit --compare-no-friction``): the
    friction-free fit's fit %, parameters and message."""
    return finite({"fit_percent": res0.fit_percent, "params": res0.params, "message": res0.message})


def interrupted_result(res, best):
    """The result ``flexarm fit`` writes when interrupted (Ctrl-C): the best so far, marked
    ``"interrupted": true, "status": "interrupted"`` (extras). ``res``: the friction fit
    when it had finished and the ``--compare-no-friction`` fit was interrupted (that one's
    best, ``best``, then goes under ``without_friction``, marked); else ``best``: the
    interrupted fit's best result; neither: an empty result saying so. Each a rig result
    or already the one :class:`~flexarm.identification.time_domain.result.FitResult`."""
    from flexarm.identification.time_domain.result import FitResult as One

    mark = {"interrupted": True, "status": "interrupted"}

    def one(x):
        return x if isinstance(x, One) else as_fit_result(x)

    if res is not None:
        out = one(res)
        out.extras["without_friction"] = (
            {**without_friction_entry(best), **mark} if best is not None else dict(mark)
        )
    elif best is not None:
        out = one(best)
    else:
        out = One(
            free=[],
            params={},
            template={},
            std={},
            correlation=np.zeros((0, 0)),
            warnings=[],
            fit_percent={},
            segment_fit_percent={},
            scenario=None,
            converged=False,
            message="interrupted before any model was evaluated",
            nfev=0,
            cost=float("nan"),
            seconds=0.0,
        )
    out.extras.update(mark)
    return out


def scenario_from_fit(res: FitResult) -> tuple[dict, dict]:
    """(scenario dict, comments keyed by 'section.key') of a fit result (session 0)."""
    p = {k.split("[")[0]: v for k, v in reversed(list(res.params.items()))}
    rig, L = res.rig, res.rig.length
    der = res.derived
    motor = {**rig.motor, "inertia": p["hub_inertia"], "viscous": p["viscous"]}
    if res.settings["friction"]:
        fr = {
            "model": "coulomb",
            "coulomb": p["coulomb"],
            "static": p["coulomb"] + p["static_excess"],
            "bias": p["bias"],
        }
        if rig.push_stiffening > 0:  # estimated from the stuck phases (guesses.pushed_ringing)
            fr.update(
                pushed_stiffening=rig.push_stiffening,
                push_threshold=rig.push_threshold,
                push_full=rig.push_full,
            )
    else:
        fr = {"model": "none"}
    log0 = res.logs[0]
    T = log0.dt
    q = rig.encoder_quantum
    rigid = "link_frequency" not in p
    sensors: dict[str, dict[str, Any]] = {"motor_angle": {"delay": res.delays["motor_angle"]}}
    if not rigid:
        sensors["tip_deflection"] = {"gain": p["tip_gain"], "delay": res.delays["tip_deflection"]}
    for ch, hz in res.settings.get("filters", {}).items():
        if hz > 0 and ch in sensors:  # the sensor low-pass, given or estimated
            sensors[ch]["bandwidth"] = hz
    if q > 0:
        counts = 2 * math.pi / q
        bits = int(math.ceil(math.log2(counts) - 1e-9))
        sensors["motor_angle"].update(bits=bits, range=q * 2**bits)
    ctrl = log0.controller.model_dump() if log0.controller is not None else None
    r = log0.columns["reference"]
    steps = np.nonzero(np.abs(np.diff(r)) > 1e-9)[0]
    ref = {
        "type": "step",
        "offset": float(r[0]),
        "amplitude": float(r[steps[0] + 1] - r[0]) if steps.size else 0.0,
        "start": float((steps[0] + 1) * T) if steps.size else 0.0,
    }
    beam = (
        {"model": "rigid", "length": L}
        if rigid
        else {
            "model": "lumped",
            "length": L,
            "flexural_rigidity": der["flexural_rigidity"],
            "damping_ratio": p["link_damping"],
            "masses": [{"mass": der["tip_mass"], "joint": "pinned"}],
        }
    )
    d = {
        "name": "fitted-arm",
        "description": "Arm fitted by flexarm.identification.time_domain from bench logs",
        "arm": {"motor": motor, "friction": fr, "beam": beam},
        "sampling": {"period": float(f"{T:.10g}"), "delay": res.settings["computation_delay"]},
        "sensors": sensors,
        "actuator": {"limit": rig.limit},
        "simulation": {
            "duration": float(log0.time[-1] - log0.time[0]),
            "substeps": res.settings["substeps"],
        },
        "reference": ref,
    }
    if ctrl is not None:
        d["controller"] = ctrl
    q_log = float((res.stages.get("guesses") or {}).get("logged_resolution") or 0.0)
    if q <= 0 and q_log > 0:
        # the controller read a finer angle than the log holds (the fit left the encoder
        # out); the logged resolution bounds its count for a design's quantisation check
        d["notes"] = {"rig": {"encoder_count": q_log}}
    c = {
        "arm.motor.inertia": "kg*m^2, J: fitted hub inertia at the output shaft",
        "arm.motor.viscous": "N*m*s/rad, B: fitted viscous friction",
        "arm.motor.motor_constant": "V*s/rad, K_m (data sheet)",
        "arm.motor.armature_resistance": "ohm (data sheet)",
        "arm.motor.gear_ratio": "K_g (data sheet)",
        "arm.friction.coulomb": "N*m, fitted Coulomb friction",
        "arm.friction.static": "N*m, fitted breakaway (static) friction",
        "arm.friction.bias": "N*m, fitted constant bias torque",
        "arm.friction.pushed_stiffening": "the link's clamp (1 + this) times stiffer while the "
        "hub is stuck and pushed (estimated from the stuck phases' ringing, not fitted)",
        "arm.friction.push_threshold": "N*m of drive torque where the stiffening of a stuck "
        "hub's clamp starts (the light stuck phases' largest push)",
        "arm.friction.push_full": "N*m of drive torque where it is complete (the pushed stuck "
        "phases' smallest push)",
        "arm.beam.damping_ratio": "fitted link damping ratio",
        "arm.beam.length": "m, link length (data sheet)",
        "sampling.period": "s",
        "sampling.delay": "samples of computation delay (given, or where the declared law "
        "best explains the logged command)",
        "actuator.limit": "V, the amplifier limit (given, or the log format's [controller] limit)",
        "notes.rig.encoder_count": "rad, the logged hub angle's resolution (the controller "
        "read a finer one): the design's quantisation check",
        "sensors.motor_angle.delay": "samples, fitted",
        "sensors.tip_deflection.gain": "fitted strain-gauge calibration (m per m, with sign)",
        "sensors.tip_deflection.delay": "samples, fitted",
        "simulation.duration": "s, length of the first log",
    }
    if not rigid:  # a rigid arm has no link stiffness (its --scenario-out raised KeyError)
        c["arm.beam.flexural_rigidity"] = (
            f"N*m^2, EI = C L / 3 with fitted stiffness C = {der['link_stiffness']:.5g} N*m/rad"
        )
        c["arm.beam.masses.mass"] = (
            f"kg, J_l / L^2 with fitted link inertia J_l = {p['link_inertia']:.5g} kg*m^2"
        )
    return d, c


def toml_with_comments(d: dict, comments: dict, header: list[str]) -> str:
    """TOML text of ``d`` (tomli_w values) with ``# comment`` after the commented keys."""
    lines = [f"# {h}" for h in header] + [""]

    def emit(prefix: str, table: dict, array_item: bool = False):
        scalars = {
            k: v
            for k, v in table.items()
            if not isinstance(v, (dict, list))
            or (isinstance(v, list) and not (v and isinstance(v[0], dict)))
        }
        if prefix:
            lines.append(f"[[{prefix}]]" if array_item else f"[{prefix}]")
        for k, v in scalars.items():
            if v is None:
                continue
            text = tomli_w.dumps({k: v}).strip()
            cm = comments.get(f"{prefix}.{k}" if prefix else k)
            lines.append(f"{text:40s} # {cm}" if cm else text)
        lines.append("")
        for k, v in table.items():
            name = f"{prefix}.{k}" if prefix else k
            if isinstance(v, dict):
                emit(name, v)
            elif isinstance(v, list) and v and isinstance(v[0], dict):
                for item in v:
                    emit(name, item, array_item=True)

    emit("", d)
    return "\n".join(lines)


def overlay_plots(directory, logs, traj, fit_percent, tag: str, label: str | None = None):
    """Measured vs simulated hub angle, tip deflection (mm) and command, with the reference,
    for each servo-rig log: one PNG per log, ``KEY_TAG.png`` (KEY the log's key without its
    extension, ``/`` as ``__``), drawn by the one overlay figure
    (:func:`~flexarm.identification.time_domain.predict.write_overlays`); ``traj`` the rig
    engines' (hub angle, tip deflection, command) arrays, one row per log; ``label`` the
    figures' title after the key (default: ``tag``)."""
    from flexarm.identification.time_domain.figures import rig_trace, write_overlays
    from flexarm.identification.time_domain.result import Prediction

    keys = log_keys(logs)
    traces = {
        key: rig_trace(g, [np.asarray(traj[r][i, : len(g)]) for r in range(3)])
        for i, (g, key) in enumerate(zip(logs, keys, strict=True))
    }
    pred = Prediction(label or tag, {k: fit_percent.get(k, {}) for k in keys}, traces)
    return write_overlays(pred, directory, tag, names=figure_names(keys, tag))


def figure_names(keys, tag: str) -> list[str]:
    """The servo rig's figure file names: ``KEY_TAG.png`` per log key (KEY without its
    extension, ``/`` as ``__``, ``#`` as ``_``)."""
    return [f"{k.rsplit('.', 1)[0].replace('/', '__').replace('#', '_')}_{tag}.png" for k in keys]


def scenario_spread(fit: dict, scenario) -> dict[str, tuple[float, float]]:
    """Scenario path → (value, std) of a servo-rig fit's JSON (:meth:`FitResult.to_dict`,
    ``flexarm fit --json``) on the scenario it wrote (``--scenario-out``), for drawing plants
    (:func:`flexarm.design.plants.from_paths`). Values are the scenario's; the standard
    deviations the fit's HAC ones, mapped as :func:`scenario_from_fit` maps the parameters:
    J → ``arm.motor.inertia``, B → ``arm.motor.viscous``, C_f → ``arm.friction.coulomb``
    (the breakaway moves with it: ``arm.friction.static`` gets the same std), ζ →
    ``arm.beam.damping_ratio``, the gauge gain → ``sensors.tip_deflection.gain``, J_l →
    the tip mass J_l / L², and the stiffness C = ω_c² J_l → EI = C L / 3 with relative std
    √((2 σ_ω/ω)² + (σ_J/J_l)²). The parameters' correlations are not in the JSON: the draws
    are independent (wider or narrower than the fit's joint uncertainty where two parameters
    trade off; the Python path :func:`flexarm.design.plants.from_fit` keeps them).

    ``fit``: the document (``params``, ``std``; the older ``parameters`` table of
    ``{value, std}`` written before the one result is read too)."""
    vals, stds = _values_and_std(fit)
    d = scenario.model_dump(mode="json", exclude_none=True)
    if any(k.startswith(("arm.", "sensors.")) for k in stds):
        # the one result's document: keyed by the scenario's own paths already
        from flexarm.specs.paths import get as path_get

        got: dict[str, tuple[float, float]] = {}
        for path, sd in stds.items():
            if path.startswith("sessions[") or sd is None or not math.isfinite(float(sd)):
                continue
            try:
                got[path] = (float(path_get(d, path)), float(sd))
            except (KeyError, IndexError, TypeError, ValueError):
                continue
        if got:
            return got
    arm = d["arm"]

    def pick(table, name):
        return table.get(name, table.get(f"{name}[0]"))

    def std(name):
        s = pick(stds, name)
        return float(s) if s is not None and math.isfinite(float(s)) else None

    def value(name):
        return pick(vals, name)

    out: dict[str, tuple[float, float]] = {}

    def put(path, mean, s):
        if s is not None and mean is not None:
            out[path] = (float(mean), float(s))

    put("arm.motor.inertia", arm["motor"].get("inertia"), std("hub_inertia"))
    put("arm.motor.viscous", arm["motor"].get("viscous"), std("viscous"))
    fr = arm.get("friction", {})
    if fr.get("model") == "coulomb":
        put("arm.friction.coulomb", fr.get("coulomb"), std("coulomb"))
        put("arm.friction.static", fr.get("static"), std("coulomb"))
    beam = arm.get("beam", {})
    if beam.get("model") == "lumped":
        put("arm.beam.damping_ratio", beam.get("damping_ratio"), std("link_damping"))
        L = float(beam["length"])
        sj, sw = std("link_inertia"), std("link_frequency")
        J, w = value("link_inertia"), value("link_frequency")
        if sj is not None and J:
            put("arm.beam.masses[0].mass", beam["masses"][0]["mass"], sj / L**2)
            if sw is not None and w:
                rel = math.hypot(2 * sw / w, sj / J)
                put(
                    "arm.beam.flexural_rigidity",
                    beam["flexural_rigidity"],
                    rel * beam["flexural_rigidity"],
                )
        tip = d.get("sensors", {}).get("tip_deflection", {})
        put("sensors.tip_deflection.gain", tip.get("gain"), std("tip_gain"))
    if not out:
        raise FitInputError(
            "the fit JSON gives no standard deviation the scenario can use "
            "(every std is missing or NaN): the fit could not estimate its "
            "uncertainty; give --spread PATH=STD instead"
        )
    return out


def _values_and_std(fit: dict) -> tuple[dict, dict]:
    """(name → value, name → std) of a servo-rig fit document: the one result's
    (``params``, ``std``), or the older layout's ``parameters`` table."""
    if isinstance(fit.get("params"), dict) and isinstance(fit.get("std"), dict):
        return fit["params"], fit["std"]
    par = fit.get("parameters")
    if isinstance(par, dict):  # the layout before the one FitResult: {name: {value, std}}
        return (
            {k: (v or {}).get("value") for k, v in par.items()},
            {k: (v or {}).get("std") for k, v in par.items()},
        )
    raise FitInputError(
        "the fit JSON has no 'params' and 'std' tables: not a document flexarm fit "
        "writes; re-run `flexarm fit ... --json FIT.json` and give that file"
    )

"""Identification of a single-link flexible arm with Coulomb joint friction (FRB Sec. II).

Pipeline of :func:`identify`, one CSV log (:mod:`flexarm.io.logs`) per sinusoidal
experiment of the motor-position loop:

1. harmonics of every log (:mod:`flexarm.identification.frequency_domain.harmonics`): ω0 from the
   reference, fundamental and odd harmonics of θm, θt, i over the last whole periods;
2. Coulomb level C_f (A) from every ω0 / 3ω0 pair, eqs. (4)-(6) with the corrected phase of
   (4) (:mod:`flexarm.identification.frequency_domain.coulomb`), averaged over the pairs;
3. motor response G_m = θm/i raw and corrected by eq. (7), beam response G_b = θt/θm
   (:mod:`flexarm.identification.frequency_domain.frf`);
4. transfer functions fitted to the corrected G_m (default one integrator, two zeros, four
   poles, the form of FRB eq. (12)) and to G_b (no zeros, two poles, the form of eq. (13))
   by :func:`flexarm.identification.frequency_domain.tfest.tfest` with the log-ratio cost
   Σ|ln(Ĥ/H)|² (log-magnitude and phase errors with equal weight, the measure of FRB
   eq. (6); the sine experiments carry no variances and span decades of |G_m|); a fit to
   the raw G_m is kept for comparison;
5. physical parameters J, V, C of eq. (1) with C_t = C(θm − θt), i.e.

       G_m(s) = K / (J s² + V s + C (1 − G_b(s))),

   by linear least squares on the *fitted* models over ``n_grid`` log-spaced frequencies
   spanning the data: minimise Σ |1 − G_m(jω) (−Jω² + jVω + C(1 − G_b(jω)))/K|²
   (the relative error of the implied motor model; linear in J, V, C).
   K (N·m/A) is given (e.g. from the catalogue, as in FRB Sec. VI-B).

Units: SI throughout (rad, s, A, N·m); C_f is reported as a current (A) and as a torque
K·C_f (N·m).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, overload

import control
import numpy as np

from flexarm.display import Table
from flexarm.identification.frequency_domain.coulomb import (
    PARTNER_TOL,
    CoulombEstimate,
    estimate_coulomb,
    find_partners,
)
from flexarm.identification.frequency_domain.frf import FrequencyResponse, frequency_response
from flexarm.identification.frequency_domain.harmonics import (
    HarmonicAnalysis,
    IdentificationError,
    _warn,
    analyse_log,
)
from flexarm.identification.frequency_domain.physical import PhysicalFit, fit_physical
from flexarm.identification.frequency_domain.tfest import (
    TFEstError,
    TFEstimate,
    tf_coefficients,
    tf_response,
    tfest,
)
from flexarm.io.logs import Log, LogError, read_log
from flexarm.io.write import save_figure, write_text
from flexarm.units import UnitError, to_si


@overload
def _cx(z: None) -> None: ...
@overload
def _cx(z: complex) -> dict[str, float]: ...
def _cx(z: complex | None) -> dict[str, float] | None:
    if z is None:
        return None
    z = complex(z)
    return {"re": float(z.real), "im": float(z.imag)}


def _roots(poly: Sequence[float]) -> list[dict[str, float]]:
    return [_cx(r) for r in np.roots(np.asarray(poly, dtype=float))] if len(poly) > 1 else []


def arm_parameters(
    motor_tf: control.TransferFunction,
    beam_tf: control.TransferFunction,
    motor_constant: float,
    omega: np.ndarray,
) -> dict[str, float]:
    """J (kg·m²), V (N·m·s/rad), C (N·m/rad) from G_m = K/(J s² + V s + C(1 − G_b)).

    Linear least squares over ``omega`` (rad/s) of the relative model error
    1 − G_m(jω)(−Jω² + jVω + C(1 − G_b(jω)))/K.  Also returns ``rms_relative_error``.
    """
    w = np.asarray(omega, dtype=float)
    gm = tf_response(motor_tf, w)
    gb = tf_response(beam_tf, w)
    rows = (gm / motor_constant)[:, None] * np.column_stack([-(w**2) + 0j, 1j * w, 1 - gb])
    A = np.vstack([rows.real, rows.imag])
    b = np.concatenate([np.ones_like(w), np.zeros_like(w)])
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    x = np.linalg.lstsq(A / scale, b, rcond=None)[0] / scale
    res = A @ x - b
    return {
        "inertia": float(x[0]),
        "viscous": float(x[1]),
        "stiffness": float(x[2]),
        "rms_relative_error": float(np.sqrt(np.mean(res[: len(w)] ** 2 + res[len(w) :] ** 2))),
    }


def _named(
    g: control.TransferFunction, name: str, input: str, output: str
) -> control.TransferFunction:
    """``g`` (the same coefficients) with a name and signal names."""
    return control.TransferFunction(g.num, g.den, g.dt, name=name, inputs=[input], outputs=[output])


@dataclass
class IdentificationResult:
    """Everything :func:`identify` found; see :meth:`to_dict` for the JSON layout."""

    files: list[Path]
    logs: list[Log]
    analyses: list[HarmonicAnalysis]
    coulomb: CoulombEstimate
    response: FrequencyResponse
    motor_fit: TFEstimate
    motor_fit_raw: TFEstimate | None
    beam_fit: TFEstimate
    motor_constant: float
    parameters: dict[str, float]
    settings: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    physical: PhysicalFit | None = None
    use_physical: bool = False

    # -- main numbers ---------------------------------------------------------------
    @property
    def coulomb_current(self) -> float | None:
        """C_f as a current (A): the mean over the ω0/3ω0 pairs (or the value given)."""
        return self.response.coulomb_current

    @property
    def coulomb_torque(self) -> float | None:
        """K·C_f (N·m)."""
        c = self.coulomb_current
        return None if c is None else c * self.motor_constant

    @property
    def motor_tf(self) -> control.TransferFunction:
        """G_m(s) = θm/i (rad/A): the structured physical fit if ``structured=True``
        (:mod:`flexarm.identification.frequency_domain.physical`), else the fit to the corrected
        data (raw if C_f is unknown); named ``G_m`` (input ``current``, output
        ``motor_angle``)."""
        if self.use_physical:
            assert self.physical is not None  # use_physical is set with a physical fit
            return _named(self.physical.motor_tf, "G_m", "current", "motor_angle")
        return self.motor_tf_corrected_fit

    @property
    def motor_tf_corrected_fit(self) -> control.TransferFunction:
        """G_m(s) fitted freely to the friction-corrected data (FRB eq. 7 and Sec. VI-B);
        named ``G_m`` (input ``current``, output ``motor_angle``)."""
        return _named(self.motor_fit.tf, "G_m", "current", "motor_angle")

    @property
    def beam_tf(self) -> control.TransferFunction:
        """G_b(s) = θt/θm fitted to the data; named ``G_b`` (input ``motor_angle``, output
        ``tip_angle``)."""
        return _named(self.beam_fit.tf, "G_b", "motor_angle", "tip_angle")

    def motor_frd(self, corrected: bool = True) -> control.FrequencyResponseData:
        return self.response.frd("motor" if corrected else "motor_raw")

    def beam_frd(self) -> control.FrequencyResponseData:
        return self.response.frd("beam")

    # -- display --------------------------------------------------------------------
    def _table(self) -> Table:
        """The headline numbers: C_f, K, the fitted parameters, the poles; the warnings."""
        rows: list[tuple[str, object]] = [
            ("experiments", len(self.analyses)),
            (
                "Coulomb current C_f",
                None if self.coulomb_current is None else f"{self.coulomb_current:.4g} A",
            ),
            (
                "Coulomb torque K·C_f",
                None if self.coulomb_torque is None else f"{self.coulomb_torque:.4g} N*m",
            ),
            ("motor constant K", f"{self.motor_constant:.4g} N*m/A"),
        ]
        rows += [(k, v) for k, v in self.parameters.items()]
        rows += [
            ("G_m poles", [complex(p) for p in np.roots(self.motor_tf.den[0][0])]),
            ("G_b poles", [complex(p) for p in np.roots(self.beam_tf.den[0][0])]),
        ]
        return Table(
            f"IdentificationResult ({len(self.files)} files)", rows, notes=list(self.warnings)
        )

    def __repr__(self) -> str:
        return self._table().text()

    def _repr_html_(self) -> str:
        return self._table().html()

    # -- exports --------------------------------------------------------------------
    def _roles(self) -> dict[str, str]:
        pairs = find_partners(self.analyses, self.settings.get("partner_tol", PARTNER_TOL))
        partners = {j for _, j in pairs if j is not None}
        roles = {}
        for k, j in pairs:
            name = self.analyses[k].name
            if j is not None:
                roles[name] = "omega0"
            elif k in partners:
                roles[name] = "3omega0_partner"
            else:
                roles[name] = "unpaired"
        for k in partners:  # an experiment may be both an ω0 and a partner
            name = self.analyses[k].name
            if roles[name] == "omega0":
                roles[name] = "omega0_and_3omega0_partner"
        return roles

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (SI units; complex numbers as {re, im})."""
        fr = self.response
        # tfest sets every fit's relative error
        assert self.motor_fit.relative_error is not None
        assert self.beam_fit.relative_error is not None
        roles = self._roles()
        by_name = {a.name: a for a in self.analyses}
        per = []
        for k, name in enumerate(fr.names):
            a = by_name[name]
            per.append(
                {
                    "file": name,
                    "omega": float(fr.omega[k]),
                    "periods_analysed": a.n_periods,
                    "role": roles.get(name, "unpaired"),
                    "motor_raw": _cx(fr.motor_raw[k]),
                    "motor_corrected": None
                    if fr.motor_corrected is None
                    else _cx(fr.motor_corrected[k]),
                    "beam": _cx(fr.beam[k]),
                    "motor_fit_relative_error": float(self.motor_fit.relative_error[k]),
                    "beam_fit_relative_error": float(self.beam_fit.relative_error[k]),
                    "current_saturation": a.saturation,
                }
            )
        c = self.coulomb
        return {
            "coulomb_current": self.coulomb_current,
            "coulomb_torque": self.coulomb_torque,
            "coulomb_current_per_frequency": [
                {
                    "omega": e.omega,
                    "partner_omega": e.partner_omega,
                    "coulomb_current": e.coulomb_current,
                    "cost": e.cost,
                    "file": e.name,
                    "partner_file": e.partner_name,
                }
                for e in c.pairs
            ],
            "coulomb_spread": {
                "mean": c.coulomb_current,
                "std": c.std,
                "max_relative_deviation": c.max_rel_dev,
                "pairs": len(c.pairs),
            },
            "motor_constant": self.motor_constant,
            "motor_tf": tf_coefficients(self.motor_tf),
            "motor_tf_method": "structured physical fit (J, V, C, C_f)"
            if self.use_physical
            else (
                "free fit to the corrected data"
                if fr.motor_corrected is not None
                else "free fit to the raw data"
            ),
            "motor_tf_corrected_fit": tf_coefficients(self.motor_fit.tf),
            "motor_tf_fitted_to": "corrected" if fr.motor_corrected is not None else "raw",
            "physical_fit": None if self.physical is None else self.physical.to_dict(),
            "motor_tf_raw": None
            if self.motor_fit_raw is None
            else tf_coefficients(self.motor_fit_raw.tf),
            "motor_poles": _roots(tf_coefficients(self.motor_tf)["den"]),
            "motor_zeros": _roots(tf_coefficients(self.motor_tf)["num"]),
            "beam_tf": tf_coefficients(self.beam_tf),
            "beam_poles": _roots(tf_coefficients(self.beam_tf)["den"]),
            "parameters": dict(self.parameters),
            "frequency_response": per,
            "warnings": list(self.warnings),
            "settings": dict(self.settings),
            "units": {
                "omega": "rad/s",
                "coulomb_current": "A",
                "coulomb_torque": "N*m",
                "motor_constant": "N*m/A",
                "motor_tf": "rad/A (s in rad/s)",
                "beam_tf": "rad/rad",
                "inertia": "kg*m**2",
                "viscous": "N*m*s/rad",
                "stiffness": "N*m/rad",
            },
        }

    def to_json(
        self, path: str | Path | None = None, *, indent: int = 2, overwrite: bool = True
    ) -> str:
        """The :meth:`to_dict` summary as JSON text; also written to ``path`` if given
        (atomically, :func:`flexarm.io.write.write_text`; an existing file is replaced unless
        ``overwrite=False``)."""
        text = json.dumps(self.to_dict(), indent=indent)
        if path is not None:
            write_text(path, text + "\n", overwrite=overwrite)
        return text

    def bode_figures(self, out_dir: str | Path, *, dpi: int = 120) -> list[Path]:
        """Bode plots as FRB Figs. 9 (motor) and 10 (beam): raw data crosses, corrected
        data diamonds, fitted model line; magnitude (dB) and phase (deg) against ω (rad/s,
        log axis).  Writes ``motor_bode.png`` and ``beam_bode.png`` into ``out_dir``."""
        from matplotlib.figure import Figure

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        fr = self.response
        lo, hi = fr.omega.min() / 2, fr.omega.max() * 2
        wg = np.logspace(np.log10(lo), np.log10(hi), 600)
        paths = []

        def panel(fig, title, model, data):
            ax1, ax2 = fig.subplots(2, 1, sharex=True)
            ph_m = np.degrees(np.unwrap(np.angle(model)))
            ax1.semilogx(
                wg, 20 * np.log10(np.abs(model)), "-", color="k", lw=1.2, label="fitted model"
            )
            ax2.semilogx(wg, ph_m, "-", color="k", lw=1.2)
            for label, H, marker in data:
                ph = np.degrees(np.angle(H))
                ref = np.interp(np.log(fr.omega), np.log(wg), ph_m)
                ph = ph + 360 * np.round((ref - ph) / 360)
                style = dict(marker=marker, ls="none", ms=7, mfc="none", label=label)
                ax1.semilogx(fr.omega, 20 * np.log10(np.abs(H)), **style)
                ax2.semilogx(fr.omega, ph, **style)
            ax1.set_ylabel("magnitude (dB)")
            ax2.set_ylabel("phase (deg)")
            ax2.set_xlabel("frequency ω (rad/s)")
            ax1.set_title(title)
            ax1.grid(True, which="both", alpha=0.3)
            ax2.grid(True, which="both", alpha=0.3)
            ax1.legend(loc="best", fontsize=8)

        fig = Figure(figsize=(7, 6), layout="constrained")
        data = [("experimental data", fr.motor_raw, "x")]
        if fr.motor_corrected is not None:
            data.append(("corrected data, eq. (7)", fr.motor_corrected, "D"))
        cf = self.coulomb_current
        panel(
            fig,
            "Motor G_m = θm/i (rad/A)" + (f", C_f = {cf:.4g} A" if cf else ""),
            tf_response(self.motor_tf, wg),
            data,
        )
        if self.physical is not None:
            ax1, ax2 = fig.axes[:2]
            other = self.motor_fit.tf if self.use_physical else self.physical.motor_tf
            h = tf_response(other, wg)
            ax1.semilogx(
                wg,
                20 * np.log10(np.abs(h)),
                "--",
                color="0.5",
                lw=1,
                label="free fit to corrected data"
                if self.use_physical
                else "structured fit (J, V, C, C_f)",
            )
            ax2.semilogx(wg, np.degrees(np.unwrap(np.angle(h))), "--", color="0.5", lw=1)
            ax1.legend(loc="best", fontsize=8)
        p = out / "motor_bode.png"
        save_figure(fig, p, overwrite=True, dpi=dpi)
        paths.append(p)

        fig = Figure(figsize=(7, 6), layout="constrained")
        panel(
            fig,
            "Beam G_b = θt/θm",
            tf_response(self.beam_tf, wg),
            [("experimental data", fr.beam, "x")],
        )
        p = out / "beam_bode.png"
        save_figure(fig, p, overwrite=True, dpi=dpi)
        paths.append(p)
        return paths

    def to_scenario_dict(
        self, *, current_limit: float | str | None = None, name: str = "identified_arm"
    ) -> dict[str, Any]:
        """Scenario fragment for a single-link arm with a transfer-function beam.

        ``arm.motor``: drive ``current``, J, V (from :func:`arm_parameters`), K, and the
        current limit (given; else the saturation level seen in the logs; else the largest
        |current| recorded, a lower bound, said so in ``notes``); ``arm.friction``: Coulomb,
        K·C_f (N·m); ``arm.beam``: ``transfer_function`` with stiffness C and the fitted
        G_b.  Sampling, simulation and controller sections are left to the caller.
        """
        J = self.parameters["inertia"]
        V = self.parameters["viscous"]
        C = self.parameters["stiffness"]
        bad = [f"{k} = {v:.4g}" for k, v in (("inertia J", J), ("stiffness C", C)) if v <= 0]
        if V < 0:
            bad.append(f"viscous V = {V:.4g}")
        if bad:
            raise IdentificationError(
                "cannot build a scenario: the identified parameters are not physical ("
                + ", ".join(bad)
                + "); check the fitted orders and the data"
            )
        notes = {
            "source": "flexarm.identification.frequency_domain.identify (FRB Sec. II)",
            "files": ", ".join(str(f) for f in self.files),
            "parameters_from": "least squares on the fitted G_m, G_b: "
            "G_m = K/(J s^2 + V s + C (1 - G_b))",
        }
        if current_limit is None:
            sat = [a.saturation for a in self.analyses if a.saturation is not None]
            if sat:
                limit = float(max(sat))
                notes["current_limit"] = "saturation level seen in the logs"
            else:
                limit = float(max(np.max(np.abs(lg["current"])) for lg in self.logs))
                notes["current_limit"] = (
                    "largest |current| recorded (a lower bound; give the amplifier's limit)"
                )
        else:
            limit = to_si(current_limit, "A", field="current_limit")
        friction = (
            {"model": "coulomb", "coulomb": float(self.coulomb_torque)}
            if self.coulomb_torque is not None
            else {"model": "none"}
        )
        gb = tf_coefficients(self.beam_tf)
        return {
            "name": name,
            "description": "single-link arm identified from sinusoidal experiments "
            "(Feliu, Rattan & Brown 1993, Sec. II)",
            "notes": notes,
            "arm": {
                "kind": "single_link",
                "motor": {
                    "drive": "current",
                    "inertia": J,
                    "viscous": max(V, 0.0),
                    "torque_constant": self.motor_constant,
                    "current_limit": limit,
                },
                "friction": friction,
                "beam": {
                    "model": "transfer_function",
                    "stiffness": C,
                    "tip_num": gb["num"],
                    "tip_den": gb["den"],
                },
            },
        }


def _unit_static_gain(fit: TFEstimate, omega: np.ndarray, H: np.ndarray) -> TFEstimate:
    """G_b with G_b(0) = 1 exactly: at rest the tip lines up with the hub (θt = θm). The
    free fit misses this by ~1e-4, enough to move G_m's integrator off the origin. The
    numerator is rescaled (tf, relative_error and parameters b_i follow; cost and
    covariance stay those of the free fit)."""
    num = np.trim_zeros(np.asarray(fit.tf.num[0][0], float), "f")
    den = np.trim_zeros(np.asarray(fit.tf.den[0][0], float), "f")
    if num[-1] == 0 or den[-1] == 0:
        return fit
    g = den[-1] / num[-1]
    tf = control.tf(num * g, den)
    err = np.abs(tf_response(tf, omega) - H) / np.abs(H)
    params = {
        k: ({**v, "value": v["value"] * g, "std": v["std"] * abs(g)} if k.startswith("b") else v)
        for k, v in fit.parameters.items()
    }
    return replace(
        fit,
        tf=tf,
        relative_error=err,
        parameters=params,
        message=fit.message + "; numerator scaled to G_b(0) = 1",
    )


def _collect_files(files_or_dir, pattern: str) -> list[Path]:
    if isinstance(files_or_dir, (str, Path)):
        p = Path(files_or_dir)
        if p.is_dir():
            files = sorted(q for q in p.glob(pattern) if q.is_file())
            if not files:
                raise IdentificationError(
                    f"{p}: no experiment logs ({pattern}) in this directory; expected one CSV "
                    "file per sinusoidal experiment (columns time,reference,current,"
                    "motor_angle,tip_angle)"
                )
            return files
        if not p.exists():
            raise IdentificationError(f"{p}: no such file or directory")
        return [p]
    files = [Path(f) for f in files_or_dir]
    if not files:
        raise IdentificationError("no experiment logs given")
    for f in files:
        if f.is_dir():
            raise IdentificationError(f"{f}: is a directory; give files, or one directory")
    return files


def identify(
    files_or_dir: str | Path | Iterable[str | Path],
    motor_constant: float | str,
    motor_orders: tuple[int, int] = (2, 4),
    beam_orders: tuple[int, int] = (0, 2),
    columns: Mapping[str, str] | None = None,
    units: Mapping[str, str] | None = None,
    *,
    motor_integrators: int = 1,
    beam_integrators: int = 0,
    coulomb_current: float | None = None,
    partner_tol: float = PARTNER_TOL,
    discard_periods: float = 1.0,
    pattern: str = "*.csv",
    n_grid: int = 400,
    structured: bool | None = None,
    friction_shape: str = "measured",
) -> IdentificationResult:
    """Identify G_m, G_b, C_f, J, V, C from sinusoidal experiments (see module docstring).

    Parameters
    ----------
    files_or_dir:
        A directory (all ``pattern`` files in it) or a list of CSV logs.
    motor_constant:
        K in N·m/A (number, or string with units such as ``"2.184 lbf*in/A"``).
    motor_orders, beam_orders:
        (zeros, poles) of the fitted G_m (poles include ``motor_integrators`` at s = 0)
        and G_b.
    columns, units:
        Column-name and unit mapping for :func:`flexarm.io.logs.read_log`.
    coulomb_current:
        A known C_f (A) to use instead of estimating it.
    partner_tol:
        Relative tolerance for matching a 3ω0 partner.
    discard_periods:
        Periods dropped at the start of each record before the whole periods analysed.
    friction_shape:
        ``"measured"`` (default): the Coulomb friction's waveform is sign(θ̇m) with the
        velocity rebuilt from the logged motor angle (FRB Sec. II: the high-gain loop gives
        "the velocity of the motor and, hence, the shape of the Coulomb friction");
        ``"ideal"``: the square wave in phase with the fundamental, as eqs. (3)-(7) print.
    structured:
        Use the joint fit of J, V, C, C_f (:mod:`flexarm.identification.frequency_domain.physical`)
        as ``motor_tf``
        and for the parameters. It is always computed and reported (``physical_fit``)
        when the beam has one mode (``beam_orders == (0, 2)``: C_t = C (θm − θt)); it is
        the better choice where friction dominates the low-frequency current and the
        loop's stops at velocity reversals distort the friction square wave.
    """
    try:
        K = to_si(motor_constant, "N*m/A", field="motor_constant")
    except UnitError as exc:
        raise IdentificationError(str(exc)) from None
    if K <= 0:
        raise IdentificationError(f"motor_constant = {K:g} N*m/A; it must be positive")
    files = _collect_files(files_or_dir, pattern)
    warnings_: list[str] = []
    logs: list[Log] = []
    analyses: list[HarmonicAnalysis] = []
    problems: list[str] = []
    for f in files:
        try:
            log = read_log(f, columns=columns, units=units)
            an = analyse_log(
                log,
                n_max=5,
                columns=["reference", "current", "motor_angle", "tip_angle"],
                discard_periods=discard_periods,
                friction_shape=friction_shape,
            )
        except (LogError, IdentificationError) as exc:
            problems.append(str(exc))
            continue
        logs.append(log)
        analyses.append(an)
        warnings_.extend(an.warnings)
    if problems:
        raise IdentificationError(
            f"{len(problems)} of {len(files)} log(s) cannot be used:\n" + "\n".join(problems)
        )

    if coulomb_current is None:
        coul = estimate_coulomb(analyses, tol=partner_tol)
        warnings_.extend(coul.warnings)
        cf = coul.coulomb_current
    else:
        cf = to_si(coulomb_current, "A", field="coulomb_current")
        coul = CoulombEstimate(cf, [], None, None)
    fr = frequency_response(analyses, cf)
    if cf is None:
        _warn(
            "the Coulomb friction is unknown: the motor model is fitted to the raw "
            "(uncorrected) frequency response, which Coulomb friction distorts",
            warnings_,
        )

    nz, npl = motor_orders
    bz, bp = beam_orders

    def fit_tf(omega, H, n_zeros, n_poles, integrators):
        return tfest(
            control.frd(np.asarray(H, complex), omega),
            n_poles,
            n_zeros,
            integrators=integrators,
            cost="log",
        )

    try:
        mfit = fit_tf(
            fr.omega,
            fr.motor_corrected if cf is not None else fr.motor_raw,
            nz,
            npl,
            integrators=motor_integrators,
        )
        bfit = fit_tf(fr.omega, fr.beam, bz, bp, integrators=beam_integrators)
    except (TFEstError, ValueError) as exc:
        raise IdentificationError(
            f"cannot fit the transfer functions to the {len(fr.omega)} experiment(s): {exc}"
        ) from None
    if beam_integrators == 0:
        bfit = _unit_static_gain(bfit, fr.omega, fr.beam)
    mfit_raw = None
    if cf is not None:
        try:
            mfit_raw = fit_tf(fr.omega, fr.motor_raw, nz, npl, integrators=motor_integrators)
        except (TFEstError, ValueError) as exc:
            _warn(f"no fit to the raw motor response: {exc}", warnings_)
    assert mfit.relative_error is not None  # tfest sets it
    worst = int(np.argmax(mfit.relative_error))
    if mfit.relative_error[worst] > 0.2:
        _warn(
            f"{fr.names[worst]}: the free fit of G_m is {100 * mfit.relative_error[worst]:.0f} % "
            f"off the data at ω = {fr.omega[worst]:.4g} rad/s; check the model orders",
            warnings_,
        )

    grid = np.logspace(np.log10(fr.omega.min()), np.log10(fr.omega.max()), n_grid)
    one_mode = beam_orders == (0, 2) and beam_integrators == 0
    phys = None
    if cf is not None and (one_mode or structured):
        try:
            phys = fit_physical(analyses, bfit.tf, K)
        except ValueError as exc:
            _warn(f"no structured fit: {exc}", warnings_)
    if phys is not None and not (min(phys.inertia, phys.stiffness) > 0 and phys.viscous >= 0):
        _warn(
            "the structured fit gave non-physical values (J, V, C = "
            f"{phys.inertia:.3g}, {phys.viscous:.3g}, {phys.stiffness:.3g})",
            warnings_,
        )
        phys = None
    if structured is None:  # auto: the joint fit where its model holds (one-mode beam)
        structured = one_mode
    use_phys = bool(structured) and phys is not None
    if structured and phys is None and cf is not None:
        _warn("no structured fit is available: using the free fit", warnings_)
    params: dict[str, Any]
    if use_phys:
        assert phys is not None  # use_phys needs one
        params = {
            "inertia": phys.inertia,
            "viscous": phys.viscous,
            "stiffness": phys.stiffness,
            "method": "structured physical fit (flexarm.identification.frequency_domain.physical)",
        }
    else:
        params = arm_parameters(mfit.tf, bfit.tf, K, grid)
        params["method"] = (
            "least squares on the fitted models, G_m = K/(J s^2 + V s + "
            f"C (1 - G_b)), {n_grid} frequencies from {grid[0]:.4g} to "
            f"{grid[-1]:.4g} rad/s"
        )
    settings = {
        "motor_orders": list(motor_orders),
        "motor_integrators": motor_integrators,
        "beam_orders": list(beam_orders),
        "beam_integrators": beam_integrators,
        "partner_tol": partner_tol,
        "discard_periods": discard_periods,
        "coulomb_current_given": coulomb_current is not None,
        "structured": use_phys,
        "friction_shape": friction_shape,
    }
    return IdentificationResult(
        files=files,
        logs=logs,
        analyses=analyses,
        coulomb=coul,
        response=fr,
        motor_fit=mfit,
        motor_fit_raw=mfit_raw,
        beam_fit=bfit,
        motor_constant=K,
        parameters=params,
        settings=settings,
        warnings=warnings_,
        physical=phys,
        use_physical=use_phys,
    )

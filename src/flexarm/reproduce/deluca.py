"""Reproduction of De Luca & Siciliano, "Regulation of flexible arms under gravity" (IEEE TRA
9(4), 1993), simulation section, on the project's benchmark arm.

The experiment (paper, Sec. "Simulation results"): the two-link arm hanging at rest,
θ(0) = (−90°, 0), δ(0) = 0, is brought to θ_d = (−45°, 0) by the PD law with constant gravity
compensation, eq. (8),

    u = K_P (θ_d − θ) − K_D θ̇ + g_θ(θ_d, δ_d),
    K_P = diag(18, 18) N·m/rad, K_D = diag(10, 2) N·m·s/rad,

where δ_d solves eq. (9), K δ_d + g_δ(θ_d, δ_d) = 0. The paper reports δ_d, that (θ_d, δ_d) is
reached "well within 2 s" (its Fig. 2), a large initial effort and constant gravity-holding
torques at steady state, α of eq. (6) computed a posteriori along the run, that the sufficient
conditions (14)–(15) hold, that larger gains stay stable with larger initial torques, that too
large gains gave numerical trouble (remedy: an interpolating trajectory), and that the law
with on-line gravity compensation, eq. (30), lowers the initial effort.

:func:`run` redoes all of it and writes, into ``out_dir``:

* ``deluca_fig2.png``: joint angles, deflections and torques against time (their Fig. 2);
* ``deluca_laws.png``: laws (8), (30a) and (30b) side by side;
* ``deluca_sweep.png``: the gain sweep and the interpolating-trajectory remedy;
* ``deluca_table.csv`` / ``.md``: every reported quantity, the paper's value, ours, the ratio;
* ``deluca_conventions.csv`` / ``.md``: δ_d and α under other mode conventions (see
  :func:`convention_study` and docs/choices.md, "De Luca reproduction").

Every choice (durations, steps, sweep factors, damping, tolerances) is a field of
:class:`DeLucaConfig`. The arm data behind the paper's numbers is not in the paper; the arm
is the project's benchmark (:func:`flexarm.specs.multilink.benchmark_arm`, EI = 15 N·m²,
clamped-mass modes normalised to the link mass), so δ_d and α are compared, not forced.
Laws, α and conditions are the project's reconstruction (:mod:`flexarm.control.regulation`).
"""

from __future__ import annotations

import csv
import math
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from flexarm.control import regulation as R
from flexarm.errors import SimulationDiverged
from flexarm.io.write import atomic_open, save_figure, write_text
from flexarm.models.multilink import MultiLinkModel, build_multilink
from flexarm.sim.continuous import simulate_continuous
from flexarm.sim.result import SimulationResult
from flexarm.specs.multilink import benchmark_arm

DEG = math.pi / 180.0

# The paper's reported values: the "paper" column of the table and nothing else.
PAPER = {
    "delta_d": (-0.15, -0.0045, -0.0056, -0.000076),  # m, from eq. (9)
    "alpha": 17.67,  # eq. (6), a posteriori along the run
}


class StabilityConditionWarning(UserWarning):
    """The gains do not satisfy a sufficient condition (14)/(15); the simulation still runs."""


@dataclass(frozen=True)
class DeLucaConfig:
    """Every choice of the reproduction, in one place (SI units; ``_deg`` fields in degrees).

    Arm: ``flexural_rigidity`` (N·m²), ``mode_type`` and ``damping_ratio`` of the benchmark
    arm (none: the paper states no structural damping; the link modes are then damped only
    through the joints, hence ``t_long``).
    Experiment: ``theta_0_deg``, ``theta_d_deg``, gains ``KP`` (N·m/rad), ``KD`` (N·m·s/rad).
    Integration: RK4 with ``step`` (s); every run has ``n_out`` output samples, so each law
    compiles once and runs of other durations reuse it; ``t_final`` is the paper's window
    ("well within 2 s"), ``t_long`` long enough for the undamped link modes to settle (steady
    torque, settling times).
    Criteria: ``settle_angle_deg`` (every joint within it), ``settle_delta_frac`` (‖δ − δ_d‖
    within this fraction of ‖δ_d‖), ``torque_tol`` (N·m, steady torque).
    α: along the run, and over the box of (θ, δ) the run spans (``alpha_samples`` random
    samples, then ``alpha_refine`` local maximisations).
    Gain sweep: K_P × f and K_D × f^``sweep_kd_exponent`` (0.5 keeps the damping ratio of the
    rigid joint loop) for f in ``sweep_factors``, each run over ``sweep_t_final``.
    Remedy: at K_P × ``remedy_factor`` a quintic from θ_0 to θ_d over ``remedy_duration`` s;
    ``unstable_factor``: the first factor beyond fixed-step RK4 stability at ``step``, and,
    with ``probe_tsit5``, the same run with the adaptive Tsit5 (rtol ``tsit5_rtol``).
    Law (30b): ``newton_iterations`` for the quasi-static deflection.
    ``conventions``: run :func:`convention_study` (EI searched in ``convention_EI_bracket``).
    """

    flexural_rigidity: float = 15.0
    mode_type: str = "clamped_mass"
    damping_ratio: float = 0.0
    theta_0_deg: tuple[float, float] = (-90.0, 0.0)
    theta_d_deg: tuple[float, float] = (-45.0, 0.0)
    KP: tuple[float, float] = (18.0, 18.0)
    KD: tuple[float, float] = (10.0, 2.0)
    step: float = 1e-4
    n_out: int = 2000
    t_final: float = 2.0
    t_long: float = 15.0
    settle_angle_deg: float = 0.5
    settle_delta_frac: float = 0.02
    torque_tol: float = 1e-3
    alpha_samples: int = 2000
    alpha_refine: int = 2
    sweep_factors: tuple[float, ...] = (1.0, 2.0, 4.0, 8.0)
    sweep_kd_exponent: float = 0.5
    sweep_t_final: float = 5.0
    remedy_factor: float = 8.0
    remedy_duration: float = 1.0
    unstable_factor: float = 16.0
    probe_tsit5: bool = True
    tsit5_rtol: float = 1e-8
    newton_iterations: int = 4
    conventions: bool = True
    convention_EI_bracket: tuple[float, float] = (0.3, 200.0)

    @property
    def theta_0(self) -> np.ndarray:
        return np.asarray(self.theta_0_deg, float) * DEG

    @property
    def theta_d(self) -> np.ndarray:
        return np.asarray(self.theta_d_deg, float) * DEG

    def model(self, **overrides) -> MultiLinkModel:
        kw: dict[str, Any] = dict(
            flexural_rigidity=self.flexural_rigidity,
            mode_type=self.mode_type,
            damping_ratio=self.damping_ratio,
        )
        kw.update(overrides)
        EI = kw.pop("flexural_rigidity")
        return build_multilink(benchmark_arm(EI, **kw))


# --------------------------------------------------------------------------- helpers
def settling_time(t: np.ndarray, err: np.ndarray, tol: float) -> float:
    """First time after which err ≤ tol for the rest of the record (inf if never; t[0] if
    always)."""
    bad = np.nonzero(np.asarray(err) > tol)[0]
    if len(bad) == 0:
        return float(t[0])
    k = bad[-1] + 1
    return float(t[k]) if k < len(t) else math.inf


def _simulate(model, law, cfg: DeLucaConfig, params, t_final: float) -> SimulationResult:
    """A run with the config's step and n_out samples (dt = t_final/n_out)."""
    dt = t_final / cfg.n_out
    n_sub = max(1, int(round(dt / cfg.step)))
    return simulate_continuous(
        model, law, model.state(theta=cfg.theta_0), t_final, dt, params=params, step=dt / n_sub
    )


def _errors(run: SimulationResult, theta_d, delta_d):
    e_th = np.abs(run.theta - theta_d).max(axis=1) / DEG
    e_d = np.linalg.norm(run.delta - delta_d, axis=1) / np.linalg.norm(delta_d)
    return e_th, e_d


def _row(quantity, paper, ours, unit="", note="", ratio=None):
    if (
        ratio is None
        and isinstance(paper, (int, float))
        and isinstance(ours, (int, float))
        and paper != 0
        and math.isfinite(ours)
    ):
        ratio = ours / paper
    return {
        "quantity": quantity,
        "paper": paper,
        "ours": ours,
        "ratio": ratio,
        "unit": unit,
        "note": note,
    }


def _fmt(v) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if not math.isfinite(v):
            return str(v)
        return f"{v:.4g}"
    return str(v)


def _write_table(rows: list[dict], path_csv: Path, path_md: Path, title: str) -> None:
    keys = list(rows[0])
    with atomic_open(path_csv, "w", overwrite=True, newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: _fmt(r[k]) for k in keys})
    lines = [f"# {title}", "", "| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for r in rows:
        lines.append("| " + " | ".join(_fmt(r[k]).replace("|", "\\|") for k in keys) + " |")
    write_text(path_md, "\n".join(lines) + "\n", overwrite=True)


def check_conditions(cond: R.StabilityConditions, where: str = "") -> list[str]:
    """Warn (:class:`StabilityConditionWarning`) for each of (14), (15) that fails, naming
    it and by how much; returns the messages."""
    msgs = []
    for tag, name, lam, margin, ok, unit in (
        ("14", "λ_min(K)", cond.lambda_min_K, cond.margin_14, cond.holds_14, "N/m"),
        ("15", "λ_min(K_P)", cond.lambda_min_KP, cond.margin_15, cond.holds_15, "N·m/rad"),
    ):
        if not ok:
            msg = (
                f"condition ({tag}) {name} > α fails{where}: {name} = {lam:.4g} {unit} ≤ "
                f"α = {cond.alpha:.4g}, short by {-margin:.4g}; (14)–(15) are only "
                "sufficient, the simulation still runs"
            )
            warnings.warn(msg, StabilityConditionWarning, stacklevel=3)
            msgs.append(msg)
    return msgs


# --------------------------------------------------------------------------- conventions
_NORMS = ("link_mass", "unit_tip", "unit_mass")


def _mode_scale(model: MultiLinkModel, norm: str) -> np.ndarray:
    """s per mode such that the modal coordinate in normalisation ``norm`` is δ/s, δ in the
    model's own normalisation (∫ρφ² (+ tip terms) = link mass): φ_norm = s φ."""
    tip = np.concatenate([m.tip_value for m in model.modes])
    mass = np.concatenate([np.full(m.n_modes, m.mass) for m in model.modes])
    if norm == "link_mass":
        return np.ones_like(tip)
    if norm == "unit_tip":  # φ(ℓ) = 1: δ is the tip deflection of the mode (m)
        return 1.0 / tip
    if norm == "unit_mass":  # generalised mass 1 kg: δ in √kg·m
        return 1.0 / np.sqrt(mass)
    raise ValueError(norm)


def convention_study(cfg: DeLucaConfig, say: Callable[[str], None] | None = None) -> list[dict]:
    """δ_d and α under other documented conventions, against the paper's values.

    For clamped-mass and clamped-free modes and three normalisations of the mode shapes
    (link mass, the project's; unit tip deflection φ(ℓ) = 1; unit generalised mass 1 kg): δ_d
    at the configured EI, α along the law (8) run (‖S ∂g/∂q S‖₂ with S the coordinate scaling:
    α depends on the δ units), and the EI (both links) for which δ_d,11 equals the paper's,
    with the other components there. A renormalisation φ → sφ maps δ → δ/s and ∂g/∂q →
    S ∂g/∂q S (S = diag(1, 1, s)), exactly; the mode type changes the model (one run each).
    g does not depend on EI, so α changes with EI only through the trajectory. ``say(what)``
    reports progress."""
    from scipy.optimize import brentq

    say = say or (lambda msg: None)
    paper = np.asarray(PAPER["delta_d"])
    rows = []
    for mt in ("clamped_mass", "clamped_free"):
        say(f"conventions: {mt} modes")
        model = cfg.model(mode_type=mt)
        p = R.regulation_params(model, np.diag(cfg.KP), np.diag(cfg.KD), cfg.theta_d)
        run = _simulate(model, R.law_pd_constant, cfg, p, cfg.t_final)
        G = np.stack([model.gravity_jacobian(x[: model.n_q]) for x in run.state_array[::10]])
        for norm in _NORMS:
            s = _mode_scale(model, norm)
            S = np.concatenate([np.ones(model.n_links), s])
            dd = np.asarray(p.delta_d) / s
            alpha = float(max(np.linalg.norm(S[:, None] * g * S[None, :], 2) for g in G))

            def d11(EI, mt=mt, norm=norm):
                m = cfg.model(mode_type=mt, flexural_rigidity=EI)
                return R.residual_deflection(m, cfg.theta_d)[0] / _mode_scale(m, norm)[0] - paper[0]

            lo, hi = cfg.convention_EI_bracket
            try:
                EI = brentq(
                    d11,
                    lo,
                    hi,
                    rtol=1e-8,  # pyright: ignore[reportArgumentType]  (scipy: rtol is typed from its float64 default)
                    xtol=1e-6,
                )
                m = cfg.model(mode_type=mt, flexural_rigidity=EI)
                dd_match = R.residual_deflection(m, cfg.theta_d) / _mode_scale(m, norm)
            except (ValueError, R.RegulationError):
                EI, dd_match = math.nan, np.full_like(dd, math.nan)
            rows.append(
                {
                    "modes": mt,
                    "normalisation": norm,
                    **{
                        f"delta_d{k + 1}_EI{cfg.flexural_rigidity:g}": float(v)
                        for k, v in enumerate(dd)
                    },
                    "alpha_along_run": alpha,
                    "EI_matching_delta_d1": EI,
                    **{f"delta_d{k + 1}_at_match": float(v) for k, v in enumerate(dd_match)},
                    **{
                        f"ratio{k + 1}_at_match": float(v / pp)
                        for k, (v, pp) in enumerate(zip(dd_match, paper, strict=False))
                    },
                }
            )
    rows.append(
        {
            k: ("paper" if k == "modes" else "" if k == "normalisation" else math.nan)
            for k in rows[0]
        }
    )
    rows[-1].update(
        {
            "alpha_along_run": PAPER["alpha"],
            **{f"delta_d{k + 1}_at_match": v for k, v in enumerate(paper)},
        }
    )
    return rows


# --------------------------------------------------------------------------- figures
def _fig2(run: SimulationResult, theta_d, delta_d, g_d, path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 9), layout="constrained")
    ax = fig.subplots(3, 2, sharex=True)
    t = run.time
    for i in range(2):
        ax[0, i].plot(t, run.theta[:, i] / DEG, label=f"θ{i + 1}")
        ax[0, i].axhline(theta_d[i] / DEG, ls="--", c="k", lw=0.8, label="θ_d")
        ax[0, i].set_ylabel(f"θ{i + 1} (deg)")
        for j in range(2):
            k = 2 * i + j
            (line,) = ax[1, i].plot(t, run.delta[:, k] * 1e3, label=f"δ{i + 1}{j + 1}")
            ax[1, i].axhline(delta_d[k] * 1e3, ls="--", c=line.get_color(), lw=0.8)
        ax[1, i].set_ylabel(f"δ link {i + 1} (mm)")
        ax[2, i].plot(t, run.torque[:, i], label=f"u{i + 1}")
        ax[2, i].axhline(g_d[i], ls="--", c="k", lw=0.8, label="g_θ(θ_d, δ_d)")
        ax[2, i].set_ylabel(f"u{i + 1} (N·m)")
        ax[2, i].set_xlabel("t (s)")
        for a in ax[:, i]:
            a.legend(fontsize=8)
            a.grid(alpha=0.3)
    fig.suptitle(
        "De Luca & Siciliano Fig. 2 on the benchmark arm: PD law (8), "
        "K_P = diag(18, 18), K_D = diag(10, 2)"
    )
    save_figure(fig, path, overwrite=True, dpi=110)


def _fig_laws(runs: dict, theta_d, path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 6), layout="constrained")
    ax = fig.subplots(2, 2, sharex=True)
    for name, run in runs.items():
        for i in range(2):
            ax[0, i].plot(run.time, run.theta[:, i] / DEG, label=name)
            ax[1, i].plot(run.time, run.torque[:, i], label=name)
    for i in range(2):
        ax[0, i].axhline(theta_d[i] / DEG, ls="--", c="k", lw=0.8)
        ax[0, i].set_ylabel(f"θ{i + 1} (deg)")
        ax[1, i].set_ylabel(f"u{i + 1} (N·m)")
        ax[1, i].set_xlabel("t (s)")
        for a in ax[:, i]:
            a.legend(fontsize=8)
            a.grid(alpha=0.3)
    fig.suptitle(
        "Law (8) (constant gravity compensation) against law (30): "
        "(30a) g_θ(θ, δ), (30b) g_θ(θ, δ̄(θ))"
    )
    save_figure(fig, path, overwrite=True, dpi=110)


def _fig_sweep(sweep_runs: dict, remedy_runs: dict, theta_d, path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 7), layout="constrained")
    ax = fig.subplots(2, 2)
    for name, run in sweep_runs.items():
        ax[0, 0].plot(run.time, run.theta[:, 0] / DEG, label=name)
        ax[0, 1].plot(run.time, run.torque[:, 0], label=name)
    for name, run in remedy_runs.items():
        ax[1, 0].plot(run.time, run.theta[:, 0] / DEG, label=name)
        ax[1, 1].plot(run.time, run.torque[:, 0], label=name)
    for a in ax[:, 0]:
        a.axhline(theta_d[0] / DEG, ls="--", c="k", lw=0.8)
        a.set_ylabel("θ1 (deg)")
    for a in ax[:, 1]:
        a.set_ylabel("u1 (N·m)")
        a.set_yscale("symlog", linthresh=10.0)
    for a in ax.ravel():
        a.set_xlabel("t (s)")
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    ax[0, 0].set_title("gain sweep (step to θ_d)")
    ax[1, 0].set_title("large gains: step against an interpolating trajectory")
    save_figure(fig, path, overwrite=True, dpi=110)


# --------------------------------------------------------------------------- the run
_STAGES = (
    "residual deflection δ_d, eq. (9)",
    "law (8)",
    "α and conditions (14)–(15)",
    "laws (30a), (30b)",
    "gain sweep",
    "large gains",
    "conventions",
    "table and figures",
)


def run(
    out_dir,
    progress: Callable[[int, int, str], None] | None = None,
    config: DeLucaConfig | None = None,
) -> dict:
    """Reproduce the paper's simulation section (module docstring) into ``out_dir``.

    ``progress(done, total, what)`` is called before each stage. Returns a dict: ``table``
    (rows: quantity, paper, ours, ratio, unit, note), ``figures`` (paths), ``table_csv``,
    ``table_md``, ``delta_d``, ``g_d``, ``alpha_along``, ``alpha_region``, ``conditions``,
    ``settling``, ``at_t_final``, ``steady``, ``laws``, ``sweep``, ``remedy``, ``conventions``,
    ``warnings`` (failed conditions), ``files``, ``config``. Gains failing (14) or (15) raise
    a :class:`StabilityConditionWarning` that names the condition and the shortfall; the
    simulation still runs."""
    cfg = config or DeLucaConfig()
    stage = iter(range(len(_STAGES)))

    def say(what: str) -> None:
        if progress is not None:
            k = next(stage, len(_STAGES) - 1)
            progress(k, len(_STAGES), what)

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    model = cfg.model()
    th_d = cfg.theta_d
    KP, KD = np.diag(cfg.KP), np.diag(cfg.KD)

    say("residual deflection δ_d, eq. (9)")
    p8 = R.regulation_params(model, KP, KD, th_d, newton_iterations=cfg.newton_iterations)
    dd, g_d = np.asarray(p8.delta_d), np.asarray(p8.g_d)

    say(f"law (8) over {cfg.t_final:g} s and {cfg.t_long:g} s")
    run8 = _simulate(model, R.law_pd_constant, cfg, p8, cfg.t_final)
    long8 = _simulate(model, R.law_pd_constant, cfg, p8, cfg.t_long)
    # settling on the fine record up to t_final, the long one after it
    later = long8.time > run8.time[-1]
    t_all = np.concatenate([run8.time, long8.time[later]])
    eth_f, ed_f = _errors(run8, th_d, dd)
    eth_l, ed_l = _errors(long8, th_d, dd)
    eth_all, ed_all = np.concatenate([eth_f, eth_l[later]]), np.concatenate([ed_f, ed_l[later]])
    settle = {
        "theta_s": settling_time(t_all, eth_all, cfg.settle_angle_deg),
        "delta_s": settling_time(t_all, ed_all, cfg.settle_delta_frac),
    }
    at_final = {
        "theta_err_deg": float(eth_f[-1]),
        "delta_err_frac": float(ed_f[-1]),
        "theta_err_deg_per_joint": (np.abs(run8.theta[-1] - th_d) / DEG).tolist(),
    }
    du = np.abs(long8.torque - g_d).max(axis=1)
    steady = {
        "u_end": long8.torque[-1].tolist(),
        "g_d": g_d.tolist(),
        "max_abs_diff_end": float(du[-1]),
        "within_tol_after_s": settling_time(long8.time, du, cfg.torque_tol),
        "t_long": cfg.t_long,
    }

    say("α along the run and over its region, conditions (14)–(15)")
    alpha_along, k_alpha = R.alpha_along(
        model, np.concatenate([run8.state_array, long8.state_array])
    )
    q = np.concatenate([run8.state_array, long8.state_array])[:, : model.n_q]
    region = R.alpha_bound(
        model,
        q[:, : model.n_links].min(0),
        q[:, : model.n_links].max(0),
        np.abs(q[:, model.n_links :]).max(0),
        n_samples=cfg.alpha_samples,
        refine=cfg.alpha_refine,
    )
    cond = R.stability_conditions(model, KP, alpha_along)
    cond_region = R.stability_conditions(model, KP, region.alpha)
    msgs = check_conditions(cond, " (α along the run)")
    msgs += check_conditions(cond_region, " (α over the region of the run)")

    say("laws (30a), (30b)")
    runs_laws = {"(8)": run8}
    for name, law in (("(30a)", R.law_pd_online), ("(30b)", R.law_pd_quasistatic)):
        runs_laws[name] = _simulate(model, law, cfg, p8, cfg.t_final)
    laws = {}
    for name, r in runs_laws.items():
        e_th, e_d = _errors(r, th_d, dd)
        laws[name] = {
            "u0": r.torque[0].tolist(),
            "u0_norm": float(np.linalg.norm(r.torque[0])),
            "peak_abs_u": float(np.abs(r.torque).max()),
            "theta_err_deg_t_final": float(e_th[-1]),
            "delta_err_frac_t_final": float(e_d[-1]),
        }

    say("gain sweep")
    sweep, sweep_runs = [], {}
    for f in cfg.sweep_factors:
        fk = f**cfg.sweep_kd_exponent
        pf = R.regulation_params(model, KP * f, KD * fk, th_d)
        entry = {
            "factor": f,
            "KP": (np.diag(KP) * f).tolist(),
            "KD": (np.diag(KD) * fk).tolist(),
            "conditions_hold": R.stability_conditions(model, KP * f, alpha_along).holds,
        }
        try:
            r = _simulate(model, R.law_pd_constant, cfg, pf, cfg.sweep_t_final)
            e_th, e_d = _errors(r, th_d, dd)
            k2 = int(np.argmin(np.abs(r.time - cfg.t_final)))
            entry.update(
                {
                    "diverged": False,
                    "u0_norm": float(np.linalg.norm(r.torque[0])),
                    "peak_abs_u": float(np.abs(r.torque).max()),
                    "theta_err_deg_t_final": float(e_th[k2]),
                    "theta_err_deg_end": float(e_th[-1]),
                    "delta_err_frac_end": float(e_d[-1]),
                    "theta_settle_s": settling_time(r.time, e_th, cfg.settle_angle_deg),
                }
            )
            sweep_runs[f"K_P×{f:g}"] = r
        except SimulationDiverged as exc:
            entry.update({"diverged": True, "error": str(exc)})
        sweep.append(entry)

    say("large gains: interpolating trajectory, numerical limit")
    f, fk = cfg.remedy_factor, cfg.remedy_factor**cfg.sweep_kd_exponent
    remedy: dict[str, Any] = {"factor": f}
    remedy_runs = {}
    for name, dur in (("step", 0.0), ("quintic", cfg.remedy_duration)):
        pr = R.regulation_params(model, KP * f, KD * fk, th_d, theta_0=cfg.theta_0, duration=dur)
        r = _simulate(model, R.law_pd_constant, cfg, pr, cfg.sweep_t_final)
        e_th, e_d = _errors(r, th_d, dd)
        k2 = int(np.argmin(np.abs(r.time - cfg.t_final)))
        remedy[name] = {
            "duration_s": dur,
            "peak_abs_u": float(np.abs(r.torque).max()),
            "peak_abs_delta_m": float(np.abs(r.delta).max()),
            "theta_err_deg_t_final": float(e_th[k2]),
            "delta_err_frac_t_final": float(e_d[k2]),
        }
        remedy_runs[f"K_P×{f:g}, {name}"] = r
    fu = cfg.unstable_factor
    unstable: dict[str, Any] = {"factor": fu}
    for name, dur in (("step", 0.0), ("quintic", cfg.remedy_duration)):
        pu = R.regulation_params(
            model, KP * fu, KD * fu**cfg.sweep_kd_exponent, th_d, theta_0=cfg.theta_0, duration=dur
        )
        try:
            _simulate(model, R.law_pd_constant, cfg, pu, cfg.t_final)
            unstable[f"rk4_{name}"] = "converged"
        except SimulationDiverged as exc:
            unstable[f"rk4_{name}"] = f"diverged: {exc}"
    if cfg.probe_tsit5:
        # the same loop with its adaptive solver (Tsit5, PID step control within each of
        # 200 output periods)
        pu = R.regulation_params(model, KP * fu, KD * fu**cfg.sweep_kd_exponent, th_d)
        try:
            ru = simulate_continuous(
                model,
                R.law_pd_constant,
                model.state(theta=cfg.theta_0),
                cfg.t_final,
                cfg.t_final / 200,
                params=pu,
                method="tsit5",
                step=cfg.step,
                rtol=cfg.tsit5_rtol,
                atol=1e-3 * cfg.tsit5_rtol,
            )
            unstable["tsit5_ok"] = True
            unstable["tsit5_theta_err_deg_t_final"] = float(np.abs(ru.theta[-1] - th_d).max() / DEG)
        except SimulationDiverged as exc:
            unstable["tsit5_ok"] = False
            unstable["tsit5_error"] = str(exc)
    remedy["unstable"] = unstable

    conventions = []
    say(
        "conventions: δ_d and α under other mode conventions"
        if cfg.conventions
        else "conventions: skipped"
    )
    if cfg.conventions:
        conventions = convention_study(cfg)

    say("table and figures")
    rows = []
    names = ["δ_d,11", "δ_d,12", "δ_d,21", "δ_d,22"]
    for k, nm in enumerate(names):
        rows.append(
            _row(
                f"{nm} (eq. 9)",
                PAPER["delta_d"][k],
                float(dd[k]),
                "m",
                "arm data not in the paper: benchmark arm, see docs/choices.md",
            )
        )
    rows.append(
        _row(
            "α a posteriori along the run (eq. 6, 2-norm)",
            PAPER["alpha"],
            alpha_along,
            "SI",
            f"max at t = {np.concatenate([run8.time, long8.time])[k_alpha]:.3g} s",
        )
    )
    rows.append(
        _row(
            "α over the region spanned by the run",
            "",
            region.alpha,
            "SI",
            f"{region.n_evaluations} evaluations",
        )
    )
    rows.append(
        _row(
            "condition (14) λ_min(K) > α",
            "satisfied",
            cond.holds_14,
            "",
            f"λ_min(K) = {cond.lambda_min_K:.4g} N/m, margin {cond.margin_14:+.4g} "
            f"(region α: {cond_region.margin_14:+.4g})",
        )
    )
    rows.append(
        _row(
            "condition (15) λ_min(K_P) > α",
            "satisfied",
            cond.holds_15,
            "",
            f"λ_min(K_P) = {cond.lambda_min_KP:.4g} N·m/rad, margin {cond.margin_15:+.4g} "
            f"(region α: {cond_region.margin_15:+.4g})",
        )
    )
    rows.append(
        _row(
            f"settling time, every |θ_i − θ_d,i| ≤ {cfg.settle_angle_deg:g}°",
            f"well within {cfg.t_final:g} s",
            settle["theta_s"],
            "s",
        )
    )
    rows.append(
        _row(
            f"settling time, ‖δ − δ_d‖ ≤ {cfg.settle_delta_frac:g}·‖δ_d‖",
            f"well within {cfg.t_final:g} s",
            settle["delta_s"],
            "s",
            "undamped link modes, damped through the joints only",
        )
    )
    rows.append(
        _row(
            f"max |θ_i − θ_d,i| at t = {cfg.t_final:g} s",
            "≈ 0 (Fig. 2)",
            at_final["theta_err_deg"],
            "deg",
        )
    )
    rows.append(
        _row(
            f"‖δ − δ_d‖/‖δ_d‖ at t = {cfg.t_final:g} s",
            "≈ 0 (Fig. 2)",
            at_final["delta_err_frac"],
            "",
        )
    )
    rows.append(
        _row(
            "steady torque u(∞) = g_θ(θ_d, δ_d)",
            "constant at steady state",
            steady["max_abs_diff_end"],
            "N·m",
            f"max |u − g_θ(θ_d, δ_d)| at t = {cfg.t_long:g} s; within "
            f"{cfg.torque_tol:g} N·m after {steady['within_tol_after_s']:.3g} s; "
            f"g_θ = ({g_d[0]:.4g}, {g_d[1]:.4g}) N·m",
        )
    )
    rows.append(_row("initial effort ‖u(0)‖, law (8)", "large", laws["(8)"]["u0_norm"], "N·m"))
    for name in ("(30a)", "(30b)"):
        rows.append(
            _row(
                f"initial effort ‖u(0)‖, law {name}",
                "lower than (8)",
                laws[name]["u0_norm"],
                "N·m",
                f"ratio to (8): {laws[name]['u0_norm'] / laws['(8)']['u0_norm']:.3f}; "
                f"|θ − θ_d| at {cfg.t_final:g} s {laws[name]['theta_err_deg_t_final']:.3g}°",
            )
        )
    for e in sweep:
        if e["diverged"]:
            rows.append(
                _row(
                    f"gain sweep K_P×{e['factor']:g}",
                    "stable, larger initial torque",
                    "diverged",
                    "",
                    e["error"][:120],
                )
            )
        else:
            rows.append(
                _row(
                    f"gain sweep K_P×{e['factor']:g}, "
                    f"K_D×{e['factor'] ** cfg.sweep_kd_exponent:.3g}",
                    "stable, larger initial torque",
                    e["u0_norm"],
                    "N·m (‖u(0)‖)",
                    f"|θ − θ_d| {e['theta_err_deg_t_final']:.3g}° at {cfg.t_final:g} s, "
                    f"{e['theta_err_deg_end']:.3g}° at {cfg.sweep_t_final:g} s; conditions "
                    f"{'hold' if e['conditions_hold'] else 'fail'}",
                )
            )
    rows.append(
        _row(
            f"too large gains (K_P×{fu:g}): numerical trouble",
            "numerical instabilities",
            unstable["rk4_step"].split(":")[0],
            "",
            f"RK4 {cfg.step:g} s; with the quintic: {unstable['rk4_quintic'].split(':')[0]}"
            + (
                f"; Tsit5 rtol {cfg.tsit5_rtol:g}: {'ok' if unstable['tsit5_ok'] else 'failed'}"
                if cfg.probe_tsit5
                else ""
            ),
        )
    )
    rows.append(
        _row(
            f"remedy at K_P×{f:g}: peak |u|, step → quintic over {cfg.remedy_duration:g} s",
            "interpolating trajectory",
            remedy["quintic"]["peak_abs_u"],
            "N·m",
            f"step {remedy['step']['peak_abs_u']:.4g} N·m; |θ − θ_d| at {cfg.t_final:g} s "
            f"{remedy['step']['theta_err_deg_t_final']:.3g}° → "
            f"{remedy['quintic']['theta_err_deg_t_final']:.3g}°",
            ratio=remedy["quintic"]["peak_abs_u"] / remedy["step"]["peak_abs_u"],
        )
    )

    files = {}
    files["table_csv"], files["table_md"] = out / "deluca_table.csv", out / "deluca_table.md"
    _write_table(
        rows,
        files["table_csv"],
        files["table_md"],
        "De Luca & Siciliano (1993), simulation section: paper vs flexarm",
    )
    if conventions:
        files["conventions_csv"] = out / "deluca_conventions.csv"
        files["conventions_md"] = out / "deluca_conventions.md"
        _write_table(
            conventions,
            files["conventions_csv"],
            files["conventions_md"],
            "δ_d and α under other mode conventions",
        )
    files["fig2"] = out / "deluca_fig2.png"
    _fig2(run8, th_d, dd, g_d, files["fig2"])
    files["laws"] = out / "deluca_laws.png"
    _fig_laws(runs_laws, th_d, files["laws"])
    files["sweep"] = out / "deluca_sweep.png"
    _fig_sweep(sweep_runs, remedy_runs, th_d, files["sweep"])

    return {
        "table": rows,
        "delta_d": dd.tolist(),
        "g_d": g_d.tolist(),
        "alpha_along": alpha_along,
        "alpha_region": region.alpha,
        "conditions": {
            "along": asdict(cond)
            | {
                "holds_14": cond.holds_14,
                "holds_15": cond.holds_15,
                "margin_14": cond.margin_14,
                "margin_15": cond.margin_15,
            },
            "region": asdict(cond_region)
            | {
                "holds_14": cond_region.holds_14,
                "holds_15": cond_region.holds_15,
                "margin_14": cond_region.margin_14,
                "margin_15": cond_region.margin_15,
            },
        },
        "settling": settle,
        "at_t_final": at_final,
        "steady": steady,
        "laws": laws,
        "sweep": sweep,
        "remedy": remedy,
        "conventions": conventions,
        "warnings": msgs,
        "figures": [str(files[k]) for k in ("fig2", "laws", "sweep")],
        "table_csv": str(files["table_csv"]),
        "table_md": str(files["table_md"]),
        "files": {k: str(v) for k, v in files.items()},
        "config": asdict(cfg),
    }


def quick_config(**overrides) -> DeLucaConfig:
    """A shorter configuration (two sweep factors, no Tsit5 probe, no convention study), for
    tests; everything else as :class:`DeLucaConfig`."""
    base = DeLucaConfig(
        sweep_factors=(1.0, 2.0),
        probe_tsit5=False,
        conventions=False,
        alpha_samples=500,
        alpha_refine=1,
        sweep_t_final=3.0,
    )
    return replace(base, **overrides)

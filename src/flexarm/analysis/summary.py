"""Write a simulation's CSV, figure and summary, and run the demo (``make demo``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from flexarm.analysis.model_info import single_link_info
from flexarm.io.write import NAME_MAX, distinct_names, safe_name, save_figure, write_json
from flexarm.metrics import step_metrics
from flexarm.sim.build import prepare, to_result
from flexarm.sim.sampled import simulate_loop
from flexarm.specs import Scenario, builtin_scenarios, load_scenario


def simulate_with_progress(scenario: Scenario, progress: bool = False):
    """Simulate a scenario, with a rich progress bar for long runs."""
    p = prepare(scenario)
    assert scenario.simulation is not None  # prepare() builds sampled-data loops only
    seed = scenario.simulation.seed
    if not progress or p.n_samples <= 20000:
        return to_result(p, simulate_loop(p.loop, p.x0, p.references, p.n_samples, seed=seed))
    from rich.progress import Progress

    with Progress() as bar:
        task = bar.add_task(f"simulating {scenario.name}", total=p.n_samples)
        out = simulate_loop(
            p.loop,
            p.x0,
            p.references,
            p.n_samples,
            seed=seed,
            progress=lambda done, total: bar.update(task, completed=done),
        )
    return to_result(p, out)


#: significant digits of a summary's numbers (``<name>.summary.json``, the demo's
#: ``summary.json`` and printed lines): what a figure resolves; machine-read documents
#: (``--json``, ``to_dict()``) keep full precision
DIGITS = 4


def rounded(obj: Any, digits: int = DIGITS) -> Any:
    """``obj`` (dicts, lists, tuples, NumPy scalars and arrays inside) with every float
    rounded to ``digits`` significant digits (0.28800000000000003 → 0.288, 153.38674875720403
    → 153.4) and every non-finite float as ``None`` (JSON has no NaN); ints, bools and
    strings as they are."""
    if isinstance(obj, dict):
        return {k: rounded(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [rounded(v, digits) for v in obj]
    if isinstance(obj, np.ndarray):
        return rounded(obj.tolist(), digits)
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return float(f"{x:.{digits}g}") if np.isfinite(x) else None
    return obj


def _tip_summary(res, ctrl: str) -> dict:
    """The tip of a single-link step run, as its figure shows it: the tip angle's range
    (rad), the largest deflection angle |tip − motor| (rad), the tip's settling time in
    the 2 % band of the step (s), or a sentence where it does not settle within the
    record; with a ``tip_deflection`` channel its peak (m) too."""
    tip, motor = np.asarray(res["tip_angle"]), np.asarray(res[ctrl])
    m = step_metrics(res.time, tip, res["reference"])
    out = {
        "tip_angle_range_rad": [float(tip.min()), float(tip.max())],
        "peak_deflection_angle_rad": float(np.max(np.abs(tip - motor))),
        "settling_time_s": (
            m.settling_time
            if m.settling_time is not None
            else f"not within the {float(res.time[-1] - res.time[0]):.3g} s record"
        ),
        "overshoot": m.overshoot,
    }
    if "tip_deflection" in res.signals:
        out["peak_tip_deflection_m"] = float(np.max(np.abs(res["tip_deflection"])))
    return out


def _response_metrics(scenario: Scenario, res, ctrl: str) -> dict:
    """Step metrics for a step reference (the controlled signal's, the tip angle's, and
    the tip as its figure shows it: :func:`_tip_summary`); tracking errors for other
    references."""
    if scenario.reference.type == "step":
        return {
            "step_metrics": step_metrics(res.time, res[ctrl], res["reference"]).to_dict(),
            "tip_metrics": step_metrics(res.time, res["tip_angle"], res["reference"]).to_dict(),
            "tip": _tip_summary(res, ctrl),
        }
    e = res["reference"] - res[ctrl]
    return {
        "tracking": {
            "signal": ctrl,
            "reference": scenario.reference.type,
            "rms_error": float(np.sqrt(np.mean(e**2))),
            "max_abs_error": float(np.max(np.abs(e))),
            "peak_tip_deflection": float(np.max(np.abs(res["tip_deflection"]))),
        }
    }


def _file_name(scenario: Scenario, name: str | None) -> str:
    """The file stem of a scenario's outputs: ``name`` (already made safe and distinct by
    the caller), else the scenario's name through :func:`flexarm.io.write.safe_name`."""
    return name if name is not None else safe_name(scenario.name, what="scenario name")


def write_simulation(
    scenario: Scenario,
    out: Path,
    progress: bool = False,
    *,
    name: str | None = None,
    overwrite: bool = False,
) -> dict:
    """Simulate and write ``<name>.csv``, ``<name>.png`` and ``<name>.summary.json`` into
    ``out``; ``name``: the file stem (default the scenario's name made a safe file name,
    :func:`flexarm.io.write.safe_name`: a name never leaves ``out``); existing files are
    replaced only with ``overwrite``."""
    if getattr(scenario.arm, "kind", "single_link") == "multi_link":
        if scenario.sampling is None:
            return write_regulation(scenario, out, name=name, overwrite=overwrite)
        return write_multilink(scenario, out, progress, name=name, overwrite=overwrite)[0]
    name = _file_name(scenario, name)
    res = simulate_with_progress(scenario, progress)
    assert scenario.sampling is not None  # a single-link scenario has one (validated)
    res.to_csv(out / f"{name}.csv", overwrite=overwrite)
    fig = res.plot_arm()
    fig.suptitle(f"{name}: closed-loop response")
    fig.tight_layout()
    save_figure(fig, out / f"{name}.png", overwrite=overwrite, dpi=120)
    ctrl = _controlled_signal(scenario.controller)
    summary = {
        "scenario": name,
        "samples": len(res.time),
        "sampling_period_s": scenario.sampling.period,
        "controlled_signal": ctrl,
        **_response_metrics(scenario, res, ctrl),
        "peak_command": float(np.max(np.abs(res.command))),
        "command": res.input_names[0],
        "command_unit": _unit(res.input_names[0]),
        "files": [f"{name}.csv", f"{name}.png"],
    }
    summary = rounded(summary)
    write_json(out / f"{name}.summary.json", summary, overwrite=overwrite)
    return summary


def _controlled_signal(spec) -> str:
    """The measured channel a single-link controller tracks the reference on: its
    ``measured``, or an ``lti`` controller's input whose setpoint is ``reference``."""
    if spec is None:
        return "motor_angle"
    if getattr(spec, "type", None) == "lti":
        return next(
            (
                i
                for i, s in zip(spec.inputs, spec.setpoints or [], strict=False)
                if s == "reference"
            ),
            spec.inputs[0],
        )
    return getattr(spec, "measured", None) or "motor_angle"


def joint_counts(scenario: Scenario, n_joints: int) -> np.ndarray:
    """One encoder count per joint (rad): range / 2**bits of the joint's sensor
    ``theta_j``; NaN where the joint has no quantised sensor."""
    out = np.full(n_joints, np.nan)
    for j in range(n_joints):
        s = scenario.sensors.get(f"theta_{j + 1}")
        if s is not None and s.bits:
            out[j] = s.range / 2**s.bits
    return out


def _joint_errors(scenario: Scenario, res) -> tuple[np.ndarray, np.ndarray]:
    """θ_d − θ (T, n) rad of a multi-link run (θ_d the controller's target; 0 without
    one) and the count per joint (rad)."""
    ctrl = scenario.controller
    n = res.n_links
    target = getattr(ctrl, "target", None) if ctrl is not None else None
    target = np.zeros(n) if target is None else np.asarray(target, float)
    return target - res.theta, joint_counts(scenario, n)


def write_multilink(
    scenario: Scenario,
    out: Path,
    progress: bool = False,
    *,
    name: str | None = None,
    overwrite: bool = False,
):
    """A multi-link arm in the sampled-data loop (``[sampling]``): simulate, write
    ``<name>.csv`` (every state and command), ``<name>.png`` (:func:`plot_joints`) and
    ``<name>.summary.json`` (``name`` as :func:`write_simulation`); returns (summary,
    result)."""
    name = _file_name(scenario, name)
    res = simulate_with_progress(scenario, progress)
    assert scenario.sampling is not None  # simulated in the sampled-data loop
    res.to_csv(out / f"{name}.csv", overwrite=overwrite)
    plot_joints({name: (scenario, res)}, out / f"{name}.png", overwrite=overwrite)
    err, count = _joint_errors(scenario, res)
    summary = {
        "scenario": name,
        "samples": len(res.time),
        "sampling_period_s": scenario.sampling.period,
        "final_joint_error_rad": err[-1].tolist(),
        **_counts(err[-1], count),
        "final_link_deflection_m": [
            float(res[f"deflection_{j + 1}"][-1]) for j in range(res.n_links)
        ],
        "peak_command": np.abs(res.command).max(axis=0).tolist(),
        "command_names": list(res.input_names),
        "files": [f"{name}.csv", f"{name}.png"],
    }
    summary = rounded(summary)
    write_json(out / f"{name}.summary.json", summary, overwrite=overwrite)
    return summary, res


def _counts(err: np.ndarray, count: np.ndarray) -> dict:
    """The final joint errors in encoder counts: a list where every joint has an encoder;
    a dict by joint (``theta_j``) of those that have one, and ``no_encoder`` naming the
    others, where some have none (no ``[None, None]``: an error in counts is not logged
    without a quantised sensor)."""
    has = np.isfinite(count)
    if has.all():
        return {"final_joint_error_counts": [float(e / c) for e, c in zip(err, count, strict=True)]}
    out: dict = {}
    if has.any():
        out["final_joint_error_counts"] = {
            f"theta_{j + 1}": float(err[j] / count[j]) for j in np.flatnonzero(has)
        }
    out["no_encoder"] = (
        f"{', '.join(f'theta_{j + 1}' for j in np.flatnonzero(~has))}: no quantised "
        "sensor in the scenario, errors in counts not logged (see final_joint_error_rad)"
    )
    return out


def plot_joints(runs: dict, path: Path, *, overwrite: bool = False) -> None:
    """Figure of multi-link runs overlaid (``runs``: label → (scenario, result)): per joint,
    the error θ_d − θ in encoder counts (symmetric-log axis, linear within ±1 count, that
    band shaded; in mrad, without a band, where the scenario has no encoder), the link's
    tip deflection w_j(ℓ_j) (mm) and the command."""
    from matplotlib.figure import Figure

    first = next(iter(runs.values()))[1]
    n = first.n_links
    fig = Figure(figsize=(5.5 * n, 9), layout="constrained")
    ax = fig.subplots(3, n, sharex=True, squeeze=False)
    for label, (sc, res) in runs.items():
        err, count = _joint_errors(sc, res)
        for j in range(n):
            c = count[j] if np.isfinite(count[j]) else 1e-3
            ax[0, j].plot(res.time, err[:, j] / c, lw=1.2, label=label)
            ax[1, j].plot(res.time, 1e3 * res[f"deflection_{j + 1}"], lw=1.0, label=label)
            ax[2, j].step(res.time, res.command[:, j], where="post", lw=0.7, alpha=0.8, label=label)
    for j in range(n):
        unit = (
            "encoder counts"
            if np.isfinite(joint_counts(next(iter(runs.values()))[0], n)[j])
            else "mrad"
        )
        ax[0, j].set_yscale("symlog", linthresh=1.0, linscale=0.6)
        if unit == "encoder counts":  # without an encoder there is no count to shade
            ax[0, j].axhspan(-1, 1, color="0.85", zorder=0, label="±1 count")
        ax[0, j].axhline(0.0, c="k", lw=0.6)
        ax[0, j].set_ylabel(f"θ_d,{j + 1} − θ_{j + 1} [{unit}]")
        ax[0, j].set_title(f"joint {j + 1}")
        ax[1, j].set_ylabel(f"link {j + 1} tip deflection w(ℓ) [mm]")
        ax[2, j].set_ylabel(f"{first.input_names[j]} [{_unit(first.input_names[j])}]")
        ax[2, j].set_xlabel("time [s]")
        for a in ax[:, j]:
            a.grid(True, alpha=0.3)
            a.legend(loc="best", fontsize=8)
    fig.suptitle(" vs ".join(runs) if len(runs) > 1 else f"{next(iter(runs))}: closed loop")
    save_figure(fig, path, overwrite=overwrite, dpi=110)


def _unit(name: str) -> str:
    from flexarm.sim.result import _unit as unit

    return unit(name)


def write_comparison(
    scenarios: list[Scenario],
    results: dict,
    out: Path,
    *,
    names: list[str] | None = None,
    overwrite: bool = False,
) -> Path:
    """One figure of several multi-link runs overlaid (:func:`plot_joints`):
    ``<name1>_vs_<name2>....png``; ``names``: the runs' file stems and keys of ``results``
    (default the scenarios' names made distinct, :func:`flexarm.io.write.distinct_names`);
    a stem longer than :data:`flexarm.io.write.NAME_MAX` becomes ``comparison.png``."""
    names = names if names is not None else distinct_names([sc.name for sc in scenarios])
    stem = "_vs_".join(names)
    if len(stem) > NAME_MAX:
        stem = "comparison"
    path = out / (stem + ".png")
    plot_joints(
        {n: (sc, results[n]) for n, sc in zip(names, scenarios, strict=True)},
        path,
        overwrite=overwrite,
    )
    return path


def run_regulation(scenario):
    """Simulate a multi-link scenario's regulation (continuous time, RK4): the model, the
    law's parameters and the run (:func:`flexarm.sim.build.regulation_run`)."""
    from flexarm.sim.build import regulation_run

    return regulation_run(scenario)


def write_regulation(
    scenario, out: Path, *, name: str | None = None, overwrite: bool = False
) -> dict:
    """Simulate a multi-link regulation; write CSV, the Fig. 2-style figure, summary
    (``name``, ``overwrite`` as :func:`write_simulation`)."""
    from matplotlib.figure import Figure

    name = _file_name(scenario, name)
    model, params, run = run_regulation(scenario)
    n = model.n_links
    path = run.to_csv(out / f"{name}.csv", overwrite=overwrite)
    fig = Figure(figsize=(7, 8))
    ax = fig.subplots(3, 1, sharex=True)
    for k in range(n):
        ax[0].plot(run.time, np.degrees(run.theta[:, k]), label=f"θ{k + 1}")
    ax[0].set_ylabel("joint angle [deg]")
    for k in range(run.delta.shape[1]):
        ax[1].plot(run.time, run.delta[:, k], label=run.state_names[n + k])
    ax[1].set_ylabel("deflection [m]")
    for k in range(n):
        ax[2].plot(run.time, run.torque[:, k], label=f"u{k + 1}")
    ax[2].set_ylabel("torque [N·m]")
    ax[2].set_xlabel("time [s]")
    for a in ax:
        a.legend(loc="best", fontsize=8)
        a.grid(True, alpha=0.3)
    fig.suptitle(f"{name}: law {scenario.regulation.law}")
    fig.tight_layout()
    save_figure(fig, out / f"{name}.png", overwrite=overwrite, dpi=120)
    th_err = np.degrees(np.abs(run.theta[-1] - np.asarray(params.theta_d)))
    dd = np.asarray(params.delta_d)
    summary = {
        "scenario": name,
        "law": scenario.regulation.law,
        "final_theta_error_deg": th_err.tolist(),
        "final_delta_m": run.delta[-1].tolist(),
        "delta_d_m": dd.tolist(),
        "final_delta_relative_error": float(
            np.linalg.norm(run.delta[-1] - dd) / np.linalg.norm(dd)
        ),
        "initial_torque_N_m": run.torque[0].tolist(),
        "final_torque_N_m": run.torque[-1].tolist(),
        "gravity_torque_at_target_N_m": np.asarray(params.g_d).tolist(),
        "files": [path.name, f"{name}.png"],
    }
    summary = rounded(summary)
    write_json(out / f"{name}.summary.json", summary, overwrite=overwrite)
    return summary


def run_demo(out: Path, console, reproductions: dict | None = None) -> dict:
    """Model and closed-loop simulation of every built-in scenario, then the papers'
    reproductions (``reproductions``: name → ``run(out_dir)``), into ``out``."""
    from flexarm.models.single_link import SingleLinkModel

    results = {}
    for name, path in sorted(builtin_scenarios().items()):
        sc = load_scenario(path)
        if sc.arm.kind == "single_link":
            info = single_link_info(SingleLinkModel.from_spec(sc.arm))
            write_json(out / f"{name}.model.json", info, overwrite=True)
        s = write_simulation(sc, out, overwrite=True)
        results[name] = s
        console.print(demo_line(name, s))
    for rname, run in (reproductions or {}).items():
        console.print(f"[bold]reproducing {rname}[/] ...")
        results[f"reproduce_{rname}"] = run(out / rname)
    write_json(out / "summary.json", rounded(results), overwrite=True, default=str)
    console.print(f"wrote {out}/")
    return results


def _mrad(x) -> str:
    return f"{1e3 * x:.3g} mrad"


def demo_line(name: str, s: dict) -> str:
    """The demo's printed line of one scenario's summary (:func:`write_simulation`,
    :func:`write_multilink`, :func:`write_regulation`), 3 significant digits; a step run
    names the tip as its figure shows it (range, peak deflection, settling)."""
    if "step_metrics" in s:
        m = s["step_metrics"]
        ts = m["settling_time"]
        settle = "never (within the record)" if ts is None else f"{ts:.3g} s"
        line = (
            f"[bold]{name}[/]: step {m['step']:.3g} rad, settling {settle}, steady-state "
            f"error {m['steady_state_error']:.3g} rad, peak command {s['peak_command']:.3g} "
            f"{s['command_unit']} ({s['command']})"
        )
        tip = s.get("tip")
        if tip:
            lo, hi = tip["tip_angle_range_rad"]
            ts = tip["settling_time_s"]
            line += (
                f"; tip {1e3 * lo:.0f} to {1e3 * hi:.0f} mrad, peak deflection "
                f"{_mrad(tip['peak_deflection_angle_rad'])} from the motor, settling "
                + (f"{ts:.3g} s" if isinstance(ts, (int, float)) else ts)
            )
        return line
    if "tracking" in s:
        tr = s["tracking"]
        return (
            f"[bold]{name}[/]: {tr['reference']} reference, rms tracking error "
            f"{tr['rms_error']:.3g} rad, peak tip deflection {tr['peak_tip_deflection']:.3g} m, "
            f"peak command {s['peak_command']:.3g} {s['command_unit']} ({s['command']})"
        )
    if "final_joint_error_rad" in s:
        counts = s.get("final_joint_error_counts")
        if isinstance(counts, list):
            err = f"{', '.join(f'{c:.3g}' for c in counts)} counts"
        else:
            err = ", ".join(_mrad(e) for e in s["final_joint_error_rad"])
            err += f" (no encoder on {s['no_encoder'].split(':')[0]}: not in counts)"
        cmds = ", ".join(
            f"{c:.3g} {_unit(n)} ({n})"
            for c, n in zip(s["peak_command"], s["command_names"], strict=True)
        )
        return f"[bold]{name}[/]: final joint errors {err}, peak commands {cmds}"
    return (
        f"[bold]{name}[/]: final joint errors "
        f"{', '.join(f'{e:.3g}' for e in s['final_theta_error_deg'])} deg, initial torques "
        f"{', '.join(f'{u:.3g}' for u in s['initial_torque_N_m'])} N*m"
    )

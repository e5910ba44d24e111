"""Write a simulation's CSV, figure and summary, and run the demo (``make demo``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from flexarm.analysis.metrics import step_metrics
from flexarm.analysis.model_info import single_link_info
from flexarm.sim.build import prepare, to_result
from flexarm.sim.sampled import simulate_loop
from flexarm.specs import Scenario, builtin_scenarios, load_scenario


def simulate_with_progress(scenario: Scenario, progress: bool = False):
    """Simulate a scenario, with a rich progress bar for long runs."""
    p = prepare(scenario)
    seed = scenario.simulation.seed
    if not progress or p.n_samples <= 20000:
        return to_result(p, simulate_loop(p.loop, p.x0, p.references, p.n_samples, seed=seed))
    from rich.progress import Progress

    with Progress() as bar:
        task = bar.add_task(f"simulating {scenario.name}", total=p.n_samples)
        out = simulate_loop(p.loop, p.x0, p.references, p.n_samples, seed=seed,
                            progress=lambda done, total: bar.update(task, completed=done))
    return to_result(p, out)


def write_simulation(scenario: Scenario, out: Path, progress: bool = False) -> dict:
    """Simulate and write ``<name>.csv``, ``<name>.png`` and ``<name>.summary.json``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    res = simulate_with_progress(scenario, progress)
    name = scenario.name
    res.to_csv(out / f"{name}.csv", overwrite=True)
    fig = res.plot_arm()
    fig.suptitle(f"{name}: closed-loop response")
    fig.savefig(out / f"{name}.png", dpi=120)
    plt.close(fig)
    ctrl = scenario.controller.measured if scenario.controller else "motor_angle"
    summary = {
        "scenario": name,
        "samples": len(res.time),
        "sampling_period_s": scenario.sampling.period,
        "controlled_signal": ctrl,
        "step_metrics": step_metrics(res.time, res[ctrl], res["reference"]).to_dict(),
        "tip_metrics": step_metrics(res.time, res["tip_angle"], res["reference"]).to_dict(),
        "peak_command": float(np.max(np.abs(res.command))),
        "command_unit": res.input_names[0],
        "files": [f"{name}.csv", f"{name}.png"],
    }
    (out / f"{name}.summary.json").write_text(json.dumps(summary, indent=2))
    return summary


def run_demo(out: Path, console) -> dict:
    """Model and closed-loop simulation of every built-in single-link arm."""
    results = {}
    for name, path in sorted(builtin_scenarios().items()):
        sc = load_scenario(path)
        if sc.arm.kind != "single_link":
            continue
        from flexarm.models.single_link import SingleLinkModel

        info = single_link_info(SingleLinkModel.from_spec(sc.arm))
        (out / f"{name}.model.json").write_text(json.dumps(info, indent=2))
        s = write_simulation(sc, out)
        results[name] = s
        m = s["step_metrics"]
        console.print(f"[bold]{name}[/]: step {m['step']:.3g} rad, settling "
                      f"{m['settling_time']} s, steady-state error {m['steady_state_error']:.3g} rad, "
                      f"peak command {s['peak_command']:.3g} {s['command_unit']}")
    (out / "summary.json").write_text(json.dumps(results, indent=2))
    console.print(f"wrote {out}/")
    return results

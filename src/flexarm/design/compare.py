"""The side-by-side prediction: the rig's own controller and each design, on the nominal
(fitted) plant and on a batch of plants drawn from the fit's uncertainty
(:mod:`flexarm.design.plants`), one ``vmap``-ed batch per controller.

The experiment: the plants at rest, a reference step of ``step`` rad (m on a linear axis,
``arm.joint = "prismatic"``: every angle below is then the carriage's position in m, the
tip the carriage itself) at ``start`` s (default the scenario's own step size),
``duration`` s, through the one sampled-data loop with everything the scenario has:
friction (Karnopp stick), sensor and computation delays, encoder quantisation, saturation.
Per plant, from the plant's true signals (not the delayed sensors), with Δ = the reference
step, k ≥ the step's sample:

* ``hub_error_counts``: the mean of |r_end − θ| / q over the last 5 % of the run, q the
  encoder count (rad; the scenario's ``sensors.motor_angle`` quantum, or ``count=``): a
  hub stuck short counts its gap, a hub hunting around the reference (friction
  compensation against a delayed encoder) its excursions;
* ``tip_settling_s``: the first time after the step after which the tip angle
  θ_t = θ + d/L stays within ±band·|Δ| of its final value (its mean over the last 5 %,
  the convention of :mod:`flexarm.metrics`); band 2 % unless given. NaN when the
  last sample is still outside (never settles);
* ``tip_overshoot_pct``: 100 max_k (θ_t − r_end) sgn Δ / |Δ|, at least 0;
* ``tip_oscillation_mm``: rms of d − d̄ over the last ``tail`` (25 %) of the run, mm;
* ``peak_command_V``: max |u| of the applied (saturated) command (in the drive's unit, V or
  A: ``settings["units"]``, :func:`units_of`; the key keeps its name); ``time_at_limit_s``:
  T · #{k : |u_k| ≥ limit (1 − 1e-9)};
* ``command_chatter_V``: rms of the command's change per sample, √(mean (u_k − u_{k−1})²),
  V: the sign switching of a friction compensation and the backward-difference rate of a
  quantised encoder (one count per sample is a rate step of q/T) show here;
* ``stable``: the run stayed finite (|signals| ≤ 1e6 SI), the tip settled, and the hub
  stayed within ±band·|Δ| of its final value over the last ``tail`` of the run (a hub
  limit cycle is not a settled response).

Summary per controller: the nominal plant's values, and over the N drawn plants the median
and the worst case (largest; a plant that never settles counts as +inf settling time), the
number unstable, and whether the voltage limit was respected. The applied command is
saturated, so "respected" means that no plant's command ever reached the limit (0 s at
it, nominal and every drawn plant): the law works inside the amplifier's range.
:class:`Comparison` gives the table as markdown/text and a dict
(JSON), and overlay figures through :func:`flexarm.io.write.save_figure`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from flexarm.design.plants import (
    BatchLoop,
    PlantBatch,
    PlantSource,
    Replace,
    chunk_plants,
    diverged,
    nominal_batch,
)

if TYPE_CHECKING:
    from flexarm.sim.batch import BatchExecutor, ChunkOptions

__all__ = [
    "compare",
    "compare_chunked",
    "Comparison",
    "batch_metrics",
    "METRICS",
    "metric_titles",
    "units_of",
    "experiment",
    "Probe",
    "probe_for",
]

#: metric → (column title, unit, how the worst case is taken)
METRICS = {
    "hub_error_counts": ("hub ss error", "counts", "max"),
    "tip_settling_s": ("tip settling", "s", "max"),
    "tip_overshoot_pct": ("tip overshoot", "%", "max"),
    "tip_oscillation_mm": ("tip residual rms", "mm", "max"),
    "peak_command_V": ("peak command", "V", "max"),
    "time_at_limit_s": ("time at limit", "s", "max"),
    "command_chatter_V": ("command chatter", "V", "max"),
}

#: a linear axis's column titles (a prismatic joint: the carriage's position in m is both
#: the "hub" and the "tip"; a rigid carriage has no deflection)
LINEAR_TITLES = {
    "hub_error_counts": "position ss error",
    "tip_settling_s": "settling",
    "tip_overshoot_pct": "overshoot",
    "tip_oscillation_mm": "deflection rms",
}


def units_of(scenario, command: int = 0) -> dict[str, str]:
    """The units the comparison's figures are in: ``position`` (rad, or m on a linear
    axis, ``arm.joint = "prismatic"``) and ``command`` (the drive's: V for a voltage
    drive, A for a current drive, N·m (N on a linear axis) for a torque drive;
    ``command`` the drive's index on a multi-link arm)."""
    linear = bool(getattr(scenario, "prismatic", False))
    arm = scenario.arm
    if hasattr(arm, "motor"):
        drive = arm.motor.drive
    else:
        joints = getattr(arm, "joints", None) or []
        drive = joints[command].drive.drive if command < len(joints) else "torque"
    cmd = {"voltage": "V", "current": "A"}.get(drive, "N" if linear else "N*m")
    return {"position": "m" if linear else "rad", "command": cmd}


def metric_titles(settings: Mapping[str, Any] | None = None) -> dict[str, tuple[str, str]]:
    """metric → (column title, unit) for a comparison's ``settings``: :data:`METRICS`'s, the
    commands in the drive's unit (``settings["units"]``, :func:`units_of`) and a linear
    axis's titles (:data:`LINEAR_TITLES`); the keys stay :data:`METRICS`'s."""
    units = (settings or {}).get("units") or {}
    cmd = units.get("command", "V")
    linear = units.get("position") == "m"
    out = {}
    for k, (t, u, _) in METRICS.items():
        if linear:
            t = LINEAR_TITLES.get(k, t)
        out[k] = (t, cmd if u == "V" else u)
    return out


@dataclass(frozen=True)
class Probe:
    """What the comparison steps and measures, by the plant's signal names: the ``hub``
    angle (rad), the tip angle as the sum of the ``tip`` signals (rad), the link's tip
    ``deflection`` (m), the ``command`` column, the stepped ``reference`` channel (the other
    named ``references`` held at 0), the hub ``encoder`` sensor. A single link:
    ``motor_angle``, ``tip_angle``, ``tip_deflection``, command 0, ``reference``; a
    multi-link arm: joint j's ``theta_j``, ``theta_j + deflection_angle_j`` (link j's tip),
    ``deflection_j``, drive j's command, its setpoint's reference (:func:`probe_for`)."""

    hub: str = "motor_angle"
    tip: tuple[str, ...] = ("tip_angle",)
    deflection: str = "tip_deflection"
    command: int = 0
    reference: str = "reference"
    references: tuple[str, ...] = ()
    encoder: str = "motor_angle"
    joint: int | None = None


def probe_for(scenario, joint: int = 0) -> Probe:
    """The :class:`Probe` of ``scenario``: a single link's, or joint ``joint`` (0: the
    shoulder) of a multi-link arm, its reference the setpoint the scenario's controller
    gives that joint's angle (an ``lti`` block's ``setpoints``), else ``theta_ref_<j+1>``."""
    if scenario.arm.kind != "multi_link":
        return Probe()
    n = len(scenario.arm.joints)
    if not 0 <= joint < n:
        raise ValueError(f"joint = {joint}: the arm has joints 0..{n - 1}")
    hub = f"theta_{joint + 1}"
    sensors = scenario.sensors or {}
    encoder = next((k for k, v in sensors.items() if (getattr(v, "signal", None) or k) == hub), hub)
    ref = None
    ctrl = scenario.controller
    if getattr(ctrl, "setpoints", None) and getattr(ctrl, "inputs", None):
        ref = next(
            (
                sp
                for i, sp in zip(ctrl.inputs, ctrl.setpoints, strict=False)
                if isinstance(sp, str) and i == encoder
            ),
            None,
        )
    refs = tuple(scenario.references or {})
    ref = ref or f"theta_ref_{joint + 1}"
    if ref not in refs:
        raise ValueError(
            f"scenario {scenario.name!r}: joint {joint + 1}'s setpoint {ref!r} is not one of "
            f"its [references] ({', '.join(refs) or 'none'}); the comparison steps it"
        )
    return Probe(
        hub,
        (hub, f"deflection_angle_{joint + 1}"),
        f"deflection_{joint + 1}",
        joint,
        ref,
        refs,
        encoder,
        joint,
    )


def batch_metrics(
    out: dict,
    signal_names,
    time: np.ndarray,
    reference: np.ndarray,
    *,
    count: float,
    limit: float,
    length: float,
    band: float = 0.02,
    tail: float = 0.25,
    probe: Probe | None = None,
) -> dict[str, np.ndarray]:
    """The per-plant metrics of the module doc from :func:`simulate_batch` arrays
    (signals (B, N, S), command (B, N, m)); ``reference`` (N,) at the sample instants,
    one step; ``length`` L (m) of the link; ``probe`` the signals measured (default a
    single link's); returns metric → (B,) arrays."""
    pr = probe or Probe()
    sig = np.asarray(out["signals"])
    idx = {n: i for i, n in enumerate(signal_names)}
    th, d = sig[..., idx[pr.hub]], sig[..., idx[pr.deflection]]
    tip = np.sum([sig[..., idx[n]] for n in pr.tip], axis=0)
    ua = np.asarray(out["command"])[..., pr.command]
    u = np.abs(ua)
    r = np.asarray(reference, float)
    jumps = np.nonzero(np.abs(np.diff(r)) > 0)[0]
    k0 = int(jumps[0] + 1) if jumps.size else 0
    delta = float(r[-1] - r[k0 - 1]) if k0 > 0 else float(r[-1] - r[0])
    if delta == 0.0:
        raise ValueError(
            "the reference has no step: the comparison needs a step of the hub angle (step= rad, "
            "m on a linear axis)"
        )
    n = r.size
    dt = float(time[1] - time[0])
    last = max(1, n // 20)
    bad = diverged(out)
    with np.errstate(invalid="ignore", over="ignore"):
        th_f = np.mean(th[:, -last:], axis=1)
        tip_f = np.mean(tip[:, -last:], axis=1)
        hub_err = np.mean(np.abs(r[-1] - th[:, -last:]), axis=1) / count
        outside = np.abs(tip - tip_f[:, None]) > band * abs(delta)
        outside[:, :k0] = False
        any_out = outside.any(axis=1)
        last_out = n - 1 - np.argmax(outside[:, ::-1], axis=1)
        ts = np.where(any_out, time[np.minimum(last_out + 1, n - 1)] - time[k0], 0.0)
        ts = np.where(any_out & (last_out == n - 1), np.nan, ts)
        over = 100 * np.max((tip[:, k0:] - r[-1]) * np.sign(delta), axis=1) / abs(delta)
        k_tail = n - max(1, int(round(tail * n)))
        hub_still = np.max(np.abs(th[:, k_tail:] - th_f[:, None]), axis=1) <= band * abs(delta)
        dt_tail = d[:, k_tail:]
        osc = 1e3 * np.sqrt(np.mean((dt_tail - dt_tail.mean(axis=1, keepdims=True)) ** 2, axis=1))
        peak = np.max(u, axis=1)
        chatter = np.sqrt(np.mean(np.diff(ua, axis=1) ** 2, axis=1))
        at_lim = dt * np.sum(u >= limit * (1 - 1e-9), axis=1)
    m = {
        "hub_error_counts": hub_err,
        "tip_settling_s": ts,
        "tip_overshoot_pct": np.maximum(over, 0.0),
        "tip_oscillation_mm": osc,
        "peak_command_V": peak,
        "time_at_limit_s": at_lim,
        "command_chatter_V": chatter,
    }
    stable = ~bad & np.isfinite(ts) & hub_still
    for k in m:
        m[k] = np.where(bad, np.nan, m[k])
    m["stable"] = stable
    return m


def experiment(
    scenario,
    *,
    step: float | None = None,
    start: float = 0.1,
    duration: float = 3.0,
    quantum: float | None = None,
    probe: Probe | None = None,
) -> dict:
    """The overrides (:func:`flexarm.design.plants.with_overrides`) of the comparison's
    experiment: at rest, a step of ``step`` rad (default the stepped reference's amplitude)
    at ``start`` s on the probe's reference (a multi-link arm: that joint's setpoint, the
    other joints' held at 0), ``duration`` s; ``quantum`` sets the hub encoder's count
    (rad) where the scenario has none."""
    pr = probe or probe_for(scenario)
    spec = scenario.reference if pr.reference == "reference" else None
    spec = spec or (scenario.references or {}).get(pr.reference)
    if step is None:
        step = float(getattr(spec, "amplitude", 0.0) or 0.0)
        if step == 0.0:
            raise ValueError(
                f"scenario {scenario.name!r}: {pr.reference}.amplitude = 0; give the "
                "step size (rad, m on a linear axis) with step= or [reference] amplitude"
            )
    if not duration > start:
        raise ValueError(f"duration = {duration} s must exceed the step time start = {start} s")
    move = {"type": "step", "offset": 0.0, "amplitude": float(step), "start": float(start)}
    over: dict[str, Any] = {
        "simulation": {"duration": float(duration)},
        "initial": {"motor_angle": 0.0, "motor_velocity": 0.0, "tip_deflection": 0.0},
    }
    if pr.reference == "reference":
        over["reference"] = move
    else:
        rest = {"type": "step", "offset": 0.0, "amplitude": 0.0, "start": 0.0}
        over["references"] = {
            r: Replace(move if r == pr.reference else rest) for r in pr.references
        }
        over["initial"] = {"joint_angles": None, "joint_velocities": None, "equilibrium": False}
    if quantum is not None:
        over["sensors"] = {pr.encoder: {"quantum": float(quantum), "bits": None, "range": None}}
    return over


#: reference types with which a design shapes its own move (run as they are)
SHAPED = ("parabolic", "quasi_parabolic")


def _own_move(design_scenario, exp: dict) -> dict:
    """Overrides that give every plant the design's controller and its own shaped move
    (from rest at 0, its distance unchanged), the run at least the experiment's length."""
    d = design_scenario.model_dump(mode="json", exclude_none=True)
    ref = {**d["reference"], "offset": 0.0}
    dur = max(float(exp["simulation"]["duration"]), float(design_scenario.simulation.duration))
    return {
        "controller": Replace(d["controller"]),
        "reference": Replace(ref),
        "simulation": {"duration": dur},
    }


def encoder_count(scenario, count: float | None = None, joint: int = 0) -> float:
    """The hub encoder's count (rad): ``count`` if given, else the scenario's hub encoder's
    quantum (``sensors.motor_angle``; a multi-link arm: joint ``joint``'s angle sensor; or
    range / 2**bits)."""
    from flexarm.sim.build import sensor_quanta

    if count is not None:
        if not count > 0:
            raise ValueError(f"count = {count!r} rad: the encoder count must be > 0")
        return float(count)
    enc = probe_for(scenario, joint).encoder
    q = sensor_quanta(scenario.sensors).get(enc, 0.0)
    if not q > 0:  # a fitted rig whose controller read finer than the log: its resolution
        q = float(
            (getattr(scenario, "notes", None) or {}).get("rig", {}).get("encoder_count", 0.0) or 0.0
        )
    if not q > 0:
        raise ValueError(
            f"scenario {scenario.name!r}: sensors.{enc} has no quantum "
            "(or bits and range), so the hub error cannot be given in encoder "
            "counts; give count= (rad per count, e.g. 2*pi/4096; m per count on a linear "
            "axis, e.g. 1e-6) or "
            f"sensors.{enc}.quantum"
        )
    return float(q)


def controller_spec(design) -> Any:
    """The ``[controller]`` spec of a design: a :class:`~flexarm.design.result.Design`, a
    scenario, or a controller spec itself."""
    sc = getattr(design, "scenario", None)
    if sc is not None and hasattr(sc, "controller"):
        return sc.controller
    if hasattr(design, "controller") and hasattr(design, "arm"):
        return design.controller
    if hasattr(design, "type"):
        return design
    raise TypeError(
        f"{type(design).__name__}: give a Design, a scenario or a controller spec to compare"
    )


def build_controller(batch: BatchLoop, spec, scenario) -> Any:
    """The discrete controller of ``spec`` for the batch's sampling, references and
    encoder (:func:`flexarm.sim.build.controller_from_spec`)."""
    from flexarm.sim.build import controller_from_spec, sensor_quanta

    lp = batch.prepared.loop
    return controller_from_spec(
        spec,
        float(scenario.sampling.period),
        input_names=lp.plant.input_names,
        references=batch.references,
        quanta=sensor_quanta(scenario.sensors),
    )


@dataclass
class Comparison:
    """``rows``: controller name → {"nominal": metrics, "median": ..., "worst": ...,
    "unstable": count, "n_plants": N, "limit_respected": bool}; ``per_plant``: name →
    metric → (N + 1,) (index 0 the nominal plant); ``traces``: name → time, reference,
    nominal tip/hub/command and the batch's 5/50/95 % tip percentiles (figures);
    ``settings``: the experiment."""

    rows: dict[str, dict[str, Any]]
    per_plant: dict[str, dict[str, np.ndarray]]
    traces: dict[str, dict[str, np.ndarray]]
    settings: dict[str, Any]
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        def clean(x):
            if isinstance(x, dict):
                return {k: clean(v) for k, v in x.items()}
            if isinstance(x, (float, np.floating)):
                return float(x) if np.isfinite(x) else None
            if isinstance(x, (np.bool_, bool)):
                return bool(x)
            if isinstance(x, (np.integer,)):
                return int(x)
            return x

        return {
            "settings": clean(self.settings),
            "rows": clean(self.rows),
            "warnings": list(self.warnings),
        }

    def table(self, fmt: str = "markdown") -> str:
        """One row per controller: each metric as nominal / median / worst, the unstable
        count and whether the voltage limit held; ``fmt`` ``markdown`` or ``text``."""
        titles = metric_titles(self.settings).values()
        head = ["controller"] + [f"{t} [{u}] nom / med / worst" for t, u in titles]
        head += ["unstable", "limit ok"]
        body = []
        for name, row in self.rows.items():
            cells = [name]
            for k in METRICS:
                cells.append(
                    " / ".join(format_metric(row[s][k]) for s in ("nominal", "median", "worst"))
                )
            cells += [
                f"{row['unstable']}/{row['n_plants']}",
                "yes" if row["limit_respected"] else "NO",
            ]
            body.append(cells)
        if fmt == "markdown":
            lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
            lines += ["| " + " | ".join(c) + " |" for c in body]
            return "\n".join(lines)
        if fmt == "text":
            w = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(head)]
            lines = ["  ".join(h.ljust(w[i]) for i, h in enumerate(head))]
            lines += ["  ".join(c.ljust(w[i]) for i, c in enumerate(b)) for b in body]
            return "\n".join(lines)
        raise ValueError(f"fmt = {fmt!r}: choose 'markdown' or 'text'")

    def figures(self, directory: str | Path, *, overwrite: bool = False) -> list[Path]:
        """Overlay figures (PNG): ``compare_tip.png`` (tip angle on the nominal plant and
        the batch's 5–95 % band per controller), ``compare_hub_command.png`` (hub angle
        and command on the nominal plant)."""
        from matplotlib.figure import Figure  # no pyplot: the caller's backend stays

        from flexarm.io.write import save_figure

        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        paths = []
        fig = Figure(figsize=(8, 4.5))
        ax = fig.subplots()
        for i, (name, tr) in enumerate(self.traces.items()):
            c = f"C{i}"
            if self.settings["n_plants"] > 0:
                ax.fill_between(
                    tr["time"],
                    tr["tip_p05"],
                    tr["tip_p95"],
                    color=c,
                    alpha=0.2,
                    lw=0,
                    label=f"{name}: 5-95 % of {self.settings['n_plants']} plants",
                )
            ax.plot(tr["time"], tr["tip_nominal"], color=c, lw=1.2, label=f"{name}: nominal")
        tr0 = next(iter(self.traces.values()))
        ax.plot(tr0["time"], tr0["reference"], "k:", lw=0.8, label="reference")
        ax.set_xlabel("time [s]")
        units = self.settings.get("units") or {}
        pos = units.get("position", "rad")
        ax.set_ylabel("position [m]" if pos == "m" else "tip angle θ + d/L [rad]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="best")
        fig.tight_layout()
        paths.append(save_figure(fig, out / "compare_tip.png", overwrite=overwrite, dpi=100))
        fig = Figure(figsize=(8, 6))
        ax = fig.subplots(2, 1, sharex=True)
        for i, (name, tr) in enumerate(self.traces.items()):
            ax[0].plot(tr["time"], tr["hub_nominal"], color=f"C{i}", lw=1.0, label=name)
            ax[1].plot(tr["time"], tr["command_nominal"], color=f"C{i}", lw=0.8, label=name)
        ax[0].plot(tr0["time"], tr0["reference"], "k:", lw=0.8, label="reference")
        lim = self.settings["limit_V"]
        for s in (-1, 1):
            ax[1].axhline(s * lim, color="k", ls="--", lw=0.6)
        ax[0].set_ylabel("position [m]" if pos == "m" else "hub angle [rad]")
        ax[1].set_ylabel(f"command [{units.get('command', 'V')}]")
        ax[1].set_xlabel("time [s]")
        for a in ax:
            a.grid(alpha=0.3)
            a.legend(fontsize=7, loc="best")
        fig.suptitle("nominal plant")
        fig.tight_layout()
        paths.append(
            save_figure(fig, out / "compare_hub_command.png", overwrite=overwrite, dpi=100)
        )
        return paths


def format_metric(v) -> str:
    """One metric's text: 3 significant digits, '-' where undefined, 'never' for ∞."""
    if v is None or (isinstance(v, float) and np.isnan(v)):
        return "-"
    if np.isinf(v):
        return "never"
    return f"{v:.3g}"


def summarise(m: dict[str, np.ndarray], limit: float) -> dict[str, Any]:
    """Nominal (index 0), median and worst over the drawn plants (index 1 on); an unstable
    plant counts as +inf in the worst case and in the median of the settling time."""
    nom = {k: float(m[k][0]) for k in METRICS}
    drawn = {k: np.asarray(m[k][1:], float) for k in METRICS}
    st = np.asarray(m["stable"][1:], bool)
    n = st.size
    med, worst = {}, {}
    for k, (_, _, _how) in METRICS.items():
        v = np.where(st, drawn[k], np.inf) if k == "tip_settling_s" else drawn[k]
        v = np.where(np.isnan(v), np.inf, v)
        med[k] = float(np.median(v)) if n else float("nan")
        worst[k] = float(np.max(v)) if n else float("nan")
    at_lim = np.asarray(m["time_at_limit_s"], float)
    return {
        "nominal": nom,
        "median": med,
        "worst": worst,
        "unstable": int(n - st.sum()),
        "nominal_stable": bool(m["stable"][0]),
        "n_plants": int(n),
        "limit_respected": bool(np.all(at_lim == 0.0)),
    }


def compare(
    plants: PlantBatch,
    designs: Mapping[str, Any] | None = None,
    *,
    logged: str | None = "logged controller",
    step: float | None = None,
    start: float = 0.1,
    duration: float = 3.0,
    band: float = 0.02,
    tail: float = 0.25,
    count: float | None = None,
    seed: int | None = None,
    joint: int = 0,
    client: BatchExecutor | None = None,
    chunks: ChunkOptions | None = None,
) -> Comparison:
    """Compare the nominal scenario's own controller (named ``logged``; None leaves it
    out) and ``designs`` (name → :class:`~flexarm.design.result.Design`, scenario or
    controller spec) on the nominal plant and the batch (module doc). ``count``: the
    encoder count (rad) where the scenario's hub sensor has none (it then also quantises
    the simulated encoder); ``seed``: the sensor noise's (default the scenario's
    ``simulation.seed``, as :func:`flexarm.simulate` uses); ``joint``: a multi-link
    arm's stepped and measured joint (0: the shoulder; :func:`probe_for`). With ``client``, a
    :class:`flexarm.sim.batch.BatchExecutor` (e.g. :class:`flexarm.distributed.DaskExecutor`;
    or ``chunks``, a :class:`flexarm.sim.batch.ChunkOptions`, or ``plants`` a
    :class:`~flexarm.design.plants.PlantSource`) the plants run in chunks, one task each,
    and only per-plant metrics come back (:func:`compare_chunked`)."""
    if client is not None or chunks is not None or not isinstance(plants, PlantBatch):
        return compare_chunked(
            plants,
            designs,
            client=client,
            options=chunks,
            logged=logged,
            step=step,
            start=start,
            duration=duration,
            band=band,
            tail=tail,
            count=count,
            seed=seed,
            joint=joint,
        )
    nominal = plants.nominal
    pr = probe_for(nominal, joint)
    q = encoder_count(nominal, count, joint)
    has_q = count is None
    exp = experiment(
        nominal, step=step, start=start, duration=duration, quantum=None if has_q else q, probe=pr
    )
    pb = plants.with_overrides(exp)
    base = pb.loop()
    scn = pb.nominal
    if seed is None:
        seed = int(scn.simulation.seed)
    specs: dict[str, Any] = {}
    if logged is not None:
        specs[logged] = scn.controller
    for name, d in (designs or {}).items():
        specs[name] = controller_spec(d)
    limit = float(np.ravel(np.asarray(base.loop.actuator.limit))[pr.command])
    length = float(scn.arm.beam.length if pr.joint is None else scn.arm.links[pr.command].length)
    rows, per, traces = {}, {}, {}
    moves = {
        name: d.scenario
        for name, d in (designs or {}).items()
        if getattr(getattr(getattr(d, "scenario", None), "reference", None), "type", None) in SHAPED
    }
    for name, spec in specs.items():
        if name in moves:
            # a design that shapes its own move (Feliu's nested loops: the quasi-parabolic
            # tip reference and its Wiener feedforward channel) runs that move, of the same
            # distance from rest, on the same plants
            bl = pb.with_overrides(_own_move(moves[name], exp)).loop()
        else:
            bl = base.with_controller(build_controller(base, spec, scn))
        out = bl.run(seed=seed)
        ref = bl.references[pr.reference]
        m = batch_metrics(
            out,
            bl.prepared.loop.plant.signal_names,
            bl.time,
            ref,
            count=q,
            limit=limit,
            length=length,
            band=band,
            tail=tail,
            probe=pr,
        )
        per[name] = m
        rows[name] = summarise(m, limit)
        sn = list(bl.prepared.loop.plant.signal_names)
        tip = np.sum([out["signals"][:, :, sn.index(c)] for c in pr.tip], axis=0)
        pct = (
            np.nanpercentile(tip[1:], [5, 50, 95], axis=0)
            if tip.shape[0] > 1
            else np.repeat(tip[:1], 3, axis=0)
        )  # nominal only: no band
        traces[name] = {
            "time": bl.time,
            "reference": ref,
            "tip_nominal": tip[0],
            "hub_nominal": out["signals"][0, :, sn.index(pr.hub)],
            "command_nominal": out["command"][0, :, pr.command],
            "tip_p05": pct[0],
            "tip_p50": pct[1],
            "tip_p95": pct[2],
        }
    step_size = float(
        (scn.reference if pr.reference == "reference" else scn.references[pr.reference]).amplitude
    )
    units = units_of(scn, pr.command)
    settings = {
        # step_rad, count_rad, limit_V: the keys of a rotary arm's figures, kept; their
        # units are ``units`` (a linear axis: m; a current drive: A)
        "step_rad": step_size,
        "step": step_size,
        "units": units,
        "stepped": pr.reference,
        "measured": {"hub": pr.hub, "tip": " + ".join(pr.tip), "command": pr.command},
        "start_s": start,
        "duration_s": duration,
        "band_fraction": band,
        "tail_fraction": tail,
        "count_rad": q,
        "limit_V": limit,
        "n_plants": len(plants),
        "seed": plants.seed,
        "noise_seed": seed,
        "plants": plants.info,
        "definitions": {k: f"{t} [{u}]" for k, (t, u) in metric_titles({"units": units}).items()},
    }
    return Comparison(rows, per, traces, settings, list(plants.warnings))


# ------------------------------------------------------------------ in chunks, on an executor
def _compare_chunk(plants, j, a, b, *, designs, kwargs, with_traces):
    cmp = compare(chunk_plants(plants, j, a, b), designs, **kwargs)
    return (
        {name: {k: np.asarray(v) for k, v in m.items()} for name, m in cmp.per_plant.items()},
        cmp.traces if with_traces else None,
        cmp.settings,
        list(cmp.warnings),
    )


def _compare_chunk_any(arg, with_traces, *, designs, kwargs):
    return _compare_chunk(*arg, designs=designs, kwargs=kwargs, with_traces=with_traces)


def compare_chunked(
    plants: PlantBatch | PlantSource,
    designs: Mapping[str, Any] | None = None,
    *,
    client: BatchExecutor | None = None,
    options: ChunkOptions | None = None,
    **kwargs,
) -> Comparison:
    """:func:`compare` over chunks of the plants (a drawn :class:`PlantBatch` sliced, or a
    :class:`PlantSource` drawn per chunk), each chunk a task on ``client``, a
    :class:`~flexarm.sim.batch.BatchExecutor` (None: in-process). Each chunk runs the
    comparison on its plants and the nominal one and returns only the per-plant metrics;
    the rows (nominal, median, worst, unstable, limit) are summarised over all plants here,
    the same as one batch would give. The figures' 5–95 % tip band is the first chunk's
    plants' (a sample of ``options.chunk`` plants), unless ``options.trajectories`` (then
    each chunk's traces come back; the band stays the first chunk's). ``kwargs``: compare's
    keywords."""
    from flexarm.sim.batch import ChunkOptions, chunk_bounds, map_chunks

    o = options or ChunkOptions()
    bounds = chunk_bounds(len(plants), o.chunk) or [(0, 0)]
    src = plants if isinstance(plants, PlantSource) or len(plants) else nominal_batch(plants)
    parts = map_chunks(
        _compare_chunk_any,
        [((src, j, a, b), j == 0 or o.trajectories) for j, (a, b) in enumerate(bounds)],
        client,
        retries=o.retries,
        workers=o.workers,
        shared=dict(designs=designs, kwargs=kwargs),
    )
    per: dict[str, dict[str, np.ndarray]] = {}
    for name in parts[0][0]:
        per[name] = {
            k: np.concatenate([parts[0][0][name][k]] + [p[0][name][k][1:] for p in parts[1:]])
            for k in parts[0][0][name]
        }
    settings = dict(parts[0][2])
    limit = float(settings["limit_V"])
    rows = {name: summarise(m, limit) for name, m in per.items()}
    settings.update(
        n_plants=len(plants),
        seed=int(getattr(plants, "seed", 0)),
        chunks=len(bounds),
        chunk=o.chunk,
        plants={
            **getattr(plants, "info", {}),
            "n": len(plants),
            "chunked": f"{len(bounds)} chunks of <= {o.chunk} plants",
        },
        band_plants="the first chunk's plants",
    )
    warn = list(dict.fromkeys(w for p in parts for w in p[3]))
    return Comparison(rows, per, parts[0][1], settings, warn)

"""Virtual frequency-response experiments on a simulated arm (FRB Sec. II-A, Fig. 1).

A PD loop holds the motor angle on a sinusoidal reference r(t) = a·sin(ω0 t); the current
and the angles are logged. Per frequency:

* the reference amplitude ramps in over ``ramp_periods`` (raised cosine), then holds for
  ``settle_periods`` (both discarded: transients), then ``periods`` whole periods are
  written to one CSV in the exchange format (time restarting at 0);
* the amplitude is chosen per frequency from the linear model: the largest a with the
  linear current a/|G_m(jω0)| plus the Coulomb current within ``current_fraction`` of
  the current limit, the beam deflection a·|1 − G_b(jω0)| within ``max_deflection``, and
  a <= ``max_amplitude``. A large motor amplitude keeps the motor's stops at velocity
  reversals short against the period, so that the Coulomb current stays a square wave in
  phase with the velocity, as FRB eq. (3) assumes;
* the PD gains default to a loop with crossover ω_c = ``bandwidth_fraction``/T on the
  rigid motor Ĝ_m = K/(s(Js + V)) (FRB eq. 9), ζ = 0.7: kp = J ω_c²/K,
  kd = (2 ζ ω_c J − V)/K — a high gain, as the paper asks, within what the sampling
  period and the computation delay allow.

Frequencies come in ω0 / 3ω0 pairs so that :mod:`flexarm.identification.frequency_domain.coulomb`
can estimate C_f.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from flexarm.control import discrete
from flexarm.models.single_link import SingleLinkModel
from flexarm.sim.build import prepare, to_result
from flexarm.sim.sampled import simulate_loop
from flexarm.specs import Scenario
from flexarm.specs.arm import SingleLinkArm


@dataclass(frozen=True)
class SineDesign:
    """Choices of the identification experiments (documented in docs/choices.md)."""

    frequencies: Sequence[float] = ()  # rad/s; empty: default_frequencies(model)
    periods: int = 20  # recorded whole periods per experiment
    ramp_periods: int = 4
    settle_periods: int = 4
    kp: float | None = None  # command units per rad
    kd: float | None = None
    bandwidth_fraction: float = 0.3  # ω_c T
    current_fraction: float = 0.6
    max_amplitude: float = 1.5  # rad
    max_deflection: float = 0.4  # rad, FRB's maximum beam deflection
    chunk: int = 4096  # samples per compiled chunk (one compilation for all lengths)
    extra: dict = field(default_factory=dict)


def default_frequencies(model: SingleLinkModel, n_pairs: int = 7) -> list[float]:
    """ω0/3ω0 pairs spanning ~0.12× to ~6× the first beam frequency, none within 10 % of
    a beam or motor resonance (a lightly damped free mode would leak into the harmonics).
    The low pairs carry the viscous coefficient V (the low real pole of G_m)."""
    wb = _beam_frequency(model)
    res = [wb] + [
        abs(p) for p in np.roots(np.asarray(model.motor_tf().den[0][0])) if abs(p.imag) > 0
    ]
    base = np.geomspace(0.12 * wb, 2.0 * wb, 4 * n_pairs)
    chosen: list[float] = []
    for w in base:
        cand = (float(w), float(3 * w))
        if all(min(abs(c - r) / r for r in res) > 0.10 for c in cand) and all(
            abs(w - c) / c > 0.3 for c in chosen
        ):
            chosen.append(float(w))
        if len(chosen) == n_pairs:
            break
    return sorted(chosen + [3 * w for w in chosen])


def _beam_frequency(model: SingleLinkModel) -> float:
    poles = np.roots(np.asarray(model.beam_tf().den[0][0]))
    w = np.abs(poles[np.abs(poles.imag) > 0])
    return float(np.min(w)) if w.size else 10.0


def pd_gains(
    model: SingleLinkModel, dt: float, fraction: float = 0.25, zeta: float = 0.7
) -> tuple[float, float]:
    """kp, kd for crossover ω_c = fraction/T on the rigid motor (see module docstring)."""
    wc = fraction / dt
    ku = float(model.drive.k_u)
    kp = model.J * wc**2 / ku
    kd = max((2 * zeta * wc * model.J - model.V - float(model.drive.k_omega)) / ku, 0.0)
    return kp, kd


def amplitude(model: SingleLinkModel, w: float, design: SineDesign) -> float:
    """The reference amplitude (rad) for frequency ``w`` (see module docstring)."""
    gm = complex(model.motor_tf()(1j * w))
    gb = complex(model.beam_tf()(1j * w))
    coulomb = float(model.friction.coulomb) / float(model.drive.k_u)
    i_lin = design.current_fraction * float(model.drive.limit) - coulomb
    if i_lin <= 0:
        raise ValueError(
            f"the Coulomb current {coulomb:.3g} leaves no room below "
            f"{design.current_fraction:g} x the limit {float(model.drive.limit):.3g}"
        )
    a = min(design.max_amplitude, i_lin * abs(gm))
    defl = abs(1 - gb)
    if defl > 0:
        a = min(a, design.max_deflection / defl)
    return float(a)


def run_sine_experiments(
    scenario: Scenario,
    out_dir: str | Path,
    design: SineDesign = SineDesign(),
    *,
    overwrite: bool = False,
    progress: Callable[[str, int, int], None] | None = None,
) -> list[Path]:
    """Run one experiment per frequency; write ``sine_<ω>rad_s.csv`` files into ``out_dir``.
    Returns the paths. Refuses to replace existing files unless ``overwrite``."""
    out = Path(out_dir)
    # FRB's sine experiments: a single-link scenario, with [sampling] and [simulation]
    assert isinstance(scenario.arm, SingleLinkArm)
    assert scenario.sampling is not None and scenario.simulation is not None
    model = SingleLinkModel.from_spec(scenario.arm)
    dt = scenario.sampling.period
    freqs = list(design.frequencies) or default_frequencies(model)
    if any(w <= 0 for w in freqs):
        raise ValueError(f"frequencies must be > 0 rad/s, got {freqs}")
    if max(freqs) > math.pi / dt / 4:
        raise ValueError(
            f"frequency {max(freqs):g} rad/s is above a quarter of the Nyquist frequency "
            f"{math.pi / dt:g} rad/s of the {dt:g} s sampling: too few samples per period"
        )
    kp, kd = design.kp, design.kd
    if kp is None or kd is None:
        kp0, kd0 = pd_gains(model, dt, design.bandwidth_fraction)
        kp = kp0 if kp is None else kp
        kd = kd0 if kd is None else kd
    ctrl = discrete.pd(kp, kd, dt, measured="motor_angle")
    paths = []
    for w in freqs:
        path = out / f"sine_{w:.4g}rad_s.csv"
        if path.exists() and not overwrite:
            raise FileExistsError(f"{path} exists; pass overwrite=True (CLI: --overwrite)")
        a = amplitude(model, w, design)
        period = 2 * math.pi / w
        t_rec0 = (design.ramp_periods + design.settle_periods) * period
        duration = t_rec0 + design.periods * period
        n = int(math.ceil(duration / dt)) + 1
        sc = scenario.model_copy(
            update={"simulation": scenario.simulation.model_copy(update={"duration": (n - 1) * dt})}
        )
        p = prepare(sc, controller=ctrl)
        assert sc.simulation is not None  # scenario's, with this run's duration
        t = p.time
        ramp_t = design.ramp_periods * period
        env = np.where(t < ramp_t, 0.5 * (1 - np.cos(np.pi * np.clip(t / ramp_t, 0, 1))), 1.0)
        p.references["reference"] = a * env * np.sin(w * t)
        cb = None if progress is None else (lambda d, tot, w=w: progress(f"{w:.4g} rad/s", d, tot))
        out_arr = simulate_loop(
            p.loop,
            p.x0,
            p.references,
            p.n_samples,
            seed=sc.simulation.seed,
            progress=cb or (lambda d, tot: None),
            chunk=design.chunk,
        )
        res = to_result(p, out_arr)
        keep = t >= t_rec0 - 1e-12
        cols = res.exchange_columns()
        rec = {k: np.asarray(v)[keep] for k, v in cols.items()}
        rec["time"] = rec["time"] - rec["time"][0]
        from flexarm.io.logs import write_log

        out.mkdir(parents=True, exist_ok=True)
        write_log(
            path,
            rec.pop("time"),
            rec,
            overwrite=overwrite,
            comments=[
                f"scenario: {scenario.name}",
                "experiment: sine",
                f"omega0_rad_s: {w:.10g}",
                f"amplitude_rad: {a:.6g}",
                f"controller: pd KP={kp:.6g} KD={kd:.6g}",
                f"sampling_period_s: {dt:g}",
                f"discarded_periods: {design.ramp_periods + design.settle_periods}",
            ],
        )
        paths.append(path)
    return paths

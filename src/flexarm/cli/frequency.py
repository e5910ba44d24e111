"""Frequency-domain identification: ``experiment`` (FRB sine experiments on the simulated
arm), ``identify`` (G_m, G_b, Coulomb friction from them), ``excite`` (multisines), ``frf``,
``tfest`` and ``friction``."""

from __future__ import annotations

from pathlib import Path
from typing import cast

import typer

from flexarm.cli import options as o
from flexarm.cli import parsing
from flexarm.cli.common import (
    check_dir_option,
    check_file_option,
    console,
    distinct_outputs,
    enable_cache,
    err,
    fail,
    fmt,
    guarded_command,
    load,
    output_folder,
    save_result,
    warn,
)
from flexarm.cli.parsing import number


@guarded_command("scenario")
def experiment(
    scenario: str = typer.Argument(..., help="scenario TOML file or built-in name"),
    out: Path = typer.Option(..., "--out", help="folder for one CSV per experiment"),
    frequencies: str | None = typer.Option(
        None,
        help="excitation frequencies in rad/s, comma separated; give ω0 "
        "and 3ω0 pairs (default: pairs chosen from the model)",
    ),
    periods: int = typer.Option(
        20, help="whole periods recorded per experiment", callback=number(ge=1, le=100_000)
    ),
    kp: float | None = typer.Option(
        None, help="PD gain, command units per rad", callback=number(example="10")
    ),
    kd: float | None = typer.Option(
        None, help="PD gain, command units*s/rad", callback=number(example="0.2")
    ),
    overwrite: bool = typer.Option(False, help="replace existing CSV files"),
) -> None:
    """Sine experiments on the simulated arm, as FRB Sec. II-A: one CSV per frequency."""
    enable_cache()
    from rich.progress import Progress

    from flexarm.identification.frequency_domain.experiments import SineDesign, run_sine_experiments

    check_dir_option("--out", out)
    sc = load(scenario)
    design = SineDesign(
        frequencies=parsing.floats(frequencies, "--frequencies"), periods=periods, kp=kp, kd=kd
    )
    try:
        with Progress(console=err) as bar:
            task = bar.add_task("experiments", total=None)
            paths = run_sine_experiments(
                sc,
                out,
                design,
                overwrite=overwrite,
                progress=lambda label, d, tot: bar.update(
                    task, description=label, completed=d, total=tot
                ),
            )
    except (ValueError, FileExistsError) as exc:
        fail(str(exc))
    console.print(f"wrote {len(paths)} experiment(s) into {out}/")


@guarded_command("files", "column", "unit")
def identify(
    files: list[Path] = typer.Argument(..., help="CSV logs, or one folder of them"),
    motor_constant: str = typer.Option(
        ..., "--motor-constant", help="K, e.g. 0.24676 (N*m/A) or '2.184 lbf*in/A'"
    ),
    json_out: o.JsonOut = None,
    plots: Path | None = typer.Option(None, help="folder for the Bode figures"),
    scenario_out: Path | None = typer.Option(
        None, "--scenario-out", help="write the identified arm as a scenario TOML"
    ),
    current_limit: str | None = typer.Option(None, help="amplifier limit for the scenario"),
    column: list[str] | None = typer.Option(None, help="map a column: current=i_m"),
    unit: list[str] | None = typer.Option(None, help="a column's unit: current=mA"),
    motor_orders: str = typer.Option("2,4", help="zeros,poles of G_m (poles incl. the integrator)"),
    beam_orders: str = typer.Option("0,2", help="zeros,poles of G_b"),
    structured: bool | None = typer.Option(
        None,
        "--structured/--free",
        help="G_m from the joint fit of J, V, C, C_f, or the paper's free fit to the "
        "corrected data (default: joint fit for a one-mode beam)",
    ),
    overwrite: bool = typer.Option(False, help="replace existing output files"),
) -> None:
    """Identify G_m, G_b and Coulomb friction from sine experiments (FRB Sec. II)."""
    import warnings

    from flexarm.identification.frequency_domain.harmonics import IdentificationError
    from flexarm.identification.frequency_domain.identify import identify as run_identify

    # count=2: two whole numbers each
    mo = cast("tuple[int, int]", parsing.ints(motor_orders, "--motor-orders", 2, "2,4"))
    bo = cast("tuple[int, int]", parsing.ints(beam_orders, "--beam-orders", 2, "0,2"))
    check_file_option("--json", json_out, overwrite)
    check_file_option("--scenario-out", scenario_out, overwrite, "arm.toml")
    distinct_outputs(("--json", json_out), ("--scenario-out", scenario_out))
    plots = output_folder("--plots", plots, overwrite)
    src = files[0] if len(files) == 1 else files
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = run_identify(
                src,
                motor_constant,
                motor_orders=mo,
                beam_orders=bo,
                columns=parsing.pairs(column, "column") or None,
                units=parsing.pairs(unit, "unit") or None,
                structured=structured,
            )
    except (IdentificationError, ValueError) as exc:
        fail(str(exc))
    for w in caught:
        warn(str(w.message))
    d = res.to_dict()
    if json_out is not None:
        save_result("--json", json_out, res.to_json(), overwrite)
    if plots is not None:
        res.bode_figures(plots)
    if scenario_out is not None:
        from flexarm.io.write import write_toml

        write_toml(scenario_out, scenario_file(res, current_limit), overwrite=overwrite)
    cf = d["coulomb_current"]
    console.print(
        f"Coulomb friction: {cf:.4g} A ({d['coulomb_torque']:.4g} N*m)"
        if cf is not None
        else "Coulomb friction: not estimated (no ω0/3ω0 pair)"
    )
    console.print(
        f"G_m num = {fmt(d['motor_tf']['num'])}\n    den = {fmt(d['motor_tf']['den'])}"
        f"  ({d['motor_tf_method']})"
    )
    console.print(f"G_b num = {fmt(d['beam_tf']['num'])}\n    den = {fmt(d['beam_tf']['den'])}")


def scenario_file(res, current_limit) -> dict:
    """An identified arm as a complete scenario (the rest from the FRB defaults)."""
    frag = res.to_scenario_dict(current_limit=current_limit)
    frag["notes"] = {k: str(v) for k, v in frag.get("notes", {}).items()}
    frag.update(
        {
            "sampling": {"period": float(res.logs[0].dt), "delay": 1},
            "simulation": {"duration": 2.0, "substeps": 10},
            "reference": {"type": "step", "amplitude": 0.2},
            "controller": {"type": "pd", "kp": 10.0, "kd": 0.2},
        }
    )
    frag["arm"].pop("kind", None)
    return frag


@guarded_command()
def excite(
    out: Path = typer.Argument(..., help="CSV to write (the signal a generator plays)"),
    fs: float = typer.Option(
        ..., "--fs", help="sampling rate, Hz", callback=number(gt=0, example="1000")
    ),
    period: int = typer.Option(
        ...,
        "--period",
        help="samples per period",
        callback=number(ge=2, le=100_000_000, example="1000"),
    ),
    f_min: float = typer.Option(..., "--f-min", help="lowest line, Hz", callback=number(ge=0)),
    f_max: float = typer.Option(..., "--f-max", help="highest line, Hz", callback=number(gt=0)),
    kind: str = typer.Option("random-odd", help="full | odd | random-odd | prbs | sweep"),
    grid: str = typer.Option("linear", help="linear | log"),
    phases: str = typer.Option("random", help="schroeder | random | min-crest"),
    rms: float = typer.Option(1.0, help="rms of the signal (multisine)", callback=number(gt=0)),
    periods: int = typer.Option(2, help="periods to play", callback=number(ge=1, le=1_000_000)),
    realisations: int = typer.Option(
        1, help="realisations (new random phases)", callback=number(ge=1, le=10_000)
    ),
    seed: int = typer.Option(0, callback=number(ge=0, le=2**32 - 1)),
    overwrite: bool = typer.Option(False, help="replace existing files"),
) -> None:
    """Design an excitation: writes OUT and OUT-lines.csv (excited and detection lines)."""
    import numpy as np

    from flexarm.identification.frequency_domain import excitation as ex

    try:
        if kind == "sweep":
            e = ex.swept_sine(period, fs, f_min, f_max, amplitude=rms * np.sqrt(2), periods=periods)
        else:
            e = ex.multisine(
                period,
                fs,
                f_min,
                f_max,
                kind=kind,
                grid=grid,
                phases=phases,
                rms=rms,
                periods=periods,
                realisations=realisations,
                seed=seed,
            )
        log, lines = ex.write_excitation(out, e, overwrite=overwrite)
    except (ValueError, FileExistsError) as exc:
        fail(str(exc))
    console.print(
        f"{log}: {e.signal.shape[1]} samples × {e.signal.shape[0]} realisation(s), "
        f"{len(e.excited)} excited and {len(e.detection)} detection lines, crest "
        f"factor {e.crest_factor:.3f}; lines in {lines}"
    )


@guarded_command("logs", "log_format", "lines")
def frf(
    logs: list[Path] = typer.Argument(
        ..., help="periodic recordings (.mat or CSV); several: one realisation each, robust BLA"
    ),
    log_format: Path | None = typer.Option(
        None, "--log-format", help="TOML with [columns] and [units]"
    ),
    input: str = typer.Option("current", "--input", help="flexarm name of the input"),
    output: str = typer.Option(
        "motor_angle", "--output", help="flexarm name(s) of the outputs, comma-separated"
    ),
    period: str = typer.Option("auto", "--period", help="samples per period, or auto"),
    lines: str = typer.Option("auto", "--lines", help="CSV of lines (from excite), or auto"),
    reference: str | None = typer.Option(
        None,
        "--reference",
        help="closed loop, with --method lpm: the reference's flexarm "
        "name; G = G_yr/G_ur (indirect). Periodic data need none: "
        "the ratio of period means is already Ȳ/Ū = (Ȳ/R̄)/(Ū/R̄)",
    ),
    method: str = typer.Option(
        "periodic",
        "--method",
        help="periodic (multisine over whole periods) or lpm "
        "(local polynomial method: non-periodic or transient records)",
    ),
    json_out: o.JsonRequired = ...,  # pyright: ignore[reportArgumentType]  (typer: ... = a required option)
    plots: o.Plots = None,
    overwrite: o.Overwrite = False,
) -> None:
    """Nonparametric FRF, noise, odd/even distortion and the BLA of a periodic recording."""
    import warnings as _w

    from flexarm.identification.frequency_domain.harmonics import IdentificationError
    from flexarm.identification.frequency_domain.periodic import (
        combine_realisations,
        lpm_frf,
        periodic_frf,
        plot_bode,
        plot_distortion,
    )
    from flexarm.io.logformat import read_recording

    if method not in ("periodic", "lpm"):
        fail(f"--method {method!r}: choose periodic or lpm")
    n_period = (
        None if period == "auto" else parsing.ints(period, "--period", 1, "1000 (or auto)")[0]
    )
    if n_period is not None and n_period < 2:
        fail(f"--period {period}: a period needs at least 2 samples; give e.g. 1000 (or auto)")
    check_file_option("--json", json_out, overwrite, "frf.json")
    plots = output_folder("--plots", plots, overwrite)
    from flexarm.io.logs import LogError

    try:
        with _w.catch_warnings(record=True) as caught:
            _w.simplefilter("always")
            ex_lines = None
            if lines != "auto":
                txt = Path(lines).read_text().splitlines()[1:]
                ex_lines = [int(r.split(",")[0]) for r in txt if r.strip().endswith("excited")]
            names = [n.strip() for n in output.split(",") if n.strip()]
            results = []
            for log in logs:  # one realisation per recording
                sig, fs = read_recording(log, log_format)
                for n in [input] + names + ([reference] if reference else []):
                    if n not in sig:
                        fail(f"{log}: no signal {n!r}; mapped: {', '.join(sig)}")
                if method == "lpm":
                    results.append(
                        lpm_frf(
                            sig[input],
                            {n: sig[n] for n in names},
                            fs,
                            input_name=input,
                            source=str(log),
                            reference=sig[reference] if reference else None,
                        )
                    )
                    continue
                results.append(
                    periodic_frf(
                        sig[input],
                        {n: sig[n] for n in names},
                        fs,
                        period=n_period,
                        lines=ex_lines,
                        input_name=input,
                        source=str(log),
                    )
                )
            res = (
                results[0]
                if len(results) == 1
                else combine_realisations(results, source=", ".join(map(str, logs)))
            )
        for c in caught:
            warn(str(c.message))
    except (IdentificationError, LogError, OSError, ValueError) as exc:
        fail(str(exc))
    save_result("--json", json_out, frf_document(logs, res), overwrite)
    if plots is not None:
        plot_distortion(res, plots / "frf-distortion.png")
        plot_bode(res, plots / "frf-bode.png")
    if method == "lpm":
        console.print(
            f"LPM: {len(res.lines)} lines {res.frequency_hz[0]:g}–"
            f"{res.frequency_hz[-1]:g} Hz from {res.period} samples; {res.verdict()}"
        )
        return
    console.print(
        f"{len(res.lines)} excited lines {res.frequency_hz[0]:g}–{res.frequency_hz[-1]:g} Hz, "
        f"period {res.period} samples, {res.periods_used} periods used "
        f"({res.transient_periods} transient); {res.verdict()}"
    )


def structure_given(st, motor_constant, resistance, gear_ratio, efficiency, length) -> dict:
    """The known constants of a structure from the CLI's data-sheet options; a clear error
    for a missing or a foreign option."""
    given = {
        "motor_constant": motor_constant,
        "armature_resistance": resistance,
        "gear_ratio": gear_ratio,
        "efficiency": efficiency,
        "length": length,
    }
    given = {k: v for k, v in given.items() if v is not None}
    opt = {
        "motor_constant": "--motor-constant",
        "armature_resistance": "--resistance",
        "gear_ratio": "--gear-ratio",
        "efficiency": "--efficiency",
        "length": "--length",
    }
    extra = [opt[k] for k in given if k not in st.given and k not in st.optional_given]
    if extra:
        fail(f"--structure {st.name} takes no {', '.join(extra)}")
    missing = [f"{opt[k]} ({st.given[k]})" for k in st.given if k not in given]
    if missing:
        fail(f"--structure {st.name} needs the data-sheet value(s) {'; '.join(missing)}")
    return given


@guarded_command("frf_json")
def tfest(
    frf_json: Path = typer.Argument(..., help="JSON written by flexarm frf"),
    poles: int | None = typer.Option(None, "--poles", callback=number(ge=0, le=100)),
    zeros: int | None = typer.Option(None, "--zeros", callback=number(ge=0, le=100)),
    integrators: int = typer.Option(0, "--integrators", callback=number(ge=0, le=10)),
    delay: bool = typer.Option(False, "--delay", help="estimate a delay"),
    structure: str | None = typer.Option(
        None,
        "--structure",
        help="physical structure: two-mass, frb-single-mass "
        "(needs --motor-constant) or voltage-servo (needs "
        "--motor-constant, --resistance, --gear-ratio, --efficiency)",
    ),
    output: str | None = typer.Option(
        None,
        "--output",
        help="output(s) to fit: one for a rational model; for a "
        "structure a comma list (default: every output of the "
        "FRF the structure has)",
    ),
    free: str | None = typer.Option(
        None, "--free", help="structure: comma list of the parameters fitted (default all)"
    ),
    fixed: list[str] = typer.Option(
        [],
        "--fix",
        help="structure: NAME=VALUE held (SI; with --free, the value of a parameter not fitted)",
    ),
    motor_constant: o.StructMotorConstant = None,
    resistance: o.StructResistance = None,
    gear_ratio: o.StructGearRatio = None,
    efficiency: o.StructEfficiency = None,
    length: o.StructLength = None,
    coulomb: bool = typer.Option(
        True,
        "--coulomb/--no-coulomb",
        help="the Coulomb level from the odd distortion "
        "(simulates the fitted model; a few seconds)",
    ),
    json_out: o.JsonRequired = ...,  # pyright: ignore[reportArgumentType]  (typer: ... = a required option)
    plots: o.Plots = None,
    overwrite: o.Overwrite = False,
) -> None:
    """Fit a transfer function or a physical structure (two-mass, frb-single-mass,
    voltage-servo) to an FRF, weighted by its variances; JSON parameters.<name> = {value, std}."""
    import control as ct
    import numpy as np

    from flexarm.identification.frequency_domain.multisine_friction import SIMULATORS
    from flexarm.identification.frequency_domain.structures import STRUCTURES, fit_structure
    from flexarm.identification.frequency_domain.tfest import TFEstError
    from flexarm.identification.frequency_domain.tfest import tfest as _tfest

    check_file_option("--json", json_out, overwrite, "tfest.json")
    plots = output_folder("--plots", plots, overwrite)
    d = parsing.json_file(frf_json, "", "an FRF JSON from flexarm frf")
    try:
        f = np.asarray(d["frequency_hz"], float)
        outs = d["outputs"]
        if not isinstance(outs, dict):
            raise ValueError("'outputs' is not a table of output channels")
    except (ValueError, KeyError, TypeError) as exc:
        fail(f"{frf_json}: not an FRF JSON from flexarm frf ({exc})")
    w = 2 * np.pi * f

    def chan(name):
        oc = outs[name]
        sd = oc.get("total_std") or oc["noise_std"]
        return np.asarray(oc["re"]) + 1j * np.asarray(oc["im"]), np.asarray(sd, float)

    try:
        if structure is not None:
            if structure not in STRUCTURES:
                fail(f"--structure {structure!r}: choose one of {', '.join(STRUCTURES)}")
            st = STRUCTURES[structure]
            names = (
                [n.strip() for n in output.split(",") if n.strip()]
                if output
                else [n for n in st.outputs if n in outs]
            )
            for n in names:
                if n not in outs:
                    fail(
                        f"{frf_json}: --output {n!r} is not in the FRF; outputs: {', '.join(outs)}"
                    )
            if not names:
                fail(
                    f"{frf_json}: none of the FRF's outputs ({', '.join(outs)}) is an output "
                    f"of the {structure} structure ({', '.join(st.outputs)}); name them with "
                    "flexarm frf --output"
                )
            given = structure_given(st, motor_constant, resistance, gear_ratio, efficiency, length)
            held = {}
            for item in fixed:
                k, _, v = item.partition("=")
                try:
                    held[k.strip()] = float(v)
                except ValueError:
                    fail(f"--fix {item!r}: write NAME=VALUE with a number (SI units)")
            chans = {n: chan(n) for n in names}
            fit = fit_structure(
                st,
                w,
                {n: c[0] for n, c in chans.items()},
                {n: c[1] for n, c in chans.items()},
                free=[x.strip() for x in free.split(",")] if free else None,
                initial=held or None,
                given=given,
            )
            out = fit.to_json()  # structure, units, given, free, outputs, cost, parameters
            if structure in SIMULATORS and coulomb and d.get("spectra") and "motor_angle" in outs:
                import warnings as _w

                from flexarm.identification.frequency_domain.harmonics import IdentificationError
                from flexarm.identification.frequency_domain.multisine_friction import (
                    coulomb_from_distortion,
                )
                from flexarm.identification.frequency_domain.periodic import PeriodicFRF

                err.print("Coulomb level from the odd distortion: simulating the fitted model ...")
                try:
                    with _w.catch_warnings(record=True) as caught:
                        _w.simplefilter("always")
                        cf = coulomb_from_distortion(
                            PeriodicFRF.from_json(d, str(frf_json)),
                            {**fit.given, **fit.values},
                            structure=structure,
                            progress=lambda i, n: err.print(f"  simulation {i}", end="\r"),
                        )
                    for c in caught:
                        if "IdentificationWarning" in type(c.message).__name__:
                            warn(str(c.message))
                    err.print("")
                    fit.parameters["coulomb_current" if cf.unit == "A" else "coulomb_torque"] = {
                        "value": cf.coulomb_current,
                        "std": cf.std,
                    }
                    out["coulomb"] = cf.to_json()
                except IdentificationError as exc:
                    warn(f"no Coulomb level: {exc}")
                    out["coulomb"] = {"error": str(exc)}
            elif structure in SIMULATORS and coulomb and "motor_angle" in outs:
                err.print(
                    "note: no Coulomb level: the FRF JSON has no period spectra (LPM, "
                    "several realisations, or written by an older flexarm frf)"
                )
        elif structure is None and poles is not None and zeros is not None:
            name = output or next(iter(outs))
            if name not in outs:
                fail(f"{frf_json}: --output {name!r} is not in the FRF; outputs: {', '.join(outs)}")
            H, sd = chan(name)
            fit = _tfest(ct.frd(H, w), poles, zeros, integrators=integrators, delay=delay, std=sd)
            out = {
                "output": name,
                "num": fit.tf.num[0][0].tolist(),
                "den": fit.tf.den[0][0].tolist(),
                "unstable_poles": [str(p) for p in fit.unstable_poles],
            }
        else:
            fail(f"give --poles N --zeros M, or --structure ({', '.join(STRUCTURES)})")
    except TFEstError as exc:
        fail(f"{frf_json}: {exc}")
    out = tfest_document(out, fit)
    save_result("--json", json_out, out, overwrite)
    if plots is not None:
        from flexarm.identification.frequency_domain.tfest import plot_fit

        if structure is not None:
            chans = {n: chan(n) for n in out["outputs"]}
            plot_fit(
                fit,
                f,
                {n: c[0] for n, c in chans.items()},
                {n: c[1] for n, c in chans.items()},
                path=plots / "tfest.png",
            )
        else:
            plot_fit(fit, f, {name: H}, {name: sd}, path=plots / "tfest.png")
    console.print(fit.verdict)
    for name, v in fit.parameters.items():
        extra = f", inflated ± {v['std_inflated']:.4g}" if "std_inflated" in v else ""
        kind = "line scatter" if name.startswith("coulomb_") else "noise"
        console.print(f"  {name} = {v['value']:.6g} ± {v['std']:.4g} ({kind}){extra}")


@guarded_command("frf_json")
def friction(
    frf_json: list[Path] = typer.Argument(
        ...,
        help="FRF JSONs written by flexarm frf, one per amplitude (same "
        "excitation lines, different levels)",
    ),
    structure: str = typer.Option(
        "two-mass", "--structure", help="two-mass, frb-single-mass or voltage-servo"
    ),
    motor_constant: o.StructMotorConstant = None,
    resistance: o.StructResistance = None,
    gear_ratio: o.StructGearRatio = None,
    efficiency: o.StructEfficiency = None,
    length: o.StructLength = None,
    iterations: int = typer.Option(
        3,
        "--iterations",
        help="simulator corrections of the Bussgang start (0: none)",
        callback=number(ge=0, le=1000),
    ),
    json_out: o.JsonRequired = ...,  # pyright: ignore[reportArgumentType]  (typer: ... = a required option)
    overwrite: o.Overwrite = False,
) -> None:
    """Coulomb friction and viscous damping from the amplitude dependence of the BLA: the
    structure fitted to each record's BLA, its viscous damping regressed on 1/σ_v
    (Bussgang), then matched with flexarm's simulator of the fitted model with friction."""
    import warnings as _w

    import numpy as np

    from flexarm.identification.frequency_domain.harmonics import IdentificationError
    from flexarm.identification.frequency_domain.multisine_friction import (
        SIMULATORS,
        coulomb_from_bla_amplitudes,
    )
    from flexarm.identification.frequency_domain.periodic import PeriodicFRF
    from flexarm.identification.frequency_domain.structures import STRUCTURES, fit_structure
    from flexarm.identification.frequency_domain.tfest import TFEstError

    check_file_option("--json", json_out, overwrite, "friction.json")
    if structure not in SIMULATORS:
        fail(f"--structure {structure!r}: the friction match simulates {', '.join(SIMULATORS)}")
    if len(frf_json) < 2:
        fail(
            "flexarm friction needs two or more FRF JSONs at different amplitudes (one "
            "amplitude: flexarm tfest --structure ... gives C_f from the odd distortion)"
        )
    st = STRUCTURES[structure]
    given = structure_given(st, motor_constant, resistance, gear_ratio, efficiency, length)
    frfs, fits = [], []
    for path in frf_json:
        d = parsing.json_file(path, "", "an FRF JSON from flexarm frf")
        try:
            frf = PeriodicFRF.from_json(d, str(path))
        except (ValueError, KeyError, TypeError, IdentificationError) as exc:
            fail(f"{path}: not an FRF JSON from flexarm frf ({exc})")
        if not frf.spectra:
            fail(
                f"{path}: the FRF JSON has no period spectra (LPM or several realisations): "
                "the record cannot be replayed by the simulator"
            )
        names = [n for n in st.outputs if n in frf.outputs]
        if "motor_angle" not in names:
            fail(
                f"{path}: no motor_angle output (outputs: {', '.join(frf.outputs)}); the "
                "velocity rms and the friction are taken at the motor"
            )
        idx = [frf.outputs.index(n) for n in names]
        try:
            fit = fit_structure(
                st,
                2 * np.pi * frf.frequency_hz,
                {n: frf.response[i] for n, i in zip(names, idx, strict=True)},
                {
                    n: (frf.total_std if frf.total_std is not None else frf.noise_std)[i]
                    for n, i in zip(names, idx, strict=True)
                },
                given=given,
            )
        except TFEstError as exc:
            fail(f"{path}: {exc}")
        frfs.append(frf)
        fits.append(fit)
        err.print(f"{path}: {structure} fit, {fit.verdict.split(':')[0]}")
    try:
        with _w.catch_warnings():
            _w.simplefilter("ignore")  # all of them are in res["warnings"]
            res = coulomb_from_bla_amplitudes(
                frfs,
                fits,
                structure,
                iterations=iterations,
                progress=lambda i, n: err.print(f"  simulation {i}", end="\r"),
            )
        err.print("")
    except IdentificationError as exc:
        fail(str(exc))
    for m in res["warnings"]:
        warn(m)
    res = friction_document(res, frf_json, fits)
    save_result("--json", json_out, res, overwrite)
    c, v = res["coulomb"], res["viscous"]
    console.print(
        f"Coulomb {c['value']:.4g} ± {c['std']:.2g} {res['unit']}, viscous "
        f"{v['value']:.4g} ± {v['std']:.2g} {res['damping_unit']} (correlation "
        f"{res['correlation']:.2f}; Bussgang start {res['bussgang']['coulomb']['value']:.4g})"
    )


# --- JSON LAYOUT ---------------------------------------------------------------------------
# The documents `frf`, `tfest` and `friction` write, assembled here; they belong to the
# library's results (PeriodicFRF, the tfest/structure fit, the friction match).


def frf_document(logs: list[Path], res) -> dict:
    """JSON LAYOUT of ``frf --json``: the source(s), the realisation count and the FRF."""
    return {
        "source": [str(x) for x in logs] if len(logs) > 1 else str(logs[0]),
        "realisations": len(logs),
        **res.to_json(),
    }


def tfest_document(out: dict, fit) -> dict:
    """JSON LAYOUT of ``tfest --json``: the model's own entries plus the cost, its check
    and the parameters with their standard deviations (and what those mean)."""
    out = {
        **out,
        "cost": fit.cost,
        "expected_cost": fit.expected_cost,
        "cost_std": fit.cost_std,
        "verdict": fit.verdict,
        "parameters": fit.parameters,
    }
    inflated = any("std_inflated" in v for v in fit.parameters.values())
    out["std_note"] = (
        "'std': from the noise (or BLA) variances alone; 'std_inflated': std × "
        "sqrt(cost/expected_cost), the misfit counted as extra noise (the fit is "
        "rejected)"
        if inflated
        else "'std': from the noise (or BLA) variances"
    )
    return out


def friction_document(res: dict, frf_json: list[Path], fits: list) -> dict:
    """JSON LAYOUT of ``friction --json``: the match's result, its sources and the
    structure fitted to each record."""
    return {**res, "sources": [str(p) for p in frf_json], "fits": [f.to_json() for f in fits]}

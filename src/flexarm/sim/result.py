"""Simulation results in python-control style.

:class:`SimulationResult` is a :class:`control.TimeResponseData` (``.time``, ``.outputs``,
``.inputs``, ``.states``, ``.output_labels``, ``.plot()``) with named access to every
signal: ``res["tip_angle"]`` (true), ``res.measured["motor_angle"]`` (as the sensors
read it), ``res.references["reference"]``, ``res.command``; ``to_csv`` writes the
flexarm CSV exchange format (what a lab log holds).

It is the one result type of every simulation: a sampled-data run of any arm, a
continuous-law run (:func:`flexarm.sim.continuous.simulate_continuous`), and batches. A batch
is one object with python-control's multi-trace layout: ``.states`` (n_x, N, T),
``.inputs`` (m, N, T), ``.outputs`` (p, N, T); the named views put the rollout first
(``res["theta_1"]`` (N, T), ``res.theta`` (N, T, n_joints)), ``res.diverged`` (N,) flags the
rollouts that left the bound, and :meth:`SimulationResult.run` gives rollout i alone. One
object rather than a list: vectorised metrics over the batch (``np.abs(res.theta - θ_d)``),
one set of labels, and python-control's own convention for several traces.

Multi-link arms (signals ``theta_i``, ``delta_i_j``) have time-major views as well:
``res.theta`` ([N,] T, n_joints) rad, ``res.delta`` ([N,] T, n_δ) m, ``res.torque`` ([N,] T, m)
(the command: N·m for torque inputs), ``res.state_array`` ([N,] T, n_x).
"""

from __future__ import annotations

from pathlib import Path

import control
import numpy as np

from flexarm.display import Table
from flexarm.io.logs import KNOWN as EXCHANGE_UNITS
from flexarm.io.logs import LINEAR_SI, write_log


def _unit(name: str) -> str:
    """SI unit of an exchange column or a multi-link state/command name."""
    if name in EXCHANGE_UNITS:
        return EXCHANGE_UNITS[name]
    for prefix, unit in (
        ("theta_dot_", "rad/s"),
        ("delta_dot_", "m/s"),
        ("theta_", "rad"),
        ("delta_", "m"),
        ("torque_", "N*m"),
        ("current_", "A"),
        ("voltage_", "V"),
        ("friction_z_", "rad"),
    ):
        if name.startswith(prefix):
            return unit
    if name.endswith("_torque"):
        return "N*m"
    return "?"


class SimulationResult(control.TimeResponseData):
    """One rollout, or a batch of N, of a closed loop (values at the sample instants).

    ``signals``/``measured``: name → ([N,] T) arrays; ``references``: name → (T,);
    ``command`` ([N,] T, m); ``states`` ([N,] T, n_x); ``diverged`` (N,) for a batch."""

    def __init__(
        self,
        time,
        signals: dict[str, np.ndarray],
        measured: dict[str, np.ndarray],
        references: dict[str, np.ndarray],
        command: np.ndarray,
        input_names,
        states: np.ndarray,
        state_names,
        title: str = "flexarm simulation",
        meta: dict | None = None,
        diverged: np.ndarray | None = None,
    ):
        self.signals = signals
        self.measured = measured
        self.references = references
        self.command = np.asarray(command)  # ([N,] T, m)
        self.input_names = tuple(input_names)
        self.meta = dict(meta or {})
        self.diverged = None if diverged is None else np.asarray(diverged, dtype=bool)
        names = list(signals)
        super().__init__(
            np.asarray(time),
            np.array([signals[n] for n in names]),
            states=np.moveaxis(np.asarray(states), -1, 0),
            inputs=np.moveaxis(self.command, -1, 0),
            output_labels=names,
            state_labels=list(state_names),
            input_labels=list(input_names),
            title=title,
            issiso=False,
        )

    # ------------------------------------------------------------ batches
    @property
    def is_batch(self) -> bool:
        return self.command.ndim == 3

    def run(self, i: int) -> SimulationResult:
        """Rollout i of a batch as a result of its own."""
        if not self.is_batch:
            raise ValueError("run(i): this result is one rollout, not a batch")
        return SimulationResult(
            self.time,
            {k: v[i] for k, v in self.signals.items()},
            {k: v[i] for k, v in self.measured.items()},
            self.references,
            self.command[i],
            self.input_names,
            self.state_array[i],
            self.state_names,
            title=str(self.title),
            meta=self.meta,
        )

    # ------------------------------------------------------------ named views
    @property
    def state_names(self) -> tuple[str, ...]:
        """The state labels (python-control's ``state_labels``, typed optional there)."""
        return tuple(self.state_labels or ())

    @property
    def state_array(self) -> np.ndarray:
        """The states with the variable last: ([N,] T, n_x) (rad, m, rad/s, m/s, ...)."""
        return np.moveaxis(self.states, 0, -1)

    def _stack(self, names: list[str]) -> np.ndarray:
        shape = self.command.shape[:-1] + (0,)
        return np.stack([self.signals[n] for n in names], axis=-1) if names else np.zeros(shape)

    @property
    def joint_names(self) -> list[str]:
        """The joint-angle signals ``theta_1``, ``theta_2``, ... (multi-link arms)."""
        return [n for n in self.signals if n.startswith("theta_") and n[6:].isdigit()]

    @property
    def n_links(self) -> int:
        return len(self.joint_names)

    @property
    def theta(self) -> np.ndarray:
        """Joint angles, ([N,] T, n_joints), rad."""
        return self._stack(self.joint_names)

    @property
    def delta(self) -> np.ndarray:
        """Modal deflections, ([N,] T, n_δ), m."""
        return self._stack([n for n in self.signals if n.startswith("delta_")])

    @property
    def torque(self) -> np.ndarray:
        """The applied command (after saturation), ([N,] T, m): joint torques in N·m for
        torque inputs (the drives' commands, A or V, otherwise)."""
        return self.command

    def __getitem__(self, name: str) -> np.ndarray:
        if name in self.signals:
            return self.signals[name]
        if name in self.input_names:
            return self.command[..., self.input_names.index(name)]
        if name in self.references:
            return self.references[name]
        if name in self.state_names:
            return self.state_array[..., self.state_names.index(name)]
        raise KeyError(
            f"{name!r}: no such signal; signals: {', '.join(self.signals)}; inputs: "
            f"{', '.join(self.input_names)}; references: {', '.join(self.references)}; "
            f"states: {', '.join(self.state_names)}"
        )

    # ------------------------------------------------------------ display
    def _table(self) -> Table:
        """One row per signal, command and reference: unit, final value, min, max (over
        every rollout of a batch; ``final`` is then their mean)."""
        t = np.asarray(self.time)
        span = f"{len(t)} samples, {t[0]:.4g}–{t[-1]:.4g} s" if len(t) else "no samples"
        if len(t) > 1:
            span += f", dt {t[1] - t[0]:.4g} s"
        title = f"SimulationResult {self.title!r}: {span}"
        notes = []
        if self.is_batch:
            n = self.command.shape[0]
            k = 0 if self.diverged is None else int(self.diverged.sum())
            title += f", {n} rollouts"
            notes.append(f"{k} of {n} rollouts diverged; final is the mean over the rollouts")

        def row(name, x, unit):
            x = np.asarray(x, float)
            if x.size == 0:
                return (name, unit, None, None, None)
            with np.errstate(all="ignore"):
                final = float(np.nanmean(x[..., -1]))
                return (name, unit, final, float(np.nanmin(x)), float(np.nanmax(x)))

        rows = [row(n, v, _unit(n)) for n, v in self.signals.items()]
        rows += [
            row(n, self.command[..., i], _unit(n))
            for i, n in enumerate(self.input_names)
            if n not in self.signals
        ]
        rows += [row(n, v, _unit(n)) for n, v in self.references.items() if n not in self.signals]
        states = self.state_names
        notes.append(
            f"{len(states)} states ({', '.join(states[:4])}"
            + (", ..." if len(states) > 4 else "")
            + "); "
            "res[name] gives any of them, res.measured[name] as the sensors read it"
        )
        return Table(title, rows, header=("signal", "unit", "final", "min", "max"), notes=notes)

    def __repr__(self) -> str:
        return self._table().text()

    def _repr_html_(self) -> str:
        return self._table().html()

    def exchange_columns(self) -> dict[str, np.ndarray]:
        """Columns of the CSV exchange format: measured where a sensor exists, else true.
        A multi-link arm (no ``motor_angle``) writes every state and every command instead
        (s, rad, m, rad/s, m/s, then the inputs' units)."""
        if self.is_batch:
            raise ValueError("to_csv: a batch has several rollouts; write one: res.run(i)")
        if "motor_angle" not in self.signals:
            cols = {"time": self.time}
            cols.update({n: self.state_array[:, k] for k, n in enumerate(self.state_names)})
            cols.update({n: self.command[:, i] for i, n in enumerate(self.input_names)})
            return cols
        cols = {"time": self.time, "reference": self.references["reference"]}
        for i, n in enumerate(self.input_names):
            cols[n] = self.command[:, i]
        for n in ("motor_angle", "tip_angle", "tip_deflection", "motor_velocity"):
            if n in self.measured:
                cols[n] = self.measured[n]
            elif n in ("motor_angle", "tip_angle") and n in self.signals:
                cols[n] = self.signals[n]
        return cols

    def to_csv(
        self, path: str | Path, *, overwrite: bool = False, comments: dict[str, str] | None = None
    ) -> Path:
        """Write the exchange format (:mod:`flexarm.io.logs`: header ``time,reference,current,
        motor_angle,...``, SI units, ``# key: value`` comment lines first, then a ``# units:``
        line). Refuses to overwrite unless asked (:class:`flexarm.io.logs.LogExistsError`, a
        ``FileExistsError``)."""
        path = Path(path)
        cols = self.exchange_columns()
        lines = [f"{k}: {v}" for k, v in {**self.meta, **(comments or {})}.items()]
        linear = self.meta.get("joint") == "prismatic"  # a linear axis: m, m/s, N
        lines.append(
            "units: "
            + ", ".join(
                f"{k} [{LINEAR_SI.get(_unit(k), _unit(k)) if linear else _unit(k)}]" for k in cols
            )
        )
        path.parent.mkdir(parents=True, exist_ok=True)
        t = cols.pop("time")
        return write_log(
            path, t, cols, comments=lines, overwrite=overwrite, fmt="%.10g", required=("time",)
        )

    def plot_arm(
        self, signals=("reference", "motor_angle", "tip_angle"), *, ax=None, command: bool = True
    ):
        """Angles against time (mrad) and, below, the command: the figure of FRB Figs. 11-19.
        Draws on ``ax`` when given, else on a new :class:`matplotlib.figure.Figure` (no pyplot
        state: a notebook shows the returned figure; :func:`flexarm.io.write.save_figure`
        writes it)."""
        if ax is None:
            from matplotlib.figure import Figure

            fig = Figure(figsize=(7, 5))
            axes = fig.subplots(2 if command else 1, 1, sharex=True, squeeze=False)[:, 0]
        else:
            axes = [ax]
            fig = ax.figure
        for n in signals:
            if n in self.signals or n in self.references:
                axes[0].plot(self.time, 1e3 * self[n], label=n.replace("_", " "))
        axes[0].set_ylabel("angle [mrad]")
        axes[0].legend(loc="best")
        axes[0].grid(True, alpha=0.3)
        if command and len(axes) > 1:
            for i, n in enumerate(self.input_names):
                axes[1].step(self.time, self.command[:, i], where="post", label=n)
            axes[1].set_ylabel(
                " / ".join(f"{n} [{EXCHANGE_UNITS.get(n, '')}]" for n in self.input_names)
            )
            axes[1].grid(True, alpha=0.3)
        axes[-1].set_xlabel("time [s]")
        fig.tight_layout()
        return fig

"""Simulation results in python-control style.

:class:`SimulationResult` is a :class:`control.TimeResponseData` (``.time``, ``.outputs``,
``.inputs``, ``.states``, ``.output_labels``, ``.plot()``) with named access to every
signal: ``res["tip_angle"]`` (true), ``res.measured["motor_angle"]`` (as the sensors
read it), ``res.references["reference"]``, ``res.command``; ``to_csv`` writes the
flexarm CSV exchange format (what a lab log holds).
"""

from __future__ import annotations

from pathlib import Path

import control
import numpy as np

from flexarm.io.logs import KNOWN as EXCHANGE_UNITS
from flexarm.io.logs import write_log


class SimulationResult(control.TimeResponseData):
    """One rollout of a sampled-data closed loop (values at the sample instants)."""

    def __init__(self, time, signals: dict[str, np.ndarray], measured: dict[str, np.ndarray],
                 references: dict[str, np.ndarray], command: np.ndarray, input_names,
                 states: np.ndarray, state_names, title: str = "flexarm simulation",
                 meta: dict | None = None):
        self.signals = signals
        self.measured = measured
        self.references = references
        self.command = command  # (N, m)
        self.input_names = tuple(input_names)
        self.meta = dict(meta or {})
        names = list(signals)
        super().__init__(
            np.asarray(time), np.array([signals[n] for n in names]),
            states=np.asarray(states).T, inputs=np.asarray(command).T,
            output_labels=names, state_labels=list(state_names),
            input_labels=list(input_names), title=title, issiso=False,
        )

    def __getitem__(self, name: str) -> np.ndarray:
        if name in self.signals:
            return self.signals[name]
        if name in self.input_names:
            return self.command[:, self.input_names.index(name)]
        if name in self.references:
            return self.references[name]
        raise KeyError(
            f"{name!r}: no such signal; signals: {', '.join(self.signals)}; inputs: "
            f"{', '.join(self.input_names)}; references: {', '.join(self.references)}"
        )

    def exchange_columns(self) -> dict[str, np.ndarray]:
        """Columns of the CSV exchange format: measured where a sensor exists, else true."""
        cols = {"time": self.time, "reference": self.references["reference"]}
        for i, n in enumerate(self.input_names):
            cols[n] = self.command[:, i]
        for n in ("motor_angle", "tip_angle", "tip_deflection", "motor_velocity"):
            if n in self.measured:
                cols[n] = self.measured[n]
            elif n in ("motor_angle", "tip_angle") and n in self.signals:
                cols[n] = self.signals[n]
        return cols

    def to_csv(self, path: str | Path, *, overwrite: bool = False,
               comments: dict[str, str] | None = None) -> Path:
        """Write the exchange format (:mod:`flexarm.io.logs`: header ``time,reference,current,
        motor_angle,...``, SI units, ``# key: value`` comment lines first, then a ``# units:``
        line). Refuses to overwrite unless asked (:class:`flexarm.io.logs.LogExistsError`, a
        ``FileExistsError``)."""
        path = Path(path)
        cols = self.exchange_columns()
        lines = [f"{k}: {v}" for k, v in {**self.meta, **(comments or {})}.items()]
        lines.append("units: " + ", ".join(f"{k} [{EXCHANGE_UNITS.get(k, '?')}]" for k in cols))
        path.parent.mkdir(parents=True, exist_ok=True)
        t = cols.pop("time")
        return write_log(path, t, cols, comments=lines, overwrite=overwrite, fmt="%.10g",
                         required=("time",))

    def plot_arm(self, signals=("reference", "motor_angle", "tip_angle"), *, ax=None,
                 command: bool = True):
        """Angles against time (mrad) and, below, the command: the figure of FRB Figs. 11-19."""
        import matplotlib.pyplot as plt

        if ax is None:
            fig, axes = plt.subplots(2 if command else 1, 1, sharex=True, figsize=(7, 5),
                                     squeeze=False)
            axes = axes[:, 0]
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
            axes[1].set_ylabel(" / ".join(f"{n} [{EXCHANGE_UNITS.get(n, '')}]" for n in self.input_names))
            axes[1].grid(True, alpha=0.3)
        axes[-1].set_xlabel("time [s]")
        fig.tight_layout()
        return fig

"""The one measured-vs-predicted figure: :func:`overlay_figure` (one panel per signal of
one log of a :class:`~flexarm.identification.time_domain.predict.Prediction`, on a
:class:`matplotlib.figure.Figure`), :func:`write_overlays` (every log's, as PNGs), and the
servo rig's trace (:func:`rig_trace`, :data:`RIG_DISPLAY`).

A leaf of the identification package (issue #43): it imports no fit engine and not the
prediction (a prediction is read by its ``traces``, ``fit_percent`` and ``scenario``), so
the engines that draw their figures through it (``general.predict_scenario``'s ``plots``,
the servo rig's ``report.overlay_plots``) do not import the front door
:mod:`~flexarm.identification.time_domain.predict` back; ``predict`` re-exports these names.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["RIG_DISPLAY", "overlay_figure", "rig_trace", "write_overlays"]


#: the servo rig's signals on the figure's axes (unit, factor): the tip deflection in mm
RIG_DISPLAY: dict[str, tuple[str, float]] = {
    "motor_angle": ("rad", 1.0),
    "tip_deflection": ("mm", 1e3),
    "command": ("", 1.0),
}


def rig_trace(log, simulated: Sequence[np.ndarray]) -> dict:
    """A servo-rig log's trace for :class:`Prediction`: ``simulated`` as the rig engines'
    (hub angle, tip deflection, command) arrays; the measured hub angle and tip deflection,
    the logged voltage as the command, the reference (drawn in the first panel) and the
    axes' units (:data:`RIG_DISPLAY`). A sensor the log does not measure (absent or
    constant: a rigid arm's zero tip column) has no panel: the rig engines simulate a
    rigid arm with an uncoupled dummy link mode, which no sensor reads."""
    names = ("motor_angle", "tip_deflection", "command")
    read = set(log.outputs) | {"command"}
    sim = {c: y for c, y in zip(names, simulated, strict=True) if c in read}
    meas = {c: log.signals[c] for c in names[:2] if c in read}
    if "voltage" in log.signals:
        meas["command"] = log.signals["voltage"]
    tr: dict[str, Any] = {"time": log.time - log.time[0], "measured": meas, "simulated": sim}
    if "reference" in log.signals:
        tr["reference"] = log.signals["reference"]
    tr["display"] = dict(RIG_DISPLAY)
    return tr


def overlay_figure(prediction: Any, key: str, fig=None):
    """Measured vs simulated, one panel per signal, for log ``key`` of ``prediction``, drawn
    on a :class:`matplotlib.figure.Figure` (a new one when ``fig`` is None; no pyplot, no
    backend switched). A trace's ``reference`` is drawn dotted in the first panel; its
    ``display`` (signal → (unit, factor); unit "" for none) scales and labels a panel's
    axis."""
    from matplotlib.figure import Figure

    tr = prediction.traces[key]
    chans = list(tr["simulated"])
    display = tr.get("display", {})
    fig = fig or Figure(figsize=(8, 2.2 * len(chans) + 0.6))
    ax = fig.subplots(len(chans), 1, sharex=True, squeeze=False)[:, 0]
    if tr.get("reference") is not None:
        f = display.get(chans[0], ("", 1.0))[1]
        ax[0].plot(tr["time"], f * np.asarray(tr["reference"]), "k:", lw=0.8, label="reference")
    for a, c in zip(ax, chans, strict=True):
        unit, f = display.get(c, ("", 1.0))
        if c in tr["measured"]:
            a.plot(tr["time"], f * np.asarray(tr["measured"][c]), lw=0.8, label="measured")
        a.plot(tr["time"], f * np.asarray(tr["simulated"][c]), lw=0.8, label="simulated")
        fpv = prediction.fit_percent.get(key, {}).get(c)
        a.set_title(f"{c}: fit {fpv:.1f} %" if fpv is not None else c, fontsize=9)
        if c in display:
            a.set_ylabel(c.replace("_", " ") + (f" [{unit}]" if unit else ""))
        a.grid(alpha=0.3)
        a.legend(loc="best", fontsize=7)
    ax[-1].set_xlabel("time [s]")
    fig.suptitle(f"{key} ({prediction.scenario})", fontsize=10)
    fig.tight_layout()
    return fig


def write_overlays(
    prediction: Any,
    directory: str | Path,
    tag: str = "predict",
    *,
    names: Sequence[str] | None = None,
) -> list[Path]:
    """:func:`overlay_figure` for every log, as PNGs in ``directory`` (written by
    :func:`flexarm.io.write.save_figure`): ``names``, one file name per log in the order
    of ``prediction.traces``, or else ``NN_KEY_TAG.png`` (NN the log's index, KEY its key
    with anything but letters, digits and ``_.-`` as ``_``)."""
    import re

    from flexarm.io.write import save_figure

    keys = list(prediction.traces)
    if names is not None and len(names) != len(keys):
        raise ValueError(f"write_overlays: {len(names)} file names for {len(keys)} logs")
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, key in enumerate(keys):
        fig = overlay_figure(prediction, key)
        if names is not None:
            name = names[i]
        else:
            name = f"{i:02d}_{re.sub(r'[^A-Za-z0-9_.-]+', '_', key)}_{tag}.png"
        p = out / name
        save_figure(fig, p, overwrite=True, dpi=90)
        paths.append(p)
    return paths

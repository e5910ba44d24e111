"""Bode figures of frequency-response data: magnitude and phase, the data with its noise
band, and the fitted model.

For every output y the figure has two axes over a log frequency axis (Hz):

* magnitude 20 log10 |G(jω_k)| (dB) of the data (points), the band
  20 log10(|G_k| ± 2 σ_k) (σ_k the standard deviation of the FRF estimate at line k: the
  noise std, or the BLA's total std when given), and the model 20 log10 |Ĝ(jω)|;
* phase ∠G (deg), unwrapped along the data and brought next to the model's branch, the
  band ∠G ± 2 arcsin(min(σ_k/|G_k|, 1)) (the angle a complex error of size 2σ can turn G), and
  the model's phase.

The |error| |Ĝ − G| of the fit is drawn in the magnitude axes as a dotted line (dB) beside
the level 2σ_k (a thin green line): where the error lies below it, the misfit is noise.
Figures are :class:`matplotlib.figure.Figure` objects (no pyplot state, no backend switch);
:func:`flexarm.io.write.save_figure` writes them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

__all__ = ["bode_figure"]


def _db(x: np.ndarray) -> np.ndarray:
    return 20 * np.log10(np.maximum(np.abs(x), 1e-300))


def _hz_axis(ax) -> None:
    """Log frequency axis labelled 1, 2, 5, 10, ... Hz; minor labels off (they overlapped
    in the old ``tfest.png``)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ax.set_xscale("log")
    ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.grid(True, which="both", alpha=0.3)


def bode_figure(
    frequency_hz: np.ndarray,
    data: Mapping[str, np.ndarray],
    std: Mapping[str, np.ndarray] | None = None,
    model: Callable[[np.ndarray], Mapping[str, np.ndarray]] | None = None,
    *,
    title: str = "",
    path: str | Path | None = None,
    dpi: int = 120,
):
    """The Bode figure of ``data`` (output name → complex G at ``frequency_hz``, Hz) with its
    ±2σ band (``std``: name → σ of the estimate at each line) and the ``model`` (a function of
    ω in rad/s returning name → complex Ĝ(jω)), drawn on a 300-point grid from half the lowest
    to twice the highest frequency; two axes (magnitude dB, phase deg) per output. Written to
    ``path`` when given. Returns the :class:`matplotlib.figure.Figure`."""
    from matplotlib.figure import Figure

    f = np.asarray(frequency_hz, float)
    names = list(data)
    if not names or f.size == 0:
        raise ValueError("bode_figure: no data (give at least one output with one frequency)")
    fig = Figure(figsize=(8, 4.2 * len(names)), layout="constrained")
    axes = fig.subplots(2 * len(names), 1, sharex=True, squeeze=False)[:, 0]
    fg = np.logspace(np.log10(f.min() / 2), np.log10(f.max() * 2), 300)
    mod = dict(model(2 * np.pi * fg)) if model is not None else {}
    mod_at = dict(model(2 * np.pi * f)) if model is not None else {}
    for j, name in enumerate(names):
        am, ap = axes[2 * j], axes[2 * j + 1]
        G = np.asarray(data[name], complex)
        ph = np.degrees(np.unwrap(np.angle(G)))
        if name in mod:
            ph_m = np.degrees(np.unwrap(np.angle(mod[name])))
            ref = np.interp(np.log(f), np.log(fg), ph_m)
            ph = ph + 360 * np.round(np.median(ref - ph) / 360)
        if std is not None and name in std:
            sd = 2 * np.asarray(std[name], float)
            am.fill_between(
                f,
                _db(np.maximum(np.abs(G) - sd, 1e-300)),
                _db(np.abs(G) + sd),
                color="tab:green",
                alpha=0.25,
                lw=0,
                label="data ± 2σ",
            )
            dphi = np.degrees(
                2 * np.arcsin(np.minimum(sd / 2 / np.maximum(np.abs(G), 1e-300), 1.0))
            )
            ap.fill_between(f, ph - dphi, ph + dphi, color="tab:green", alpha=0.25, lw=0)
        am.plot(f, _db(G), "k.", ms=4, label="data")
        ap.plot(f, ph, "k.", ms=4)
        if name in mod:
            am.plot(fg, _db(mod[name]), "r-", lw=1.2, label="fit")
            ap.plot(fg, ph_m, "r-", lw=1.2)
            am.plot(f, _db(np.asarray(mod_at[name]) - G), "b:", lw=1, label="|fit − data|")
        if std is not None and name in std:  # the level |fit − data| is to be compared with
            am.plot(f, _db(2 * np.asarray(std[name], float)), "g-", lw=0.8, label="2σ level")
        am.set_ylabel(f"{name}\nmagnitude (dB)")
        ap.set_ylabel("phase (deg)")
        am.legend(fontsize=7, loc="best")
        for ax in (am, ap):
            _hz_axis(ax)
    axes[-1].set_xlabel("frequency (Hz)")
    if title:
        fig.suptitle(title)
    if path is not None:
        from flexarm.io.write import save_figure

        save_figure(fig, path, overwrite=True, dpi=dpi)
    return fig

"""The one HTML report of a fit, a validation or a design: a single self-contained file.

Everything the page shows is inside the file: the figures as PNG data URIs
(``<img src="data:image/png;base64,...">``, or SVG the same way), the style sheet inline,
no scripts, no fonts, no links to anything outside; it reads the same offline, in any
browser, without JavaScript. Contents, top to bottom:

* the command that produced it (as an equivalent ``flexarm ...`` line), the flexarm
  version, the time it was written and the inputs (log file names, scenario);
* the warnings, highlighted;
* tables: parameters as value ± std with the unit and the relative std 100 σ/|value| %
  (the result's own standard deviations: the bench fit's Newey–West HAC values,
  :class:`flexarm.identification.time_domain.report.FitResult`; the general fit's,
  :class:`flexarm.identification.time_domain.general.ScenarioFit`), and the fit

      fit % = 100 (1 − ‖y − ŷ‖ / ‖y − mean(y)‖)

  per log and signal (values under 80 % marked, the fit's own warning level);
* the figures the results already draw (the fits' and validations' overlay figures,
  written by :func:`flexarm.io.write.save_figure`; or matplotlib ``Figure`` objects),
  embedded.

:class:`HtmlReport` is the builder (sections of headings, tables, figures, text, each
value escaped); :func:`fit_report`, :func:`validate_report` and :func:`design_report` fill
one from a result; ``HtmlReport.write`` writes it through the one atomic writer
(:func:`flexarm.io.write.write_text`: no overwrite unless asked).
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import io
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flexarm.io.write import write_text

__all__ = [
    "HtmlReport",
    "fit_report",
    "validate_report",
    "design_report",
    "figure_data_uri",
    "LOW_FIT_PERCENT",
    "POOR_RELATIVE_STD",
]

#: fit % below this is marked (the bench fit warns below it: report.FitResult.build)
LOW_FIT_PERCENT = 80.0
#: relative std (%) above which a parameter is marked as poorly determined
POOR_RELATIVE_STD = 50.0

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Helvetica,Arial,sans-serif;margin:24px auto;
max-width:1100px;color:#1a1a1a;line-height:1.4;padding:0 16px}
h1{font-size:1.6em;margin-bottom:.2em}h2{font-size:1.25em;border-bottom:1px solid #ccc;
padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;margin:.6em 0;font-size:.92em}
th,td{border:1px solid #ccc;padding:3px 8px;text-align:left;vertical-align:top}
th{background:#f0f0f0}td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
td.low{background:#fde2c8}
.meta td:first-child{font-weight:600;white-space:nowrap}
code,pre{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:.9em}
pre{background:#f6f6f6;padding:8px;overflow-x:auto;white-space:pre-wrap;word-break:break-all}
.warnings{background:#fff4c2;border:2px solid #e0a800;border-radius:4px;padding:6px 14px;
margin:1em 0}.warnings h2{border:none;margin-top:.3em;color:#8a5a00}
.ok{background:#e6f4e6;border:1px solid #7bb87b;border-radius:4px;padding:6px 14px}
figure{margin:1em 0;border:1px solid #ddd;padding:6px;display:inline-block;max-width:100%}
figure img{max-width:100%;height:auto;display:block}figcaption{font-size:.9em;color:#444}
"""


def figure_data_uri(fig: Any) -> str:
    """A figure as a ``data:`` URI: a matplotlib ``Figure`` (rendered to PNG at its own dpi),
    a ``.png`` / ``.svg`` file path, or PNG bytes."""
    if isinstance(fig, (bytes, bytearray)):
        data, mime = bytes(fig), "image/png"
    elif isinstance(fig, (str, Path)):
        p = Path(fig)
        if not p.is_file():
            raise FileNotFoundError(f"report figure {p}: no such file")
        mime = {".png": "image/png", ".svg": "image/svg+xml"}.get(p.suffix.lower())
        if mime is None:
            raise ValueError(
                f"report figure {p}: a {p.suffix or 'suffix-less'} file cannot be "
                "embedded; give a .png or .svg figure (or a matplotlib Figure)"
            )
        data = p.read_bytes()
    elif hasattr(fig, "savefig"):
        buf = io.BytesIO()
        fig.savefig(buf, format="png")
        data, mime = buf.getvalue(), "image/png"
    else:
        raise TypeError(
            f"report figure: cannot embed a {type(fig).__name__}; give a "
            "matplotlib Figure, a .png/.svg path or PNG bytes"
        )
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _num(v: Any, fmt: str = ".5g") -> str:
    if v is None:
        return "–"
    try:
        f = float(v)
    except (TypeError, ValueError):
        return _e(v)
    return "–" if not math.isfinite(f) else format(f, fmt)


@dataclass
class HtmlReport:
    """An HTML document built section by section; ``html()`` gives the page, ``write(path)``
    writes it. ``command``: the command line that produced the result; ``inputs``: the
    files it read (shown by name with their folder)."""

    title: str
    command: str | None = None
    inputs: Sequence[str | Path] = ()
    warnings: list[str] = field(default_factory=list)
    parts: list[str] = field(default_factory=list)
    n_figures: int = 0

    # ------------------------------------------------------------------ building blocks
    def heading(self, text: str) -> HtmlReport:
        self.parts.append(f"<h2>{_e(text)}</h2>")
        return self

    def text(self, text: str, *, pre: bool = False) -> HtmlReport:
        self.parts.append(f"<pre>{_e(text)}</pre>" if pre else f"<p>{_e(text)}</p>")
        return self

    def table(
        self,
        header: Sequence[str],
        rows: Iterable[Sequence[Any]],
        *,
        low: Iterable[tuple[int, int]] = (),
        formats: Mapping[int, str] | None = None,
    ) -> HtmlReport:
        """A table; numbers (int/float, None as –) right-aligned, with 5 significant digits
        or ``formats[column]``; ``low``: (row, column) cells to mark."""
        low = set(low)
        formats = formats or {}
        out = [
            "<table><thead><tr>"
            + "".join(f"<th>{_e(h)}</th>" for h in header)
            + "</tr></thead><tbody>"
        ]
        for i, row in enumerate(rows):
            cells = []
            for j, v in enumerate(row):
                cls = "num" if isinstance(v, (int, float)) or v is None else ""
                if (i, j) in low:
                    cls += " low"
                c = f' class="{cls.strip()}"' if cls.strip() else ""
                t = _num(v, formats.get(j, ".5g")) if cls.startswith("num") else _e(v)
                cells.append(f"<td{c}>{t}</td>")
            out.append("<tr>" + "".join(cells) + "</tr>")
        out.append("</tbody></table>")
        self.parts.append("".join(out))
        return self

    def parameters(
        self, rows: Iterable[tuple[str, float, float | None, str]], *, std_label: str = "std"
    ) -> HtmlReport:
        """(name, value, std, unit) rows as value ± std (2 significant digits), unit,
        relative std 100 σ/|value| %; a relative std over :data:`POOR_RELATIVE_STD` %
        (a parameter the data hardly determine) is marked."""
        body, low = [], []
        for i, (name, v, s, unit) in enumerate(rows):
            sf = float(s) if s is not None else math.nan
            rel = _rel(v, s)
            if rel is not None and rel > POOR_RELATIVE_STD:
                low.append((i, 4))
            body.append((name, float(v), sf if math.isfinite(sf) else None, unit or "", rel))
        return self.table(
            ("parameter", "value", f"± {std_label}", "unit", "relative std [%]"),
            body,
            low=low,
            formats={2: ".2g", 4: ".3g"},
        )

    def fit_percent(
        self, fp: Mapping[str, Mapping[str, float | None]], title: str | None = None
    ) -> HtmlReport:
        """fit % per log (rows) and signal (columns); values under :data:`LOW_FIT_PERCENT`
        marked."""
        if title:
            self.heading(title)
        signals = list(dict.fromkeys(k for d in fp.values() for k in d))
        rows, low = [], []
        for i, (log, d) in enumerate(fp.items()):
            row: list[Any] = [Path(str(log)).name]
            for j, s in enumerate(signals, start=1):
                v = d.get(s)
                row.append(None if v is None else float(v))
                if v is not None and float(v) < LOW_FIT_PERCENT:
                    low.append((i, j))
            rows.append(row)
        self.table(
            ["log"] + [f"{s} fit [%]" for s in signals],
            rows,
            low=low,
            formats={j: ".1f" for j in range(1, len(signals) + 1)},
        )
        return self

    def figures(self, figs: Iterable[Any], captions: Sequence[str] | None = None) -> HtmlReport:
        """Embed figures (see :func:`figure_data_uri`); a path's caption is its file name."""
        figs = list(figs)
        for k, f in enumerate(figs):
            cap = (
                captions[k]
                if captions is not None and k < len(captions)
                else Path(f).name
                if isinstance(f, (str, Path))
                else f"figure {self.n_figures + 1}"
            )
            self.n_figures += 1
            self.parts.append(
                f'<figure><img src="{figure_data_uri(f)}" alt="{_e(cap)}" '
                f'id="figure-{self.n_figures}"><figcaption>{_e(cap)}</figcaption></figure>'
            )
        return self

    # ------------------------------------------------------------------ output
    def html(self) -> str:
        from flexarm.version import __version__

        now = _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M:%S %Z")
        meta = [
            (
                "command",
                f"<code>{_e(self.command)}</code>"
                if self.command
                else "(not run from the command line)",
            ),
            ("flexarm", _e(__version__)),
            ("written", _e(now)),
        ]
        if self.inputs:
            meta.append(("inputs", "<br>".join(_input(p) for p in self.inputs)))
        head = "".join(f"<tr><td>{k}</td><td>{v}</td></tr>" for k, v in meta)
        if self.warnings:
            warn = (
                '<div class="warnings" id="warnings"><h2>Warnings</h2><ul>'
                + "".join(f"<li>{_e(w)}</li>" for w in self.warnings)
                + "</ul></div>"
            )
        else:
            warn = '<p class="ok" id="warnings">No warnings.</p>'
        return (
            '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            '<meta name="viewport" content="width=device-width, initial-scale=1">'
            f'<meta name="generator" content="flexarm {_e(__version__)}">'
            f"<title>{_e(self.title)}</title><style>{_CSS}</style></head><body>\n"
            f'<h1>{_e(self.title)}</h1>\n<table class="meta">{head}</table>\n{warn}\n'
            + "\n".join(self.parts)
            + "\n</body></html>\n"
        )

    def write(self, path: str | Path, *, overwrite: bool = False) -> Path:
        """Write the page to ``path`` (atomically; an existing file only with ``overwrite``)."""
        return write_text(path, self.html(), overwrite=overwrite)


def _input(p: str | Path) -> str:
    """An input by name, its folder beside it (a built-in scenario's name alone)."""
    p = Path(str(p))
    folder = f" <small>({_e(p.parent)})</small>" if str(p.parent) != "." else ""
    return f"<code>{_e(p.name)}</code>{folder}"


# ---------------------------------------------------------------------- fit / validate
def fit_report(
    result: Any,
    *,
    figures: Iterable[Any] = (),
    command: str | None = None,
    inputs: Sequence[str | Path] | None = None,
    fit_percent: Mapping[str, Mapping] | None = None,
    extra_fit_percent: Mapping[str, Mapping] | None = None,
) -> HtmlReport:
    """The report of a time-domain fit (:class:`~flexarm.identification.time_domain.result.
    FitResult`): the servo rig's (its ``stages["servo_rig"]``: parameters ± HAC std with
    units, derived values, sensor delays, fit % per log and signal, status and warnings; the
    rig engine's own result is taken too) or the general engine's (each free scenario path
    with its template value, fitted value ± std, fit %).
    ``fit_percent``: the fit % to show instead of the result's own (the general fit's
    whole-log prediction when it was made separately); ``extra_fit_percent``: further fit %
    tables by title (held-out windows, the fit without friction)."""
    if hasattr(result, "space") and hasattr(result, "result"):  # the servo rig engine's own
        result = result.result()
    rig = result.stages.get("servo_rig")  # the servo rig's record (report.as_fit_result)
    if rig is None:  # the general engine's FitResult
        rep = HtmlReport(
            f"flexarm fit: {result.scenario.name}",
            command,
            list(inputs or ()),
            list(result.warnings),
        )
        if not result.converged:
            m = result.message
            rep.warnings.insert(
                0, m if m.upper().startswith("NOT CONVERGED") else f"not converged: {m}"
            )
        rep.heading("Status").text(result.message)
        rep.heading("Fitted parameters (SI units of the scenario)")
        if "std_source" in result.stages:
            rep.text(f"std: {result.stages['std_source']}.")
        rep.table(
            ("parameter", "template", "fitted", "± std", "relative std [%]"),
            [
                (
                    p,
                    result.template[p],
                    result.params[p],
                    result.std.get(p),
                    _rel(result.params[p], result.std.get(p)),
                )
                for p in result.free
            ],
            formats={3: ".2g", 4: ".3g"},
        )
        fp = fit_percent or result.prediction.get("fit_percent") or result.fit_percent
        rep.fit_percent(fp, "Fit % (whole-log prediction)")
    else:  # the servo rig's FitResult
        eng = result.engine_result
        logs = (
            [getattr(g, "path", None) or g.name for g in eng.logs]
            if eng is not None
            else list(result.fit_percent)
        )
        rep = HtmlReport(
            "flexarm fit: " + ", ".join(Path(str(n)).name for n in logs),
            command,
            list(inputs if inputs is not None else logs),
            list(result.warnings),
        )
        if not result.converged:
            rep.warnings.insert(0, result.message)
        st = rig.get("settings", {})
        rep.heading("Status").text(
            f"{result.message}. Mode {st.get('mode')}, joint friction "
            f"{'on' if st.get('friction') else 'off'}, {result.seconds:.1f} s."
        )
        rep.heading("Fitted parameters")
        units = rig.get("units", {})
        rep.parameters(
            ((k, v, result.std.get(k), units.get(k, "")) for k, v in result.params.items()),
            std_label="std (bootstrap)" if "bootstrap" in result.stages else "std (HAC)",
        )
        rep.text(
            f"std: {result.stages['std_source']}."
            if "std_source" in result.stages
            else "std: Newey–West (HAC) sandwich standard deviations (the residuals are "
            "autocorrelated); a local linearisation that ignores the jumps of "
            "stick-slip and any bias of the model structure."
        )
        if rig.get("derived"):
            rep.heading("Derived values")
            rep.table(("quantity", "value [SI]"), list(rig["derived"].items()))
        rep.heading("Sensor delays")
        rep.table(("signal", "delay [samples]"), list(rig.get("delays_samples", {}).items()))
        rep.fit_percent(fit_percent or result.fit_percent, "Fit % per log and signal")
    for title, fp in (extra_fit_percent or {}).items():
        rep.fit_percent(fp, title)
    figs = list(figures)
    if figs:
        rep.heading("Figures: measured and simulated")
        rep.figures(figs)
    return rep


def validate_report(
    result: Mapping[str, Any],
    *,
    scenario: str | None = None,
    figures: Iterable[Any] = (),
    command: str | None = None,
    inputs: Sequence[str | Path] = (),
) -> HtmlReport:
    """The report of a validation (the dict of :func:`flexarm.identification.validate`
    or of the CLI's general path): fit % per log and signal of the scenario as given and,
    after a friction refit, the refitted friction ± std and the fit % again."""
    name = scenario or result.get("scenario") or "scenario"
    rep = HtmlReport(
        f"flexarm validate: {Path(str(name)).name}",
        command,
        list(inputs),
        list(result.get("warnings", [])),
    )
    rep.fit_percent(result["fit_percent"], "Fit % per log and signal (parameters fixed)")
    low = [
        f"{Path(str(log)).name}: fit {v:.1f} % on {s} is low"
        for log, d in result["fit_percent"].items()
        for s, v in d.items()
        if v is not None and v < LOW_FIT_PERCENT
    ]
    rep.warnings += low
    refit = result.get("refit")
    if refit:
        rep.warnings += list(refit.get("warnings", []))
        rep.heading(
            f"Friction refitted on {refit.get('window_s')} s of "
            f"{Path(str(refit.get('log', ''))).name}"
        )
        rep.table(
            ("parameter", "scenario", "refitted", "± std", "relative std [%]"),
            [
                (p, refit["template"][p], v, refit["std"].get(p), _rel(v, refit["std"].get(p)))
                for p, v in refit["params"].items()
            ],
            formats={3: ".2g", 4: ".3g"},
        )
        rep.fit_percent(refit["fit_percent"], "Fit % with the refitted friction")
    figs = list(figures)
    if figs:
        rep.heading("Figures: measured and predicted")
        rep.figures(figs)
    return rep


def _rel(v: Any, s: Any) -> float | None:
    try:
        v, s = float(v), float(s)
    except (TypeError, ValueError):
        return None
    return 100 * s / abs(v) if v and math.isfinite(s) else None


# ---------------------------------------------------------------------- design
def design_report(
    design: Any,
    *,
    figures: Iterable[Any] = (),
    command: str | None = None,
    inputs: Sequence[str | Path] = (),
    comparison: Any = None,
) -> HtmlReport:
    """The report of a controller design (:class:`flexarm.design.result.Design`): method,
    the rig's scenario, the designed ``[controller]`` table, the linear part (poles of
    its state matrix, or the transfer function), the method's figures in ``design.info``
    (numbers and short lists as a table, longer structures as JSON text), the warnings,
    and ``figures``. ``comparison``: the side-by-side prediction as one table, one row
    per controller: a sequence of row dicts, a mapping controller → row dict, or an object
    with such a mapping as ``.rows`` (and ``.warnings``, added to the report's); nested
    dicts become dotted columns (``median.hub_error_counts``)."""
    import json

    sc = design.scenario
    rep = HtmlReport(
        f"flexarm design --method {design.method}: {sc.name}",
        command,
        list(inputs),
        list(design.warnings),
    )
    rep.heading("Designed controller")
    ctrl = sc.model_dump(mode="json", exclude_none=True).get("controller", {})
    rep.table(("field", "value"), [(k, _short(v)) for k, v in _flatten(ctrl)])
    lin = design.controller
    if lin is not None:
        rep.heading("Linear part")
        rep.text(_lti_text(lin), pre=True)
    if design.info:
        rep.heading("Design figures")
        scalars = [
            (k, v)
            for k, v in _flatten(design.info)
            if not isinstance(v, (dict, list))
            or (
                isinstance(v, list)
                and len(v) <= 8
                and all(not isinstance(x, (dict, list)) for x in v)
            )
        ]
        rep.table(("quantity", "value"), [(k, _short(v)) for k, v in scalars])
        rest = {
            k: v for k, v in design.info.items() if k not in {s.split(".")[0] for s, _ in scalars}
        }
        if rest:
            rep.text(json.dumps(rest, indent=1, default=str)[:20000], pre=True)
    if comparison is not None:
        rep.warnings += list(getattr(comparison, "warnings", []) or [])
        rows = getattr(comparison, "rows", comparison)
        if isinstance(rows, Mapping):
            rows = [{"controller": name, **row} for name, row in rows.items()]
        rows = [dict(_flatten(r)) for r in rows]
        cols = list(dict.fromkeys(k for row in rows for k in row))
        rep.heading("Prediction: logged controller and design")
        rep.table(cols, [[_short(row.get(c)) for c in cols] for row in rows])
    figs = list(figures)
    if figs:
        rep.heading("Figures")
        rep.figures(figs)
    return rep


def _flatten(d: Mapping[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    out = []
    for k, v in d.items():
        name = f"{prefix}.{k}" if prefix else str(k)
        if isinstance(v, Mapping):
            out += _flatten(v, name)
        else:
            out.append((name, v))
    return out


def _short(v: Any) -> Any:
    """Numbers as they are (the table formats them); lists with 5 significant digits."""
    if v is None:
        return None
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, (int, float)):
        return v
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_short_item(x) for x in v) + "]"
    return str(v)


def _short_item(x: Any) -> str:
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(_short_item(y) for y in x) + "]"
    if isinstance(x, float):
        return _num(x)
    return str(x)


def _lti_text(sys: Any) -> str:
    """A python-control system in words: its class, sampling period and poles; a mapping of
    named systems (the nested loops' G_cm1, G_cm2, G_cb, N) one after the other."""
    import numpy as np

    if isinstance(sys, dict):
        return "\n\n".join(f"{name}: {_lti_text(part)}" for name, part in sys.items())
    lines = [f"{type(sys).__name__}, dt = {getattr(sys, 'dt', None)} s"]
    try:
        p = np.asarray(sys.poles())
        lines.append("poles: " + ", ".join(f"{z.real:.5g}{z.imag:+.5g}j" for z in p))
        if getattr(sys, "dt", None):
            lines.append("|poles| (discrete; < 1 stable): " + ", ".join(f"{abs(z):.5g}" for z in p))
    except Exception as exc:  # a law without poles (e.g. a static gain of zero order)
        lines.append(f"poles: not available ({exc})")
    lines.append(str(sys))
    return "\n".join(lines)

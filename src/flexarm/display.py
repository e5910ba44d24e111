"""How results read: one table for every result's ``__repr__`` (terminal, ≤ 80 columns) and
``_repr_html_`` (a compact HTML table in a notebook).

A result builds a :class:`Table` (a title, an optional header, rows of cells, notes) and
returns ``table.text()`` from ``__repr__`` and ``table.html()`` from ``_repr_html_``. The
module imports nothing of flexarm, so every layer (sim, identification, design, analysis)
can use it::

    def _table(self) -> Table:
        return Table("SimulationResult", [("samples", 2001), ("duration", 2.0, "s")])

    def __repr__(self):
        return self._table().text()

    def _repr_html_(self):
        return self._table().html()

Numbers are written by :func:`fmt`: four significant digits (``%.4g``), complex as
``a±bj``, ``None`` and NaN as ``–``. The text form never cuts a cell: when the columns do
not fit the width, each row is stacked as ``header: value`` lines, wrapped.
"""

from __future__ import annotations

import html
import math
import textwrap
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from numbers import Complex, Real

__all__ = ["Table", "fmt"]

#: the width of a terminal that the text form keeps within
WIDTH = 80


def fmt(value: object, digits: int = 4) -> str:
    """A cell as text: numbers with ``digits`` significant digits, complex as ``a±bj``,
    ``None``/NaN as ``–``, sequences as their items joined by ``, ``."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, Real):
        v = float(value)
        return "–" if math.isnan(v) else f"{v:.{digits}g}"
    if isinstance(value, Complex):
        z = complex(value)
        sign = "-" if z.imag < 0 else "+"
        return f"{z.real:.{digits}g}{sign}{abs(z.imag):.{digits}g}j"
    if isinstance(value, str):
        return value
    if isinstance(value, Iterable):
        return ", ".join(fmt(v, digits) for v in value)
    return str(value)


@dataclass(frozen=True)
class Table:
    """A titled table: ``rows`` of cells (numbers, text, ``None``), an optional ``header``
    (one name per column) and ``notes`` (sentences under the table)."""

    title: str
    rows: Sequence[Sequence[object]]
    header: Sequence[str] | None = None
    notes: Sequence[str] = field(default_factory=tuple)

    def _cells(self) -> list[list[str]]:
        return [[fmt(c) for c in row] for row in self.rows]

    def text(self, width: int = WIDTH) -> str:
        """The table as plain text within ``width`` columns: aligned columns when they fit,
        otherwise every row stacked as ``name: value`` lines (nothing is cut)."""
        cells = self._cells()
        ncol = max([len(r) for r in cells] + [len(self.header or ())] + [0])
        rows = [r + [""] * (ncol - len(r)) for r in cells]
        head = list(self.header) + [""] * (ncol - len(self.header)) if self.header else None
        lines = [self.title]
        allrows = ([head] if head else []) + rows
        widths = [max(len(r[k]) for r in allrows) for k in range(ncol)] if allrows else []
        lead = sum(widths[:-1]) + 2 * ncol if ncol else 0  # where the last column starts
        if 2 + sum(widths) + 2 * max(ncol - 1, 0) <= width or (ncol and width - lead >= 30):
            # aligned columns; the last one wrapped when it is too long
            last = max(width - lead, 1)
            for i, r in enumerate(allrows):
                cols = zip(r[:-1], widths[:-1], strict=True)
                first = "  " + "  ".join(c.ljust(w) for c, w in cols)
                first = first + "  " if ncol > 1 else first
                parts = textwrap.wrap(r[-1], last, break_on_hyphens=False) or [""]
                lines.append((first + parts[0]).rstrip())
                lines.extend(" " * len(first) + p for p in parts[1:])
                if head and i == 0:
                    lines.append("  " + "  ".join("-" * min(w, last) for w in widths))
        else:  # stack: one block per row, every cell on its own wrapped line
            names = head or [""] * ncol
            for r in rows:
                text = [f"{n}: {c}" if n else c for n, c in zip(names, r, strict=True) if c or n]
                for k, t in enumerate(text):
                    ind = "  " if k == 0 else "    "
                    lines.extend(
                        textwrap.wrap(
                            t,
                            width,
                            initial_indent=ind,
                            subsequent_indent=ind + "  ",
                            break_on_hyphens=False,
                        )
                        or [""]
                    )
        for n in self.notes:
            lines.extend(
                textwrap.wrap(n, width, initial_indent="  note: ", subsequent_indent="        ")
            )
        return "\n".join(lines)

    def html(self) -> str:
        """The table as a compact HTML ``<table>`` (the title as its caption, notes in a
        last row), escaped."""
        e = html.escape
        out = [
            '<table class="flexarm" style="font-size:small;border-collapse:collapse">',
            f'<caption style="text-align:left;font-weight:bold">{e(self.title)}</caption>',
        ]
        if self.header:
            out.append(
                "<thead><tr>" + "".join(f"<th>{e(h)}</th>" for h in self.header) + "</tr></thead>"
            )
        out.append("<tbody>")
        ncol = max([len(r) for r in self.rows] + [len(self.header or ())] + [1])
        for row in self._cells():
            tds = (
                [
                    f"<th style='text-align:left'>{e(row[0])}</th>"
                    if not self.header
                    else f"<td>{e(row[0])}</td>"
                ]
                if row
                else []
            )
            tds += [f"<td>{e(c)}</td>" for c in row[1:]]
            out.append("<tr>" + "".join(tds) + "</tr>")
        for n in self.notes:
            out.append(f"<tr><td colspan='{ncol}'><em>{e(n)}</em></td></tr>")
        out.append("</tbody></table>")
        return "".join(out)


def fit_percent_lines(fit_percent: dict, digits: int = 1) -> list[str]:
    """One line per log of a ``fit_percent`` mapping (log key → signal → fit %):
    ``key: signal 98.1, signal 80.3`` (``–`` where the log lacks the signal); the notes of
    the fit and prediction results' tables."""
    out = []
    for key, per in fit_percent.items():
        cells = ", ".join(
            f"{sig} {'–' if v is None else f'{float(v):.{digits}f}'}" for sig, v in per.items()
        )
        out.append(f"fit % {key}: {cells}")
    return out


def parameter_rows(values: dict, std: dict, units: dict | None = None) -> list[tuple]:
    """Rows ``(name, value, ± std, std %, unit)`` of fitted parameters (``std`` missing or
    NaN: ``–``); the body of the fit results' tables."""
    rows = []
    for k, v in values.items():
        s = std.get(k)
        s = None if s is None or (isinstance(s, float) and math.isnan(s)) else float(s)
        rel = None if s is None or not v else 100.0 * s / abs(float(v))
        rows.append((k, float(v), s, rel, (units or {}).get(k, "")))
    return rows

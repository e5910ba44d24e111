"""The result of a controller design: the rig's scenario with the designed ``[controller]``,
the linear part as a python-control object, and the design's figures.

One class for every method (``lqr``, ``place``, ``nested``, ``tune``); ``write`` puts

* ``design.toml``: the rig's scenario with the designed ``[controller]`` (a scenario file:
  ``flexarm simulate DIR/design.toml`` runs it, ``flexarm export-c DIR`` exports it);
* ``design.json``: method, options, the figures in ``info``, the warnings and the gate's
  ``verdict`` (:mod:`flexarm.design.gate`: ``"stable"``, what failed, or ``null`` when the
  design was not checked);

through the one atomic writer (:mod:`flexarm.io.write`): nothing is overwritten unless asked.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flexarm.io.write import write_each, write_json, write_toml

__all__ = ["Design"]


@dataclass
class Design:
    """``method``: how it was designed; ``scenario``: the rig with the designed controller
    (a :class:`flexarm.specs.scenario.Scenario`); ``controller``: its linear part as a
    python-control ``StateSpace`` / ``TransferFunction`` with ``dt`` (None where the law has
    no single linear part); ``info``: method-specific figures (gains, poles, costs; JSON
    values); ``warnings``: what to check before running it on the rig; ``verdict``: the
    gate's (:func:`flexarm.design.gate.design_checked`): ``"stable"``, what failed, or None
    (not checked); ``gate``: the gate's figures (unstable count, plants at the limit, the
    share allowed); ``comparison``: the :class:`~flexarm.design.compare.Comparison` it was
    checked on (not written here; ``flexarm design`` writes compare.json)."""

    method: str
    scenario: Any
    controller: Any = None
    info: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    verdict: str | None = None
    gate: dict[str, Any] | None = None
    comparison: Any = field(default=None, repr=False, compare=False)

    @property
    def stable(self) -> bool:
        """Whether the gate's verdict is ``"stable"`` (False when not checked)."""
        return self.verdict == "stable"

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "scenario": self.scenario.name,
            "verdict": self.verdict,
            "gate": self.gate,
            "info": self.info,
            "warnings": list(self.warnings),
        }

    def summary(self) -> str:
        """A few lines for the terminal: the method, the verdict (with the unstable count
        over the drawn plants and the plants at the limit) and the warnings."""
        v = self.verdict if self.verdict is not None else "not checked"
        lines = [f"{self.method} design of {self.scenario.name}: verdict {v}"]
        g = self.gate
        if g is not None:
            unit = f" {g['limit_unit']}" if g.get("limit_unit") else ""  # V or A
            lim = "" if g.get("limit") is None else f" ±{g['limit']:g}{unit}"
            lines.append(
                f"  nominal plant {'stable' if g['nominal_stable'] else 'UNSTABLE'}"
                + (f"{', reaches the' + lim + ' limit' if g['nominal_limit_reached'] else ''}")
                + (
                    f"; drawn plants: {g['unstable']}/{g['n_plants']} unstable, "
                    f"{g['limit_reached']}/{g['n_plants']} reach the{lim} limit (at most "
                    f"{100 * g['max_unstable_share']:g} % allowed)"
                    if g["n_plants"]
                    else ""
                )
            )
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def _table(self):
        from flexarm.display import Table

        v = self.verdict if self.verdict is not None else "not checked"
        rows: list[tuple] = [("method", self.method), ("rig", self.scenario.name), ("verdict", v)]
        c = self.controller
        if c is not None:
            rows.append(
                (
                    "controller",
                    f"{type(c).__name__}: {c.ninputs} in, {c.noutputs} "
                    f"out, {getattr(c, 'nstates', 0)} states, dt {c.dt}",
                )
            )
        g = self.gate
        if g is not None and g.get("n_plants"):
            rows.append(("unstable plants", f"{g['unstable']}/{g['n_plants']}"))
            rows.append(("plants at the limit", f"{g['limit_reached']}/{g['n_plants']}"))
        for k in ("model", "step"):
            for kk, vv in (self.info.get(k) or {}).items():
                if isinstance(vv, (int, float, str)) or (isinstance(vv, list) and len(vv) <= 4):
                    rows.append((f"{k} {kk}", vv))
        return Table(
            f"Design ({self.method}) of {self.scenario.name}",
            rows,
            notes=[f"warning: {w}" for w in self.warnings],
        )

    def __repr__(self) -> str:
        return self._table().text()

    def _repr_html_(self) -> str:
        return self._table().html()

    def require_stable(self, accept_unstable: bool = False) -> Design:
        """This design, or :class:`flexarm.errors.UnstableDesignError` when its verdict is
        not ``"stable"`` (not checked included) and ``accept_unstable`` is False."""
        if self.stable or accept_unstable:
            return self
        from flexarm.errors import UnstableDesignError

        why = self.verdict if self.verdict is not None else "not checked by the design gate"
        raise UnstableDesignError(
            f"the {self.method} design is not safe to run: {why}",
            design=self,
            fix="pass accept_unstable (--accept-unstable) to keep it",
        )

    def write(self, directory: str | Path, *, overwrite: bool = False) -> list[Path]:
        """Write ``design.toml`` and ``design.json`` into ``directory`` (created)."""
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        data = self.scenario.model_dump(mode="json", exclude_none=True)
        return write_each(  # both tried: a full disk at one keeps the other (rescued)
            lambda: write_toml(d / "design.toml", data, overwrite=overwrite),
            lambda: write_json(d / "design.json", self.to_dict(), overwrite=overwrite),
        )

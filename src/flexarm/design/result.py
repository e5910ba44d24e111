"""The result of a controller design: the rig's scenario with the designed ``[controller]``,
the linear part as a python-control object, and the design's figures.

One class for every method (``lqr``, ``place``, ``nested``, ``tune``); ``write`` puts

* ``design.toml``: the rig's scenario with the designed ``[controller]`` (a scenario file:
  ``flexarm simulate DIR/design.toml`` runs it, ``flexarm export-c DIR`` exports it);
* ``design.json``: method, options, the figures in ``info`` and the warnings;

through the one atomic writer (:mod:`flexarm.io.write`): nothing is overwritten unless asked.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flexarm.io.write import write_json, write_toml

__all__ = ["Design"]


@dataclass
class Design:
    """``method``: how it was designed; ``scenario``: the rig with the designed controller
    (a :class:`flexarm.specs.scenario.Scenario`); ``controller``: its linear part as a
    python-control ``StateSpace`` / ``TransferFunction`` with ``dt`` (None where the law has
    no single linear part); ``info``: method-specific figures (gains, poles, costs; JSON
    values); ``warnings``: what to check before running it on the rig."""

    method: str
    scenario: Any
    controller: Any = None
    info: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"method": self.method, "scenario": self.scenario.name, "info": self.info,
                "warnings": list(self.warnings)}

    def write(self, directory: str | Path, *, overwrite: bool = False) -> list[Path]:
        """Write ``design.toml`` and ``design.json`` into ``directory`` (created)."""
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        data = self.scenario.model_dump(mode="json", exclude_none=True)
        return [write_toml(d / "design.toml", data, overwrite=overwrite),
                write_json(d / "design.json", self.to_dict(), overwrite=overwrite)]

"""Errors shared across layers (kept at the bottom so every layer may raise them)."""


class SimulationDiverged(RuntimeError):
    """A closed loop whose state became non-finite or left the plausible range; the
    message says when and which signal or state variable."""

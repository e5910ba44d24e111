"""Errors shared across layers (kept at the bottom so every layer may raise them)."""


class SimulationDiverged(RuntimeError):
    """A closed loop whose state became non-finite or left the plausible range; the
    message says when and which signal or state variable."""


class OutputExistsError(FileExistsError):
    """A writer (:mod:`flexarm.io.write`) refused to replace an existing file; the message
    names it (pass ``overwrite=True``, on the command line ``--overwrite``)."""


class FitInterrupted(Exception):
    """A fit stopped by the user (Ctrl-C).  ``.result`` is the best result so far, with the
    normal fit result's writing methods (``to_dict``, ``to_json``, ``write_scenario``,
    ``plots``, ``summary``), or ``None`` when nothing was evaluated yet."""

    def __init__(self, result=None, message: str = "fit interrupted by the user"):
        super().__init__(message)
        self.result = result

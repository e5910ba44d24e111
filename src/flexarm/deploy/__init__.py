"""Deploying a designed controller on a real-time target: C99 code of a scenario's
``[controller]`` (:mod:`flexarm.deploy.c_export`, ``flexarm export-c``)."""

from flexarm.deploy.c_export import CCode, ExportError, export_c, generate_c

__all__ = ["CCode", "ExportError", "export_c", "generate_c"]

"""Controller design for a fitted rig: state feedback (``lqr``, ``place``), Feliu's nested
loops (``nested``) and gains tuned in simulation over the fit's uncertainty (``tune``)."""

from flexarm.design.result import Design

__all__ = ["Design"]

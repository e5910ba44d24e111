"""flexarm: model, identify, simulate and control flexible-link robot arms with joint friction."""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

__version__ = "0.1.0"

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

try:  # property tests (tests/test_properties_*.py): repeatable, bounded, no example database
    from hypothesis import settings

    settings.register_profile("flexarm", derandomize=True, database=None, deadline=None,
                              print_blob=True)
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "flexarm"))
except ImportError:  # the property test files skip themselves
    pass

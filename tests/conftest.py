import functools
import os
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# the CLI keeps JAX's compiled loops in the user's cache folder by default (issue #46); the
# suite writes nothing there unless FLEXARM_JAX_CACHE names a folder
os.environ.setdefault("FLEXARM_JAX_CACHE", "0")

import jax

jax.config.update("jax_enable_x64", True)

try:  # property tests (tests/test_*__properties.py): repeatable, bounded, no example database
    from hypothesis import settings

    settings.register_profile(
        "flexarm", derandomize=True, database=None, deadline=None, print_blob=True
    )
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "flexarm"))
except ImportError:  # the property test files skip themselves
    pass


# ------------------------------------------------------------------ the real lab logs
#: the repository root
ROOT = Path(__file__).resolve().parents[1]
#: the real lab logs: $FLEXARM_DATA, else ../shared/data beside the repository (absent in a
#: user's clone; tests that need them are marked ``rig`` and skip, naming this path)
DATA = Path(os.environ.get("FLEXARM_DATA") or ROOT.parent / "shared" / "data").resolve()


def skip_without_data(sub: str = "") -> Path:
    """``DATA / sub``, or skip the calling test saying where the logs were looked for."""
    path = DATA / sub
    if not path.exists():
        pytest.skip(
            f"real lab logs not found at {path} (set FLEXARM_DATA to the folder "
            "that holds rotary-rig/, two-link-rig/, motor-bench/)"
        )
    return path


#: the rotary-rig logs (../shared/data/rotary-rig: absent in a user's clone, present in CI)
ROTARY_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "rotary-rig"
ROTARY_FORMAT = Path(__file__).resolve().parents[1] / "examples" / "quanser-rotflex.toml"
#: the lab's data sheet (README of the data): geared voltage-driven servo, 0.45 m link
ROTARY_SHEET = dict(
    drive="voltage",
    gear_ratio=48.4,
    motor_constant=0.0107,
    armature_resistance=3.29,
    link_length=0.45,
    computation_delay=1,
    voltage_limit=10.0,
)  # the limit the tests' figures were measured at


@functools.cache
def _rotary_whole_fit(name: str):
    from flexarm.identification.time_domain import load_rig_log
    from flexarm.identification.time_domain.fit import fit

    return fit([load_rig_log(ROTARY_DATA / name, log_format=ROTARY_FORMAT)], **ROTARY_SHEET)


@pytest.fixture(scope="session")
def rotary_whole_fit():
    """``get(name)``: the servo-rig fit of one rotary-rig log on its whole length with the
    data sheet, one fit per log for the whole test session (the design, tuning and report
    tests share it; treat the result as read-only). Skips where ../shared is absent."""
    if not ROTARY_DATA.is_dir():
        pytest.skip(
            f"real rig logs not found at {ROTARY_DATA} (../shared is absent in a "
            "user's clone; CI has it)"
        )
    return _rotary_whole_fit


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_loops():
    """After each test module, JAX's in-memory caches of compiled loops are cleared: the
    suite compiles several hundred loops (each scenario, batch size and horizon its own),
    and keeping them all grew the one test process to 8 GiB at 70 % of the suite; the last
    clean run then crashed inside XLA's compiler (SIGSEGV) at 93 %. A module that uses a
    loop again recompiles it."""
    yield
    import gc

    jax.clear_caches()
    gc.collect()

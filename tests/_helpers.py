"""Shared builders for the tests."""

import shutil
import subprocess
import tomllib
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from flexarm.control.discrete import FunctionController
from flexarm.specs import builtin_scenarios, scenario_from_dict


def scenario_dict(name: str = "feliu-single-mass") -> dict:
    return tomllib.loads(builtin_scenarios()[name].read_text())


def scenario(name: str = "feliu-single-mass", **patch):
    """A built-in scenario with sections patched: patch(arm={'friction': {...}}) etc."""
    d = scenario_dict(name)
    for section, values in patch.items():
        _merge(d.setdefault(section, {}), values) if isinstance(values, dict) else d.__setitem__(
            section, values
        )
    return scenario_from_dict(d)


def _merge(d: dict, new: dict) -> None:
    for k, v in new.items():
        if (
            isinstance(v, dict)
            and isinstance(d.get(k), dict)
            and not {"model", "type", "drive"} & set(v)
        ):
            _merge(d[k], v)
        else:
            d[k] = v


def constant_command(u: float) -> FunctionController:
    """Open loop: the same command at every sample."""
    return FunctionController(
        lambda p, s, m, r: (s, jnp.reshape(p, (1,))), jnp.asarray(u), jnp.zeros(())
    )


# ----------------------------------------------------------------------------- generated C
#: a C compiler on PATH (None: the tests that compile the generated C skip)
CC = next((c for c in ("cc", "gcc", "clang") if shutil.which(c)), None)
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2"]

#: reads N, then per sample the measured and the reference values; prints u per line
C_DRIVER = r"""
#include <stdio.h>
#include "ctl.h"
int main(int argc, char **argv)
{
    double m[CTL_N_MEASURED + 1], r[CTL_N_REFERENCE + 1], u[CTL_N_U];
    long n, k;
    int i;
    ctl_state s;
    FILE *f;
    if (argc != 2 || !(f = fopen(argv[1], "r"))) return 2;
    if (fscanf(f, "%ld", &n) != 1) return 3;
    ctl_init(&s);
    for (k = 0; k < n; ++k) {
        for (i = 0; i < CTL_N_MEASURED; ++i) if (fscanf(f, "%lf", &m[i]) != 1) return 4;
        for (i = 0; i < CTL_N_REFERENCE; ++i) if (fscanf(f, "%lf", &r[i]) != 1) return 4;
        ctl_step(&s, m, r, u);
        for (i = 0; i < CTL_N_U; ++i) printf("%.17g%c", u[i], i + 1 < CTL_N_U ? ' ' : '\n');
    }
    fclose(f);
    return 0;
}
"""


def run_c(folder: Path, meas: dict, refs: dict) -> np.ndarray:
    """Compile ``folder``/ctl.c (``flexarm export-c --name ctl``) with :data:`C_DRIVER` and
    run it on the sequence (``meas`` then ``refs``, each name → samples): u (N, n_u)."""
    (folder / "driver.c").write_text(C_DRIVER)
    cols = [np.asarray(v) for v in meas.values()] + [np.asarray(v) for v in refs.values()]
    n = len(cols[0])
    rows = "\n".join(" ".join(repr(float(c[k])) for c in cols) for k in range(n))
    (folder / "input.txt").write_text(f"{n}\n{rows}\n")
    exe = folder / "driver"
    cp = subprocess.run(
        [CC, *CFLAGS, "-o", str(exe), str(folder / "driver.c"), str(folder / "ctl.c")],
        capture_output=True,
        text=True,
    )
    assert cp.returncode == 0, f"the generated C does not compile:\n{cp.stderr}"
    run = subprocess.run(
        [str(exe), str(folder / "input.txt")], capture_output=True, text=True, check=True
    )
    return np.loadtxt(run.stdout.splitlines(), ndmin=2)

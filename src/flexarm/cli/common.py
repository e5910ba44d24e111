"""What every command shares: the consoles, the one way to refuse (:func:`fail`), loading a
scenario, checking output paths before any work, the report writer and progress lines."""

from __future__ import annotations

import contextlib
import os
import tempfile
import threading
import time
from pathlib import Path
from typing import NoReturn

import typer
from rich.console import Console
from rich.markup import escape

console = Console()
err = Console(stderr=True)


#: the values of ``$FLEXARM_JAX_CACHE`` that turn the compilation cache off
CACHE_OFF = ("0", "off", "false", "no")


def cache_folder() -> Path | None:
    """Where the ``flexarm`` command keeps JAX's persistent compilation cache:
    ``$FLEXARM_JAX_CACHE`` where it names a folder, None (no cache) where it is ``0`` /
    ``off`` (or ``flexarm --no-jax-cache``), else ``jax/`` in the user's cache folder
    (``platformdirs.user_cache_dir("flexarm")`` where platformdirs is installed, else
    ``~/.cache/flexarm``)."""
    value = os.environ.get("FLEXARM_JAX_CACHE", "").strip()
    if value.lower() in CACHE_OFF:
        return None
    if value:
        return Path(value).expanduser()
    try:
        import platformdirs

        return Path(platformdirs.user_cache_dir("flexarm")) / "jax"
    except ImportError:
        return Path.home() / ".cache" / "flexarm" / "jax"


def enable_cache() -> None:
    """JAX's persistent compilation cache in :func:`cache_folder` (on by default, issue #46:
    a repeated command loads its compiled loops instead of compiling them; every
    compilation is stored), float64 either way; a folder that cannot be created leaves the
    command uncached. :data:`flexarm.distributed.CACHE_NOTE` records an abort of jaxlib
    0.10.2 while writing the two-link LQG replay (2026-11-28) that did not recur on
    2026-12-05 (two runs of tests/test_lqg.py's two-link LQG with every compilation cached);
    ``FLEXARM_JAX_CACHE=0`` or ``flexarm --no-jax-cache`` turn it off."""
    from flexarm.distributed import enable_compilation_cache

    folder = cache_folder()
    if folder is not None:
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError:
            folder = None
    if folder is None:
        os.environ["FLEXARM_JAX_CACHE"] = "0"  # float64 only (and no cache for workers)
        enable_compilation_cache()
        return
    enable_compilation_cache(folder, min_compile_seconds=0.0)


def fold(text: str) -> str:
    """A message as one line: its lines joined (after a colon by a space, else by "; "),
    runs of spaces made one."""
    out = ""
    for line in (" ".join(ln.split()) for ln in str(text).splitlines()):
        if line:
            out += line if not out else (" " if out.endswith(":") else "; ") + line
    return out


def fail(msg: str) -> NoReturn:
    """Refuse a bad input: ``error: MSG`` as one line on stderr, exit 2."""
    err.print(f"[bold red]error:[/] {escape(fold(msg))}", highlight=False, soft_wrap=True)
    raise typer.Exit(2)


def check_cluster(scheduler: str | None, workers: int | None) -> None:
    """``--scheduler`` / ``--workers`` checked before any work (the commands that run on
    Dask: ``fit-many``, ``design``); :func:`flexarm.distributed.client_for` checks the same
    values again when it starts the client."""
    if scheduler is not None and workers is not None:
        fail("give --scheduler or --workers, not both")
    if workers is not None and workers < 1:
        fail(f"--workers {workers}: give 1 or more")


def load(scenario: str):
    """A scenario (file or built-in name) with the model's own checks; a bad one is one
    line naming the field."""
    from flexarm.specs import ScenarioError, load_scenario

    try:
        sc = load_scenario(scenario)
        if sc.arm.kind == "single_link":  # the model's own checks (a proper, stable G_b, ...)
            from flexarm.models.single_link import SingleLinkModel

            SingleLinkModel.from_spec(sc.arm)
    except ScenarioError as exc:
        fail(str(exc))
    except ValueError as exc:
        fail(f"{scenario}: {exc}")
    return sc


def writable(option: str, path: Path, folder: Path) -> None:
    """``folder`` (where ``path`` will be made) must be a writable folder."""
    if not os.access(folder, os.W_OK | os.X_OK):
        fail(
            f"{option} {path}: cannot write into {folder} (permission denied); choose a "
            "folder you can write to"
        )


def _not_an_input(option: str, path: Path) -> None:
    """Refuse an output path that is (inside) an input of the run
    (:func:`flexarm.io.write.is_input`), --overwrite or not."""
    from flexarm.io.write import is_input

    src = is_input(path)
    if src is not None:
        fail(
            f"{option} {path}: is an input of this run ({src}); flexarm never writes over "
            "an input, even with --overwrite; give another output path"
        )


def check_dir_option(option: str, path: Path | None) -> None:
    """An output folder option: refuse, before any work, a path that is an existing file,
    lies below a file, or cannot be created or written (the folder itself may be missing:
    it is created with its parents)."""
    if path is None:
        return
    _not_an_input(option, path)
    if path.exists() and not path.is_dir():
        fail(
            f"{option} {path}: is a file, not a folder; give a folder name (flexarm writes "
            "several files into it), or move the file away"
        )
    anc = path
    while not anc.exists():
        if anc.parent == anc:
            break
        anc = anc.parent
    if not anc.is_dir():
        fail(
            f"{option} {path}: {anc} is a file, so the folder cannot be created there; "
            "give a path below a folder"
        )
    writable(option, path, anc)


def check_file_option(
    option: str, path: Path | None, overwrite: bool, example: str = "result.json"
) -> None:
    """An output file option: refuse, before any work, a folder, an existing file (unless
    --overwrite), a missing or non-folder parent, or a parent that cannot be written."""
    if path is None:
        return
    _not_an_input(option, path)
    if path.is_dir():
        fail(f"{option} {path}: is a folder, not a file; give a file name, e.g. {path / example}")
    if path.exists() and not overwrite:
        fail(f"{option} {path}: exists; pass --overwrite to replace it")
    parent = path.parent
    if not parent.exists():
        fail(
            f"{option} {path}: the folder {parent} does not exist; create it first "
            f"(mkdir -p {parent})"
        )
    if not parent.is_dir():
        fail(f"{option} {path}: {parent} is a file, not a folder; give a path in a folder")
    writable(option, path, parent)


def outdir(out: Path, overwrite: bool, option: str = "--out") -> Path:
    """An output folder, created; a non-empty one only with --overwrite; locked for this
    command (:func:`flexarm.io.write.output_folder`): a second run writing into it at the
    same time is refused."""
    from flexarm.errors import FlexarmError
    from flexarm.io.write import output_folder as _folder

    check_dir_option(option, out)
    try:
        return _folder(out, overwrite=overwrite)
    except FlexarmError as exc:
        if "holds files already" in str(exc):
            fail(f"{option} {out}: exists and is not empty; pass --overwrite to write into it")
        fail(f"{option} {exc}")


def command_line(ctx: typer.Context) -> str:
    """The running command as an equivalent ``flexarm ...`` line (for reports): its
    arguments and the options given on the command line (defaults left out), shell-quoted."""
    import shlex

    args, opts = [], []
    for prm in ctx.command.params:
        src = ctx.get_parameter_source(prm.name)
        if getattr(src, "name", None) != "COMMANDLINE":
            continue
        v = ctx.params[prm.name]
        vals = list(v) if isinstance(v, (list, tuple)) else [v]
        if prm.param_type_name == "argument":
            args += [str(x) for x in vals]
        elif getattr(prm, "is_flag", False):
            names = prm.opts if v else prm.secondary_opts
            opts += names[:1]
        else:
            for x in vals:
                opts += [prm.opts[0], str(x)]
    return shlex.join(["flexarm", str(ctx.info_name), *args, *opts])


@contextlib.contextmanager
def figure_folder(plots: Path | None, report: Path | None):
    """Where the figures go: --plots, else (a report needs them) a temporary folder removed
    after the report is written; None when neither is asked for."""
    if plots is not None or report is None:
        yield plots
    else:
        with tempfile.TemporaryDirectory(prefix="flexarm-report-") as d:
            yield Path(d)


def write_report(rep, path: Path | None, overwrite: bool) -> None:
    """Write an :class:`flexarm.analysis.html_report.HtmlReport` to --report."""
    from flexarm.errors import OutputExistsError

    try:
        rep.write(path, overwrite=overwrite)
    except (OutputExistsError, OSError) as exc:
        fail(f"--report {path}: {exc}")
    console.print(f"report: {escape(str(path))}")


def progress(status, message: str) -> None:
    """A long job's stage: on the status line, and as a plain line on stderr when that is
    not a terminal (a log file or a pipe: the status line is not drawn there); under
    :func:`working`, with the seconds since the job began."""
    if isinstance(status, Working):
        status.update(message)
        return
    status.update(message)
    if not err.is_terminal:
        err.print(message, highlight=False)


#: Seconds of work between two progress lines of a long job (issue #46 item 5).
HEARTBEAT_S = 5.0


class Working:
    """A long job's progress with its elapsed time (s since it began): each stage
    (:meth:`update`) as a line ``[  12.3 s] stage`` (on stderr where that is not a
    terminal; in a terminal above the status line, whose text ticks the seconds), and
    while one stage lasts, a line ``[  17.3 s] still: stage`` every :data:`HEARTBEAT_S`
    seconds, from a daemon thread. A job that ends (or fails) within :data:`HEARTBEAT_S`
    prints none of them: its lines are held until the job has run that long (a bad input
    stays one line)."""

    def __init__(self, status, label: str, every: float | None = None):
        self.status, self.message, self.label = status, label, label
        self.every = HEARTBEAT_S if every is None else every
        self.t0 = self.last = time.perf_counter()
        self._held: list[str] | None = []  # None once the lines go out as they come
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._beat, daemon=True)

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def _print(self, line: str) -> None:
        if err.is_terminal:
            self.status.console.print(escape(line), highlight=False)
        else:
            err.print(escape(line), highlight=False)

    def _line(self, text: str) -> None:
        line = f"[{self.elapsed():7.1f} s] {text}"
        if self._held is not None:
            self._held.append(line)
        else:
            self._print(line)

    def update(self, message: str) -> None:
        with self._lock:
            self.message, self.last = message, time.perf_counter()
            self.status.update(f"{message} ({self.elapsed():.0f} s)")
            self._line(message)

    def _beat(self) -> None:
        while not self._stop.wait(min(1.0, self.every)):
            with self._lock:
                self.status.update(f"{self.message} ({self.elapsed():.0f} s)")
                if self._held is not None and self.elapsed() >= self.every:
                    for line in self._held:
                        self._print(line)
                    self._held = None
                if time.perf_counter() - self.last >= self.every:
                    self.last = time.perf_counter()
                    self._line(f"still: {self.message}")

    def __enter__(self) -> Working:
        self._line(self.message)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        if exc[0] is None and self._held is None:
            self._line(f"done: {self.label}")


@contextlib.contextmanager
def working(label: str):
    """``console.status(label)`` as a :class:`Working`: the job's stages and, every
    :data:`HEARTBEAT_S` s of one stage, a line with the elapsed seconds."""
    with console.status(label) as status, Working(status, label) as w:
        yield w


def warn(message: str) -> None:
    """A warning line on stderr."""
    err.print(f"[yellow]warning:[/] {escape(message)}", highlight=False)


def fmt(c: list[float]) -> str:
    """Numbers as ``[a, b, c]`` with 6 significant digits."""
    return "[" + ", ".join(f"{x:.6g}" for x in c) + "]"


@contextlib.contextmanager
def guarded(*paths):
    """The run of one command (issue #25): its input files declared
    (:func:`flexarm.io.write.inputs`: no writer of the run may write over them, even with
    --overwrite) and SIGINT / SIGTERM handled by :func:`flexarm.io.write.interruptible`
    (a second signal does not break the writing of a best result).  ``paths``: input files
    or folders, or lists of them; ``None`` and built-in scenario names (not files) are
    skipped.  Yields the :class:`flexarm.io.write.Interruptible` state (``.signal``: the
    first signal's name, for a command that catches the interruption itself and exits
    128 + its number).  An interruption that reaches here ends the command with exit
    128 + the signal's number (130 for Ctrl-C, 143 for SIGTERM) and one line on stderr."""
    import signal as signal_mod

    from flexarm.errors import Interrupted
    from flexarm.io import write

    files = []
    for p in paths:
        for q in p if isinstance(p, (list, tuple)) else [p]:
            if q is not None and Path(q).exists():
                files.append(Path(q))

    def again(name: str) -> None:
        err.print(f"{name} again: finishing the writing of the result first", highlight=False)

    try:
        with write.interruptible(on_repeat=again) as state, write.inputs(files), write.run_scope():
            yield state
        name = state.signal or state.deferred
        if name is not None:  # a signal the command ran through: never exit 0
            err.print(f"interrupted by {name}", highlight=False)
            raise typer.Exit(128 + int(getattr(signal_mod.Signals, name)))
    except Interrupted as exc:
        err.print(f"interrupted by {exc.signal}", highlight=False)
        raise typer.Exit(128 + int(exc.number)) from None
    except KeyboardInterrupt:
        err.print("interrupted by SIGINT", highlight=False)
        raise typer.Exit(130) from None


def guarded_command(*names: str):
    """A command run inside :func:`guarded`, with the values of its parameters ``names``
    (input files, folders or lists of them) declared as the run's inputs."""
    import functools

    def deco(f):
        @functools.wraps(f)
        def run(*args, **kwargs):
            with guarded(*[kwargs.get(n) for n in names]):
                return f(*args, **kwargs)

        return run

    return deco


def distinct_outputs(*outputs: tuple[str, Path | None]) -> None:
    """A command's output files (option, path) checked together before any work
    (:func:`flexarm.io.write.check_outputs`): two options on one path (``--json o/a
    --scenario-out o/a``) or an output that is an input of the run are refused as one line;
    each file's own checks are :func:`check_file_option`'s."""
    from flexarm.errors import FlexarmError
    from flexarm.io.write import check_outputs

    try:
        check_outputs(outputs, overwrite=True)
    except FlexarmError as exc:
        fail(str(exc))


def output_folder(option: str, path: Path | None, overwrite: bool) -> Path | None:
    """A figure (or other output) folder, checked and created before any work by
    :func:`flexarm.io.write.output_folder`: a folder holding files only with --overwrite,
    never an input; refused as one line naming ``option``."""
    if path is None:
        return None
    from flexarm.errors import FlexarmError
    from flexarm.io.write import output_folder as _folder

    check_dir_option(option, path)
    try:
        return _folder(path, overwrite=overwrite)
    except FlexarmError as exc:
        fail(
            f"{option} {exc}".replace(
                "(pass overwrite=True, on the command line --overwrite)",
                "(pass --overwrite to write into it)",
            )
        )


def save_result(option: str, path: Path, data, overwrite: bool, writer=None) -> None:
    """The command's final write (:func:`flexarm.io.write.save_or_rescue`): written where
    asked, or, when that fails (a full disk, a vanished folder), next to it and said so in
    one ``error:`` line, exit 2 (the command did not do what was asked, but the result is
    kept); an input of the run is never written over (the rescue copy goes beside it)."""
    from flexarm.io.write import save_or_rescue

    saved = save_or_rescue(path, data, overwrite=overwrite, writer=writer)
    if saved.rescued:  # one line (not wrapped): the path must be copyable; not done: exit 2
        err.print(
            f"[bold red]error:[/] {escape(option + ': ' + saved.message())}",
            highlight=False,
            soft_wrap=True,
        )
        raise typer.Exit(2)

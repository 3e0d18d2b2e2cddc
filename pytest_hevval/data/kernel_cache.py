"""The compiled kernel's lifecycle: filling numba's cache, in the background or on request,
and what a run tells its user about it.

The core (:mod:`pytest_hevval.core.kernel`) chooses the path a record takes, numpy or the
compiled kernel, and dispatches to it; it writes no file, starts no process and says nothing.
Everything that acts on the disk or on the machine for the kernel's sake lives here instead:

* :func:`compile_all` (``hevval kernel --compile``) compiles every function into numba's
  on-disk cache now;
* :func:`start_background_compile` compiles it in a separate, low-priority process, detached
  from the run, with a lock file in the cache folder so that the workers of one run, or runs
  side by side, start one compile between them;
* :func:`expect` (the engine, before a spec) and :func:`finish_run` (both front ends, as a run
  ends) start that compile where the kernel would pay and its cache is cold; the core asks for
  one mid-run, when a process has lost more to numpy than compiling costs, through
  :func:`pytest_hevval.core.kernel.on_compile_wanted`, which importing this module sets;
* :func:`compile_note` and :func:`describe` are the sentences: the note at the end of a run
  that started a compile, and the line of ``hevval --version`` and ``hevval kernel``.

Why here, in ``data/``: this layer is where the package meets the disk for its inputs, and
numba's cache is one more of them, read by every run and filled when it pays. It sits above the
core, which may not import it (the core's contract in ``pyproject.toml``), and below scoring and
the front ends, which call it. The decision of *when* a compile pays stays in the core with
the rest of the path's economics (:data:`~pytest_hevval.core.kernel.KERNEL_LOAD_S`,
:data:`~pytest_hevval.core.kernel.NUMPY_EXTRA_S`, :func:`~pytest_hevval.core.kernel.kernel_for`);
this room reads those facts and acts on them.

``HEVVAL_BACKGROUND_COMPILE=0`` stops a run from starting a background compile.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

from ..core import kernel
from ..core.kernel import (
    COMPILED,
    KERNEL_ENV,
    KERNEL_LOAD_S,
    NUMPY_EXTRA_S,
    active_path,
    cache_folder,
    cached_functions,
)
from ..errors import HevvalError, MissingExtraError

__all__ = [
    "BACKGROUND_COMPILE_ENV",
    "COMPILE_LOCK_S",
    "FIRST_COMPILED",
    "active_path",
    "background_compile_started",
    "cache_folder",
    "cached_functions",
    "compile_all",
    "compile_note",
    "describe",
    "expect",
    "finish_run",
    "start_background_compile",
]

#: Environment variable that, set to 0, stops a run from starting a background compile (for a
#: job that must not leave a process behind; the test suite sets it for stable output).
BACKGROUND_COMPILE_ENV = "HEVVAL_BACKGROUND_COMPILE"
#: A background compile another process started is trusted for this long (seconds) before a
#: run starts its own: long enough for every function on a busy machine.
COMPILE_LOCK_S = 600.0

#: The order a background compile takes: what a run needs soonest and most often first (the
#: data-quality checks run before the scoring).
FIRST_COMPILED = (
    "quality_steps",
    "quality_runs",
    "main_pass",
    "lag_window",
    "fine_block_sums",
    "dtw_path",
)

_lock = threading.Lock()
# This process's background compile: "asked" once one was tried, "process" once one started.
_background: dict[str, Any] = {}


def _unloadable() -> MissingExtraError:
    reason = kernel.load_failure() or "unknown reason"
    return MissingExtraError(
        f"the compiled kernel cannot be loaded ({reason})",
        hint='install the extra: pip install "pytest-hevval[fast]"',
    )


def compile_all(order: tuple[str, ...] = COMPILED) -> dict[str, float]:
    """Compile every function of :data:`~pytest_hevval.core.kernel.COMPILED` (those of
    ``order`` first, in that order) into numba's on-disk cache, in seconds each.

    Each runs once through its wrapper on a small record
    (:func:`~pytest_hevval.core.kernel.sample_calls`), so numba compiles the signature a
    scoring run calls (float64, contiguous) and stores it; from then on the auto path takes the
    kernel for every record. Raises :class:`~pytest_hevval.errors.MissingExtraError` when numba
    cannot be loaded, and :class:`~pytest_hevval.errors.HevvalError` when the cache could not
    be written.
    """
    module = kernel.load()
    if module is None:
        raise _unloadable()
    calls = kernel.sample_calls(module)
    seconds: dict[str, float] = {}
    for name in dict.fromkeys([*order, *COMPILED]):
        started = time.perf_counter()
        calls[name]()
        seconds[name] = time.perf_counter() - started
    kernel.forget_cold_cache()
    missing = [name for name, cached in kernel.cached_functions().items() if not cached]
    if missing:
        raise HevvalError(
            f"compiled, but numba could not store {', '.join(missing)} in its cache "
            f"({kernel.cache_folder()})",
            key="NUMBA_CACHE_DIR",
            hint="set NUMBA_CACHE_DIR to a folder you can write to, then compile again",
        )
    return seconds


def expect(samples: int) -> None:
    """Before a piece of work of ``samples`` samples (a spec's signals times its record's
    length): where numpy would lose more on it alone than loading the kernel costs and numba's
    cache does not hold the kernel, start compiling it in the background now, so that it is
    ready for most of that work (the rest of the reading overlaps the compile)."""
    if samples * NUMPY_EXTRA_S["main_pass"] >= KERNEL_LOAD_S:
        _compile_if_cold()


def finish_run() -> None:
    """At the end of a run (every process that scored): if the kernel would have paid in it and
    numba's cache does not hold it, compile it in the background for the next runs. Imports
    nothing where the run never reached the kernel."""
    if kernel.numpy_seconds_lost() >= KERNEL_LOAD_S:
        _compile_if_cold()


def _on_auto_path() -> bool:
    """Whether ``HEVVAL_KERNEL`` leaves the choice to the run (False for a bad value, which the
    scoring reports with its hint)."""
    try:
        return kernel.requested_path() == "auto"
    except HevvalError:
        return False


def _compile_if_cold() -> None:
    if _on_auto_path() and kernel.numba_installed() and not kernel.cache_warm(COMPILED):
        # What every spec scores first, then the intervals (on by default), then the options.
        start_background_compile(FIRST_COMPILED)


def start_background_compile(first: tuple[str, ...] = ()) -> bool:
    """Compile the kernel into numba's cache in a separate low-priority process, ``first``
    first; True if this call started it.

    Once per process; and not while another process's compile of the same cache (a lock file
    in the cache folder, trusted for :data:`COMPILE_LOCK_S`) is under way. The run that starts
    it does not wait for it.
    """
    if os.environ.get(BACKGROUND_COMPILE_ENV, "").strip() == "0":
        return False
    with _lock:
        if _background:
            return False
        _background["asked"] = True
    folder = kernel.cache_folder()
    marker = _compile_marker()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if _compile_under_way():
            return False
        with contextlib.suppress(FileNotFoundError):
            marker.unlink()  # left by a compile that died
        descriptor = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        os.close(descriptor)
    except OSError:
        return False  # a folder numba could not write to either: stay on numpy
    order = [name for name in first if name in COMPILED]
    order += [name for name in COMPILED if name not in order]
    script = (
        "import os, sys\n"
        "if hasattr(os, 'nice'):\n"
        "    os.nice(10)\n"
        f"from {__name__} import compile_all\n"
        "try:\n"
        "    compile_all(tuple(sys.argv[2:]))\n"
        "finally:\n"
        "    os.unlink(sys.argv[1])\n"
    )
    try:
        process = _launch([sys.executable, "-c", script, str(marker), *order])
    except OSError:
        with contextlib.suppress(OSError):
            marker.unlink()
        return False
    _background["process"] = process
    return True


def _launch(command: list[str]) -> Any:
    """Start ``command`` detached from the run: no input, output dropped, its own session (so
    that ending the run, or Ctrl-C in its terminal, leaves the compile to finish)."""
    import subprocess

    return subprocess.Popen(
        command,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )


def _compile_marker() -> Path:
    return kernel.cache_folder() / ".hevval-compiling"


def _compile_under_way() -> bool:
    """Whether a background compile of this cache (this process's or another's) is running."""
    try:
        return time.time() - _compile_marker().stat().st_mtime < COMPILE_LOCK_S
    except OSError:
        return False


def background_compile_started() -> bool:
    """Whether this run's kernel is being compiled in the background: this process started it,
    or another process of the run did (a pytest-xdist worker, for the controller's note)."""
    if "process" in _background:
        return True
    return _on_auto_path() and _compile_under_way() and not kernel.cache_warm(COMPILED)


def compile_note() -> str | None:
    """A line for the end of a run's summary when this process started a background compile;
    None otherwise. Imports nothing."""
    if not background_compile_started():
        return None
    return (
        "hevval: numba's cache did not hold the compiled kernel, so this run scored on numpy; "
        "it is being compiled in the background for the next runs"
    )


def describe() -> str:
    """One line for ``hevval --version``: the active path and why."""
    path = kernel.requested_path()
    if path == "numpy":
        return f"kernel: numpy ({KERNEL_ENV}=numpy)"
    if not kernel.numba_installed():
        return 'kernel: numpy (numba not installed; pip install "pytest-hevval[fast]")'
    if kernel.load() is None:
        return f"kernel: numpy (numba unusable: {kernel.load_failure() or 'unknown reason'})"
    import numba

    version = getattr(numba, "__version__", "?")
    if path == "numba":
        return f"kernel: numba {version} ({KERNEL_ENV}=numba)"
    if kernel.cache_warm(COMPILED):
        return (
            f"kernel: numba {version} (cache warm) once a run's work pays for loading it "
            f"(about {KERNEL_LOAD_S:g} s of numpy time); numpy before"
        )
    return (
        f"kernel: numba {version} (cache cold: the first run that would gain compiles it in "
        "the background as it ends; hevval kernel --compile fills it now); numpy until then"
    )


# The core asks for a compile mid-run, once a process has lost more to numpy than compiling
# costs (kernel_for); this room is the one that starts it.
kernel.on_compile_wanted(start_background_compile)

"""The optional compiled kernel: which path scores a record, numba or numpy.

The numpy code in :mod:`~pytest_hevval.core.characteristics` and :mod:`~pytest_hevval.core.lag`
is the reference. With the ``fast`` extra (numba) installed, the main pass (the sums behind
λ1–λ6, the reference's extremes, the λ2 sign count and the first pyramid levels), the exact lag
window and the interpolation plans of alignment run as compiled loops instead. They release
the GIL and cover ranges of chunks, which long records spread over threads; the per-chunk
results are combined in chunk order, so a result is the same for any thread count and agrees
with numpy to rounding. Signals scored side by side on the engine's threads run side by side
in the kernel too.

Compiling takes seconds and loading compiled code most of a second, which a user must never
pay by surprise. On the ``auto`` path a process takes the kernel once it pays: when the numpy
time the kernel would have saved so far in this process (estimated per function from
:data:`NUMPY_EXTRA_S`) reaches what loading it costs (:data:`KERNEL_LOAD_S`), so a short run
stays on numpy and a long one switches early; and only once numba's on-disk cache holds the
functions it needs, so that nothing compiles mid-run. Records of at least
:data:`KERNEL_MIN_SAMPLES` samples take the kernel at once, compiling it in the run if need be.
A process that has already lost more to numpy than compiling costs (:data:`KERNEL_COMPILE_S`)
asks for a compile (:func:`on_compile_wanted`).

This module only chooses and dispatches: it writes no file, starts no process and words no
note. Filling numba's cache (``hevval kernel --compile``, the background compile a run starts
as it ends or when a spec alone would pay, its lock file) and the sentences about the kernel
live in :mod:`pytest_hevval.data.kernel_cache`, which reads the facts this module exposes
(:func:`cache_warm`, :func:`cached_functions`, :func:`numpy_seconds_lost`,
:func:`load_failure`, :func:`sample_calls`). numba writes its cache next to this module
(``__pycache__``) or under ``NUMBA_CACHE_DIR``; CI keeps it between runs by caching that
folder.

``HEVVAL_KERNEL`` forces a path: ``numpy``, ``numba`` (an error if numba cannot be loaded) or
``auto`` (the default). numba is imported only when the kernel is about to run, and any
failure to import it (not installed, or built for an older numpy) leaves the numpy path.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.util
import itertools
import os
import sys
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from types import ModuleType
from typing import Any, Literal, NamedTuple

import numpy as np
import numpy.typing as npt

from ..errors import HevvalError, MissingExtraError
from ..lazy import import_own

__all__ = [
    "COMPILED",
    "KERNEL_ENV",
    "KERNEL_MIN_SAMPLES",
    "GroupRuns",
    "KernelPath",
    "active_path",
    "cache_folder",
    "cache_warm",
    "cached_functions",
    "forget_cold_cache",
    "kernel_for",
    "load",
    "load_failure",
    "load_or_raise",
    "loaded_path",
    "numba_installed",
    "numpy_seconds_lost",
    "on_compile_wanted",
    "requested_path",
    "sample_calls",
    "squares_rule_out_scale",
]

KernelPath = Literal["auto", "numpy", "numba"]

#: Environment variable that forces a path (tests and benchmarks): auto, numpy or numba.
KERNEL_ENV = "HEVVAL_KERNEL"
#: On the auto path with a cold cache, records shorter than this stay on numpy. The compile
#: (2.4–2.6 s, once per environment: it is cached) is then a few times what numpy spends on one
#: such record (0.5 s at 10^8 samples on two threads, docs/performance.md), never a surprise
#: on short records.
KERNEL_MIN_SAMPLES = 1 << 26
#: What loading the compiled kernel costs a process, in seconds: importing numba (0.22 s) and
#: loading the cached code, most of it on the first function (0.52 s); measured 2026-11-26,
#: docs/performance.md.
KERNEL_LOAD_S = 0.75
#: CPU seconds a compile of every function costs (12.5–16 s on 2026-11-27's machine,
#: docs/performance.md): a process that has lost this much to numpy compiles during its run.
KERNEL_COMPILE_S = 15.0
#: Seconds the numpy path spends beyond the compiled loop, per sample (per band cell for the
#: warping path), for each function; the callers' work is weighed by the first function they
#: name. Measured on records of 10^4–10^6 samples (docs/performance.md), rounded down: the
#: estimate only decides when loading the kernel has paid for itself.
NUMPY_EXTRA_S = {
    "main_pass": 6e-9,
    "lag_window": 6e-9,
    "quarter_level": 1e-9,
    "interpolate": 2e-9,
    "grouped_sums": 3e-9,
    "fine_block_sums": 3e-9,
    "dtw_path": 1.5e-8,
    "quality_steps": 9e-9,
}
#: Samples per chunk of the compiled loops: both chunks of a pair, and the lag window's
#: centred copies, stay in a 1 MiB L2 cache.
KERNEL_CHUNK = 1 << 15
#: Shorter loops run on the calling thread alone. Waking a second thread costs up to a
#: scheduler time slice on a busy machine (measured 8 ms with the load at 5 on 2 cores), more
#: than the whole loop over a million samples.
KERNEL_PARALLEL_MIN = 1 << 21
#: The same for applying an interpolation plan, which costs about 15 times more per sample
#: than the main pass (most of it the first write to the new column's pages).
INTERPOLATE_PARALLEL_MIN = 1 << 17

#: Sums of squares that prove the peak within (2^-395, 2^395), so that no power-of-two scale
#: is needed (``characteristics.power_of_two_scale`` acts beyond 2^±400): a margin of 2^10 on
#: the squares for their rounding.
SQUARES_HIGH = 2.0**790
SQUARES_LOW = 2.0**-790

#: Columns of one chunk's row of sums from the compiled main pass. The simulated extremes are
#: left to the caller, as on the numpy path, which rarely needs them.
FIELDS = 13
(
    N,
    ABS_ERROR,
    SQ_ERROR,
    ERROR_SUM,
    ERROR_M2,
    REF_SUM,
    SIM_SUM,
    REF_SQ,
    SIM_SQ,
    CROSS,
    REF_MIN,
    REF_MAX,
    SIGN_MATCHES,
) = range(FIELDS)

#: Every compiled function a scoring run may call, as named in ``_fused``.
COMPILED = (
    "main_pass",
    "lag_window",
    "quarter_level",
    "interpolate",
    "grouped_sums",
    "fine_block_sums",
    "dtw_path",
    "quality_steps",
    "quality_runs",
)

_PATHS: tuple[KernelPath, ...] = ("auto", "numpy", "numba")
_lock = threading.Lock()
_loaded: dict[str, ModuleType | None] = {}
_failure: dict[str, str] = {}
# (cache folder, compiled functions) found in the cache: numba only adds to it, so found stays
# found.
_warm_found: set[tuple[Path, tuple[str, ...]]] = set()

FloatArray = npt.NDArray[np.float64]
AnyFloatArray = npt.NDArray[np.floating]


def requested_path() -> KernelPath:
    """The path ``HEVVAL_KERNEL`` asks for (``auto`` when unset)."""
    value = os.environ.get(KERNEL_ENV, "auto").strip().lower() or "auto"
    for path in _PATHS:
        if value == path:
            return path
    raise HevvalError(
        f"{value!r} is not a kernel path",
        key=KERNEL_ENV,
        hint="set it to auto, numpy or numba, or unset it",
    )


def _load() -> ModuleType | None:
    """The compiled module, or None (the reason kept for :func:`load_failure`)."""
    with _lock:
        if "module" not in _loaded:
            try:
                _loaded["module"] = import_own(f"{__package__}._fused")
            except Exception as error:
                _loaded["module"] = None
                _failure["reason"] = f"{type(error).__name__}: {error}".splitlines()[0]
        return _loaded["module"]


def load() -> ModuleType | None:
    """The compiled module, loaded now if need be, or None where numba cannot be loaded."""
    return _load()


def load_failure() -> str | None:
    """Why the compiled module could not be loaded (the error's first line), or None."""
    return _failure.get("reason")


@functools.lru_cache(maxsize=4)
def _cache_folder(custom: str | None = None) -> Path:
    """The folder numba keeps this module's cache in, as its locators choose it: with
    ``NUMBA_CACHE_DIR`` set, ``<that>/<folder name>_<SHA-1 of its path>``
    (``_CacheLocator.get_suitable_cache_subpath``); else ``__pycache__`` beside the module
    when it can be written (a venv); else numba's user-wide cache folder (a read-only
    install). Found without importing numba, which costs a third of a second."""
    here = os.path.dirname(os.path.abspath(__file__))
    subpath = f"{os.path.basename(here)}_{hashlib.sha1(here.encode()).hexdigest()}"
    if custom:
        return Path(custom) / subpath
    in_tree = Path(here) / "__pycache__"
    if os.access(in_tree if in_tree.is_dir() else here, os.W_OK):
        return in_tree
    return _user_cache_root() / subpath


def _user_cache_root() -> Path:
    """numba's ``appdirs.user_cache_dir("numba", appauthor=False)``."""
    if sys.platform == "win32":
        local = os.environ.get("LOCALAPPDATA") or os.path.expanduser("~\\AppData\\Local")
        return Path(local) / "numba" / "Cache"
    if sys.platform == "darwin":
        return Path(os.path.expanduser("~/Library/Caches")) / "numba"
    return Path(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")) / "numba"


#: A cold cache is looked at again after this many seconds at the soonest: the look costs a
#: directory listing, and the engine asks once per signal.
_COLD_RECHECK_S = 1.0
_cold_seen: dict[tuple[Path, tuple[str, ...]], float] = {}


def cache_warm(names: tuple[str, ...] = ("main_pass", "lag_window")) -> bool:
    """Whether numba's on-disk cache already holds the kernel for this Python.

    A stale entry (another numba version or an edited source) costs one compile, after which
    the cache is warm again.
    """
    key = (cache_folder(), names)
    if key in _warm_found:
        return True
    seen = _cold_seen.get(key)
    if seen is not None and time.monotonic() - seen < _COLD_RECHECK_S:
        return False
    if _cache_holds(key[0], names):
        _warm_found.add(key)
        _cold_seen.pop(key, None)
        return True
    _cold_seen[key] = time.monotonic()
    return False


def _cache_holds(folder: Path, names: tuple[str, ...]) -> bool:
    """Whether ``folder`` has numba's index of every one of ``names`` under this Python."""
    tag = f"py{sys.version_info.major}{sys.version_info.minor}"
    return all(any(folder.glob(f"_fused.{name}-*.{tag}.nbi")) for name in names)


def cache_folder() -> Path:
    """Where numba keeps this module's cache now: under ``NUMBA_CACHE_DIR`` when it is set."""
    return _cache_folder(os.environ.get("NUMBA_CACHE_DIR") or None)


def cached_functions() -> dict[str, bool]:
    """Whether numba's cache holds each function of :data:`COMPILED` for this Python."""
    folder = cache_folder()
    return {name: _cache_holds(folder, (name,)) for name in COMPILED}


def _runs(n: int, fine: int) -> GroupRuns:
    """``n`` samples in consecutive runs of ``fine``, one group each."""
    starts = np.arange(0, n, fine, dtype=np.int64)
    groups = starts.shape[0]
    return GroupRuns(
        starts=starts,
        stops=np.minimum(starts + fine, n),
        run_group=np.arange(groups, dtype=np.int64),
        groups=groups,
        shift=0.0,
    )


def sample_calls(module: ModuleType) -> dict[str, Callable[[], object]]:
    """One call of each function of :data:`COMPILED` on a small record, through its wrapper,
    keyed by name: the signature a scoring run calls (float64, contiguous, read-only), which is
    the one numba compiles and caches when a call runs (what ``hevval kernel --compile``
    does)."""
    n = 4 * 64
    x = np.sin(np.linspace(0.0, 6.0, n))
    y = np.cos(np.linspace(0.0, 6.0, n))
    fine = 4
    return {
        "main_pass": lambda: main_pass(module, x, y, 1.0, 1, None, _runs(n, fine)),
        "lag_window": lambda: lag_window(module, x, y, -2, 5, 0.0, 0.0, 1.0, (2, n - 2), 1),
        "quarter_level": lambda: quarter_level(module, x, 1),
        "interpolate": lambda: interpolate(
            module, x, np.arange(n - 1, dtype=np.intp), np.zeros(n - 1), np.ones(n - 1), 1
        ),
        "grouped_sums": lambda: grouped_sums(module, x, y, _runs(n, fine)),
        "fine_block_sums": lambda: fine_block_sums(
            module, x, y, fine, 8, np.empty((n // fine, 10), dtype=np.float64)
        ),
        "dtw_path": lambda: dtw_path(module, x[:32], y[:32], 3),
        "quality_steps": lambda: quality_steps(module, x),
        "quality_runs": lambda: quality_runs(
            module, x, np.arange(n, dtype=np.float64), 0.1, (1.0, 1.0, 1.0), (1.0, -1.0), 15
        ),
    }


def forget_cold_cache() -> None:
    """Look at numba's cache again on the next :func:`cache_warm`, however recently it was found
    cold (after a compile in this process)."""
    _cold_seen.clear()


@functools.lru_cache(maxsize=1)
def _numba_installed() -> bool:
    # Asked once per process: the look-up stats the import path, and the engine asks per signal.
    return importlib.util.find_spec("numba") is not None


def numba_installed() -> bool:
    """Whether numba can be found (not whether it loads: :func:`load`)."""
    return _numba_installed()


def load_or_raise() -> ModuleType:
    """The compiled module, or a clear error where numba cannot be loaded."""
    module = _load()
    if module is None:
        raise MissingExtraError(
            f"the compiled kernel cannot be loaded ({_failure.get('reason', 'unknown reason')})",
            key=KERNEL_ENV,
            hint=f'install the extra (pip install "pytest-hevval[fast]") or unset {KERNEL_ENV}',
        )
    return module


# Numpy seconds the kernel would have saved in this process so far (see kernel_for).
_would_save = [0.0]
# Called with the functions a compile should take first, when one pays mid-run (see
# on_compile_wanted).
_compile_wanted: list[Callable[[tuple[str, ...]], object]] = []


def numpy_seconds_lost() -> float:
    """The numpy time, in seconds, the kernel would have saved in this process so far: where it
    reaches :data:`KERNEL_LOAD_S`, the kernel would have paid in this run."""
    return _would_save[0]


def on_compile_wanted(start: Callable[[tuple[str, ...]], object]) -> None:
    """Have ``start(functions)`` called when a compile pays now: this process has lost more to
    numpy than compiling costs (:data:`KERNEL_COMPILE_S`) and numba's cache does not hold
    ``functions`` (the ones a compile should take first). The core decides that a compile
    pays; :mod:`pytest_hevval.data.kernel_cache`, which runs it, registers itself here when
    imported. Without a registration no compile is started."""
    _compile_wanted[:] = [start]


def kernel_for(
    samples: int, functions: tuple[str, ...] = ("main_pass", "lag_window")
) -> ModuleType | None:
    """The compiled module if it should score ``samples`` samples (band cells for the warping
    path) with ``functions``, else None.

    On the auto path a record of :data:`KERNEL_MIN_SAMPLES` or more takes the kernel. A
    shorter one takes it once the kernel pays in this process (see the module's docstring) and
    numba's cache holds every one of ``functions``; where it does not, this record stays on
    numpy and the compile waits for the run's end (``data.kernel_cache.finish_run``), unless
    this process has lost more to numpy than compiling costs (then :func:`on_compile_wanted`).
    """
    path = requested_path()
    if path == "numpy":
        return None
    if path == "numba":
        return load_or_raise()
    if not _numba_installed():
        return None
    if samples >= KERNEL_MIN_SAMPLES:
        return _load()
    loaded = _loaded.get("module")
    if loaded is not None and cache_warm(functions):
        return loaded  # the load is paid already
    with _lock:
        _would_save[0] += samples * NUMPY_EXTRA_S.get(functions[0], 0.0)
        saved = _would_save[0]
    if saved < KERNEL_LOAD_S:
        return None
    if cache_warm(functions):
        return _load()
    if saved >= KERNEL_COMPILE_S:
        for start in _compile_wanted:
            start(functions)
    return None


def active_path() -> str:
    """``numba`` or ``numpy``: the path a long record takes now (loads numba if installed)."""
    if requested_path() == "numpy" or not _numba_installed():
        return "numpy"
    return "numba" if _load() is not None else "numpy"


def loaded_path() -> str:
    """``numba`` when this process has loaded the compiled kernel (some record took it),
    else ``numpy``; loads nothing. Recorded with a run as the path its scoring took."""
    return "numba" if _loaded.get("module") is not None else "numpy"


_pool_lock = threading.Lock()
_pool: ThreadPoolExecutor | None = None
_pool_pid = 0


def _helpers() -> ThreadPoolExecutor:
    """The kernel's helper threads, made on first use and again in a forked child (a fork
    copies the pool but not its threads, so work handed to it would never run)."""
    global _pool, _pool_pid
    with _pool_lock:
        if _pool is None or _pool_pid != os.getpid():
            _pool = ThreadPoolExecutor(
                max_workers=max(1, (os.cpu_count() or 2) - 1), thread_name_prefix="hevval-kernel"
            )
            _pool_pid = os.getpid()
        return _pool


def _spread(
    function: Any, chunks: int, workers: int, samples: int, minimum: int, *arguments: Any
) -> None:
    """Run ``function(*arguments, first, last)`` over the chunks [0, chunks).

    The compiled loops release the GIL, so contiguous ranges of chunks run side by side: the
    calling thread takes the first and helper threads the others. Shorter loops than
    ``minimum`` samples stay on the calling thread, where waking a helper would cost more than
    the loop. Each chunk's row is computed alike on any thread, so the result does not depend
    on the thread count.
    """
    parts = max(1, min(workers, chunks)) if samples >= minimum else 1
    bounds = [chunks * i // parts for i in range(parts + 1)]
    if parts == 1:
        function(*arguments, 0, chunks)
        return
    pool = _helpers()
    spans = list(itertools.pairwise(bounds))
    run = functools.partial(function, *arguments)
    pending = [pool.submit(run, a, b) for a, b in spans[1:]]
    try:
        run(*spans[0])
    finally:
        for future in pending:
            future.result()


def accepts(*arrays: AnyFloatArray) -> bool:
    """Whether the kernel's one compiled signature takes these arrays (float64, contiguous)."""
    return all(a.dtype == np.float64 and a.flags.c_contiguous for a in arrays)


def _read_only(array: npt.ArrayLike, dtype: npt.DTypeLike = np.float64) -> npt.NDArray[Any]:
    """An input as the kernel's one signature takes it: contiguous, of ``dtype``, read-only.

    numba compiles one signature for each mix of writable and read-only arrays (a record read
    from Parquet is read-only, one computed in memory is not), so a warm cache could still
    compile mid-run; every input goes in as a read-only view instead (no copy where the array
    already has the layout and type).
    """
    view: npt.NDArray[Any] = np.ascontiguousarray(array, dtype=dtype)
    if view.flags.writeable:
        view = view.view()
        view.flags.writeable = False
    return view


def main_pass(
    module: ModuleType,
    ref: AnyFloatArray,
    sim: AnyFloatArray,
    scale: float,
    workers: int,
    levels: tuple[FloatArray, ...] | None,
    runs: GroupRuns | None = None,
) -> tuple[FloatArray, FloatArray | None]:
    """Rows of per-chunk sums (columns named in ``_fused``), in record order; ``levels`` are
    the pyramid's (ref, sim) block means by 4, 16 and 64 to fill, flattened.

    With ``runs``, an unscaled pass on one thread also gives :func:`grouped_sums`' table, from
    each chunk while it is in cache; otherwise (a scale, or a record long enough to be shared
    between threads, whose group rows would then depend on the split) the table is None.
    """
    n = ref.shape[0]
    chunks = (n + KERNEL_CHUNK - 1) // KERNEL_CHUNK
    empty = np.empty(0, dtype=np.float64)
    ref4, sim4, ref16, sim16, ref64, sim64 = levels if levels is not None else (empty,) * 6
    rows = np.empty((chunks, FIELDS), dtype=np.float64)
    shared = workers > 1 and chunks > 1 and n >= KERNEL_PARALLEL_MIN
    if runs is not None and (scale != 1.0 or shared):
        runs = None
    sums = np.zeros((runs.groups if runs is not None else 0, 10), dtype=np.float64)
    _spread(
        module.main_pass,
        chunks,
        workers,
        n,
        KERNEL_PARALLEL_MIN,
        _read_only(ref),
        _read_only(sim),
        float(scale),
        KERNEL_CHUNK,
        ref4,
        sim4,
        ref16,
        sim16,
        ref64,
        sim64,
        rows,
        *_run_arrays(runs),
        float(runs.shift) if runs is not None else 0.0,
        sums,
    )
    return rows, (sums if runs is not None else None)


def lag_window(
    module: ModuleType,
    r: AnyFloatArray,
    s: AnyFloatArray,
    lo: int,
    count: int,
    r_mean: float,
    s_mean: float,
    scale: float,
    window: tuple[int, int],
    workers: int,
) -> FloatArray:
    """C(lo + k) for k < count over ``window``, then the shifted reference energy: the
    per-chunk rows summed in chunk order."""
    width = window[1] - window[0]
    chunks = (width + KERNEL_CHUNK - 1) // KERNEL_CHUNK
    rows = np.empty((chunks, count + 1), dtype=np.float64)
    _spread(
        module.lag_window,
        chunks,
        workers,
        width,
        KERNEL_PARALLEL_MIN,
        _read_only(r),
        _read_only(s),
        int(lo),
        int(count),
        float(r_mean),
        float(s_mean),
        float(scale),
        int(window[0]),
        int(window[1]),
        KERNEL_CHUNK,
        rows,
    )
    total = np.zeros(count + 1, dtype=np.float64)
    for row in rows:
        total += row
    return total


def quarter_level(module: ModuleType, x: AnyFloatArray, workers: int) -> FloatArray:
    """Block means by 4 of x (a trailing partial block dropped), on ``workers`` threads."""
    out = np.empty(x.shape[0] // 4, dtype=np.float64)
    per = KERNEL_CHUNK // 4
    chunks = (out.shape[0] + per - 1) // per
    _spread(
        module.quarter_level,
        chunks,
        workers,
        x.shape[0],
        KERNEL_PARALLEL_MIN,
        _read_only(x),
        out,
        KERNEL_CHUNK,
    )
    return out


def interpolate(
    module: ModuleType,
    values: AnyFloatArray,
    index: npt.NDArray[np.intp],
    offset: FloatArray,
    step: FloatArray,
    workers: int = 2,
) -> FloatArray:
    """One column through an interpolation plan: np.interp's arithmetic, compiled."""
    return interpolate_columns(module, [values], index, offset, step, workers)[0]


def interpolate_into(
    module: ModuleType,
    values: AnyFloatArray,
    index: npt.NDArray[np.intp],
    offset: FloatArray,
    step: FloatArray,
    out: FloatArray,
) -> FloatArray:
    """One column through an interpolation plan into ``out``, on the calling thread."""
    module.interpolate(
        _read_only(values),
        _read_only(index, np.intp),
        _read_only(offset),
        _read_only(step),
        out,
        0,
        int(index.shape[0]),
    )
    return out


def interpolate_columns(
    module: ModuleType,
    columns: Sequence[AnyFloatArray],
    index: npt.NDArray[np.intp],
    offset: FloatArray,
    step: FloatArray,
    workers: int = 2,
) -> list[FloatArray]:
    """Columns of one time base through its interpolation plan, each into a new array.

    Several columns go to the threads whole, in one hand-over for all of them: waking a
    helper per column cost more than the column on a busy machine. One column is split into
    chunks instead.
    """
    n = index.shape[0]
    index = _read_only(index, np.intp)
    offset, step = _read_only(offset), _read_only(step)
    inputs = [_read_only(values) for values in columns]
    outs = [np.empty(0, dtype=np.float64)] * len(inputs)
    if len(inputs) == 1:
        out = outs[0] = np.empty(n, dtype=np.float64)
        chunks = (n + KERNEL_CHUNK - 1) // KERNEL_CHUNK
        bounds = np.minimum(np.arange(chunks + 1) * KERNEL_CHUNK, n)

        def run_chunks(first: int, last: int) -> None:
            module.interpolate(
                inputs[0], index, offset, step, out, int(bounds[first]), int(bounds[last])
            )

        _spread(run_chunks, chunks, workers, n, INTERPOLATE_PARALLEL_MIN)
        return outs

    def run_columns(first: int, last: int) -> None:
        for k in range(first, last):
            # Allocated on the thread that writes it: the first touch of its pages, most of a
            # column's cost, is spread over the threads too.
            out = np.empty(n, dtype=np.float64)
            module.interpolate(inputs[k], index, offset, step, out, 0, n)
            outs[k] = out

    _spread(run_columns, len(inputs), workers, n * len(inputs), INTERPOLATE_PARALLEL_MIN)
    return outs


class GroupRuns(NamedTuple):
    """A record's samples in runs of one group, in sample order, as the compiled passes take
    them (``core.groups.Grouping.runs``), and the shift of the error sums."""

    starts: npt.NDArray[np.int64]
    stops: npt.NDArray[np.int64]
    #: Each run's group, in [0, groups).
    run_group: npt.NDArray[np.int64]
    groups: int
    shift: float


def grouped_sums(
    module: ModuleType, ref: AnyFloatArray, sim: AnyFloatArray, runs: GroupRuns
) -> npt.NDArray[np.float64]:
    """The (groups, 10) table of ``core.groups.SUM_COLUMNS`` of every group of ``runs``, in one
    sequential compiled pass: the table the main pass gives when it sums the groups.

    Sequential per signal, so the table is repeatable bit for bit; signals run side by side on
    the engine's threads (the loop releases the GIL). The sums are reassociated, as the main
    pass's are: they agree with the numpy path's to rounding.
    """
    sums = np.zeros((runs.groups, 10), dtype=np.float64)
    module.grouped_sums(
        _read_only(ref),
        _read_only(sim),
        *_run_arrays(runs),
        float(runs.shift),
        KERNEL_CHUNK,
        sums,
    )
    return sums


def _run_arrays(runs: GroupRuns | None) -> tuple[npt.NDArray[np.int64], ...]:
    if runs is None:
        return (_read_only(np.empty(0, dtype=np.int64), np.int64),) * 3
    return tuple(_read_only(a, np.int64) for a in (runs.starts, runs.stops, runs.run_group))


def squares_rule_out_scale(power: float, samples: int, summed: int) -> bool:
    """Whether Σx² over ``summed`` of a record's ``samples`` values (both signals) proves that
    no power-of-two scale is needed (every |x| within (2^-395, 2^395)): peak² ≤ Σx² ≤ n·peak².
    A NaN or inf sum, or samples left out of it, prove nothing."""
    return summed == samples and SQUARES_LOW * max(samples, 1) < power < SQUARES_HIGH


def fine_block_sums(
    module: ModuleType,
    ref: AnyFloatArray,
    sim: AnyFloatArray,
    fine: int,
    shift_samples: int,
    out: npt.NDArray[np.float64],
) -> tuple[float, float, float]:
    """One signal's sums over runs of ``fine`` samples into ``out`` (rows, 10), and its
    (scale, shift, ρ), in one compiled call (see ``_fused.fine_block_sums``)."""
    blocks = _fine_runs(int(np.shape(ref)[0]), int(fine))
    scale, shift, rho = module.fine_block_sums(
        _read_only(ref), _read_only(sim), int(fine), *blocks, int(shift_samples), out
    )
    if scale != 1.0:
        # Values beyond 2^±400: the sums are of copies scaled by a power of two (exactly the
        # products a scaled loop would form), through the same compiled signature.
        _, shift, rho = module.fine_block_sums(
            _read_only(np.multiply(ref, scale, dtype=np.float64)),
            _read_only(np.multiply(sim, scale, dtype=np.float64)),
            int(fine),
            *blocks,
            int(shift_samples),
            out,
        )
    return float(scale), float(shift), float(rho)


@functools.lru_cache(maxsize=4)
def _fine_runs(n: int, fine: int) -> tuple[npt.NDArray[np.int64], ...]:
    """The fine blocks of a record of ``n`` samples as runs (starts, stops, groups), read-only
    as ``_run_arrays`` gives the windows': shared by every signal of the record."""
    return _run_arrays(_runs(n, max(1, fine)))


def dtw_path(
    module: ModuleType, x: AnyFloatArray, y: AnyFloatArray, band: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """ISO/TS 18571's warping path (rows of x, columns of y), one sequential compiled pass."""
    rows, cols = module.dtw_path(
        _read_only(x),
        _read_only(y),
        int(band),
    )
    return rows, cols


def quality_steps(
    module: ModuleType, values: AnyFloatArray
) -> tuple[float, bool, bool, float, float]:
    """(resolution, any step moves, every step moves, max, min) of a finite channel, in one
    compiled loop (see ``_fused.quality_steps``). The resolution is numpy's, or, where every
    step that moves overflows, a finite number whose double is inf as numpy's is."""
    n = values.shape[0]
    resolution, still, top, bottom = module.quality_steps(_read_only(values))
    return float(resolution), still < n - 1, still == 0, float(top), float(bottom)


#: Kinds of run ``quality_runs`` reports, in its rows' first column.
STRAIGHT_RUN, FLAT_RUN, TOP_RUN, BOTTOM_RUN = range(4)
# Rows made ready for a channel's runs; a channel with more is scanned again with room for all.
_QUALITY_ROWS = 64


def quality_runs(
    module: ModuleType,
    values: AnyFloatArray,
    time: AnyFloatArray,
    limit: float,
    seconds: tuple[float, float, float],
    extremes: tuple[float, float],
    checks: int,
) -> npt.NDArray[np.int64]:
    """Rows (kind, start, final) of a finite channel's long runs, in one compiled loop (see
    ``_fused.quality_runs``): ``seconds`` are the straight, flat and saturation lengths,
    ``extremes`` (max, min), ``checks`` a bit per kind."""
    straight_s, flat_s, saturation_s = seconds
    top, bottom = extremes
    arguments = (
        _read_only(values),
        _read_only(time),
        float(limit),
        float(straight_s),
        float(flat_s),
        float(top),
        float(bottom),
        float(saturation_s),
        int(checks),
    )
    out = np.empty((_QUALITY_ROWS, 3), dtype=np.int64)
    count = int(module.quality_runs(*arguments, out))
    if count > out.shape[0]:
        out = np.empty((count, 3), dtype=np.int64)
        module.quality_runs(*arguments, out)
    return out[:count]

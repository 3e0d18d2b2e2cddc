"""Evaluate many specs on a Dask cluster: one task per spec, results in input order.

Each task loads its spec **on the worker** and reads the data where the worker sees it (a
shared file system, or an fsspec URL such as ``s3://…``); only the spec's path goes out and only
its JSON-safe result comes back. Errors a user can fix come back as data too (see
:func:`error_payload`), so one bad spec does not hide the results of the others.

Why one task per spec, even for specs with hundreds of signals
--------------------------------------------------------------
A spec's signals share its two data files and its alignment grid. Splitting a spec into
per-signal tasks would either read both files once per task or ship the aligned columns
between workers: 600 signals of one hour at 100 Hz are 2 × 600 × 360,000 float64 values,
3.5 GB, against a result of a few hundred kilobytes. Within a task the engine scores the
signals on threads (numpy releases the GIL), up to two per task by default; ``threads_per_spec``
changes that. The cost of a run is therefore about

    T ≈ max(longest spec, Σ spec times / task slots) + per-task overhead (a few ms),

where a spec's time is its read time (file size / read bandwidth) plus roughly linear terms
in signals × samples (see ``docs/scaling.md`` for measured figures). Many small specs spread
well; one huge spec is bounded by one worker's cores, memory and read bandwidth.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..data.digest import DEFAULT_HASH
from ..errors import (
    DataError,
    DegenerateSignalError,
    ExpressionError,
    HevvalError,
    MissingExtraError,
    SpecError,
)

__all__ = ["error_from_payload", "error_payload", "evaluate_on_dask", "is_error_payload"]

#: The address that starts a throw-away ``LocalCluster`` on this machine.
LOCAL = "local"
#: ``dashboard_address`` for local clusters: any free port.
FREE_PORT = ":0"

_KINDS: dict[str, type[HevvalError]] = {
    cls.__name__: cls
    for cls in (
        HevvalError,
        SpecError,
        DataError,
        ExpressionError,
        DegenerateSignalError,
        MissingExtraError,
    )
}

Progress = Callable[[int], None]

# A Dask worker runs several tasks on threads of one process. Spec loading parses signal
# expressions with ast.parse, whose recursion counter CPython 3.11 shares between threads:
# two specs loaded at once can fail with "SystemError: AST constructor recursion depth
# mismatch" (python/cpython#106905). Loading takes milliseconds; evaluation stays parallel.
_PARSE_LOCK = threading.Lock()


def error_payload(spec_path: str, exc: HevvalError) -> dict[str, Any]:
    """A JSON-safe description of ``exc`` that :func:`error_from_payload` turns back into it."""
    kind = type(exc).__name__
    return {
        "spec": spec_path,
        "error": str(exc),
        "kind": kind if kind in _KINDS else "HevvalError",
        "problem": exc.problem,
        "file": exc.file,
        "line": exc.line,
        "key": exc.key,
        "column": exc.column,
        "hint": exc.hint,
    }


def is_error_payload(payload: Mapping[str, Any]) -> bool:
    """True when ``payload`` is an error from :func:`error_payload`, not a spec result."""
    return "error" in payload and "kind" in payload


def error_from_payload(payload: Mapping[str, Any]) -> HevvalError:
    """The :class:`HevvalError` subclass (and message) that an error payload describes."""
    cls = _KINDS.get(str(payload.get("kind")), HevvalError)
    if "problem" not in payload:
        return cls(str(payload["error"]), file=payload.get("spec"))
    return cls(
        str(payload["problem"]),
        file=payload.get("file"),
        line=payload.get("line"),
        key=payload.get("key"),
        column=payload.get("column"),
        hint=payload.get("hint"),
    )


def evaluate_spec_file(
    spec_path: str,
    rootdir: str,
    figures: bool = False,
    threads_per_spec: int | None = None,
    data_hash: str = DEFAULT_HASH,
    intervals: bool = True,
) -> dict[str, Any]:
    """Load and evaluate one spec file here; the Dask task body (also usable on its own).

    Returns ``SpecResult.to_dict()`` or, for an error the user can fix, :func:`error_payload`.
    Anything else (a bug) propagates, so that the client shows its traceback.
    """
    from ..core.registry import load_entry_points
    from ..spec.load import load_specs
    from .engine import DataCache, evaluate_spec

    try:
        # A Dask worker is its own process: it learns registered characteristics here.
        load_entry_points()
        with _PARSE_LOCK:
            # A campaign's recording travels as ``file::recording``.
            (spec,) = load_specs(spec_path)
        evaluation = evaluate_spec(
            spec,
            cache=DataCache(data_hash),
            rootdir=Path(rootdir),
            figures=figures,
            workers=threads_per_spec,
            intervals=intervals,
        )
    except HevvalError as exc:
        return error_payload(spec_path, exc)
    return evaluation.result.to_dict()


def _distributed() -> Any:
    try:
        import distributed
    except ImportError:
        raise MissingExtraError.for_extra("running specs on Dask", "dask", "distributed") from None
    return distributed


def evaluate_on_dask(
    spec_paths: Sequence[Path],
    address: str,
    *,
    rootdir: Path,
    figures: bool = False,
    progress: Progress | None = None,
    threads_per_spec: int | None = None,
    data_hash: str = DEFAULT_HASH,
    intervals: bool = True,
) -> list[dict[str, Any]]:
    """Evaluate every spec on the Dask cluster at ``address``; one result per spec, in order.

    Parameters
    ----------
    spec_paths
        Spec files as the workers see them (a shared file system, or the same checkout).
        Relative data paths resolve against each spec's folder, on the worker.
    address
        A scheduler address (``tcp://host:8786``), a scheduler file written by
        ``dask scheduler --scheduler-file`` (a path ending in ``.json``), or ``"local"`` to
        start a ``LocalCluster`` on this machine for the duration of the call.
    rootdir
        The project root, where model callables are imported from; it must exist on workers.
    figures
        Include figure data in each result (for HTML reports).
    progress
        Called with the number of specs completed so far, each time one completes.
    threads_per_spec
        Threads the engine scores one spec's signals on; ``None``: one on a ``"local"``
        cluster (a worker process per core), else the engine's default (up to two). The
        results do not depend on it.
    data_hash
        How data files are identified in the results: ``"fast"`` or ``"sha256"``.
    intervals
        Give every λ and Φ its bootstrap interval (``False``: ``--no-intervals``).

    Returns
    -------
    list of dict
        For each spec, ``SpecResult.to_dict()`` or an error payload; test with
        :func:`is_error_payload`, raise with :func:`error_from_payload`.

    Raises
    ------
    MissingExtraError
        When ``distributed`` is not installed.
    HevvalError
        When no scheduler answers at ``address``.
    Exception
        Whatever a task raised that is not a :class:`HevvalError` (a bug). A spec whose
        worker died comes back as an error payload instead, so the other results survive.
    """
    paths = [str(p) for p in spec_paths]
    if not paths:
        return []
    distributed = _distributed()
    if address == LOCAL and threads_per_spec is None:
        # One process per core already fills this machine; a second thread per spec only
        # contends with the other worker (the results are the same on any thread count).
        threads_per_spec = 1
    # evaluate_spec_file's arguments after the spec's path, the same for every task.
    task_arguments = (str(rootdir), figures, threads_per_spec, data_hash, intervals)
    if address == LOCAL:
        # Worker processes, one thread each: YAML parsing and CSV reading hold the GIL, and
        # the engine adds its own threads for the numpy work. The scheduler's web server takes
        # a free port: the default 8787 may be held by another cluster (a second run, an xdist
        # worker), which distributed reports with a warning.
        with (
            distributed.LocalCluster(
                n_workers=os.cpu_count() or 1,
                threads_per_worker=1,
                processes=True,
                dashboard_address=FREE_PORT,
            ) as cluster,
            distributed.Client(cluster) as client,
        ):
            return _run(client, distributed, paths, task_arguments, progress)
    connect: dict[str, Any] = (
        {"scheduler_file": address}
        if address.endswith(".json") and os.path.isfile(address)
        else {"address": address}
    )
    try:
        client = distributed.Client(**connect)
    except (OSError, ValueError) as exc:
        # distributed raises OSError for a scheduler that does not answer within its connect
        # timeout and ValueError for an address it cannot parse.
        raise HevvalError(
            f"cannot connect to the Dask scheduler at {address!r} ({exc})",
            hint="start one with `dask scheduler`, pass its address or scheduler file, "
            "or use 'local'",
        ) from None
    with client:
        return _run(client, distributed, paths, task_arguments, progress)


def _run(
    client: Any,
    distributed: Any,
    paths: list[str],
    task_arguments: tuple[Any, ...],
    progress: Progress | None,
) -> list[dict[str, Any]]:
    futures = [
        # pure=False: the same path may hold a changed spec or data by the next call.
        client.submit(
            evaluate_spec_file,
            path,
            *task_arguments,
            pure=False,
            key=f"hevval-spec-{index}-{os.path.basename(path)}-{os.urandom(4).hex()}",
        )
        for index, path in enumerate(paths)
    ]
    position = {future.key: index for index, future in enumerate(futures)}
    results: list[dict[str, Any] | None] = [None] * len(futures)
    done = 0
    try:
        for future in distributed.as_completed(futures):
            index = position[future.key]
            try:
                results[index] = future.result()
            except distributed.KilledWorker as exc:
                # The worker died running this spec (most often: out of memory); the other
                # specs' results are still good.
                results[index] = error_payload(
                    paths[index],
                    HevvalError(
                        f"the Dask worker evaluating this spec died ({exc})",
                        file=paths[index],
                        hint="it most likely ran out of memory; give workers more memory "
                        "(docs/scaling.md says how much a spec needs)",
                    ),
                )
            # Drop the finished future so the worker can free the result.
            future.release()
            done += 1
            if progress is not None:
                progress(done)
    finally:
        # On an error or an interrupt, stop the tasks not yet run.
        client.cancel([f for f in futures if not f.done()])
    return [r for r in results if r is not None]

"""The engine: spec → data → core → tree/Φ → result.

Used identically by the pytest items, the ``hevval`` CLI and Dask workers. It computes; it
never prints, and it writes nothing.
"""

from __future__ import annotations

import math
import os
import sys
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
import numpy.typing as npt

from ..core import kernel
from ..core.characteristics import SignalCharacteristics, signal_characteristics
from ..core.registry import Characteristic, compute_characteristic
from ..core.tree import ScoredNode, TreeNode, error_origins, global_metric, iter_nodes, score_tree
from ..core.uncertainty import BlockSums, block_sums_many, block_sums_stacked
from ..core.upooling import u_distribution_of
from ..data.align import AlignedData, Interpolation, align_records
from ..data.digest import DEFAULT_HASH, file_digest
from ..data.quality import assess, fail_on, mask_on_grid
from ..data.record import Record, SourceOptions, model_column_error
from ..data.remote import is_url
from ..errors import (
    CharacteristicError,
    DataError,
    DegenerateSignalError,
    ExpressionError,
    HevvalError,
    SpecError,
    did_you_mean,
)
from ..results.diagnosis import SignalDiagnosis
from ..results.local import LocalFailure, LocalResult
from ..results.runtime import ModelRuntime, RuntimeGate
from ..results.spec_result import Failure, SignalResult, SpecResult
from ..spec.expressions import Expression
from ..spec.model import SignalSpec, SourceSpec, Spec
from .confidence import spec_confidence
from .local import (
    Labels,
    LocalSums,
    label_samples,
    local_failures,
    local_results,
    local_sums,
    spec_local_summary,
)

__all__ = ["DataCache", "Evaluation", "evaluate_spec", "file_digest"]

FloatArray = npt.NDArray[np.float64]

if TYPE_CHECKING:
    from ..core.standard._moments import Moments

T = TypeVar("T")
R = TypeVar("R")


def _reader() -> Callable[[str, Iterable[str] | None, SourceOptions], Record]:
    from ..data.readers import read_record

    return read_record


#: glibc returns freed blocks above 128 KiB to the system at once, so every column-sized
#: temporary (2.9 MB for an hour at 100 Hz) was page-faulted in afresh: 9 of 17 CPU seconds
#: of the 600-signal hour were the kernel's. Blocks up to this size stay in the heap, and the
#: heap keeps this much free memory for the next one (docs/performance.md, "Allocator").
ALLOCATOR_KEEP_BYTES = 1 << 27
_allocator_tuned = threading.Event()


def _tune_allocator() -> None:
    """Keep column-sized blocks in glibc's heap (once per process; Linux only, and never
    against a MALLOC_MMAP_THRESHOLD_ or MALLOC_TRIM_THRESHOLD_ the user set)."""
    if _allocator_tuned.is_set():
        return
    _allocator_tuned.set()
    if not sys.platform.startswith("linux"):
        return
    if "MALLOC_MMAP_THRESHOLD_" in os.environ or "MALLOC_TRIM_THRESHOLD_" in os.environ:
        return
    import ctypes

    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:  # musl or another C library: leave it as it is
        return
    m_trim_threshold, m_mmap_threshold = -1, -3
    libc.mallopt(m_mmap_threshold, ALLOCATOR_KEEP_BYTES)
    libc.mallopt(m_trim_threshold, 2 * ALLOCATOR_KEEP_BYTES)


def _digest_or_empty(path: str, algorithm: str) -> dict[str, str]:
    try:
        return file_digest(path, algorithm)
    except OSError:
        return {}


class DataCache:
    """Reads each data file once per session, with the union of the columns every spec needs.

    Specs declare their columns at collection time (:meth:`declare`); the first :meth:`read` of
    a file then reads all declared columns in one go. A file's data are let go once every spec
    that declared it is done with it (:meth:`release`), so a campaign holds the data of the
    recordings being scored, not of every recording scored so far.
    """

    def __init__(self, data_hash: str = DEFAULT_HASH) -> None:
        _tune_allocator()
        #: How data files are identified in results (see :mod:`pytest_hevval.data.digest`).
        self.data_hash = data_hash
        self._lock = threading.Lock()
        self._records: dict[tuple[str, str], Record] = {}
        #: Every numeric column of a file, for the diagnosis's candidates (:meth:`read_whole`).
        self._whole: dict[tuple[str, str], Record] = {}
        self._declared: dict[tuple[str, str], set[str]] = {}
        #: Declarations not yet released, by file: the record is kept while any is left.
        self._users: dict[tuple[str, str], int] = {}
        self._digests: dict[str, Future[dict[str, str]]] = {}
        self._hasher: ThreadPoolExecutor | None = None
        #: How many times each file was actually read (tests and benchmarks check it).
        self.reads: dict[str, int] = {}

    @staticmethod
    def _key(source: SourceSpec) -> tuple[str, str]:
        options = source.options
        return (
            str(source.path),
            repr(
                (
                    options.time,
                    options.format,
                    options.sep,
                    options.encoding,
                    options.decimal,
                    options.group,
                    options.time_scale,
                    sorted(options.extra.items()),
                )
            ),
        )

    def declare(self, source: SourceSpec, columns: Iterable[str]) -> None:
        if source.kind != "file":
            return
        key = self._key(source)
        with self._lock:
            self._declared.setdefault(key, set()).update(columns)
            self._users[key] = self._users.get(key, 0) + 1

    def release(self, source: SourceSpec) -> None:
        """One declaration of ``source`` is done with it; the last one lets its data go."""
        if source.kind != "file":
            return
        key = self._key(source)
        with self._lock:
            left = self._users.get(key, 0) - 1
            if left > 0:
                self._users[key] = left
            else:
                self._users.pop(key, None)
                self._records.pop(key, None)
                self._whole.pop(key, None)

    def held(self) -> list[str]:
        """The files whose data this cache holds now."""
        with self._lock:
            return sorted(path for path, _ in self._records)

    def declare_spec(self, spec: Spec) -> None:
        """The columns ``spec`` reads from its reference and model files."""
        self.declare(spec.reference, spec.reference_columns())
        self.declare(spec.model, spec.model_columns())

    def release_spec(self, spec: Spec) -> None:
        """``spec`` is scored: its files' data may go (:meth:`release`)."""
        self.release(spec.reference)
        self.release(spec.model)

    def read(self, source: SourceSpec, columns: Iterable[str]) -> Record:
        key = self._key(source)
        wanted = set(columns)
        with self._lock:
            cached = self._records.get(key)
            if cached is not None and wanted <= set(cached.channels):
                return cached
            union = wanted | self._declared.get(key, set())
            if cached is not None:
                union |= set(cached.channels)
            while True:
                try:
                    record = _reader()(str(source.path), sorted(union), source.options)
                    break
                except DataError as exc:
                    # A column another spec declared and the file lacks is that spec's error,
                    # not this one's: read without it, and let that spec's own read say so.
                    if exc.column is None or exc.column in wanted or exc.column not in union:
                        raise
                    union.discard(exc.column)
                    self._declared.get(key, set()).discard(exc.column)
            self.reads[key[0]] = self.reads.get(key[0], 0) + 1
            self._records[key] = record
            self._start_digest(key[0])
            return record

    def read_whole(self, source: SourceSpec) -> Record:
        """Every numeric column of ``source``, read once and let go with its other data."""
        key = self._key(source)
        with self._lock:
            if key not in self._whole:
                self._whole[key] = _reader()(str(source.path), None, source.options)
                self.reads[key[0]] = self.reads.get(key[0], 0) + 1
            return self._whole[key]

    def _start_digest(self, path: str) -> Future[dict[str, str]]:
        # hashlib and xxhash release the GIL, so hashing overlaps with reading and scoring.
        if path not in self._digests:
            if self._hasher is None:
                self._hasher = ThreadPoolExecutor(max_workers=1, thread_name_prefix="hevval-hash")
            self._digests[path] = self._hasher.submit(_digest_or_empty, path, self.data_hash)
        return self._digests[path]

    def digest(self, path: str) -> dict[str, str]:
        """``{"hash": …, "digest": …}`` of a data file (empty if it could not be read)."""
        with self._lock:
            future = self._start_digest(path)
        return future.result()


@dataclass
class Evaluation:
    """A scored spec plus what diagnosis and reports need from the data."""

    spec: Spec
    result: SpecResult
    #: None when the spec was scored elsewhere (a Dask worker): only the result came back.
    aligned: AlignedData | None
    arrays: dict[str, tuple[FloatArray, FloatArray]] = field(default_factory=dict)
    characteristics: dict[str, SignalCharacteristics] = field(default_factory=dict)
    #: Diagnoses of the failing signals, by the signal diagnosed for them
    #: (:func:`pytest_hevval.scoring.diagnosis.diagnose_failures`), or why one failed.
    diagnoses: dict[str, SignalDiagnosis | HevvalError] = field(default_factory=dict)
    #: The cache the spec's data were read through; the diagnosis reads its candidates there.
    cache: DataCache | None = None


def _check_model_output(spec: Spec) -> None:
    """A campaign recording whose exported model output is missing fails before its data are
    read, naming both files."""
    path = spec.model.path
    if spec.recording is None or spec.model.kind != "file" or path is None or is_url(path):
        return
    if not os.path.exists(path):
        raise DataError(
            f"recording {spec.recording!r} has no model output: the file does not exist "
            f"(its measured data: {spec.reference.path})",
            file=path,
            hint="export the model's run of this recording to that file, or drop the "
            "recording from the campaign",
        )


def _load_model(
    spec: Spec, reference: Record, cache: DataCache, folders: list[Path]
) -> tuple[Record, dict[str, Any], ModelRuntime | None]:
    """The model's output, what identifies the model, and what running it cost (None for
    exported files: they ran elsewhere)."""
    model = spec.model
    if model.kind == "file":
        record = cache.read(model, spec.model_columns())
        # The file's digest is computed while the spec is scored; _spec_result waits for it.
        return record, {"path": model.path, "kind": "file"}, None
    runs = [_run_model(spec, reference, folders) for _ in range(spec.runtime.repeat)]
    record = runs[0]
    info: dict[str, Any]
    if model.kind == "callable":
        from ..data.models import callable_identity

        info = {
            "callable": model.callable,
            "params": dict(model.params),
            "kind": "callable",
            **callable_identity(str(model.callable)),
        }
    else:
        info = {"path": model.path, "kind": "fmu", "params": dict(model.params)}
        if record.meta.get("guid"):
            info["guid"] = record.meta["guid"]
        if record.meta.get("unscored"):
            # Outputs without numbers (text, bytes), left out when the spec names no outputs.
            info["unscored_outputs"] = dict(record.meta["unscored"])
    costs = [run.meta["cost"] for run in runs]
    peaks = [c.peak_bytes for c in costs if c.peak_bytes is not None]
    time = next(iter(record.channels.values())).time if record.channels else None
    runtime = ModelRuntime(
        kind=model.kind,
        simulated_s=float(time[-1] - time[0]) if time is not None and time.size else 0.0,
        wall_s=tuple(c.wall_s for c in costs),
        cpu_s=tuple(c.cpu_s for c in costs),
        peak_memory_bytes=max(peaks) if peaks else None,
        steps=record.meta.get("steps"),
        events=record.meta.get("events"),
        gate=RuntimeGate(spec.runtime.min_realtime_factor, spec.runtime.max_s, spec.runtime.clock)
        if spec.runtime.gated
        else None,
    )
    return record, info, runtime


def _run_model(spec: Spec, reference: Record, folders: list[Path]) -> Record:
    """One run of a model that runs itself (a callable or an FMU) on ``reference``."""
    model = spec.model
    if model.kind == "callable":
        from ..data.models import run_callable

        inputs = spec.callable_inputs()
        try:
            return run_callable(
                str(model.callable),
                reference,
                inputs=inputs,
                params=dict(model.params),
                reference_time=spec.reference.options.time or "time",
                model_time=model.options.time or "time",
                folders=folders,
                spec_file=str(spec.path),
                options=model.options,
                scored=spec.scored_reference_columns(),
            )
        except DataError as exc:
            # The spec's `model:` line: where the inputs it names are given.
            raise exc.with_context(line=model.line) from None
    from ..data.fmu import run_fmu

    times = [c.time for c in reference.channels.values() if c.time.shape[0]]
    if not times:
        raise DataError("the reference has no samples to drive the FMU", file=str(spec.path))
    run = model.fmu_run
    start = max(float(t[0]) for t in times) if run.start_time is None else run.start_time
    stop = min(float(t[-1]) for t in times) if run.stop_time is None else run.stop_time
    return run_fmu(
        str(model.path),
        reference,
        dict(model.fmu_inputs),
        dict(model.fmu_outputs),
        start_time=start,
        stop_time=stop,
        step_size=model.step_size,
        parameters=dict(model.params),
        interface=run.interface,
        tolerance=run.tolerance,
    )


def _check_model_columns(node: SignalSpec, model: Record) -> tuple[str, ...]:
    """The model columns a signal reads; one a model callable did not return is the spec
    line's error (the output is no file to point at)."""
    names = _columns_of(node.sim, model)
    if model.meta.get("model_output"):
        for name in names:
            if name not in model.channels:
                error = model_column_error(model, name)
                raise DataError(
                    f"{model.source}: {error.problem}",
                    column=name,
                    line=node.line,
                    key=f"{node.key}.sim",
                    hint=error.hint,
                )
    return names


def _columns_of(expression: Expression, record: Record) -> tuple[str, ...]:
    """Columns an expression reads; a whole-string column name wins over a parse of it."""
    if not expression.is_column and expression.source in record.channels:
        return (expression.source,)
    return expression.columns


def _signal_side(
    aligned: AlignedData,
    side: str,
    expression: Expression,
    node: SignalSpec,
) -> Side:
    """One side of a signal on the grid, or a logged column as it is, off the grid, as the
    :class:`Interpolation` that puts it there where it is used (see ``_SignalArrays``)."""
    record = aligned.reference if side == "reference" else aligned.model
    # A CAN log's signals hold their value between frames; other sources are interpolated.
    method = node.interpolation or record.meta.get("interpolation", "linear")
    names = _columns_of(expression, record)
    unit_from = node.ref_unit if side == "reference" else node.sim_unit
    # The conversion, when its units differ: (from, to).
    converted = (
        (unit_from, node.unit) if unit_from and node.unit and unit_from != node.unit else None
    )
    scale = node.ref_scale if side == "reference" else node.sim_scale
    offset = node.ref_offset if side == "reference" else node.sim_offset
    as_logged = expression.is_column or names == (expression.source,)
    if as_logged and converted is None and scale == 1.0 and offset == 0.0:
        deferred = aligned.deferred_column(side, names[0], method)  # type: ignore[arg-type]
        if deferred is not None:
            return deferred
    columns = aligned.columns(side, names, method)  # type: ignore[arg-type]
    if as_logged:
        values = columns[names[0]]
    else:
        values = np.asarray(expression.evaluate(columns, aligned.time), dtype=np.float64)
    if converted is not None:
        values = _convert_units(values, *converted, node, side)
    if scale != 1.0 or offset != 0.0:
        values = _scaled(values, scale, offset, node, side)
    return values


def _scaled(
    values: FloatArray, scale: float, offset: float, node: SignalSpec, side: str
) -> FloatArray:
    """``values * scale + offset``, or the error naming the key that takes them beyond what
    float64 holds (the range the signal is normalised by included)."""
    with np.errstate(over="ignore", invalid="ignore"):
        result = values * scale + offset
        finite = result[np.isfinite(result)]
        spread = float(finite.max() - finite.min()) if finite.size else 0.0
    overflowed = np.isinf(result) & np.isfinite(values)
    if not (bool(overflowed.any()) or math.isinf(spread)):
        return result
    prefix = "ref" if side == "reference" else "sim"
    key = f"{prefix}_scale" if scale != 1.0 else f"{prefix}_offset"
    largest = float(np.nanmax(np.abs(values))) if values.size else 0.0
    raise ExpressionError(
        f"{key} {scale if scale != 1.0 else offset:g} takes the {side} side beyond what float64 "
        f"holds (its largest magnitude is {largest:g})",
        key=f"{node.key}.{key}",
        line=node.line,
        hint=f"check {key}: it converts the data to the signal's unit",
    )


def _convert_units(
    values: FloatArray, source_unit: str, target_unit: str, node: SignalSpec, side: str
) -> FloatArray:
    try:
        import pint
    except ImportError:
        from ..errors import MissingExtraError

        raise MissingExtraError.for_extra("unit conversion", "units", "pint") from None
    registry = _unit_registry()
    try:
        quantity = registry.Quantity(values, source_unit)
        return np.asarray(quantity.to(target_unit).magnitude, dtype=np.float64)
    except (pint.errors.PintError, ValueError, TypeError) as exc:
        key = "ref_unit" if side == "reference" else "sim_unit"
        raise ExpressionError(
            f"cannot convert {source_unit!r} to {target_unit!r}: {exc}",
            key=f"{node.key}.{key}",
            line=node.line,
        ) from None


_REGISTRY: Any = None


def _unit_registry() -> Any:
    global _REGISTRY
    if _REGISTRY is None:
        import pint

        _REGISTRY = pint.UnitRegistry()
    return _REGISTRY


def _signature(node: SignalSpec) -> tuple[Any, ...]:
    """Two nodes with the same signature are the same signal: score it once."""
    return (
        node.ref.source,
        node.sim.source,
        node.interpolation,
        node.reference_range,
        node.unit,
        node.ref_unit,
        node.sim_unit,
        node.ref_scale,
        node.ref_offset,
        node.sim_scale,
        node.sim_offset,
    )


def evaluate_spec(
    spec: Spec,
    *,
    cache: DataCache | None = None,
    rootdir: Path | None = None,
    figures: bool = False,
    keep_arrays: bool = False,
    workers: int | None = None,
    intervals: bool = True,
) -> Evaluation:
    """Score every signal of ``spec`` against its reference. Raises HevvalError on bad input.

    ``intervals``: give every λ and Φ its bootstrap interval (one more pass per signal).
    """
    try:
        return _evaluate(
            spec, cache or DataCache(), rootdir, figures, keep_arrays, workers, intervals
        )
    except HevvalError as exc:
        raise exc.with_context(file=str(spec.path)) from None


Signature = tuple[Any, ...]
NodePath = tuple[str, ...]


def _evaluate(
    spec: Spec,
    cache: DataCache,
    rootdir: Path | None,
    figures: bool,
    keep_arrays: bool,
    workers: int | None,
    intervals: bool = True,
) -> Evaluation:
    folders = [spec.path.parent] + ([rootdir] if rootdir else [])
    _check_model_output(spec)
    reference = cache.read(spec.reference, spec.reference_columns())
    nodes = list(spec.walk())
    kernel.expect(len(nodes) * max((c.values.size for c in reference.channels.values()), default=0))
    model_record, model_info, runtime = _load_model(spec, reference, cache, folders)
    aligned = _align(spec, nodes, reference, model_record, workers)
    unique, values = _signal_arrays(nodes, aligned, reference)
    dt = aligned.grid.dt
    labels = _labels(spec, aligned)
    scored = _fused_characteristics(
        spec,
        unique,
        values,
        dt,
        workers,
        labels,
        intervals,
        aligned if figures else None,
    )
    fused, local = scored.characteristics, scored.local
    registered = _registered_characteristics(spec, unique, values, dt, scored.standard)
    node_specs = {path: node for _, path, node in nodes}
    roots = _score_trees(spec, node_specs, fused, registered)
    failures = _gate(spec, roots, node_specs)
    within = _measurement_checks(spec, failures, node_specs, fused, values)
    missed_locally = {
        path: local_failures(spec, node, labels, local.get(_signature(node)))
        for path, node in node_specs.items()
    }
    signals: list[SignalResult] = []
    arrays: dict[str, tuple[FloatArray, FloatArray]] = {}
    characteristics: dict[str, SignalCharacteristics] = {}
    for scored_node in iter_nodes(roots):
        node = node_specs[scored_node.path]
        signature = _signature(node)
        chars = fused[signature]
        signals.append(
            _signal_result(
                spec,
                node,
                scored_node,
                chars,
                {name: parts for name, (_, parts) in registered[signature].items() if parts},
                failures,
                scored.figures.get(signature),
                local.get(signature),
                missed_locally,
            )
        )
        characteristics[signals[-1].path] = chars
        if keep_arrays:
            arrays[signals[-1].path] = values[signature]
    for signal in signals:
        signal.within_uncertainty = within.get(signal.path, [])
    result = _spec_result(spec, signals, aligned, model_info, cache)
    result.runtime = runtime
    if intervals:
        blocks = _block_sums({k: values[k] for k in values if k not in scored.blocks}, workers)
        _add_intervals(spec, result, roots, node_specs, fused, {**scored.blocks, **blocks})
    result.local = spec_local_summary(
        spec, labels, [(s.alpha, s.local) for s in signals if s.local is not None], result.weights
    )
    if spec.campaign is not None:
        _add_campaign_facts(spec, result, scored.u_distributions, node_specs)
    return Evaluation(
        spec=spec,
        result=result,
        aligned=aligned,
        arrays=arrays,
        characteristics=characteristics,
        cache=cache,
    )


def _check_rate_limits(spec: Spec, examined: set[str]) -> None:
    """A rate limit on a channel the quality check does not examine would never run: a
    misspelt channel, most likely, which the spec must hear of."""
    for channel in spec.data_quality.rate_limits:
        if channel not in examined:
            suggestion = did_you_mean(channel, sorted(examined))
            raise SpecError(
                "no signal of the spec reads this measured channel, so its rate limit "
                "would never be checked",
                file=str(spec.path),
                key=f"data_quality.rate_limits.{channel}",
                hint=suggestion
                or "name a measured channel the spec reads: "
                + ", ".join(repr(c) for c in sorted(examined)[:12]),
            )


def _align(
    spec: Spec,
    nodes: list[tuple[int, NodePath, SignalSpec]],
    reference: Record,
    model_record: Record,
    workers: int | None = None,
) -> AlignedData:
    """Both records on one time grid, with the columns every signal reads."""
    ref_columns: set[str] = set()
    model_columns: set[str] = set()
    for _, _, node in nodes:
        ref_columns.update(_columns_of(node.ref, reference))
        model_columns.update(_check_model_columns(node, model_record))
    for expression in _local_expressions(spec):
        ref_columns.update(_columns_of(expression, reference))
    alignment = spec.alignment
    _check_rate_limits(spec, ref_columns)
    # On the scoring threads: the channels' values are examined side by side.
    findings = assess(
        reference, sorted(ref_columns), spec.data_quality, threads=scoring_threads(workers)
    )
    if spec.data_quality.action == "error":
        fail_on(findings, reference.source)
    # Whether each model column is finite, found side by side before the alignment asks column
    # by column (the checks above found the reference's).
    per_item(
        lambda channel: channel.finite,
        [model_record.channels[n] for n in sorted(model_columns) if n in model_record.channels],
        scoring_threads(workers),
    )
    aligned = align_records(
        reference,
        model_record,
        reference_columns=sorted(ref_columns),
        model_columns=sorted(model_columns),
        rate_hz=alignment.rate_hz,
        window=alignment.window,
        offset_s=alignment.offset_s,
        offset_from=alignment.offset_from,
        max_offset_s=alignment.max_offset_s,
        # Scoring around bad stretches includes stretches of NaN.
        nan_policy="omit" if spec.data_quality.action == "omit" else alignment.nan,
        by=alignment.by,
    )
    aligned.quality = findings
    if findings and spec.data_quality.action == "omit":
        bad = mask_on_grid(findings, aligned.time)
        aligned.gap_mask = bad if aligned.gap_mask is None else aligned.gap_mask | bad
    return aligned


def _local_expressions(spec: Spec) -> list[Expression]:
    """The reference expressions that cut a record into phases, conditions and cells."""
    expressions: list[Expression] = []
    if spec.local is not None:
        if spec.local.phases is not None:
            expressions.append(spec.local.phases)
        expressions.extend(c.expression for c in spec.local.conditions)
    if spec.regions is not None:
        expressions.extend(spec.regions.by)
    return expressions


def _reference_values(aligned: AlignedData, expression: Expression, key: str) -> FloatArray:
    """A reference column or expression on the grid (phases, conditions, region variables)."""
    record = aligned.reference
    names = _columns_of(expression, record)
    method = record.meta.get("interpolation", "linear")
    try:
        columns = aligned.columns("reference", names, method)
        if expression.is_column or names == (expression.source,):
            return np.asarray(columns[names[0]], dtype=np.float64)
        return np.asarray(expression.evaluate(columns, aligned.time), dtype=np.float64)
    except ExpressionError as exc:
        raise exc.with_context(key=key) from None


def _labels(spec: Spec, aligned: AlignedData) -> Labels | None:
    keep = None
    if aligned.gap_mask is not None and aligned.gap_mask.any():
        keep = ~aligned.gap_mask
    try:
        return label_samples(
            spec,
            aligned.time,
            keep,
            lambda expression, key: _reference_values(aligned, expression, key),
        )
    except DegenerateSignalError as exc:
        raise exc.with_context(key="regions") from None


def _block_sums(
    values: Mapping[Signature, tuple[FloatArray, FloatArray]], workers: int | None
) -> dict[Signature, BlockSums]:
    """Each distinct signal's sums over consecutive fine blocks, for its bootstrap intervals.

    The signals are summed as stacks, one stack per scoring thread.
    """
    if not values:
        return {}
    signatures = list(values)
    threads = max(1, min(scoring_threads(workers), len(signatures)))
    size = -(-len(signatures) // threads)
    shares = [signatures[i : i + size] for i in range(0, len(signatures), size)]

    def sums(share: list[Signature]) -> list[tuple[Signature, BlockSums]]:
        found = block_sums_many([values[signature] for signature in share])
        return list(zip(share, found, strict=True))

    return dict(pair for share in per_item(sums, shares, threads) for pair in share)


def _add_intervals(
    spec: Spec,
    result: SpecResult,
    roots: list[ScoredNode],
    node_specs: Mapping[NodePath, SignalSpec],
    fused: Mapping[Signature, SignalCharacteristics],
    blocks: Mapping[Signature, BlockSums],
) -> None:
    """Every λ and Φ of ``result`` gets its bootstrap interval."""
    confidence = spec_confidence(
        roots,
        lambda path: _signature(node_specs[path]),
        blocks,
        {signature: chars.reference_range for signature, chars in fused.items()},
        result.phi,
        result.weights,
        correlation=spec.correlation,
        variant=spec.emergent,
    )
    result.phi_interval = confidence.phi
    # result.signals were made in iter_nodes order (a name may itself hold a "/").
    for node, signal in zip(iter_nodes(roots), result.signals, strict=True):
        signal.intervals = confidence.signals[node.path]
        signal.block_samples = confidence.block_samples[node.path]


Side = FloatArray | Interpolation


class _SignalArrays(Mapping[Signature, tuple[FloatArray, FloatArray]]):
    """Each distinct signal's aligned (reference, simulated) arrays, gaps removed.

    A side that is an off-grid column as logged is kept as its :class:`Interpolation` and put
    on the grid where it is used: into a thread's buffers by :meth:`pair` (the scoring pass),
    into new arrays by ``self[signature]`` (whatever reads a signal after it). So a spec of
    many interpolated columns never holds them all at full length, and the memory they are
    written into is written once per thread, not once per column.
    """

    def __init__(self, sides: dict[Signature, tuple[Side, Side]], n: int) -> None:
        self._sides = sides
        self._n = n

    def __getitem__(self, signature: Signature) -> tuple[FloatArray, FloatArray]:
        ref, sim = self._sides[signature]
        return _on_grid(ref, None), _on_grid(sim, None)

    def __iter__(self) -> Iterator[Signature]:
        return iter(self._sides)

    def __len__(self) -> int:
        return len(self._sides)

    def pair(self, signature: Signature, buffers: threading.local) -> tuple[FloatArray, FloatArray]:
        """The signal's arrays, an interpolated side written into this thread's buffer for
        that side (valid until the thread's next call)."""
        ref, sim = self._sides[signature]
        return self._into(ref, buffers, "ref"), self._into(sim, buffers, "sim")

    def _into(self, side: Side, buffers: threading.local, name: str) -> FloatArray:
        if not isinstance(side, Interpolation):
            return side
        out = getattr(buffers, name, None)
        if out is None:
            out = np.empty(self._n, dtype=np.float64)
            setattr(buffers, name, out)
        return side.into(out)


def _on_grid(side: Side, buffer: FloatArray | None) -> FloatArray:
    return side.into(buffer) if isinstance(side, Interpolation) else side


def _signal_arrays(
    nodes: list[tuple[int, NodePath, SignalSpec]], aligned: AlignedData, reference: Record
) -> tuple[dict[Signature, SignalSpec], _SignalArrays]:
    """The aligned (reference, simulated) arrays of each distinct signal, gaps removed."""
    # Evaluate each distinct signal once, even when it appears in several sets.
    unique: dict[Signature, SignalSpec] = {}
    for _, _, node in nodes:
        unique.setdefault(_signature(node), node)
    sides: dict[Signature, tuple[Side, Side]] = {}
    for signature, node in unique.items():
        pair: list[Side] = []
        for side, expression, key in (("reference", node.ref, "ref"), ("model", node.sim, "sim")):
            try:
                pair.append(_signal_side(aligned, side, expression, node))
            except ExpressionError as exc:
                raise exc.with_context(line=node.line, key=f"{node.key}.{key}") from None
        sides[signature] = (pair[0], pair[1])
    if aligned.gap_mask is not None and aligned.gap_mask.any():
        # Scoring around gaps copies every signal anyway.
        keep = ~aligned.gap_mask
        sides = {
            k: (_on_grid(r, None)[keep], _on_grid(s, None)[keep]) for k, (r, s) in sides.items()
        }
    # Sides put on the grid where they are used exist only without gaps: grid-long.
    return unique, _SignalArrays(sides, aligned.grid.n_samples)


def scoring_threads(workers: int | None) -> int:
    """Threads a spec's signals are scored (and its failing signals diagnosed) on: as asked,
    else up to two."""
    return workers if workers is not None else min(2, os.cpu_count() or 1)


def per_item(score: Callable[[T], R], items: list[T], threads: int) -> list[R]:
    """``score`` of every item in order, on ``threads`` threads when there is more than one.

    numpy's loops and the compiled kernel release the GIL, so signals score side by side.
    """
    if threads > 1 and len(items) > 1:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            return list(pool.map(score, items))
    return [score(item) for item in items]


Scored = tuple[float, dict[str, float]]


@dataclass
class _SignalPass:
    """What one distinct signal's pass on its scoring thread found."""

    characteristics: dict[Signature, SignalCharacteristics] = field(default_factory=dict)
    local: dict[Signature, LocalResult] = field(default_factory=dict)
    #: The standard metrics: value and components by name.
    standard: dict[Signature, dict[str, Scored]] = field(default_factory=dict)
    #: Fine-block sums for the intervals, of records not summed as a stack.
    blocks: dict[Signature, BlockSums] = field(default_factory=dict)
    #: The report's figure data, when asked for.
    figures: dict[Signature, dict[str, Any]] = field(default_factory=dict)
    #: A campaign recording's u-pooling distributions.
    u_distributions: dict[Signature, list[float]] = field(default_factory=dict)


def _fused_characteristics(
    spec: Spec,
    unique: dict[Signature, SignalSpec],
    values: _SignalArrays,
    dt: float,
    workers: int | None,
    labels: Labels | None,
    intervals: bool = False,
    figures_of: AlignedData | None = None,
) -> _SignalPass:
    """λ1–λ6 and the physical errors of each distinct signal, from the core's fused pass, and
    with ``labels`` the signal over the spec's windows, phases, conditions and cells: the same
    pass sums them, and the tables' λ come from one vectorised call for all signals after the
    pass (a call per signal took turns at the interpreter with the other threads). The spec's
    standard metrics are scored on the same thread, those built on moments from the pass's
    sums, and with ``intervals`` the fine-block sums of a record not summed as a stack
    (``block_sums_stacked``) are taken there too, while the signal is fresh in cache; so are
    the figures (with ``figures_of``, the grid they are drawn on) and a campaign recording's u
    distributions. Nothing else reads the signals' arrays unless asked, so a column put on the
    grid here (``_SignalArrays``) goes into a buffer the thread keeps for its next signal."""
    n_workers = scoring_threads(workers)
    metrics = [c for c in spec.characteristics() if c.compute is not None and c.standard]
    if metrics:
        # Only then: the standard metrics' package imports scipy.signal, a tenth of a second.
        from ..core.standard._moments import moments_from_pass
    found = _SignalPass()
    buffers = threading.local()
    local: dict[Signature, LocalSums] = {}

    def score(item: tuple[Signature, SignalSpec]) -> HevvalError | None:
        signature, node = item
        ref, sim = values.pair(signature, buffers)
        group_runs = labels.grouping.runs(ref, sim) if labels is not None else None
        try:
            chars = signal_characteristics(
                ref,
                sim,
                dt=dt,
                max_lag_s=spec.alignment.max_lag_s,
                correlation=spec.correlation,
                reference_range=node.reference_range,
                workers=1 if len(unique) > 1 else n_workers,
                group_runs=group_runs,
            )
        except DegenerateSignalError as exc:
            return exc.with_context(line=node.line, key=node.key)
        if metrics and chars.sums is not None:
            moments = moments_from_pass(chars.sums, ref, sim)
            try:
                found.standard[signature] = _characteristics_of(
                    metrics, node, ref, sim, dt, moments
                )
            except HevvalError as exc:
                return exc
        if labels is not None:
            local[signature] = local_sums(labels, ref, sim, chars.reference_range, chars.group_sums)
        if intervals and not block_sums_stacked(int(ref.shape[0])):
            found.blocks[signature] = block_sums_many([(ref, sim)])[0]
        if figures_of is not None:
            found.figures[signature] = _figures(ref, sim, chars, figures_of)
        if spec.campaign is not None:
            u_distribution = _u_distribution(ref, sim)
            if u_distribution is not None:
                found.u_distributions[signature] = u_distribution
        # The sums have served: a spec keeps its signals' characteristics to the end.
        found.characteristics[signature] = replace(chars, sums=None, group_sums=None)
        return None

    # Each thread writes its own signals' entries; the errors are raised in signal order.
    for error in per_item(score, list(unique.items()), n_workers):
        if error is not None:
            raise error
    found.characteristics = {s: found.characteristics[s] for s in unique}
    if labels is not None:
        found.local = dict(
            zip(local, local_results(labels, list(local.values()), spec.correlation), strict=True)
        )
    return found


def _registered_characteristics(
    spec: Spec,
    unique: dict[Signature, SignalSpec],
    values: Mapping[Signature, tuple[FloatArray, FloatArray]],
    dt: float,
    standard: Mapping[Signature, Mapping[str, Scored]],
) -> dict[Signature, dict[str, Scored]]:
    """Each distinct signal's registered (non-built-in) characteristics: value and components.

    The standard metrics come scored from the fused pass's threads (``standard``); a user's
    ``compute`` runs here, one signal after another, as its author may expect.
    """
    wanted = [c for c in spec.characteristics() if c.compute is not None]
    users = [c for c in wanted if not c.standard]
    out: dict[Signature, dict[str, Scored]] = {}
    for signature, node in unique.items():
        found = dict(standard.get(signature, {}))
        if users:
            ref, sim = values[signature]
            found.update(_characteristics_of(users, node, ref, sim, dt))
        out[signature] = {c.name: found[c.name] for c in wanted}
    return out


def _characteristics_of(
    characteristics: list[Characteristic],
    node: SignalSpec,
    ref: FloatArray,
    sim: FloatArray,
    dt: float,
    moments: Moments | None = None,
) -> dict[str, Scored]:
    """``characteristics`` of one signal pair, an error naming the signal's spec line."""
    out: dict[str, Scored] = {}
    for characteristic in characteristics:
        try:
            scored = compute_characteristic(characteristic, ref, sim, dt, moments)
        except CharacteristicError as exc:
            raise CharacteristicError(
                f"{exc.problem} for signal {node.name!r}",
                line=node.line,
                key=node.key,
                hint=exc.hint,
            ) from None
        except Exception as exc:
            raise CharacteristicError(
                f"characteristic {characteristic.name!r} failed on signal {node.name!r}: "
                f"{type(exc).__name__}: {exc}",
                line=node.line,
                key=node.key,
                hint="fix its compute(ref, sim, dt) function",
            ) from exc
        out[characteristic.name] = (scored.value, dict(scored.components))
    return out


def _score_trees(
    spec: Spec,
    node_specs: Mapping[NodePath, SignalSpec],
    fused: Mapping[Signature, SignalCharacteristics],
    registered: Mapping[Signature, Mapping[str, tuple[float, dict[str, float]]]],
) -> list[ScoredNode]:
    """Every set scored: each node's characteristics keyed by name, λ7 added on the tree."""

    def base(path: NodePath) -> dict[str, float]:
        signature = _signature(node_specs[path])
        own = fused[signature].values
        own.update((name, value) for name, (value, _) in registered[signature].items())
        return own

    return [
        score_tree(_tree_of(root), base, set_index=index, variant=spec.emergent)
        for index, root in enumerate(spec.sets, start=1)
    ]


def _gate(
    spec: Spec, roots: list[ScoredNode], node_specs: Mapping[NodePath, SignalSpec]
) -> dict[NodePath, list[Failure]]:
    """Each node's characteristics below their thresholds."""
    failures: dict[NodePath, list[Failure]] = {}
    for scored_node in iter_nodes(roots):
        thresholds = spec.thresholds_for(scored_node.path, node_specs[scored_node.path])
        failures[scored_node.path] = [
            Failure(name, scored_node.lambdas[name], limit)
            for name, limit in thresholds.items()
            if scored_node.lambdas[name] < limit
        ]
    return failures


def _measurement_checks(
    spec: Spec,
    failures: dict[NodePath, list[Failure]],
    node_specs: Mapping[NodePath, SignalSpec],
    fused: Mapping[Signature, SignalCharacteristics],
    values: Mapping[Signature, tuple[FloatArray, FloatArray]],
) -> dict[str, list[Failure]]:
    """Each missed error threshold (λ3–λ6) with its limit, margin and measurement uncertainty.

    Rewrites ``failures`` in place. With ``measurement.within_uncertainty: pass`` a miss within
    the uncertainty leaves ``failures`` and is returned instead, by signal path.
    """
    from ..core.measurement import ERROR_CHARACTERISTICS
    from ..results.measurement import check_error

    passing = spec.measurement.within_uncertainty == "pass"
    within: dict[str, list[Failure]] = {}
    for path, missed in failures.items():
        if not any(f.characteristic in ERROR_CHARACTERISTICS for f in missed):
            continue
        node = node_specs[path]
        signature = _signature(node)
        errors = fused[signature].as_dict()
        declared = node.uncertainty
        reference_rms = 0.0
        if declared is not None and declared.rel > 0:
            reference = values[signature][0]
            reference_rms = float(np.sqrt(np.mean(np.square(reference))))
        kept: list[Failure] = []
        for failure in missed:
            if failure.characteristic in ERROR_CHARACTERISTICS:
                error_key, _ = ERROR_CHARACTERISTICS[failure.characteristic]
                failure = replace(
                    failure,
                    check=check_error(
                        float(errors[error_key]),  # type: ignore[arg-type]
                        failure.threshold,
                        float(errors["reference_range"]),  # type: ignore[arg-type]
                        declared,
                        reference_rms,
                    ),
                )
                if passing and failure.within_uncertainty:
                    within.setdefault("/".join(path), []).append(failure)
                    continue
            kept.append(failure)
        failures[path] = kept
    return within


def _figures(
    ref: FloatArray, sim: FloatArray, chars: SignalCharacteristics, aligned: AlignedData
) -> dict[str, Any]:
    from ..core.figures import figure_data

    return figure_data(
        ref,
        sim,
        dt=aligned.grid.dt,
        start_s=aligned.grid.start_s,
        max_lag=chars.lag_search.max_lag if chars.lag_search else 0,
        # About one point per pixel of the page's plots; the JSON stays half the size.
        points=1000,
        search=chars.lag_search,
    )


def _signal_result(
    spec: Spec,
    node: SignalSpec,
    scored_node: ScoredNode,
    chars: SignalCharacteristics,
    components: dict[str, dict[str, float]],
    failures: Mapping[NodePath, list[Failure]],
    figures: dict[str, Any] | None,
    local: LocalResult | None,
    missed_locally: Mapping[NodePath, list[LocalFailure]],
) -> SignalResult:
    path = scored_node.path

    def failed(candidate: ScoredNode) -> bool:
        return bool(failures[candidate.path] or missed_locally[candidate.path])

    origins = error_origins(scored_node, failed)
    return SignalResult(
        path="/".join(path),
        name=node.name,
        set=scored_node.set_index,
        level=scored_node.level,
        position=scored_node.position,
        alpha=scored_node.alpha,
        line=node.line,
        lambdas=dict(scored_node.lambdas),
        characteristics=chars,
        components=components,
        thresholds=spec.thresholds_for(path, node),
        failures=failures[path],
        unit=node.unit,
        description=node.description,
        origin=failed(scored_node) and origins == (scored_node,),
        origins=["/".join(o.path) for o in origins],
        children=["/".join(c.path) for c in scored_node.children],
        figures=figures,
        local=local,
        local_failures=missed_locally[path],
        requirements=list(node.requirements),
    )


def _spec_result(
    spec: Spec,
    signals: list[SignalResult],
    aligned: AlignedData,
    model_info: dict[str, Any],
    cache: DataCache,
) -> SpecResult:
    weights = spec.beta()
    phi = global_metric(((s.alpha, s.lambdas) for s in signals), weights)
    return SpecResult(
        name=spec.name,
        spec=spec.key,
        spec_hash=spec.text_hash,
        phi=phi,
        min_phi=spec.min_phi,
        min_phi_line=spec.min_phi_line,
        min_phi_on=spec.min_phi_on,
        weights=weights,
        signals=signals,
        requirements=list(spec.requirements),
        data={
            "reference": {
                "path": spec.reference.path,
                **cache.digest(str(spec.reference.path)),
            },
            "model": _with_digest(model_info, cache),
            **(
                {
                    "quality": {
                        "action": spec.data_quality.action,
                        "findings": [f.to_dict() for f in aligned.quality],
                    }
                }
                if aligned.quality
                else {}
            ),
        },
        alignment={
            "rate_hz": aligned.grid.rate_hz,
            "start_s": aligned.grid.start_s,
            "stop_s": aligned.grid.stop_s,
            "n_samples": aligned.grid.n_samples,
            "offset_s": aligned.offset_s,
            "offset_found": aligned.offset_found,
            "coverage": aligned.coverage,
            "by": aligned.by,
            **({"clock_offset_s": aligned.clock_offset_s} if aligned.by == "clock" else {}),
            **(
                {"absolute_start": aligned.absolute_start()}
                if aligned.absolute_start() is not None
                else {}
            ),
        },
    )


def _with_digest(model_info: dict[str, Any], cache: DataCache) -> dict[str, Any]:
    """A model file's entry with its digest after its path (a callable has neither)."""
    if "path" not in model_info:
        return model_info
    path = model_info["path"]
    return {"path": path, **cache.digest(str(path)), **model_info}


def _add_campaign_facts(
    spec: Spec,
    result: SpecResult,
    u_distributions: Mapping[Signature, list[float]],
    node_specs: Mapping[NodePath, SignalSpec],
) -> None:
    """A campaign recording's result names its recording and keeps what pools over them."""
    assert spec.campaign is not None
    result.name = f"{spec.name} · {spec.recording}"
    result.recording = spec.recording
    result.role = spec.role
    result.campaign = {
        "name": spec.name,
        "recordings": [r.id for r in spec.campaign.recordings],
        "min_pass_rate": spec.campaign.min_pass_rate,
        "phi_quantile": list(spec.campaign.phi_quantile) if spec.campaign.phi_quantile else None,
        "line": spec.campaign.line,
    }
    if spec.campaign.unused_models:
        result.campaign["unused_models"] = list(spec.campaign.unused_models)
    for signal in result.signals:
        found = u_distributions.get(_signature(node_specs[tuple(signal.path.split("/"))]))
        if found is not None:
            signal.u_distribution = found


def _u_distribution(ref: FloatArray, sim: FloatArray) -> list[float] | None:
    """A campaign signal's u-pooling distribution (its finite samples), if it has any."""
    finite = np.isfinite(ref)
    if finite.any() and np.isfinite(sim).any():
        return [float(x) for x in u_distribution_of(ref[finite], sim[np.isfinite(sim)])]
    return None


def _tree_of(node: SignalSpec) -> TreeNode:
    return TreeNode(
        name=node.name,
        alpha=node.alpha,
        children=tuple(_tree_of(child) for child in node.children),
    )


def summarise_origins(result: SpecResult) -> Mapping[str, SignalResult]:
    """The signals where errors appear, keyed by path."""
    return {s.path: s for s in result.signals if s.origin}

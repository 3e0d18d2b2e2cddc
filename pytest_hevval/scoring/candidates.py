"""The candidate effects of a scored spec on its aligned grid: the spec's declared
``candidates:`` expressions, every measured reference channel the spec does not use, read through
the spec's data cache, and the time derivative of each; and the unit each is measured in."""

from __future__ import annotations

import ast
import contextlib
from collections.abc import Mapping, Sequence

import numpy as np
import numpy.typing as npt

from ..core.residual import Candidate
from ..data.record import Record
from ..errors import DataError, HevvalError
from ..results.signal_diagnosis import candidate_unit
from ..spec.expressions import Expression
from .data_cache import DataCache
from .engine import Evaluation

__all__ = [
    "candidates_for",
    "declared_unit",
    "derivative_name",
    "derivative_window",
]

FloatArray = npt.NDArray[np.float64]


#: Channels beyond this many are not tried automatically (the spec's own come first).
MAX_CHANNELS = 50
#: Window of the centred mean applied to a channel before its derivative is taken.
DERIVATIVE_SMOOTHING_S = 1.0
#: A channel that changes less often than once per smoothing window is quantised (a state of
#: charge in 0.1 % steps, a limit that moves a few times a trip): its mean is taken over this
#: many of its steps before it is differentiated, so that its rate is a slope, not a row of
#: spikes ...
QUANTISED_SMOOTHING_STEPS = 5
#: ... and one that changes fewer times than this over the record has no derivative candidate:
#: a handful of steps says nothing of a rate.
MIN_DERIVATIVE_STEPS = 20


def _smoothed(values: FloatArray, window: int) -> FloatArray:
    if window <= 1:
        return values
    from scipy.ndimage import uniform_filter1d

    return np.asarray(uniform_filter1d(values, size=window, mode="nearest"), dtype=np.float64)


def _full_reference(evaluation: Evaluation) -> Record:
    """Every numeric channel of the reference file, read through the spec's data cache (once,
    and let go with the file's other data: :meth:`DataCache.read_whole`)."""
    spec = evaluation.spec
    assert evaluation.aligned is not None
    if spec.reference.kind == "file" and spec.reference.path:
        cache = evaluation.cache or DataCache()
        # If the whole file cannot be read, diagnose with the channels already read.
        with contextlib.suppress(DataError):
            return cache.read_whole(spec.reference)
    return evaluation.aligned.reference


def candidates_for(evaluation: Evaluation, *, channels: bool = True) -> list[Candidate]:
    """Declared expressions, then unused channels and their derivatives, on the grid."""
    spec = evaluation.spec
    aligned = evaluation.aligned
    if aligned is None:
        return []
    time = aligned.time
    keep = None if aligned.gap_mask is None else ~aligned.gap_mask
    found: list[Candidate] = []

    def add(name: str, kind: str, values: FloatArray) -> None:
        # Scored arrays drop the grid points in gaps; candidates must drop the same ones.
        if keep is not None:
            values = values[keep]
        if np.all(np.isfinite(values)) and np.ptp(values) > 0:
            found.append(Candidate(name, kind, values))  # type: ignore[arg-type]

    for name, expression in spec.candidates.items():
        columns = aligned.columns("reference", expression.columns, "linear")
        try:
            add(name, "declared", np.asarray(expression.evaluate(columns, time), dtype=float))
        except HevvalError:
            continue
    if not channels:
        return found
    used: set[str] = set()
    for _, _, node in spec.walk():
        used.update(node.ref.columns)
        if node.ref.is_column:
            used.add(node.ref.source)
    record = _full_reference(evaluation)
    # Logged channels are quantised (GPS elevation in centimetre steps) or held between CAN
    # frames; differentiated sample by sample they are mostly steps. A centred 1 s mean first
    # keeps the slow slope the model may lack; a coarser channel is averaged over several of
    # its steps (derivative_window).
    smoothing = max(1, round(DERIVATIVE_SMOOTHING_S / aligned.grid.dt))
    time_name = spec.reference.options.time
    names = [
        n
        for n in (record.numeric or tuple(record.channels))
        if n not in used and n != time_name and n in record.channels
    ][:MAX_CHANNELS]
    for name in names:
        found_on_grid = _on_grid(record, name, time)
        if found_on_grid is None:
            continue
        on_grid, values = found_on_grid
        add(name, "channel", on_grid)
        window = derivative_window(values, smoothing, on_grid.shape[0])
        if window is not None:
            add(derivative_name(name), "derivative", np.gradient(_smoothed(on_grid, window), time))
    return found


def _on_grid(record: Record, name: str, time: FloatArray) -> tuple[FloatArray, FloatArray] | None:
    """A logged channel linearly on the grid, and its finite logged values; None when it
    holds fewer than three finite values."""
    channel = record.channels[name]
    values = np.asarray(channel.values, dtype=np.float64)
    ok = np.isfinite(values)
    if ok.sum() < 3:
        return None
    return np.interp(time, channel.time[ok], values[ok]), values[ok]


def derivative_window(values: FloatArray, smoothing: int, samples: int) -> int | None:
    """The centred mean's window (grid samples) before a channel is differentiated: the
    default ``smoothing``, or :data:`QUANTISED_SMOOTHING_STEPS` of its steps for a channel
    that changes less often than once per window; None (no derivative) for one that changes
    fewer than :data:`MIN_DERIVATIVE_STEPS` times."""
    steps = int(np.count_nonzero(np.diff(values)))
    if steps < MIN_DERIVATIVE_STEPS:
        return None
    spacing = samples / steps
    if spacing <= smoothing:
        return smoothing
    return min(samples, round(QUANTISED_SMOOTHING_STEPS * spacing))


def declared_unit(expression: Expression) -> str | None:
    """The unit of a declared candidate, read from the columns it uses: one column's, a sum or
    difference of columns in one unit, scaled by a number, or the derivative (``per s``) of
    one; None when the expression combines units otherwise (its unit is then unknown)."""
    if expression.is_column:
        return candidate_unit(expression.columns[0], "channel")
    # The parsed form the expression keeps: its tree and the columns behind its names.
    tree = expression._tree
    names = expression._names
    return None if tree is None else _unit_of(tree, names)


def _unit_of(node: ast.expr, names: Mapping[str, str]) -> str | None:
    if isinstance(node, ast.Name):
        column = names.get(node.id)
        return None if column is None else candidate_unit(column, "channel")
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
        return _unit_of(node.operand, names)
    if isinstance(node, ast.BinOp):
        if isinstance(node.op, (ast.Add, ast.Sub)):
            left, right = _unit_of(node.left, names), _unit_of(node.right, names)
            return left if left is not None and left == right else None
        if isinstance(node.op, (ast.Mult, ast.Div)) and isinstance(node.right, ast.Constant):
            return _unit_of(node.left, names)
        if isinstance(node.op, ast.Mult) and isinstance(node.left, ast.Constant):
            return _unit_of(node.right, names)
        return None
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.args:
        inner = _unit_of(node.args[0], names)
        if node.func.id == "smooth":
            return inner
        if node.func.id == "derivative" and inner is not None:
            return f"{inner}/s"
    return None


def _with_derivatives(names: Sequence[str]) -> tuple[str, ...]:
    """Names declared for a channel also cover its derivative candidate."""
    return (*names, *(derivative_name(n) for n in names))


def derivative_name(channel: str) -> str:
    """The name of the derivative candidate of a channel."""
    return f"d/dt {channel}"

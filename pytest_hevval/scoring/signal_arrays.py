"""Each distinct signal of a spec, put on the aligned grid once (reference and simulated side).

Two nodes reading the same columns the same way are one signal (:func:`signature_of`), scored
once however many sets name it. A side logged off the grid stays an interpolation until a
scoring thread writes it into its own buffer (:class:`SignalArrays`).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from ..data.align import AlignedData, Interpolation
from ..data.record import Record
from ..errors import ExpressionError
from ..spec.expressions import Expression
from ..spec.model import SignalSpec
from .units import convert_units, scaled

__all__ = [
    "NodePath",
    "Side",
    "SignalArrays",
    "Signature",
    "columns_of",
    "on_grid",
    "signal_arrays",
    "signature_of",
]

FloatArray = npt.NDArray[np.float64]


Signature = tuple[Any, ...]


NodePath = tuple[str, ...]


Side = FloatArray | Interpolation


def signature_of(node: SignalSpec) -> tuple[Any, ...]:
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


def columns_of(expression: Expression, record: Record) -> tuple[str, ...]:
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
    :class:`Interpolation` that puts it there where it is used (see ``SignalArrays``)."""
    record = aligned.reference if side == "reference" else aligned.model
    # A CAN log's signals hold their value between frames; other sources are interpolated.
    method = node.interpolation or record.meta.get("interpolation", "linear")
    names = columns_of(expression, record)
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
        values = convert_units(values, *converted, node, side)
    if scale != 1.0 or offset != 0.0:
        values = scaled(values, scale, offset, node, side)
    return values


class SignalArrays(Mapping[Signature, tuple[FloatArray, FloatArray]]):
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
        return on_grid(ref, None), on_grid(sim, None)

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


def on_grid(side: Side, buffer: FloatArray | None) -> FloatArray:
    return side.into(buffer) if isinstance(side, Interpolation) else side


def signal_arrays(
    nodes: list[tuple[int, NodePath, SignalSpec]], aligned: AlignedData, reference: Record
) -> tuple[dict[Signature, SignalSpec], SignalArrays]:
    """The aligned (reference, simulated) arrays of each distinct signal, gaps removed."""
    # Evaluate each distinct signal once, even when it appears in several sets.
    unique: dict[Signature, SignalSpec] = {}
    for _, _, node in nodes:
        unique.setdefault(signature_of(node), node)
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
        sides = {k: (on_grid(r, None)[keep], on_grid(s, None)[keep]) for k, (r, s) in sides.items()}
    # Sides put on the grid where they are used exist only without gaps: grid-long.
    return unique, SignalArrays(sides, aligned.grid.n_samples)

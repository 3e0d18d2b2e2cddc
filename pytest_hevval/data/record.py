"""The in-memory shape every reader returns: named channels, each with its own time base.

Files with one shared time column (CSV, Parquet, MAT, HDF5 tables) give every channel the same
time array object; MDF files may give each channel its own rate. Alignment onto the common grid
happens later, in :mod:`pytest_hevval.data.align`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from ..errors import DataError, did_you_mean

__all__ = [
    "Channel",
    "Reader",
    "Record",
    "SourceOptions",
    "all_finite",
    "missing_column",
    "model_column_error",
]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Channel:
    """One measured or simulated signal: strictly increasing ``time`` [s] and ``values``."""

    time: FloatArray
    values: npt.NDArray[np.floating]
    unit: str | None = None

    @property
    def finite(self) -> bool:
        """Whether every value is finite. Found once per channel: the data-quality checks, the
        alignment and the interpolation all ask, and on a long record each asking is a read
        of the whole column."""
        # Not functools.cached_property: before Python 3.12 it holds one lock for every
        # instance while it computes, which would make the channels' threads take turns.
        known: bool | None = self.__dict__.get("_finite")
        if known is None:
            known = all_finite(self.values)
            object.__setattr__(self, "_finite", known)
        return known


def all_finite(values: npt.NDArray[np.floating]) -> bool:
    """Whether every value is finite, usually in one pass that allocates nothing.

    A NaN or an infinity makes any sum that includes it non-finite, so a finite sum proves
    every value finite; only a sum that overflows (or a bad value) needs the exact look.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        total = float(np.add.reduce(values))
    return math.isfinite(total) or bool(np.isfinite(values).all())


@dataclass
class Record:
    """Channels read from one file (or produced by one model run)."""

    source: str
    channels: dict[str, Channel]
    #: Every channel name the source holds, read or not: for suggestions and diagnosis.
    available: tuple[str, ...] = ()
    #: Numeric channels the source holds (candidates for automatic diagnosis).
    numeric: tuple[str, ...] = ()
    meta: dict[str, Any] = field(default_factory=dict)

    def channel(self, name: str) -> Channel:
        try:
            return self.channels[name]
        except KeyError:
            if self.meta.get("model_output"):
                raise model_column_error(self, name) from None
            # A column the source holds but left out, such as an FMU's text output.
            unscored: Mapping[str, str] = self.meta.get("unscored", {})
            if name in unscored:
                raise DataError(
                    unscored[name],
                    file=self.source,
                    column=name,
                    hint="score a numeric column",
                ) from None
            raise missing_column(self.source, name, self.available or self.channels) from None


@dataclass(frozen=True)
class SourceOptions:
    """How to read one file; every field is optional in the spec."""

    time: str | None = None
    format: str | None = None
    sep: str | None = None
    encoding: str | None = None
    decimal: str | None = None
    #: HDF5 group / MAT struct / table key that holds the channels.
    group: str | None = None
    #: Multiply the time column by this to get seconds (e.g. 0.001 for ms); None when the
    #: spec does not say (a unit in the time column's header then decides).
    time_scale: float | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)


class Reader(Protocol):
    """A format reader: read only ``columns`` (all numeric ones when None)."""

    def __call__(
        self, path: str, columns: Iterable[str] | None, options: SourceOptions
    ) -> Record: ...


def model_column_error(record: Record, name: str) -> DataError:
    """The error for a column a model callable's output does not hold, or holds as text."""
    holds = record.meta.get("not_numeric", {}).get(name)
    if holds is not None:
        return DataError(
            f"holds {holds} in the model's output, not numbers",
            file=record.source,
            column=name,
            hint="return the column as numbers (float or int)",
        )
    return missing_column(
        record.source, name, record.available or record.channels, where="in the model's output"
    )


def missing_column(
    source: str, name: str, available: Iterable[str], *, where: str = "in this file"
) -> DataError:
    """The error for a column that is not in a file (or a model's output, ``where``), with the
    nearest names as a suggestion."""
    names = list(available)
    suggestion = did_you_mean(name, names)
    holder = "it" if where != "in this file" else "the file"
    hint = suggestion or (
        f"{holder} has {len(names)} columns: " + ", ".join(repr(n) for n in names[:12])
        if names
        else f"{holder} has no columns"
    )
    return DataError(f"no such column {where}", file=source, column=name, hint=hint)
